"""A dependency-free progress bar for the training shell (stderr; throttled when not a terminal)."""

from __future__ import annotations

import sys
import time
from collections import deque

import numpy as np


def _clock(seconds: float) -> str:
    seconds = int(max(seconds, 0))
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"


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

    def update(self, done: int, status: str = "", force: bool = False, eta: float | None = None) -> None:
        """Redraw with `done` units finished; `eta` [s], when given, replaces the estimate from the total rate."""
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
        eta = "?" if eta is None else _clock(eta)
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
    (`pow2_batch`), where a step takes less time. So the estimate walks the learners' finishing order: with
    s_1 <= ... <= s_k the steps left of the k unfinished learners (trials left x each one's steps per trial over
    the last `window` updates), the batch runs s_1 steps at size pow2_batch(k), then s_2 - s_1 at
    pow2_batch(k - 1), and so on, each step costing `seconds_per_step` at that size.
    """

    def __init__(self, budget: int, window: int = 20, fixed_share: float = 0.65):
        """Args:
        budget: trials per learner.
        window: updates over which a learner's steps per trial are measured.
        fixed_share: the share of a step's time that does not shrink with the batch, assumed until two batch
          sizes are measured: about 0.7 here (benchmarks/results/throughput.json: 8.2 us a step for 1 learner,
          11.4 us for 8 on 2 devices), about 1 on a GPU. tests/test_progress.py holds the estimate within 25%
          from half the run for true shares of 0.5 to 1.
        """
        self.budget = budget
        self.fixed_share = fixed_share
        self.history: deque = deque(maxlen=window + 1)  # (time [s], trials (L,), steps (L,))
        self.step_time: dict[int, float] = {}  # batch size -> seconds per step in its newest chunk

    def update(self, trials, steps, now: float, batch_size: int) -> float | None:
        """Record the learners' trials and steps after a chunk that ran `batch_size` learners, at time `now` [s].

        Returns the estimate [s], 0 when every learner is done, or None before two points or while an unfinished
        learner has ended no trial in the window.
        """
        trials = np.minimum(np.asarray(trials, dtype=np.float64), self.budget)
        steps = np.asarray(steps, dtype=np.float64)
        if self.history:
            t_prev, _, steps_prev = self.history[-1]
            took = float(np.max(steps - steps_prev))  # the chunk's length: an unfinished member ran all of it
            if now > t_prev and took > 0:
                self.step_time[batch_size] = (now - t_prev) / took
        self.history.append((now, trials, steps))
        left = self.budget - trials
        busy = left > 0
        if not busy.any():
            return 0.0
        _, first_trials, first_steps = self.history[0]
        ended = trials - first_trials
        if not self.step_time or np.any(ended[busy] <= 0):
            return None
        steps_left = np.sort(left[busy] * (steps - first_steps)[busy] / ended[busy])
        seconds, done = 0.0, 0.0
        for k, s in zip(range(len(steps_left), 0, -1), steps_left, strict=True):
            seconds += (s - done) * self.seconds_per_step(pow2_batch(k, len(trials)))
            done = s
        return seconds

    def seconds_per_step(self, size: int) -> float:
        """Time of one step at batch `size` [s]: measured, else a straight line in the size through the measured
        sizes (through one, with `fixed_share` of it independent of the size)."""
        if size in self.step_time:
            return self.step_time[size]
        sizes = np.array(sorted(self.step_time), dtype=np.float64)
        times = np.array([self.step_time[int(n)] for n in sizes])
        if len(sizes) == 1:
            slope = (1.0 - self.fixed_share) * times[0] / sizes[0]
        else:
            slope = max(float(np.polyfit(sizes, times, 1)[0]), 0.0)
        nearest = int(np.argmin(np.abs(sizes - size)))
        return max(float(times[nearest] + slope * (size - sizes[nearest])), 0.0)
