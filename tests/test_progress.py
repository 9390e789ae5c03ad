"""The progress bar's time estimate, driven by a fake clock: the slowest learner and the batch size set it."""

from __future__ import annotations

import functools
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import committed_runs

from reach_jax import config, train
from reach_jax.store import run_dir as run_dir_io
from reach_jax.train.progress import LearnerEta, Progress, pow2_batch


def simulated_run(budget: float, fixed: float, chunk: int = 500):
    """A run of 8 learners with the trainer's tail repacking, on a fake clock: (time, trials, steps, batch) per chunk.

    Trials get shorter as learners learn (each at its own pace), and a step of a smaller batch takes less time.
    """
    # Steps per trial once learned: the Table-2 runs' learners needed 54-103 million steps for 2e6 trials.
    base = np.linspace(27.0, 51.5, 8)
    trials, steps, now, rows = np.zeros(8), np.zeros(8), 0.0, []
    while (trials < budget).any():
        size = pow2_batch(int(np.sum(trials < budget)), 8)
        for _ in range(chunk // 50):  # integrate d trials / d step = 1 / (steps per trial) in slices of 50 steps
            busy = trials < budget
            per_trial = base * (1.0 + 1.5 * np.exp(-trials / 200.0))  # learned within ~1/4 of the run
            trials = np.where(busy, np.minimum(trials + 50.0 / per_trial, budget), trials)
            steps = np.where(busy, steps + 50.0, steps)
        # [s]: a step's fixed cost plus the cost of the learners on the busiest of 2 devices (not the ETA's prior)
        now += chunk * 1e-5 * (fixed + (1.0 - fixed) * math.ceil(size / 2) / 4)
        rows.append((now, trials.copy(), steps.copy(), size))
    return rows


# The share of a step's time that does not shrink with the batch: this machine ~0.7, a GPU ~1. Below ~0.4 the
# estimate errs long by more than a quarter until the batch first shrinks (0.3: 37%). Here the learners' differences
# persist, against the relaxation toward the batch's median (`regress`), which therefore errs short: 33% where a step
# costs the same at every batch size (24% without it, regress=0, which checks the repacking alone).
PERSISTENT_ON_A_GPU = pytest.mark.xfail(
    strict=True, reason="the slowest learner is relaxed toward the median though its trials stay long: 33% short"
)


@pytest.mark.parametrize(
    "fixed, regress",
    [(0.5, 0.1), (0.65, 0.1), (0.8, 0.1), pytest.param(1.0, 0.1, marks=PERSISTENT_ON_A_GPU)]
    + [(fixed, 0.0) for fixed in (0.5, 0.65, 0.8, 1.0)],
)
def test_eta_is_within_a_quarter_of_the_truth_from_half_the_run_despite_repacking(fixed, regress):
    worst, checked = simulated_errors(fixed, regress)
    assert checked > 20
    assert worst <= 0.25, worst


def simulated_errors(fixed: float, regress: float) -> tuple[float, int]:
    """The estimate's largest relative error from half of `simulated_run` on (more than two chunks before its end),
    and the updates judged; it ends at 0 once every learner is done."""
    rows = simulated_run(budget=2000.0, fixed=fixed)
    end = rows[-1][0]
    assert len({size for *_, size in rows}) == 4  # the batch shrank 8 -> 4 -> 2 -> 1
    eta, checked, worst = LearnerEta(2000, devices=2, regress=regress), 0, 0.0
    eta.update(np.zeros(8), np.zeros(8), 0.0, 8)
    for now, trials, steps, size in rows:
        got = eta.update(trials, steps, now, size)
        left = end - now
        if now >= 0.5 * end and left >= 2 * (rows[-1][0] - rows[-2][0]):
            worst, checked = max(worst, abs(got / left - 1)), checked + 1
    assert got == 0.0  # every learner done
    return worst, checked


def test_eta_follows_the_slowest_learner_at_a_constant_step_time():
    budget = 1000
    # A step costs the same at any size; no relaxation toward the median (next test).
    eta = LearnerEta(budget, window=4, fixed_learners=1e12, min_done=0.0, regress=0.0)
    per_trial = np.array([1.0, 10.0, 2.0])  # steps per trial; 100 steps a second
    assert eta.update(np.zeros(3), np.zeros(3), 0.0, 4) is None  # one point: no rate yet
    for t in range(1, 30):
        steps = np.full(3, 100.0 * t)
        trials = np.minimum(steps / per_trial, budget)
        left = eta.update(trials, steps, float(t), 4)
        true = (budget - 10.0 * t) / 10.0  # learner 1 finishes last
        assert left == pytest.approx(true), t
    # Before it says that min_done of the run is done, it gives none.
    early = LearnerEta(budget, window=4, min_done=0.05)
    early.update(np.zeros(3), np.zeros(3), 0.0, 4)
    assert early.update(np.minimum(100.0 / per_trial, budget), np.full(3, 100.0), 1.0, 4) is None
    # Stalled learners give no estimate rather than a wrong one.
    stall = LearnerEta(1000, window=2)
    for t in range(4):
        got = stall.update([5.0], [100.0 * t], float(t), 1)
    assert got is None


@pytest.mark.parametrize("weight", [0.0, 0.5, 1.0])
def test_a_learner_off_the_median_is_relaxed_toward_it_over_a_share_of_the_budget(weight):
    budget, per_trial = 1000, np.array([1.0, 10.0, 2.0])  # steps per trial: the median is 2
    eta = LearnerEta(budget, window=4, fixed_learners=1e12, min_done=0.0, regress=0.1, regress_weight=weight)
    eta.update(np.zeros(3), np.zeros(3), 0.0, 4)
    for t in range(1, 30):  # 100 steps a second, until a learner is done (as the trainer counts them)
        steps = np.minimum(100.0 * t, budget * per_trial)
        trials = steps / per_trial
        got = eta.update(trials, steps, float(t), 4)
        left = budget - trials
        # r(tau) = 2 + (r - 2) exp(-tau / 100) summed over the trials left; the slowest learner sets the time
        relaxed = 2.0 * left + (per_trial - 2.0) * 100.0 * (1.0 - np.exp(-left / 100.0))
        busy = left > 0
        want = np.max((per_trial * left)[busy]) ** (1 - weight) * np.max(relaxed[busy]) ** weight / 100.0
        assert got == pytest.approx(want, rel=1e-9), t


@functools.cache
def committed_profile(run: str):
    """A committed run's learners, chunk by chunk: (trials (C, L), steps (C, L), budget, chunk steps)."""
    root = Path(__file__).resolve().parent.parent / "runs" / run
    train_cfg = json.loads((root / "config.json").read_text())["train"]
    rows = run_dir_io.read_metrics(root)
    chunks = sorted({r["chunk"] for r in rows})
    where = {c: i for i, c in enumerate(chunks)}
    trials = np.full((len(chunks), max(r["learner"] for r in rows) + 1), np.nan)
    steps = trials.copy()
    for r in rows:
        trials[where[r["chunk"]], r["learner"]], steps[where[r["chunk"]], r["learner"]] = r["trials"], r["steps"]
    for i in range(1, len(chunks)):  # a learner without a row kept its counts
        trials[i] = np.where(np.isnan(trials[i]), trials[i - 1], trials[i])
        steps[i] = np.where(np.isnan(steps[i]), steps[i - 1], steps[i])
    return trials, steps, int(float(train_cfg["trials"])), train_cfg["chunk_steps"]


# The step time of this machine (benchmarks/results/throughput-20261130T105428Z.json, 2 devices): 6 us plus
# 1.7 us per learner on the busiest device.
STEP_FIXED, STEP_PER_LEARNER = 6.0e-6, 1.7e-6


COMMITTED_RUNS = (
    "table2",
    "heldout",
    "dev_gradual",
    "dev_delayed",
    "dev_value",
    "dev_value_half",
    "screen",
    "screen2",
    "screen3",
)


def fake_clock(run: str) -> np.ndarray:
    """A committed run's chunk end times [s] on a fake clock: each chunk's steps at this machine's step time for
    its batch size (STEP_FIXED, STEP_PER_LEARNER on 2 devices)."""
    trials, _, budget, chunk_steps = committed_profile(run)
    per_learner = [math.ceil(size / 2) for size in batch_sizes(trials, budget)]
    return np.cumsum([chunk_steps * (STEP_FIXED + STEP_PER_LEARNER * k) for k in per_learner])


def wall_clock(run: str) -> np.ndarray:
    """A committed run's chunk end times [s] as its metrics recorded them (`wall_s`)."""
    rows = run_dir_io.read_metrics(Path(__file__).resolve().parent.parent / "runs" / run)
    wall: dict[int, float] = {}
    for row in rows:
        wall[row["chunk"]] = max(wall.get(row["chunk"], 0.0), row["wall_s"])
    return np.array([wall[c] for c in sorted(wall)])


def batch_sizes(trials: np.ndarray, budget: int) -> list[int]:
    """The batch size of each chunk under the trainer's tail repacking, from the trials before it."""
    n = trials.shape[1]
    return [pow2_batch(int(np.sum(before < budget)), n) for before in [np.zeros(n), *trials[:-1]]]


def worst_eta_errors(run: str, clock: np.ndarray, starts=(0.05, 0.5), **settings) -> dict[float, float]:
    """Replays a committed run's trials and steps at the chunk end times `clock` [s]: the largest relative error of
    the estimate (`LearnerEta` with `settings`) from each share of the run in `starts`. Errors within one chunk's
    time are not counted."""
    trials, steps, budget, _ = committed_profile(run)
    sizes = batch_sizes(trials, budget)
    eta = LearnerEta(budget, devices=2, **settings)
    eta.update(np.zeros(trials.shape[1]), np.zeros(trials.shape[1]), 0.0, sizes[0])
    worst = dict.fromkeys(starts, 0.0)
    for now, t, s, size, took in zip(clock, trials, steps, sizes, np.diff(clock, prepend=0.0), strict=True):
        got, left = eta.update(t, s, now, size), clock[-1] - now
        if got is None or left <= took or abs(got - left) <= took:
            continue
        for start in worst:
            if now >= start * clock[-1]:
                worst[start] = max(worst[start], abs(got / left - 1))
    assert got == 0.0
    return worst


def band_record(run: str, **settings) -> tuple[float, float]:
    """Replays a committed run at its fake clock (`LearnerEta` with `settings`): the share of the updates from a
    quarter of the run on whose true time left lies in the band (within one chunk's time), and the band's widest
    half-width from half of the run."""
    trials, steps, budget, _ = committed_profile(run)
    if not (trials[-1] >= budget).all():
        pytest.skip(f"runs/{run} has not finished its trials")
    clock, sizes = fake_clock(run), batch_sizes(trials, budget)
    eta = LearnerEta(budget, devices=2, **settings)
    eta.update(np.zeros(trials.shape[1]), np.zeros(trials.shape[1]), 0.0, sizes[0])
    inside, judged, widest = 0, 0, 0.0
    for now, t, s, size, took in zip(clock, trials, steps, sizes, np.diff(clock, prepend=0.0), strict=True):
        got, left = eta.update(t, s, now, size), clock[-1] - now
        if got is None or left <= took:
            continue
        low, high = eta.band
        assert low < got < high and math.isclose(math.sqrt(low * high), got)  # the estimate is its geometric middle
        if now >= 0.25 * clock[-1]:
            judged += 1
            inside += low - took <= left <= high + took
        if now >= 0.5 * clock[-1]:
            widest = max(widest, (high - low) / 2 / got)
    return inside / judged, widest


FINISHED_RUNS = committed_runs()  # those still training, or stopped early (dev_anneal), are skipped: no end to count to
# Where the truth strays from the estimate by more than the band for long, for reasons the trial lengths before it
# do not show, the estimate short throughout: dev_delayed's anneal to half the noise lengthens its trials after
# mid-run (the estimate 32-41% short from a quarter to the end: inside the band in 35% of the updates), dev_gradual's
# trials lengthen in its second quarter (32-36% short through its middle: 69%), a late setback in dev_gain_mid (43-63%
# short from 70%: 37%), and collapse_dev's collapsed learners never return to the batch's median, as the relaxation
# toward it expects (19-35% short from a tenth on: 73%). Before the relaxation (commit 2a512ad)
# table2 (77%) and geometry_map (84%) missed instead of collapse_dev, and dev_delayed held the truth in 73%,
# dev_gradual in 82% and dev_gain_mid in 43% of the updates (benchmarks/results/eta-replay-20261208.json).
BAND_MISSES = {"collapse_dev", "dev_delayed", "dev_gain_mid", "dev_gradual"}


@pytest.mark.parametrize(
    "run",
    [
        pytest.param(r, marks=pytest.mark.xfail(strict=True, reason="issue 39's target is not met here"))
        if r in BAND_MISSES
        else r
        for r in FINISHED_RUNS
    ],
)
def test_the_eta_band_holds_the_truth_in_nine_of_ten_updates_from_a_quarter_of_every_committed_run(run):
    covered, widest = band_record(run)
    assert widest <= 0.35 + 1e-12, widest  # at most +-35% of the estimate from half of the run
    assert covered >= 0.9, covered


def test_the_band_is_the_estimate_times_and_over_one_plus_its_width_early_and_late():
    eta = LearnerEta(1000, window=4, fixed_learners=1e12, min_done=0.0, early_width=0.6, late_width=0.35, late_from=0.4)
    eta.update(np.zeros(1), np.zeros(1), 0.0, 1)
    bands = []
    for t in range(1, 10):  # 100 steps a second, 10 steps a trial: done at t = 100 s
        left = eta.update([10.0 * t], [100.0 * t], float(t), 1)
        bands.append((eta.band[0] / left, eta.band[1] / left))
    assert bands[-1] == pytest.approx((1 / 1.6, 1.6))  # 9% done: the early width
    assert eta.update([390.0], [3900.0], 39.0, 1) == pytest.approx(61.0) and eta.band == pytest.approx((38.125, 97.6))
    assert eta.update([400.0], [4000.0], 40.0, 1) == pytest.approx(60.0) and eta.band == pytest.approx(
        (60 / 1.35, 81.0)
    )
    stalled = LearnerEta(1000, window=2)
    stalled.update([5.0], [100.0], 0.0, 1)
    assert stalled.update([5.0], [200.0], 1.0, 1) is None and stalled.band is None
    assert eta.update([1000.0], [10000.0], 100.0, 1) == 0.0 and eta.band is None  # done: no "(0–0 s)" range


@pytest.mark.parametrize("run", COMMITTED_RUNS)
def test_eta_on_the_trial_lengths_of_committed_runs(run):
    """Within half of the truth from 5% of the run (the issue-21 target), and within 40% from half of it: a guard
    against getting worse than today, not the target (next test)."""
    worst = worst_eta_errors(run, fake_clock(run))
    assert worst[0.05] <= 0.5 and worst[0.5] <= 0.4, worst


@pytest.mark.xfail(
    strict=True,
    reason="issue 21's target of a quarter from half the run is not met: 37% in runs/table2 (long, where its slowest "
    "learner's trials shorten later than the relaxation toward the batch's median foresees) and in runs/dev_delayed "
    "(short, where an anneal lengthens the trials), 36% in runs/dev_gradual (short)",
)
def test_eta_is_within_a_quarter_of_the_truth_from_half_of_every_committed_run():
    assert max(worst_eta_errors(run, fake_clock(run))[0.5] for run in COMMITTED_RUNS) <= 0.25


def test_eta_on_the_real_clock_of_a_committed_run():
    """runs/dev_gain (16 learners, 2M trials, alone on the machine, never interrupted) replayed with its own wall
    clock, compile times and the tail's batch changes included: within 35% of the truth from half of the run and
    within 15% from 85%. Pricing a batch size by its newest chunk alone erred by up to 410% here (the run's printed
    bar, made so, read up to +135% in the tail): the next size compiles during the last chunk of the old one, and
    that time then skewed the fitted cost line."""
    trials, _, budget, _ = committed_profile("dev_gain")
    assert len(set(batch_sizes(trials, budget))) == 5  # the batch shrank 16 -> 8 -> 4 -> 2 -> 1
    worst = worst_eta_errors("dev_gain", wall_clock("dev_gain"), starts=(0.5, 0.85))
    assert worst[0.5] <= 0.35 and worst[0.85] <= 0.15, worst


def test_a_slow_chunk_does_not_price_its_batch_size():
    eta = LearnerEta(1000, window=2, min_done=0.0)
    now = 0.0
    for k, took in enumerate([1.0, 1.0, 1.0, 6.0]):  # the last chunk also compiled the next batch size
        now += took
        eta.update([10.0 * k], [100.0 * k], now, 8)
    assert eta.seconds_per_step(8) == pytest.approx(0.01)


def test_bar_prints_the_given_eta():
    out = io.StringIO()
    bar = Progress(100, "trials", stream=out, min_interval=0.0)
    bar.update(10, "x", eta=3725.0)
    assert "ETA 1:02:05" in out.getvalue()
    assert "20/100" not in out.getvalue()
    bar.update(20, "x", eta=900.0, eta_range=(720.0, 1140.0))
    assert out.getvalue().splitlines()[-1].endswith("ETA 0:15:00 (12–19 min)")
    bar.update(30, "x", eta=9000.0, eta_range=(5400.0, 12600.0))
    assert out.getvalue().splitlines()[-1].endswith("ETA 2:30:00 (1.5–3.5 h)")


class Terminal(io.StringIO):
    """A stream that says it is a terminal, so the bar redraws at every update."""

    def isatty(self) -> bool:
        return True


def test_a_real_run_draws_the_bar_with_its_estimate(tmp_path):
    stream = Terminal()
    cfg = config.from_partial(
        {"train": {"trials": 30, "seeds": 1, "conditions": ["none", "random"], "chunk_steps": 300}}
    )
    assert train.run(cfg, tmp_path / "run", stream=stream) == tmp_path / "run"
    lines = stream.getvalue().strip().split("\r")
    assert lines[-1].startswith("[####################] 60/60 trials 100% | done |")
    assert any("ETA 0:0" in line for line in lines[1:-1])  # a time left, once a rate is known
    assert "ETA ?" in lines[0]
