"""Run directories: the one reader and writer of config.json, the metrics log and the learners' checkpoints.

Layout of RUN_DIR: config.json (the whole Config), metrics.jsonl.gz (one row per learner per chunk, appended one
gzip member a chunk; runs begun before it keep their metrics.jsonl, one JSON object a line: `metrics_log`),
checkpoints/chunk_NNNNNNN.npz (`checkpoint`), trials/ (the per-trial log, with train.trial_log_every) and eval/
(written by `evaluate`).
Every failure to read is a CheckpointError whose one-line message names the file and the field.
"""

from __future__ import annotations

import functools
import json
import math
import os
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from reach_jax.config import Config, compat, first_difference, from_dict, hyper, to_dict, to_json
from reach_jax.config.schema import SPEED_RESULT_FIELDS, Speed
from reach_jax.engine import batch, learner_state
from reach_jax.env import trial_log
from reach_jax.store import checkpoint, files, metrics_log
from reach_jax.store.checkpoint import CheckpointError

CONFIG_FILE = "config.json"
METRICS_FILE = "metrics.jsonl.gz"  # the metrics log of a run: gzip members, one per chunk (`metrics_log`)
LEGACY_METRICS_FILE = "metrics.jsonl"  # the JSON lines of runs begun before METRICS_FILE: read, and resumed, as such
# A learner's fixed columns in its metrics rows (its identity, its hyperparameters): once, in METRICS_FILE's header
LEARNER_COLUMNS = ("condition", "seed", *hyper.NAMES)
TRIALS_DIR = "trials"  # the per-trial log: one little-endian binary file per column, appended chunk by chunk
TRIAL_KEYS = {"learner": "<i4", "trial": "<i4", "chunk": "<i4"}  # columns the shell adds to trial_log.COLUMNS


def read_config(run_dir: Path) -> Config:
    """config.json of a run; raises CheckpointError naming the file and field."""
    path = Path(run_dir) / CONFIG_FILE
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise CheckpointError(f"{path}: missing") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CheckpointError(f"{path}: unreadable ({exc})") from None
    if not isinstance(data, dict):
        raise CheckpointError(f"{path}: expected a JSON object")
    try:
        return from_dict(data)
    except (TypeError, ValueError) as exc:
        raise CheckpointError(f"{path}: {exc}") from None


def create(run_dir: Path, cfg: Config) -> None:
    """Start a run directory: write config.json and drop any metrics of an earlier attempt."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    files.atomic_write_bytes(run_dir / CONFIG_FILE, to_json(cfg).encode())
    for name in (METRICS_FILE, LEGACY_METRICS_FILE):
        (run_dir / name).unlink(missing_ok=True)
    for name in trial_columns():
        (run_dir / TRIALS_DIR / f"{name}.bin").unlink(missing_ok=True)


def holds_run(run_dir: Path) -> bool:
    """Whether run_dir already has a config.json."""
    return (Path(run_dir) / CONFIG_FILE).exists()


def metrics_path(run_dir: Path) -> Path:
    """The run's metrics log: its LEGACY_METRICS_FILE if it has one (begun before METRICS_FILE), else METRICS_FILE."""
    legacy = Path(run_dir) / LEGACY_METRICS_FILE
    return legacy if legacy.exists() else Path(run_dir) / METRICS_FILE


def read_metrics(run_dir: Path, up_to_chunk: float = math.inf) -> list[dict]:
    """Rows of the metrics log up to a chunk ([] when the run has no finished chunk), in either form; raises
    CheckpointError, naming the file, on a line or member that cannot be read."""
    path = metrics_path(run_dir)
    if not path.exists():
        return []
    if path.name == LEGACY_METRICS_FILE:
        return metrics_log.read_lines(path, up_to_chunk)
    return metrics_log.read_members(path, up_to_chunk)


def append_metrics(run_dir: Path, rows: list[dict]) -> None:
    """Append a chunk's rows to the metrics log, in the form the run began with."""
    path = metrics_path(run_dir)
    if path.name == LEGACY_METRICS_FILE:
        metrics_log.append_lines(path, rows)
    else:
        metrics_log.append_member(path, rows, LEARNER_COLUMNS)


def truncate_metrics(run_dir: Path, chunk: int) -> None:
    """Drop the metrics rows past `chunk` (and any torn tail), atomically; a resumed run then appends after them."""
    path = metrics_path(run_dir)
    if not path.exists():
        return
    if path.name == LEGACY_METRICS_FILE:
        metrics_log.truncate_lines(path, chunk)
    else:
        metrics_log.truncate_members(path, chunk)


