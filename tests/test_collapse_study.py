"""studies/collapse: the replay's folding, the post-mortem's phases, the held-out candidate and the adoption rule."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import ROOT


def test_fold_trials_averages_each_trials_steps_and_drops_the_unfinished_one(load_tool):
    trace = load_tool("studies/collapse/trace")
    ended = np.array([0, 0, 1, 0, 1, 0], bool)  # trials of 3 and 2 steps, then one still under way
    steps = {name: np.zeros(6) for name in ("drifted", "gate_open", "n_max", "distance", "failure", "goal", "cap")}
    steps.update(ended=ended, out=ended.copy(), w_norm=np.zeros((6, 3)), grad=np.arange(18.0).reshape(6, 3))
    means = ("p", "p_target", "p_prev", "sat_h1", "sat_h2", "sat_m", "tau_clipped", "value_scale", "target_beyond")
    steps.update({name: np.arange(6.0) for name in (*means, "critic_error")})
    steps.update({name: -np.arange(12.0).reshape(6, 2) for name in ("m", "actor_error", "actor_signal", "rnd")})
    steps.update(u_out=np.zeros((6, 3)), actor_push=np.ones((6, 2)))
    got = trace.fold_trials(steps)
    assert got["length"].tolist() == [3, 2] and got["out"].tolist() == [True, True]
    assert got["p_mean"].tolist() == [1.0, 3.5] and got["p_first"].tolist() == [0.0, 3.0]
    assert got["grad_mean"][1].tolist() == [10.5, 11.5, 12.5]
    assert got["m_abs"][0].tolist() == [2.0, 3.0]  # |m| averaged over the trial's steps


def test_the_post_mortem_finds_the_collapse_and_a_setback_that_recovered_before_it(load_tool):
    pm = load_tool("studies/collapse/postmortem")
    n, onset, low, back = 20_000, 15_000, 3_000, 4_000
    out = np.zeros(n, bool)
    out[onset:] = True
    out[onset + 100] = False  # one success among the outs: still at least 95% out from the onset
    distance = np.full(n, pm.FULL)
    distance[low:back] = 0.1
    distance[onset:] = 0.064
    t = {"length": np.ones(n), "out": out, "distance": distance, "chunk": np.arange(n) // 1000}
    got = pm.phases(t)
    # 95% of the 500 trials from 24 before the outs begin end out (475 of them, the one success among them aside).
    start = onset - 24
    assert got["onset"] == (start, start) and got["run-up"] == (start - pm.RUN_UP, start)
    assert got["before the setback"] == (low - pm.HEALTHY, low) and got["after its recovery"] == (
        back,
        back + pm.RECOVERED,
    )
    distance[back:onset] = 0.1  # no recovery before the collapse: no setback phase
    assert "after its recovery" not in pm.phases(t)


def test_the_committed_post_mortem_is_its_traces_read_again(load_tool, tmp_path):
    pm = load_tool("studies/collapse/postmortem")
    folders = [ROOT / "studies" / "collapse" / f"trace_{name}" for name in ("viscous0", "none1")]
    assert all(json.loads((f / "replay.json").read_text())["identical"] for f in folders)  # probes changed nothing
    pm.main([*map(str, folders), "--out", str(tmp_path / "pm")])
    stored = json.loads((ROOT / "studies" / "collapse" / "postmortem.json").read_text())
    assert json.loads((tmp_path / "pm.json").read_text())["traces"] == stored["traces"]
    viscous = stored["traces"]["viscous seed 0"]["phases"]
    # The absorbing state: every trial out, the critic at its floor, a pinned actor, a vanished gradient.
    assert viscous["absorbing"]["out %"] > 99 and viscous["absorbing"]["critic, mean"] < -0.29
    assert (
        viscous["absorbing"]["shoulder actor, abs. pre-activation"]
        > 2 * viscous["healthy"]["shoulder actor, abs. pre-activation"]
    )
    assert viscous["absorbing"]["gradient, layer 1 (1e-3)"] < viscous["healthy"]["gradient, layer 1 (1e-3)"] / 10


def record(recipe, d, stable, collapsed=(), learners=16, damping=20.0, verdicts=None):
    """A rank.records entry."""
    names = [{"learning": "none", "seed": s} for s in collapsed]
    verdicts = verdicts or {k: "holds" for k in range(1, 6)}
    return {"recipe": recipe, "D": d, "stable_learners": stable, "learners": learners, "collapsed": names,
            "damping_none": damping, "verdicts": verdicts, "hypers": {"noise": 0.2}}  # fmt: skip


def test_the_candidate_is_the_nearest_recipe_without_a_collapse_among_the_stable(load_tool):
    rank = load_tool("studies/collapse/rank")
    recs = [record(0, 24.0, 16), record(1, 15.0, 16, collapsed=[2]), record(2, 18.0, 15), record(3, 12.0, 14)]
    assert rank.candidate(recs)["recipe"] == 2  # 1 collapsed, 3 has too few stable
    # None qualifies: the fewest collapsed, then the most stable, then the lowest D.
    recs = [
        record(0, 24.0, 10, collapsed=[1]),
        record(1, 15.0, 12, collapsed=[1]),
        record(2, 9.0, 16, collapsed=[1, 2]),
    ]
    assert rank.candidate(recs)["recipe"] == 1


@pytest.mark.parametrize(
    ("heldout", "adopt"),
    [
        (record(0, 20.0, 30, learners=32), True),
        (record(0, 20.0, 30, collapsed=[3], learners=32), False),
        (record(0, 20.0, 29, learners=32), False),
        (record(0, 24.4, 32, learners=32), False),  # D must be below the default's, not equal
    ],
)
def test_the_adoption_rule_needs_every_part(load_tool, heldout, adopt):
    verdict = load_tool("studies/collapse/verdict")
    got = verdict.decide(heldout, record(0, 24.4, 32, learners=32))
    assert got["adopt"] is adopt
    assert got["targets"]["D at most 16"] is False and got["targets"]["claims 1-4 hold"] is True
