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


class LearnerEta:
    """Time left [s] until the slowest learner is done, from each learner's own recent rate of trials.

    Learners of a batch run in lockstep, so the run ends when the last one reaches its budget; an estimate from
    the total rate is far too early once the fast learners are done. Each learner's rate is taken over the last
    `window` updates, and the estimate is the largest (budget - trials) / rate over the unfinished learners.
    """

    def __init__(self, budget: int, window: int = 20):
        self.budget = budget
        self.history: deque = deque(maxlen=window + 1)

    def update(self, trials, now: float) -> float | None:
        """Record the learners' trial counts at time `now` [s]; returns the estimate, or None before two points."""
        trials = np.minimum(np.asarray(trials, dtype=np.float64), self.budget)
        self.history.append((now, trials))
        (t0, first), (t1, last) = self.history[0], self.history[-1]
        left = self.budget - last
        if t1 <= t0 or not np.any(left > 0):
            return None if np.any(left > 0) else 0.0
        rate = (last - first) / (t1 - t0)
        busy = left > 0
        if np.any(rate[busy] <= 0):
            return None
        return float(np.max(left[busy] / rate[busy]))
