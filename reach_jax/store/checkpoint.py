"""Atomic, versioned checkpoints of batched learner pytrees.

A checkpoint is one .npz holding every leaf under its pytree path, plus a JSON `__meta__` entry
(format version, chunk index, learner table). Files are written to a temporary name, fsynced and
renamed, so a kill at any moment leaves the previous checkpoint readable.
"""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np

from reach_jax.config import compat
from reach_jax.errors import OneLineError
from reach_jax.store.files import atomic_write_bytes

CHECKPOINT_DIR = "checkpoints"
KEEP = 2  # newest checkpoints kept on disk while a run trains
KEEP_FINISHED = 1  # newest checkpoints kept once it has finished: its final one
# The leaves an older checkpoint may lack, keyed like `flatten(template)`: made only when one is missing.
Defaults = Callable[[], dict[str, np.ndarray]]


class CheckpointError(OneLineError):
    """A checkpoint or run directory that cannot be used; the message names the file and field."""


class CheckpointGone(CheckpointError):
    """A listed checkpoint that was no longer there to read: a live run pruned it, which is no corruption."""


def flatten(tree) -> dict[str, np.ndarray]:
    """Leaves of a pytree as NumPy arrays keyed by their path, as a checkpoint stores them."""
    leaves, _ = jax.tree_util.tree_flatten_with_path(tree)
    return {jax.tree_util.keystr(path): np.asarray(leaf) for path, leaf in leaves}


def checkpoint_path(run_dir: Path, chunk: int) -> Path:
    """Path of the checkpoint written after `chunk` chunks."""
    return Path(run_dir) / CHECKPOINT_DIR / f"chunk_{chunk:07d}.npz"


def save(run_dir: Path, chunk: int, tree, meta: dict, keep_every: int = 0) -> Path:
    """Atomically write `tree` as the checkpoint after `chunk` chunks; prune old ones (`prune`, the newest KEEP)."""
    folder = Path(run_dir) / CHECKPOINT_DIR
    folder.mkdir(parents=True, exist_ok=True)
    arrays = flatten(tree)
    arrays["__meta__"] = np.frombuffer(
        json.dumps({"format_version": compat.CHECKPOINT_VERSION, "chunk": chunk, **meta}).encode(), dtype=np.uint8
    )
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    path = checkpoint_path(run_dir, chunk)
    atomic_write_bytes(path, buf.getvalue())
    prune(run_dir, KEEP, keep_every)
    return path


def prune(run_dir: Path, keep: int, keep_every: int = 0) -> None:
    """Remove all but the newest `keep` checkpoints, except, with keep_every > 0, every checkpoint whose chunk is a
    multiple of keep_every (snapshots for looking back at a run)."""
    for old in list_checkpoints(run_dir)[:-keep]:
        if not (keep_every and checkpoint_chunk(old) % keep_every == 0):
            old.unlink()


def checkpoint_chunk(path: Path) -> int:
    """Chunk index in a checkpoint's file name."""
    return int(Path(path).stem.removeprefix("chunk_"))


def list_checkpoints(run_dir: Path) -> list[Path]:
    """Complete checkpoints of a run, oldest first."""
    folder = Path(run_dir) / CHECKPOINT_DIR
    if not folder.is_dir():
        return []
    return sorted(folder.glob("chunk_*.npz"))


def load(path: Path, template, defaults: Defaults | None = None, aliases=compat.state_aliases) -> tuple[object, dict]:
    """Read a checkpoint into the structure of `template`; raises CheckpointError naming what is wrong.

    A leaf the file lacks is read under the first of `aliases(name, format_version)` that it holds (where older
    formats kept it), else taken from `defaults()`, leaves keyed like `flatten(template)` (fields added to the state
    since the file was written), called once and only then; any other missing leaf is an error.
    """
    path = Path(path)
    try:
        # Once open, the file reads whole even if a live run prunes it meanwhile: it is removed, never rewritten.
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except FileNotFoundError:
        raise CheckpointGone(f"{path}: no longer there (pruned by the run that writes it?)") from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise CheckpointError(f"{path}: corrupt or truncated checkpoint ({exc})") from None
    if "__meta__" not in arrays:
        raise CheckpointError(f"{path}: field __meta__ missing")
    try:
        meta = json.loads(arrays.pop("__meta__").tobytes().decode())
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise CheckpointError(f"{path}: field __meta__ is not valid JSON") from None
    version = meta.get("format_version")
    if version not in compat.READABLE_CHECKPOINTS:
        readable = " or ".join(map(str, compat.READABLE_CHECKPOINTS))
        raise CheckpointError(f"{path}: field format_version is {version}, expected {readable}")
    leaves, treedef = jax.tree_util.tree_flatten_with_path(template)
    fallback = None
    restored = []
    for key_path, leaf in leaves:
        name = jax.tree_util.keystr(key_path)
        old = next((a for a in aliases(name, version) if a in arrays), None) if name not in arrays else None
        if old is not None:
            arrays[name] = arrays[old]
        if name not in arrays and defaults is not None:
            fallback = defaults() if fallback is None else fallback
            if name in fallback:
                arrays[name] = fallback[name]
        if name not in arrays:
            raise CheckpointError(f"{path}: field {name} missing")
        value = arrays[name]
        if value.shape != tuple(leaf.shape) or value.dtype != np.dtype(leaf.dtype):
            raise CheckpointError(
                f"{path}: field {name} has shape {value.shape} {value.dtype}, "
                f"expected {tuple(leaf.shape)} {np.dtype(leaf.dtype)}"
            )
        restored.append(value)
    return jax.tree_util.tree_unflatten(treedef, restored), meta


def load_newest(run_dir: Path, template, defaults: Defaults | None = None) -> tuple[object, dict, Path]:
    """`load` of a run's newest checkpoint, and its path; raises CheckpointError when there is none.

    A live run may prune the newest one listed before it is read; the listing is then taken again, and the
    newest then on disk is read (a truly corrupt file still raises).
    """
    while True:
        listed = list_checkpoints(run_dir)
        if not listed:
            raise CheckpointError(f"{Path(run_dir) / CHECKPOINT_DIR}: no checkpoints")
        try:
            return (*load(listed[-1], template, defaults), listed[-1])
        except CheckpointGone:
            continue