def trial_columns() -> dict[str, str]:
    """Every column of the per-trial log and its NumPy dtype."""
    return {**TRIAL_KEYS, **{name: "<f4" for name in trial_log.COLUMNS}}


def append_trials(run_dir: Path, columns: dict[str, np.ndarray]) -> None:
    """Append records (one array per column of `trial_columns`, equal lengths) to the run's per-trial log."""
    folder = Path(run_dir) / TRIALS_DIR
    folder.mkdir(exist_ok=True)
    for name, dtype in trial_columns().items():
        with open(folder / f"{name}.bin", "ab") as f:
            f.write(np.asarray(columns[name], dtype).tobytes())
            f.flush()
            os.fsync(f.fileno())


def _trial_lengths(folder: Path) -> int:
    """Records that every column holds (a kill mid-append leaves some columns longer)."""
    sizes = [
        (folder / f"{n}.bin").stat().st_size // np.dtype(d).itemsize if (folder / f"{n}.bin").exists() else 0
        for n, d in trial_columns().items()
    ]
    return min(sizes)


def read_trials(run_dir: Path, up_to_chunk: float = math.inf) -> dict[str, np.ndarray] | None:
    """The per-trial log up to a chunk, one array per column; None when the run keeps none."""
    folder = Path(run_dir) / TRIALS_DIR
    if not folder.is_dir():
        return None
    n = _trial_lengths(folder)
    columns = {name: np.fromfile(folder / f"{name}.bin", dtype, count=n) for name, dtype in trial_columns().items()}
    keep = int(np.searchsorted(columns["chunk"], up_to_chunk, side="right"))
    return {name: column[:keep] for name, column in columns.items()}


def truncate_trials(run_dir: Path, chunk: int) -> None:
    """Drop per-trial records past `chunk` (and any torn tail); a resumed run then appends after them."""
    folder = Path(run_dir) / TRIALS_DIR
    if not folder.is_dir():
        return
    keep = len(read_trials(run_dir, chunk)["chunk"])
    for name, dtype in trial_columns().items():
        path = folder / f"{name}.bin"
        if path.exists():
            os.truncate(path, keep * np.dtype(dtype).itemsize)


def speed_settings(speed: Speed, engine: str) -> dict:
    """What of how a run computes changes its results, as a checkpoint stores it: the settings of `speed` that do
    (`SPEED_RESULT_FIELDS`) and the arithmetic's engine (`distribute.engine`)."""
    return {**{name: getattr(speed, name) for name in SPEED_RESULT_FIELDS}, "engine": engine}


def write_checkpoint(run_dir: Path, chunk: int, learners: batch.Batch, cfg: Config, speed: Speed, engine: str) -> Path:
    """Save the learner states and hyperparameters after `chunk` chunks, with the config, the speed settings
    that change results and the engine as the run's identity."""
    tree = {"states": learners.states, "hypers": learners.hypers}
    return checkpoint.save(run_dir, chunk, tree, _identity(cfg, speed, engine), cfg.train.keep_every)


@functools.lru_cache(maxsize=8)
def _identity(cfg: Config, speed: Speed, engine: str) -> dict:
    """A checkpoint's config and speed entries, made once a run: the config's dict took ~1.3 ms of every chunk."""
    return {"config": to_dict(cfg), "speed": {**speed_settings(speed, engine), "loop": speed.engine}}  # loop: unchecked


def check_speed(path: Path, meta: dict, speed: Speed, engine: str) -> None:
    """Raise CheckpointError if `speed` or `engine` would change the results of the run that wrote `path`."""
    stored = meta.get("speed", {})
    if not isinstance(stored, dict):
        raise CheckpointError(f"{path}: field speed is not an object")
    for name, wanted in speed_settings(speed, engine).items():
        made = stored.get(name, compat.SPEED_BEFORE_STORED[name])
        if made != wanted:
            hint = compat.ENGINE_CODE.get(made, "") if name == "engine" else ""
            raise CheckpointError(
                f"{path}: field speed.{name} is {made!r}; resuming with {wanted!r} would change the results{hint}"
            )


