"""A dependency-free progress bar for the training shell (stderr; throttled when not a terminal)."""

from __future__ import annotations

import math
import sys
import time
from collections import deque

import numpy as np


def _clock(seconds: float) -> str:
    seconds = int(max(seconds, 0))
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"


def _span(low: float, high: float) -> str:
    """A range of seconds in the coarsest unit that still tells its ends apart: "12–19 min", "1.5–2.4 h"."""
    if high < 120:
        return f"{low:.0f}–{high:.0f} s"
    if high < 2 * 3600:
        return f"{low / 60:.0f}–{high / 60:.0f} min"
    return f"{low / 3600:.1f}–{high / 3600:.1f} h"


class Progress:
    """Shows done/total, a bar, a free-form status and an ETA."""

    def __init__(self, total: int, unit: str, stream=None, min_interval: float = 10.0):
        self.total = max(int(total), 1)
        self.unit = unit
        self.stream = stream if stream is not None else sys.stderr
        self.tty = self.stream.isatty()
        self.min_interval = 0.0 if self.tty else min_interval
        self.start = time.monotonic()
        self.first_done = None
        self.last_print = -float("inf")

    def update(
        self,
        done: int,
        status: str = "",
        force: bool = False,
        eta: float | None = None,
        eta_range: tuple[float, float] | None = None,
    ) -> None:
        """Redraw with `done` units finished; `eta` [s], when given, replaces the estimate from the total rate, and
        `eta_range` ([s], [s]) is shown beside it, the span in which the time left is likely to lie."""
        now = time.monotonic()
        if self.first_done is None:
            self.first_done = (done, now)
        if not force and now - self.last_print < self.min_interval:
            return
        self.last_print = now
        frac = min(done / self.total, 1.0)
        d0, t0 = self.first_done
        rate = (done - d0) / (now - t0) if now > t0 and done > d0 else 0.0
        if eta is None:
            eta = (self.total - done) / rate if rate > 0 else None
        eta = "?" if eta is None else _clock(eta) + ("" if eta_range is None else f" ({_span(*eta_range)})")
        bar = "#" * int(20 * frac) + "." * (20 - int(20 * frac))
        line = (
            f"[{bar}] {done:,}/{self.total:,} {self.unit} {100 * frac:3.0f}% | {status} | "
            f"{_clock(now - self.start)} elapsed, ETA {eta}"
        )
        end = "" if self.tty else "\n"
        self.stream.write(("\r" if self.tty else "") + line + end)
        self.stream.flush()

    def close(self) -> None:
        """End the bar's line."""
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


def pow2_batch(unfinished: int, learners: int) -> int:
    """Learners a chunk runs while `unfinished` of `learners` are left: the next power of two, at most all of them
    (the rule of `train.chunk_members`)."""
    return min(learners, 1 << max(unfinished - 1, 0).bit_length())


