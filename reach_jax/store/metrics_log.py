"""The metrics log of a run in its two forms: rows (one dict per learner per chunk) appended chunk by chunk, readable
and whole after a kill at any moment.

JSON lines (`read_lines`, `append_lines`, `truncate_lines`), what runs begun before the gzip form wrote: one JSON
object per row and line. Gzip (`read_members`, `append_member`, `truncate_members`), what new runs write:
concatenated gzip members, each whole JSON lines. The first holds `{"learners": [...]}`, each learner's fixed
columns (the `fixed` names: its identity and hyperparameters), once; each later one is one append: a line
`{"columns": [...]}` and one JSON array per row, those columns without the fixed ones. A reader puts a learner's
fixed columns back after its "learner" column, so a row reads as it was appended. A kill mid-append leaves its
member cut short: readers leave it out, and truncation on resume removes it.
"""

from __future__ import annotations

import gzip
import json
import math
import zlib
from collections.abc import Iterator
from pathlib import Path

from reach_jax.store import files
from reach_jax.store.checkpoint import CheckpointError

GZIP_WBITS = 31  # zlib's window bits for one gzip member, its header and CRC checked
READ_BLOCK = 1 << 16  # bytes read at a time


def read_lines(path: Path, up_to_chunk: float = math.inf) -> list[dict]:
    """Rows of a JSON-lines log up to a chunk; raises CheckpointError on a line that is not a JSON object."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{path}: unreadable ({exc})") from None
    rows = []
    # An unterminated last line is an append still in flight (or cut by a kill): of a chunk past every checkpoint.
    for n, line in enumerate(text.split("\n")[:-1], 1):
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            raise CheckpointError(f"{path}: line {n} is not valid JSON") from None
        if not isinstance(row, dict):
            raise CheckpointError(f"{path}: line {n} is not a JSON object")
        if row.get("chunk", 0) <= up_to_chunk:
            rows.append(row)
    return rows


def append_lines(path: Path, rows: list[dict]) -> None:
    """Append one JSON line per row to a JSON-lines log."""
    files.append_lines(path, [json.dumps(r) for r in rows])


def truncate_lines(path: Path, chunk: int) -> None:
    """Drop the lines of a JSON-lines log past `chunk` (and any torn tail), atomically."""
    keep = []
    for line in path.read_text().splitlines():
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            break
        if row.get("chunk", math.inf) > chunk:
            break
        keep.append(line)
    files.atomic_write_bytes(path, "".join(x + "\n" for x in keep).encode())


def _members(path: Path) -> Iterator[tuple[int, str]]:
    """Each whole gzip member of a file, as (the offset just past it, its text); a member cut short is left out.

    Raises CheckpointError at bytes that are no gzip member (or fail its CRC).
    """
    start, fed, pending = 0, 0, b""
    member, parts = zlib.decompressobj(GZIP_WBITS), []
    with open(path, "rb") as f:
        while block := pending or f.read(READ_BLOCK):
            try:
                parts.append(member.decompress(block))
            except zlib.error as exc:
                raise CheckpointError(f"{path}: corrupt gzip member at byte {start} ({exc})") from None
            fed += len(block)
            pending = b""
            if member.eof:
                pending = member.unused_data
                start += fed - len(pending)
                try:
                    text = b"".join(parts).decode()
                except UnicodeDecodeError:
                    raise CheckpointError(f"{path}: the gzip member ending at byte {start} is not UTF-8") from None
                yield start, text
                member, parts, fed = zlib.decompressobj(GZIP_WBITS), [], 0


def _lines(path: Path, n: int, text: str) -> list:
    """The JSON values of member n's lines; raises CheckpointError on a line that is not JSON."""
    try:
        return [json.loads(line) for line in text.splitlines()]
    except json.JSONDecodeError:
        raise CheckpointError(f"{path}: gzip member {n} holds a line that is not valid JSON") from None


def _head(path: Path, n: int, lines: list, key: str) -> list:
    """The list under `key` in the object on member n's first line; raises CheckpointError when it has none."""
    head = lines[0] if lines else None
    if not isinstance(head, dict) or not isinstance(head.get(key), list):
        raise CheckpointError(f"{path}: gzip member {n} does not start with a {key} record")
    return head[key]


