"""studies/hover/settle.py: the settle rule on synthetic series, the setback windows and the recommendation."""

from __future__ import annotations

import numpy as np
import pytest

from reach_jax.config import Config


@pytest.fixture
def tool(load_tool):
    return load_tool("studies/hover/settle")


def test_a_series_that_settles_at_a_known_point(tool):
    # damping falls from 60 N s/m and, from 800k trials on, alternates 19 / 21: inside the 3 N s/m band
    x = np.arange(0, 2_100_000, 100_000)
    y = np.where(x < 800_000, 60.0 - 2e-5 * x, 20.0 + (-1.0) ** (x // 100_000))
    final = y[-1]
    assert tool.settle_point(x, y, final, tool.damping_band(final)) == 800_000


def test_a_series_that_never_settles(tool):
    # swings between 10 and 40 N s/m: only the last point and one a chunk before it lie in the final value's band
    x = np.array([*range(0, 2_000_000, 100_000), 1_999_000, 2_000_000], dtype=float)
    y = np.array([10.0, 40.0] * 10 + [40.0, 40.0])
    assert tool.settle_point(x, y, y[-1], tool.damping_band(y[-1])) is None


def test_a_series_out_of_band_at_its_end_has_not_settled(tool):
    assert tool.settle_point([0, 1e6, 2e6], [5.0, 5.0, 9.0], 5.0, 1.0) is None


def test_the_band_is_relative_with_a_floor(tool):
    assert tool.damping_band(40.0) == pytest.approx(8.0)
    assert tool.damping_band(5.0) == pytest.approx(3.0)
    assert tool.setback_band(0.2) == pytest.approx(0.05)
    assert tool.setback_band(0.0) == pytest.approx(0.02)


def _rows(learner, condition, distances, trials_per_chunk=100_000):
    return [
        {
            "learner": learner,
            "condition": condition,
            "chunk": c + 1,
            "chunk_trials": trials_per_chunk,
            "trials": (c + 1) * trials_per_chunk,
            "distance_m": d,
        }
        for c, d in enumerate(distances)
    ]


def test_setbacks_count_after_the_first_whole_field(tool):
    cfg = Config()
    full = cfg.sensor.n_cells * cfg.sensor.cell_size
    edges = np.arange(0, 2_200_000, 200_000, dtype=float)
    # below the field for 3 chunks (not counted: before the first whole field), then one setback at 1.0M trials
    distances = [0.5 * full] * 3 + [full] * 20
    distances[9] = 0.5 * full
    windows = tool.setback_windows(_rows(0, "none", distances), [0], cfg, edges)
    # the chunk ending at 400k trials first reached the whole field: counting starts with the one at 500k
    assert windows["all"]["counted"][:3] == [0, 0, 2]
    assert windows["none"]["setback"] == [0, 0, 0, 0, 1, 0, 0, 0, 0, 0]
    assert windows["none"]["fraction"][4] == pytest.approx(0.5)
    settled = tool.setback_settle(windows["all"], edges)
    assert settled["late"] == 0.0
    assert settled["settled_at"] == 1_200_000  # windows from 1.0M on hold no setback


def test_recommend_takes_most_full_length_runs(tool):
    def rec(at, full=True):
        return {"full_length": full, "both_settled_at": at}

    records = [rec(1_230_000), rec(None), rec(1_610_000), rec(400_000, full=False)]
    assert tool.recommend(records) == {"runs": 3, "most": 2, "settled_in_most": True, "trials": 1_700_000}
    # not settled in most runs: a screen needs the full length
    unsettled = tool.recommend([rec(None), rec(None), rec(1e6)])
    assert not unsettled["settled_in_most"] and unsettled["trials"] == tool.FULL_TRIALS


def test_verdict_by_length_reads_the_claims_rule(tool):
    cfg = Config()
    full = cfg.sensor.n_cells * cfg.sensor.cell_size
    # learner 0 stays at the whole field; learner 1 falls back in its last chunks only
    rows = _rows(0, "none", [full] * 20) + _rows(1, "none", [full] * 18 + [0.5 * full] * 2)
    by_length = tool.verdict_by_length(rows, [0, 1], cfg, [1_000_000, 2_000_000])
    assert by_length[0] == {"trials": 1e6, "unstable": [], "matching": 1, "found": 0}
    assert by_length[1] == {"trials": 2e6, "unstable": [1], "matching": 2, "found": 1}