class LearnerEta:
    """Time left [s] until the slowest learner is done, from each learner's steps left and the time of a step.

    Learners of a batch run in lockstep, and in a run's tail the batch shrinks to the unfinished learners
    (`pow2_batch`), where a step takes less time. So the estimate walks the learners' finishing order: with s_1 <=
    ... <= s_k the steps left of the k unfinished learners, the batch runs s_1 steps at size pow2_batch(k), then s_2
    - s_1 at pow2_batch(k - 1), and so on.

    Steps left are trials left x steps per trial, which changes as a learner learns and in its crises. Three
    measures of it each give an estimate: over the last `window` updates (follows a change), over the last
    `long_window` (rides out a passing crisis) and over the learner's life (carries the slow fall of trial lengths).
    A learner far from the batch's median steps per trial tends to return to it (a lagging learner's crisis passes),
    but not always (a collapsed one stays slow), so each measure r is also relaxed toward the median m over
    `regress` of the budget: r(tau) = m + (r - m) exp(-tau / T) for its tau-th trial to come; the estimate is the
    geometric mean of the three measures' own and relaxed estimates, the relaxed ones weighted `regress_weight`.
    Beside it, `band` is the range estimate / (1 + width) to estimate x (1 + width): the early width until the
    estimate says that `late_from` of the run is done, the late one from then on. The widths are set by replaying
    every committed run's metrics (tests/test_progress.py), where the truth strays from the estimate by up to a third
    for long stretches as learners speed up or slow down; the spread of the measures did not foretell those errors,
    so it does not set the width.

    A step at batch size n costs a + b ceil(n / devices): one device's share of the learners plus a fixed cost, a =
    fixed_learners x b until two per-device sizes are measured (`seconds_per_step`); a measured size costs the
    median of its last `recent_chunks` chunks, since the chunk during which the next batch size compiles takes
    several times as long as the rest. No estimate is given before it says that `min_done` of the run is done.
    """

    def __init__(
        self,
        budget: int,
        devices: int = 1,
        window: int = 20,
        long_window: int = 400,
        fixed_learners: float = 3.5,
        min_done: float = 0.05,
        recent_chunks: int = 5,
        early_width: float = 0.6,
        late_width: float = 0.4,
        late_from: float = 0.4,
        regress: float = 0.1,
        regress_weight: float = 0.5,
    ):
        """Args:
        budget: trials per learner.
        devices: devices the learners are spread over.
        window, long_window: updates over which the two recent measures of steps per trial are taken.
        fixed_learners: the step's fixed cost in learners' worth of per-device cost, assumed until two sizes are
          measured: 3.5 on this CPU (benchmarks/results/throughput-20261130T105428Z.json: 12.7, 32.8 and 114 us a
          step for 8, 32 and 128 learners on 2 devices); far more on a GPU, where the fixed cost dominates.
        min_done: the share of the run, by its own estimate, before which none is given.
        recent_chunks: chunks of one batch size whose median step time prices it.
        early_width, late_width: the band's width (a ratio less one) before and from `late_from` of the run by the
          estimate's own reckoning; the late one 0.4 (a half-width of 34% of the estimate), so that the band is
          narrow from the true half of every committed run on.
        regress: the time constant of the relaxation toward the batch's median steps per trial, a share of the
          budget; 0 relaxes nothing.
        regress_weight: the relaxed estimates' weight in the geometric mean. Both were chosen on a grid replayed
          over every finished committed run (benchmarks/results/eta-replay-20261208.json, docs/how-it-works.md).
        """
        self.budget = budget
        self.devices = max(int(devices), 1)
        self.fixed_learners = fixed_learners
        self.min_done = min_done
        self.history: deque = deque(maxlen=long_window + 1)  # (time [s], trials (L,), steps (L,))
        self.window = window
        self.start: float | None = None
        self.recent_chunks = recent_chunks
        self.step_times: dict[int, deque] = {}  # batch size -> seconds per step in its newest chunks
        self.widths, self.late_from = (early_width, late_width), late_from
        self.regress_trials, self.regress_weight = regress * budget, regress_weight
        self.latest_rate: np.ndarray | None = None  # (L,) steps per trial over each learner's newest window
        self.band: tuple[float, float] | None = None  # (low, high) [s] around the latest estimate; None without one

    def update(self, trials, steps, now: float, batch_size: int) -> float | None:
        """Record the learners' trials and steps after a chunk that ran `batch_size` learners, at time `now` [s].

        Returns the estimate [s], 0 when every learner is done, or None before two points, while an unfinished
        learner has ended no trial in the window, or before min_done of the run; sets `band` to match (None when
        there is no estimate or nothing is left).
        """
        seconds = self._estimate(trials, steps, now, batch_size)
        self.band = None
        if seconds:
            elapsed = now - self.start
            width = self.widths[int(elapsed >= self.late_from * (elapsed + seconds))]
            self.band = (seconds / (1.0 + width), seconds * (1.0 + width))
        return seconds

    def _estimate(self, trials, steps, now: float, batch_size: int) -> float | None:
        trials = np.minimum(np.asarray(trials, dtype=np.float64), self.budget)
        steps = np.asarray(steps, dtype=np.float64)
        if self.history:
            t_prev, _, steps_prev = self.history[-1]
            took = float(np.max(steps - steps_prev))  # the chunk's length: an unfinished member ran all of it
            if now > t_prev and took > 0:
                times = self.step_times.setdefault(batch_size, deque(maxlen=self.recent_chunks))
                times.append((now - t_prev) / took)
        else:
            self.start = now
        self.history.append((now, trials, steps))
        left = self.budget - trials
        busy = left > 0
        if not busy.any():
            return 0.0
        recent = self.history[max(len(self.history) - 1 - self.window, 0)]
        moved = trials - recent[1] > 0
        rate = self._steps_per_trial(trials, steps, recent)
        latest = np.full(len(trials), np.nan) if self.latest_rate is None else self.latest_rate
        self.latest_rate = np.where(moved, rate, latest)  # a finished learner keeps its last window with trials
        if not self.step_times or np.any(~moved[busy]):
            return None
        median = float(np.nanmedian(self.latest_rate))  # finished learners count at their last measure
        per_trial = [rate[busy], self._steps_per_trial(trials, steps, self.history[0])[busy]]
        per_trial.append((steps / np.maximum(trials, 1.0))[busy])
        logs, weights = [], (1.0 - self.regress_weight, self.regress_weight)
        prices = self._step_prices(int(busy.sum()), len(trials))
        for r in per_trial:
            for steps_left in (left[busy] * r, self._relaxed(r, median, left[busy])):
                logs.append(np.log(max(self._seconds(steps_left, prices), 1e-9)))
        seconds = float(np.exp(np.average(logs, weights=weights * len(per_trial))))
        elapsed = now - self.start
        return seconds if elapsed >= self.min_done * (elapsed + seconds) else None

    def _relaxed(self, rate: np.ndarray, median: float, trials_left: np.ndarray) -> np.ndarray:
        """Steps left [steps] (L,) if steps per trial relax from `rate` (L,) to `median` over `regress` trials."""
        tau = self.regress_trials
        if tau <= 0:
            return trials_left * rate
        return median * trials_left + (rate - median) * tau * -np.expm1(-trials_left / tau)

    @staticmethod
    def _steps_per_trial(trials, steps, since) -> np.ndarray:
        _, trials_then, steps_then = since
        return (steps - steps_then) / np.maximum(trials - trials_then, 1e-9)

    def _step_prices(self, busy: int, n_learners: int) -> np.ndarray:
        """Time of a step [s] while the k-th of `busy` unfinished learners finishes, k = 1..busy (`_seconds`)."""
        sizes = [pow2_batch(k, n_learners) for k in range(busy, 0, -1)]
        price = {n: self.seconds_per_step(n) for n in set(sizes)}  # a few powers of two, each priced once
        return np.array([price[n] for n in sizes])

    @staticmethod
    def _seconds(steps_left: np.ndarray, prices: np.ndarray) -> float:
        """Time [s] until the last of the learners with `steps_left` (L,) is done, at `prices` (`_step_prices`)."""
        return float(np.diff(np.sort(steps_left), prepend=0.0) @ prices)

    def seconds_per_step(self, size: int) -> float:
        """Time of one step at batch `size` [s]: measured (the median of its newest chunks), else
        a + b ceil(size / devices) fitted to the measured sizes (through one, with a = fixed_learners x b)."""
        measured = {n: float(np.median(times)) for n, times in self.step_times.items()}
        if size in measured:
            return measured[size]
        share = np.array([math.ceil(n / self.devices) for n in measured], dtype=np.float64)
        times = np.array(list(measured.values()))
        if len(set(share)) < 2:
            b = float(np.mean(times / (self.fixed_learners + share)))
            a = self.fixed_learners * b
        else:
            b, a = (max(float(c), 0.0) for c in np.polyfit(share, times, 1))
        return a + b * math.ceil(size / self.devices)
