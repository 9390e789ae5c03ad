"""Stopping a training run when asked: a first SIGTERM or SIGINT ends it after the chunk in flight, a second at once."""

from __future__ import annotations

import contextlib
import os
import shlex
import signal
import threading
from collections.abc import Iterator
from pathlib import Path

import jax
import numpy as np

from reach_jax.engine import distribute

SIGNALS = (signal.SIGTERM, signal.SIGINT)
RESUME_COMMAND = "python -m reach_jax.train --resume"


class Interrupted(Exception):
    """Training stopped on a signal; the checkpoint after `chunk` chunks resumes it."""

    def __init__(self, signum: int, run_dir: Path, chunk: int):
        self.signum, self.run_dir, self.chunk = signum, Path(run_dir), chunk
        super().__init__(f"stopped by {signal.Signals(signum).name} after chunk {chunk}")

    def resume_command(self) -> str:
        """The command line that continues the run (with --multihost when several processes trained it)."""
        multihost = " --multihost" if jax.process_count() > 1 else ""
        return f"{RESUME_COMMAND} {shlex.quote(str(self.run_dir))}{multihost}"


class Stop:
    """The first stop signal caught (`catch`), which the training loop asks about between chunks."""

    def __init__(self, signals: tuple = ()):
        self.signals = signals  # those whose handler is `handle`
        self.signum: int | None = None

    def handle(self, signum, frame) -> None:
        """Signal handler: remember the first; a second ends the process at once, as the signal would have."""
        if self.signum is not None:
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
        self.signum = signum
        # From now on the kernel ends the process on either signal, even while Python waits in compiled code.
        for s in self.signals:
            signal.signal(s, signal.SIG_DFL)

    def anywhere(self) -> int | None:
        """The signal that stops the run: this process's, else (in a multi-process run) another's; None to go on.

        In a multi-process run every process must call it at the same point, once per chunk: they stop together.
        """
        if jax.process_count() == 1:
            return self.signum
        caught = distribute.gather_processes(np.array([self.signum or 0], np.int32))
        return int(caught.max()) or None


@contextlib.contextmanager
def catch() -> Iterator[Stop]:
    """Within, SIGTERM and SIGINT set the Stop they yield instead of ending the process; the previous handlers
    come back after. Off the main thread (where Python cannot handle signals) nothing is installed."""
    if threading.current_thread() is not threading.main_thread():
        yield Stop()
        return
    # A signal that was ignored (SIGINT of a background job) stays ignored.
    previous = {s: signal.getsignal(s) for s in SIGNALS if signal.getsignal(s) is not signal.SIG_IGN}
    stop = Stop(tuple(previous))
    for s in previous:
        signal.signal(s, stop.handle)
    try:
        yield stop
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def wait_ready(tree) -> None:
    """Block until every array of tree is computed, waiting in Python so that signal handlers run meanwhile.

    jax's own wait holds a handler off until the computation ends; here a helper thread waits for it instead.
    """
    ready = threading.Event()

    def block():
        with contextlib.suppress(Exception):  # the caller's device_get raises the computation's error again
            jax.block_until_ready(tree)
        ready.set()

    threading.Thread(target=block, daemon=True).start()
    # A signal that another thread took does not wake this wait; the timeout lets its handler run soon anyway.
    while not ready.wait(0.1):
        pass
