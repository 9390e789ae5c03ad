"""studies/frame: the adoption rule on synthetic records, and the orientation map's turns."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from reach_jax.config import Config, condition


def record(run, frame, d, collapsed=(), stable=32, holding=2, out=0.1):
    verdicts = {k: "holds" if k <= holding else "does not hold" for k in range(1, 6)}
    return {
        "run": run,
        "frame": frame,
        "hypers": {"lr": 1.0},
        "collapsed": list(collapsed),
        "stable_learners": stable,
        "learners": 32,
        "D": d,
        "verdicts": verdicts,
        "holding": holding,
        "none_field": {"success": 0.5, "out": out},
    }


def test_the_lowest_d_among_the_candidates_that_pass_every_check_is_adopted(load_tool):
    verdict = load_tool("studies/frame/verdict")
    base = record("a", "viscous", 23.0)
    recs = [
        base,
        record("a", "viscous_mirror", 10.0, collapsed=[{"learner": 1}]),  # lowest D, but a network collapsed
        record("b", "viscous", 20.0),
        record("b", "viscous_mirror", 14.0, out=0.4),
    ]
    got = verdict.decide(recs)
    assert got["comparator"] is base
    assert [c["qualifies"] for c in got["candidates"]] == [False, True, True]
    assert got["adopted"]["run"] == "b" and got["adopted"]["frame"] == "viscous_mirror"
    assert got["targets"]["none -> field out at least 25%"] and not got["targets"]["D at most 12"]
    assert "**Adopted: `b`, frame viscous_mirror**" in verdict.markdown(got, "cmd")


@pytest.mark.parametrize(
    "change", [{"stable": 29}, {"holding": 1}, {"d": 23.0}], ids=["unstable", "fewer claims", "no lower D"]
)
def test_a_candidate_that_misses_one_check_is_not_adopted(load_tool, change):
    verdict = load_tool("studies/frame/verdict")
    got = verdict.decide([record("a", "viscous", 23.0), record("a", "viscous_mirror", **{"d": 10.0, **change})])
    assert got["adopted"] is None and got["targets"] is None
    assert "**Nothing adopted**" in verdict.markdown(got, "cmd")


def test_the_mirrored_frame_is_a_turn_of_the_field_and_the_map_tests_it(load_tool):
    orientation = load_tool("studies/frame/orientation")
    b, mirrored = (np.asarray(condition(Config(), n).viscous) for n in ("viscous", "viscous_mirror"))
    phis = orientation.turns(b, mirrored)  # checks that the turn gives the mirrored matrix
    assert len(phis) == 13 and set(orientation.STEP_TURNS) < set(phis)
    mirror = next(p for p in phis if p not in orientation.STEP_TURNS)
    assert orientation.pushing_axis(b) == pytest.approx(113.2, abs=0.1)
    assert orientation.pushing_axis(orientation.turned(b, mirror)) == pytest.approx(66.8, abs=0.1)
    assert orientation.pushing_axis(orientation.turned(b, 90.0)) == pytest.approx(23.2, abs=0.1)


def test_the_committed_verdict_is_the_rule_applied_to_the_committed_runs(load_tool):
    verdict = load_tool("studies/frame/verdict")
    root = Path(__file__).resolve().parent.parent
    committed = json.loads((root / "studies" / "frame" / "verdict.json").read_text())
    runs = [root / "runs" / name for name in ("frame_default", "frame_constant")]
    recs = [r for run in runs for r in verdict.records(run)]
    for r in recs:
        r["run"] = str(Path(r["run"]).relative_to(root))  # the committed file names the runs from the root
    result = verdict.decide(recs)
    assert json.loads(json.dumps(result)) == {k: v for k, v in committed.items() if k != "command"}
    assert verdict.markdown(result, committed["command"]) == (root / "studies" / "frame" / "verdict.md").read_text()
