"""One writer per run directory: an advisory flock on RUN_DIR/.lock, which the OS drops when its holder dies."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import socket
import time
from collections.abc import Iterator
from pathlib import Path

from reach_jax.errors import OneLineError

LOCK_FILE = ".lock"  # holds {"pid": ..., "host": ...} of the live holder; the flock, not the text, is the lock
READER_GRACE = 0.5  # [s] a writer retries for while a reader's probe (a shared flock of an instant) is in the way


class RunLockedError(OneLineError):
    """Another live process trains the run directory."""


def lock_path(run_dir: Path) -> Path:
    """The lock file of a run directory."""
    return Path(run_dir) / LOCK_FILE


def _describe(text: bytes) -> str:
    """'PID 12 on host h' from a lock file's text; what is missing (a holder that has not written it yet) says so."""
    try:
        who = json.loads(text.decode())
        return f"PID {int(who['pid'])} on host {who['host']}"
    except (UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError, ValueError):
        return "holder's PID and host unknown"


def holder(run_dir: Path) -> str | None:
    """Who holds run_dir's lock ('PID 12 on host h'), or None when no live process does; writes nothing."""
    try:
        fd = os.open(lock_path(run_dir), os.O_RDONLY)
    except (OSError, ValueError):  # no lock file (no run yet, or every holder ended cleanly), or no such path
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return _describe(os.pread(fd, 4096, 0))
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


def locked_message(run_dir: Path, who: str) -> str:
    """The one line that refuses a second writer."""
    return f"{run_dir} is being trained by another process ({who}); wait for it to end or stop it"


def check_free(run_dir: Path) -> None:
    """Raise RunLockedError when a live process holds run_dir's lock; writes nothing."""
    who = holder(run_dir)
    if who is not None:
        raise RunLockedError(locked_message(run_dir, who))


def _acquire(path: Path) -> int:
    """A descriptor of `path` holding its exclusive flock, with this process's PID and host written into it."""
    deadline = time.monotonic() + READER_GRACE
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            who = _describe(os.pread(fd, 4096, 0))
            os.close(fd)
            if time.monotonic() < deadline:
                time.sleep(0.05)
                continue
            raise RunLockedError(locked_message(path.parent, who)) from None
        try:
            current = os.stat(path).st_ino
        except FileNotFoundError:
            current = None
        if current == os.fstat(fd).st_ino:
            break
        os.close(fd)  # a holder that just ended removed this file; lock the one at the path now
    os.ftruncate(fd, 0)
    os.write(fd, json.dumps({"pid": os.getpid(), "host": socket.gethostname()}).encode())
    return fd


@contextlib.contextmanager
def hold(run_dir: Path) -> Iterator[None]:
    """Hold run_dir's lock within (creating run_dir); raises RunLockedError at once when a live process holds it.

    A clean end removes the lock file; a killed holder leaves it, unlocked, for the next writer to take.
    """
    path = lock_path(run_dir)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = _acquire(path)
    try:
        yield
    finally:
        # Unlink before unlocking: a writer waiting on this file then finds it gone and locks a new one.
        with contextlib.suppress(FileNotFoundError):
            if os.stat(path).st_ino == os.fstat(fd).st_ino:
                path.unlink()
        os.close(fd)
