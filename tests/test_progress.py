"""The progress bar's time estimate, driven by a fake clock: the slowest learner sets it."""

from __future__ import annotations

import io

import numpy as np
import pytest

from reach_jax.progress import LearnerEta, Progress


def test_eta_follows_the_slowest_learner():
    budget = 1000
    eta = LearnerEta(budget, window=4)
    rates = np.array([100.0, 10.0, 50.0])  # trials per second
    assert eta.update(np.zeros(3), 0.0) is None  # one point: no rate yet
    for t in range(1, 30):
        trials = np.minimum(rates * t, budget)
        left = eta.update(trials, float(t))
        true = (budget - 10.0 * t) / 10.0  # learner 1 finishes last
        assert left == pytest.approx(true), t
    # When everyone is done there is nothing left.
    assert eta.update(np.full(3, budget), 200.0) == 0.0


def test_eta_adapts_when_a_learner_speeds_up():
    eta = LearnerEta(1000, window=3)
    trials = 0.0
    for t in range(10):
        trials += 10.0
        eta.update([trials], float(t))
    for t in range(10, 20):
        trials += 40.0  # four times faster, e.g. after the batch shrank
        got = eta.update([trials], float(t))
    assert got == pytest.approx((1000 - trials) / 40.0)
    # Stalled learners give no estimate rather than a wrong one.
    stall = LearnerEta(1000, window=2)
    for t in range(3):
        stall.update([5.0], float(t))
    assert stall.update([5.0], 3.0) is None


def test_bar_prints_the_given_eta():
    out = io.StringIO()
    bar = Progress(100, "trials", stream=out, min_interval=0.0)
    bar.update(10, "x", eta=3725.0)
    assert "ETA 1:02:05" in out.getvalue()
    assert "20/100" not in out.getvalue()