def load_batch(
    run_dir: Path, cfg: Config, path: Path | None = None, speed: Speed | None = None, engine: str | None = None
) -> tuple[batch.Batch, int]:
    """Newest (or given) checkpoint of a run as a Batch, with its chunk index.

    Raises CheckpointError when there is none, when the config stored in it disagrees with `cfg`, or when
    `speed` and `engine` (what the run continues with, `check_speed`; None: not checked) would change results.
    """
    hypers = batch.hyper_columns(cfg)
    template = {"states": _state_shapes(cfg, jax.config.jax_enable_x64), "hypers": hypers}

    # Hyperparameters added since the checkpoint was written take their values from the config, and state fields
    # added since (the condition and block a trial runs in, which never change without a protocol, and the
    # others of compat.ADDED_STATE_FIELDS) the values of a fresh learner.
    def defaults():
        return {**checkpoint.flatten({"hypers": hypers}), **added_state_defaults(cfg)}

    if path is None:
        tree, meta, path = checkpoint.load_newest(run_dir, template, defaults)
    else:
        tree, meta = checkpoint.load(path, template, defaults)
    try:
        # Through from_dict, so a stored config of an older version reads as what the run trained with.
        stored = from_dict(meta["config"])
    except (KeyError, TypeError, ValueError) as exc:
        raise CheckpointError(f"{path}: stored config unreadable ({exc})") from None
    diff = first_difference(stored, cfg)
    if diff:
        raise CheckpointError(f"{path}: field config.{diff} disagrees with {CONFIG_FILE}")
    if speed is not None:
        check_speed(path, meta, speed, engine)
    states, hypers = (jax.tree.map(jnp.asarray, tree[k]) for k in ("states", "hypers"))
    return batch.Batch(states, batch.conditions(cfg), hypers, batch.plans(cfg)), int(meta["chunk"])


@functools.lru_cache(maxsize=32)
def _state_shapes(cfg: Config, x64: bool) -> learner_state.LearnerState:
    """The shape and dtype of every leaf of cfg's fresh learner states, traced, never built; kept per config and
    JAX's 64-bit mode (`x64`, which sets the dtypes), since readers such as `--resume`'s validation ask again."""
    return jax.eval_shape(lambda: batch.fresh_states(cfg))


def added_state_defaults(cfg: Config) -> dict[str, np.ndarray]:
    """The leaves of a fresh batch that older checkpoints lack (`compat.ADDED_STATE_FIELDS`), keyed as stored.

    One compiled program keeps just these leaves: copies of the config's conditions and blocks, and constants, bit
    for bit what `batch.fresh_states` gives them.
    """

    def added():
        leaves = jax.tree_util.tree_flatten_with_path({"states": batch.fresh_states(cfg)})[0]
        named = ((jax.tree_util.keystr(path), leaf) for path, leaf in leaves)
        return {name: leaf for name, leaf in named if compat.is_added_state_field(name)}

    return {name: np.asarray(leaf) for name, leaf in jax.jit(added)().items()}


class Run(NamedTuple):
    """Everything read from a run directory: config, learners at one checkpoint, and the metrics up to it."""

    cfg: Config
    batch: batch.Batch
    chunk: int  # chunks trained at the checkpoint
    learners: list  # (condition, seed index) per learner, `batch.learner_table`
    metrics: list  # metrics rows up to `chunk` (`read_metrics`)
    trials: dict | None  # the per-trial log up to `chunk` (`read_trials`); None when the run keeps none


def load(run_dir: Path, path: Path | None = None) -> Run:
    """A run at its newest (or the given) checkpoint; raises CheckpointError naming the bad path."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise CheckpointError(f"{run_dir}: not a run directory (missing or not a directory)")
    if path is not None and not Path(path).is_file():
        raise CheckpointError(f"{path}: no such checkpoint")
    cfg = read_config(run_dir)
    learners, chunk = load_batch(run_dir, cfg, path)
    table = batch.learner_table(cfg.train)
    return Run(cfg, learners, chunk, table, read_metrics(run_dir, chunk), read_trials(run_dir, chunk))


def load_params(run_dir: Path, path: Path | None = None) -> tuple[dict, list[tuple[str, int]]]:
    """The trained network parameters of a run: a pytree with the learner axis first, and who each learner is.

    Args:
      run_dir: a run directory written by `reach_jax.train`.
      path: a checkpoint to read instead of the newest.

    Returns:
      (params, learners): params as `network.init_params` builds them, each leaf (L, ...);
      learners[i] = (condition, seed index) of learner i.
    """
    run = load(run_dir, path)
    return run.batch.states.agent.params, run.learners


MODEL_SECTIONS = ("arm", "sensor", "encoding", "network")  # what a network's weights mean


def load_networks(cfg: Config) -> tuple:
    """(LearnerState, learner table) at the last checkpoint of cfg.train.init_from, whose model must be cfg's.

    Raises CheckpointError naming the run and the first model field that differs.
    """
    source = Path(cfg.train.init_from)
    stored = read_config(source)
    for section in MODEL_SECTIONS:
        if getattr(stored, section) != getattr(cfg, section):
            raise CheckpointError(f"train.init_from: {source} has another {section} section than this run")
    learners, _ = load_batch(source, stored)
    return learners.states, batch.learner_table(stored.train)
