"""Durable file writes for run directories and evaluations: whole files by rename, whole lines or blocks by append."""

from __future__ import annotations

import os
from pathlib import Path


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write data to path via a fsynced temporary file and a rename."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(path.parent)


def append_bytes(path: Path, data: bytes) -> None:
    """Append data with a single write and fsync: a kill leaves at most a prefix of it, after every earlier append."""
    with open(path, "ab") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


def append_lines(path: Path, lines: list[str]) -> None:
    """Append whole lines with a single write and fsync, so no line is torn."""
    append_bytes(path, "".join(line + "\n" for line in lines).encode())