def read_members(path: Path, up_to_chunk: float = math.inf) -> list[dict]:
    """Rows of a gzip log up to a chunk, each learner's fixed columns put back; raises CheckpointError naming the
    member that cannot be read."""
    rows, learners = [], None
    for n, (_, text) in enumerate(_members(path)):
        lines = _lines(path, n, text)
        if learners is None:
            learners = _head(path, n, lines, "learners")
            continue
        columns = _head(path, n, lines, "columns")
        for values in lines[1:]:
            if not isinstance(values, list) or len(values) != len(columns):
                raise CheckpointError(f"{path}: gzip member {n} has a row that does not match its columns")
            row = {}
            for name, value in zip(columns, values, strict=True):
                row[name] = value
                if name == "learner":
                    if not (isinstance(value, int) and 0 <= value < len(learners)):
                        raise CheckpointError(f"{path}: gzip member {n} names learner {value}, not in its header")
                    row.update(learners[value])
            if row.get("chunk", 0) <= up_to_chunk:
                rows.append(row)
    return rows


def _member(lines: list) -> bytes:
    """Values as one gzip member of compact JSON lines; the member's time is 0, so equal lines give equal bytes."""
    text = "".join(json.dumps(x, separators=(",", ":")) + "\n" for x in lines)
    return gzip.compress(text.encode(), mtime=0)


def append_member(path: Path, rows: list[dict], fixed: tuple[str, ...]) -> None:
    """Append rows to a gzip log as one member, their `fixed` columns left out.

    The first append writes the file whole, by rename, headed by the learners' fixed columns, so its rows must hold
    every learner 0..L-1; each later one is a single fsynced append.
    """
    columns = [name for name in rows[0] if name not in fixed]
    if any(list(r) != list(rows[0]) for r in rows):
        raise ValueError("every metrics row of an append needs the same columns")
    member = _member([{"columns": columns}, *([r[name] for name in columns] for r in rows)])
    if path.exists():
        files.append_bytes(path, member)
        return
    learners = {r["learner"]: {name: r[name] for name in fixed} for r in rows}
    if sorted(learners) != list(range(len(learners))):
        raise ValueError("the first metrics append needs a row of every learner")
    header = _member([{"learners": [learners[i] for i in range(len(learners))]}])
    files.atomic_write_bytes(path, header + member)


def gzip_lines(src: Path, dst: Path, fixed: tuple[str, ...]) -> None:
    """Write the rows of the JSON-lines log `src` as the gzip log `dst`, one member per chunk, so that
    `read_members(dst)` gives the rows that `read_lines(src)` gives; `src` is left as it is.

    A name of `fixed` goes in the header only where every row holds it and each learner's rows agree on it (a run
    resumed under newer code may have gained a column part way); other columns stay in the rows. A row's columns
    keep their order where its fixed ones follow "learner", as every run writes them.
    """
    rows = read_lines(src)
    if not rows:
        raise ValueError(f"{src}: no rows to convert")
    per_learner: dict[int, dict] = {}
    for r in rows:
        per_learner.setdefault(r["learner"], r)
    kept = tuple(name for name in fixed if all(name in r and r[name] == per_learner[r["learner"]][name] for r in rows))
    if sorted(per_learner) != list(range(len(per_learner))):
        raise ValueError(f"{src}: learners are not numbered 0..L-1")
    header = _member([{"learners": [{n: per_learner[i][n] for n in kept} for i in range(len(per_learner))]}])
    members, group = [], [rows[0]]
    for r in rows[1:]:
        if r["chunk"] == group[0]["chunk"] and list(r) == list(group[0]):
            group.append(r)
        else:
            members.append(group)
            group = [r]
    members.append(group)
    parts = [header]
    for group in members:
        columns = [name for name in group[0] if name not in kept]
        parts.append(_member([{"columns": columns}, *([r[name] for name in columns] for r in group)]))
    files.atomic_write_bytes(dst, b"".join(parts))


def truncate_members(path: Path, chunk: int) -> None:
    """Drop the members of a gzip log whose rows are past `chunk`, and any member cut short or unreadable, atomically.

    Each member holds one chunk's rows, so the file is cut between members. Without a whole header nothing is kept:
    the file is removed, and the next append writes it anew.
    """
    end = 0
    try:
        for n, (stop, text) in enumerate(_members(path)):
            if n:
                lines = _lines(path, n, text)
                at = _head(path, n, lines, "columns").index("chunk")
                if any(values[at] > chunk for values in lines[1:]):
                    break
            end = stop
    except (CheckpointError, ValueError, TypeError, IndexError):
        pass  # from there on the file is no log: dropped, like a torn tail
    if end == 0:
        path.unlink()
        return
    with open(path, "rb") as f:
        files.atomic_write_bytes(path, f.read(end))
