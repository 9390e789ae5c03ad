"""studies/hover/loop.py reads a learner's tail from its metrics rows as the stability verdict does."""

from __future__ import annotations

import pytest

from reach_jax.config import ClaimsConfig


@pytest.fixture
def tool(load_tool):
    return load_tool("studies/hover/loop")


def _row(trials, chunk_trials, steps, n_max, drift, gate=None):
    return {
        "trials": trials,
        "chunk_trials": chunk_trials,
        "mean_trial_steps": steps,
        "n_max": n_max,
        "drift_rate": drift,
        "out_rate": 0.0,
        "cap_rate": 0.0,
        "gate_open_rate": gate,
    }


def test_the_tail_weights_chunks_by_their_trials_and_skips_the_early_ones(tool):
    rows = [_row(100, 100, 500.0, 900.0, 1.0), _row(900, 300, 20.0, 60.0, 0.0), _row(1000, 100, 60.0, 80.0, 0.4)]
    tail = tool.learner_tail(rows, trials=1000, tail=0.2)  # the first row lies before the last 20% of trials
    assert tail["steps_per_trial"] == pytest.approx((300 * 20 + 100 * 60) / 400)
    assert tail["drift_rate"] == pytest.approx(0.1) and tail["n_max"] == 80.0
    assert tail["gate_open_rate"] is None  # a run that logged no gate reports none


def test_a_learner_with_no_chunk_in_its_tail_reports_nothing(tool):
    assert tool.learner_tail([_row(100, 100, 30.0, 90.0, 0.0)], trials=1000, tail=0.2) == {}


def test_a_recipe_without_the_gate_reads_no_gate_and_a_gated_one_its_open_share(tool):
    base = {"run": "runs/x", "condition": "none", "networks": 4, "steps_per_trial": 22.0, "n_max": 69.0}
    rates = {"drift_rate": 0.07, "out_rate": 0.001, "cap_rate": 0.0, "setback_share": 0.0, "unstable": 0}
    rows = [
        {**base, **rates, "recipe": "ungated", "gated": False, "gate_open_rate": 1.0},
        {**base, **rates, "recipe": "gated", "gated": True, "gate_open_rate": 0.004},
    ]
    lines = tool.markdown(rows, "cmd", ClaimsConfig()).splitlines()
    ungated, gated = (next(line for line in lines if f"| {name} |" in line) for name in ("ungated", "gated"))
    assert "| no gate |" in ungated and "100.0%" not in ungated
    assert "| 0.4% |" in gated and "no gate" not in gated
