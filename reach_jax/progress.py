"""A dependency-free progress bar for the training shell (stderr; throttled when not a terminal)."""

from __future__ import annotations

import sys
import time


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

    def update(self, done: int, status: str = "", force: bool = False) -> None:
        """Redraw with `done` units finished."""
        now = time.monotonic()
        if self.first_done is None:
            self.first_done = (done, now)
        if not force and now - self.last_print < self.min_interval:
            return
        self.last_print = now
        frac = min(done / self.total, 1.0)
        d0, t0 = self.first_done
        rate = (done - d0) / (now - t0) if now > t0 and done > d0 else 0.0
        eta = _clock((self.total - done) / rate) if rate > 0 else "?"
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
