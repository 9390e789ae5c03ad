"""Turn the plain metrics.jsonl of committed runs into metrics.jsonl.gz, the form new runs write, and check it.

    python tools/gzip_metrics.py runs/heldout runs/table2 ...

For each run it writes metrics.jsonl.gz beside metrics.jsonl, reads both back and removes the plain file only
when every row reads equal, key order included; it prints the sizes. The run then reads, resumes and evaluates as
before (`store.run_dir.metrics_path` takes the gzip form once the plain one is gone).
"""

from __future__ import annotations

import sys
from pathlib import Path

from reach_jax.store import metrics_log
from reach_jax.store import run_dir as run_dir_io


def convert(run: Path) -> tuple[int, int]:
    """Convert one run's log; returns (bytes before, bytes after). Raises ValueError if a row would read otherwise."""
    src, dst = run / run_dir_io.LEGACY_METRICS_FILE, run / run_dir_io.METRICS_FILE
    if dst.exists():
        raise ValueError(f"{dst}: already there")
    metrics_log.gzip_lines(src, dst, run_dir_io.LEARNER_COLUMNS)
    before, after = metrics_log.read_lines(src), metrics_log.read_members(dst)
    if before != after or [list(r) for r in before] != [list(r) for r in after]:
        dst.unlink()
        raise ValueError(f"{dst}: its rows do not read back as {src}'s; left unconverted")
    sizes = src.stat().st_size, dst.stat().st_size
    src.unlink()
    return sizes


def main(argv: list[str]) -> int:
    for run in map(Path, argv):
        before, after = convert(run)
        print(f"{run}: {before:,} -> {after:,} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
