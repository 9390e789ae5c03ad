"""Training: a pure compiled core over a batch of learners, and an impure shell that runs it in chunks.

`python -m reach_jax.train --trials 2e6 --seeds 2` trains the four Table-2 conditions x 2 seeds as one batch.
The shell, between compiled chunks, draws the progress bar, appends metrics, writes checkpoints and
checks that every learner is still finite. Units: trials, steps (of cfg.arm.dt seconds), seconds.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import math
import os
import sys
import time
import zlib
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from reach_jax import checkpoint, rollout, task
from reach_jax.config import (
    CONDITIONS,
    MAX_HIDDEN_PAD,
    Config,
    OneLineError,
    TrainConfig,
    error_line,
    from_dict,
    to_dict,
    to_json,
    tuplify,
)
from reach_jax.progress import LearnerEta, Progress

EXIT_USAGE = 2  # bad arguments, config or checkpoint; nothing written
EXIT_NUMERICS = 3  # a learner went non-finite; the last good checkpoint is kept
EXIT_IO = 4  # a write failed; the last good checkpoint is kept
EXIT_PEER = 5  # another process of a multi-process run stopped; the last good checkpoint is kept

# Where --multihost looks for a setting that its flag does not give (jax itself reads only the first).
CLUSTER_ENV = {
    "coordinator": "JAX_COORDINATOR_ADDRESS",
    "num_processes": "JAX_NUM_PROCESSES",
    "process_id": "JAX_PROCESS_ID",
}


class Batch(NamedTuple):
    """Everything a chunk needs, learner axis first."""

    states: rollout.LearnerState
    conds: task.Condition
    hypers: rollout.Hyper


class NumericsError(RuntimeError):
    """A learner's parameters or state stopped being finite."""


# rollout.Hyper field -> the TrainConfig grid that sweeps it (its default is the LearnerConfig field of that name).
HYPER_GRIDS = {
    "lr": "lr_grid",
    "noise": "noise_grid",
    "lam": "lam_grid",
    "noise_final_ratio": "noise_final_ratio_grid",
    "noise_anneal_delay": "noise_anneal_delay_grid",
    "noise_anneal_trials": "noise_anneal_trials_grid",
}


def hyper_grid(cfg: Config) -> list[dict[str, float]]:
    """Hyperparameter combinations of a sweep, keyed like rollout.Hyper; the learner defaults when nothing is swept."""
    axes = [getattr(cfg.train, grid) or (getattr(cfg.learner, name),) for name, grid in HYPER_GRIDS.items()]
    return [dict(zip(HYPER_GRIDS, combo, strict=True)) for combo in itertools.product(*axes)]


def learner_hypers(cfg: Config) -> list[dict[str, float]]:
    """Hyperparameters of every learner, aligned with learner_table."""
    return [h for _ in cfg.train.conditions for h in hyper_grid(cfg) for _ in range(cfg.train.seeds)]


def learner_table(train: TrainConfig) -> list[tuple[str, int]]:
    """(condition, seed index) of every learner, in batch order: condition, then sweep point, then seed."""
    n_grid = math.prod(max(len(getattr(train, grid)), 1) for grid in HYPER_GRIDS.values())
    return [(c, s) for c in train.conditions for _ in range(n_grid) for s in range(train.seeds)]


def learner_key(seed: int, index: int) -> jax.Array:
    """Key of seed index `index`; shared across conditions, so each seed starts from the same weights."""
    return jax.random.fold_in(jax.random.PRNGKey(seed), index)


def init_batch(cfg: Config) -> Batch:
    """Fresh learners for cfg.train's conditions x seeds."""
    table = learner_table(cfg.train)
    conds = task.stack_conditions([c for c, _ in table], cfg)
    keys = jnp.stack([learner_key(cfg.train.seed, s) for _, s in table])
    states = jax.vmap(lambda k, c: rollout.init_learner(k, c, cfg))(keys, conds)
    hypers = rollout.Hyper(**{name: jnp.asarray([float(h[name]) for h in learner_hypers(cfg)]) for name in HYPER_GRIDS})
    # Fresh buffers: init may alias leaves, which the donating chunk cannot accept.
    return Batch(*jax.tree.map(jnp.copy, (states, conds, hypers)))


def make_train(cfg: Config, n_steps: int):
    """Pure `train(key, cond, hyper) -> LearnerState` for one learner; jit(vmap(train)) trains many."""

    def train(key, cond, hyper):
        def step_body(state, u):
            return rollout.learner_step(state, u, cond, hyper, cfg)[0], None

        return rollout.scan_steps(step_body, rollout.init_learner(key, cond, cfg), n_steps, cfg)[0]

    return train


@jax.jit
def finite_learners(states: rollout.LearnerState) -> jax.Array:
    """(L,) bool: every parameter and arm value of the learner is finite."""
    leaves = jax.tree.leaves((states.params, states.arm, states.n_max))
    per_leaf = [jnp.all(jnp.isfinite(x.reshape(x.shape[0], -1)), axis=1) for x in leaves]
    return jnp.all(jnp.stack(per_leaf), axis=0)


def metrics_rows(states: rollout.LearnerState, table, chunk: int, wall: float, cfg: Config) -> list[dict]:
    """One metrics record per learner for the chunk just run."""
    s = jax.device_get(states.stats)
    trials, steps = np.asarray(states.trials), np.asarray(states.steps)
    distance, n_max = np.asarray(states.distance), np.asarray(states.n_max)
    hypers = learner_hypers(cfg)
    columns = rollout.Hyper(**{name: jnp.asarray([h[name] for h in hypers]) for name in HYPER_GRIDS})
    bound = np.asarray(rollout.exploration_bound(columns, states.trials, states.full_at))
    rows = []
    for i, ((cond, seed), hyper) in enumerate(zip(table, hypers, strict=True)):
        ended = int(s.trials[i])

        def per(counter, i=i, ended=ended):
            return float(counter[i]) / ended if ended else None

        mean_steps = per(s.trial_steps)
        rows.append(
            {
                "chunk": chunk,
                "learner": i,
                "condition": cond,
                "seed": seed,
                **hyper,
                "trials": int(trials[i]),
                "steps": int(steps[i]),
                "chunk_trials": ended,
                "success_rate": per(s.goals),
                "out_rate": per(s.outs),
                "cap_rate": per(s.caps),
                "drift_rate": per(s.drifted),
                "mean_trial_steps": mean_steps,
                "mean_trial_s": None if mean_steps is None else mean_steps * cfg.arm.dt,
                "distance_m": float(distance[i]),
                "n_max": float(n_max[i]),
                "exploration": float(bound[i]),
                "wall_s": round(wall, 3),
            }
        )
    return rows


def status_line(rows: list[dict]) -> str:
    """Recent success rate per condition, for the progress bar."""
    by_cond: dict[str, list[float]] = {}
    for r in rows:
        if r["success_rate"] is not None:
            by_cond.setdefault(r["condition"], []).append(r["success_rate"])
    return " ".join(f"{c} {np.mean(v):.2f}" for c, v in by_cond.items()) or "no trial ended yet"


def chunk_members(trials: np.ndarray, budget: int) -> np.ndarray:
    """Sorted indices of the learners that the next chunk runs.

    Every unfinished learner, padded with finished ones (which stay frozen) up to the next power of two, or to
    the whole batch: in the tail of a run the chunk costs about as many learners as are left, and only a few
    batch sizes are ever compiled. A learner's steps do not depend on which others share its chunk.

    Args:
      trials: (L,) trials ended per learner.
      budget: trials per learner.
    """
    left = np.flatnonzero(trials < budget)
    if len(left) == 0:
        return left
    size = min(len(trials), 1 << (len(left) - 1).bit_length())
    done = np.flatnonzero(trials >= budget)
    return np.sort(np.concatenate([left, done[: size - len(left)]]))


def merge_members(states, members: np.ndarray, ran):
    """Host states of every learner after a chunk that ran only `members`: theirs from `ran`, the others as they
    were but with zeroed chunk counters."""
    states = states.replace(stats=jax.tree.map(np.zeros_like, states.stats))
    if len(members) == len(np.asarray(states.trials)):
        return jax.tree.map(np.asarray, ran)

    def put(whole, part):
        whole = np.array(whole)
        whole[members] = part
        return whole

    return jax.tree.map(put, states, ran)


def checkpoint_meta(cfg: Config) -> dict:
    """Identity of a run, stored in each checkpoint."""
    return {"config": to_dict(cfg)}


def _first_difference(a, b, prefix: str = "") -> str | None:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            diff = _first_difference(a.get(k), b.get(k), f"{prefix}{k}.")
            if diff:
                return diff
        return None
    return prefix.rstrip(".") if a != b else None


def write_checkpoint(run_dir: Path, chunk: int, batch: Batch, cfg: Config) -> Path:
    """Save the learner states and hyperparameters after `chunk` chunks."""
    tree = {"states": batch.states, "hypers": batch.hypers}
    return checkpoint.save(run_dir, chunk, tree, checkpoint_meta(cfg), cfg.train.keep_every)


def load_batch(run_dir: Path, cfg: Config, path: Path | None = None) -> tuple[Batch, int]:
    """Newest (or given) checkpoint of a run as a Batch, with its chunk index."""
    ckpts = checkpoint.list_checkpoints(run_dir)
    if path is None and not ckpts:
        raise checkpoint.CheckpointError(f"{Path(run_dir) / checkpoint.CHECKPOINT_DIR}: no checkpoints")
    path = path or ckpts[-1]
    fresh = jax.eval_shape(lambda: init_batch(cfg))
    # Hyperparameters added since the checkpoint was written take their values from the config.
    defaults = {"hypers": jax.tree.map(np.asarray, init_batch(cfg).hypers)}
    tree, meta = checkpoint.load(path, {"states": fresh.states, "hypers": fresh.hypers}, defaults)
    try:
        # Through from_dict, so a field added to the config since the checkpoint reads as its default.
        stored = json.loads(json.dumps(to_dict(from_dict(meta["config"]))))
    except (KeyError, TypeError, ValueError) as exc:
        raise checkpoint.CheckpointError(f"{path}: stored config unreadable ({exc})") from None
    diff = _first_difference(stored, json.loads(json.dumps(to_dict(cfg))))
    if diff:
        raise checkpoint.CheckpointError(f"{path}: field config.{diff} disagrees with {checkpoint.CONFIG_FILE}")
    conds = task.stack_conditions([c for c, _ in learner_table(cfg.train)], cfg)
    return Batch(jax.tree.map(jnp.asarray, tree["states"]), conds, jax.tree.map(jnp.asarray, tree["hypers"])), int(
        meta["chunk"]
    )


def read_config(run_dir: Path) -> Config:
    """config.json of a run; raises CheckpointError naming the file and field."""
    path = Path(run_dir) / checkpoint.CONFIG_FILE
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise checkpoint.CheckpointError(f"{path}: missing") from None
    except (OSError, json.JSONDecodeError) as exc:
        raise checkpoint.CheckpointError(f"{path}: unreadable ({exc})") from None
    if not isinstance(data, dict):
        raise checkpoint.CheckpointError(f"{path}: expected a JSON object")
    try:
        return from_dict(data)
    except (TypeError, ValueError) as exc:
        raise checkpoint.CheckpointError(f"{path}: {exc}") from None


def truncate_metrics(run_dir: Path, chunk: int) -> None:
    """Drop metrics lines past `chunk` (and any torn tail), atomically."""
    path = Path(run_dir) / checkpoint.METRICS_FILE
    if not path.exists():
        return
    keep = []
    for line in path.read_text().splitlines():
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            break
        if row.get("chunk", math.inf) > chunk:
            break
        keep.append(line)
    checkpoint.atomic_write_bytes(path, "".join(x + "\n" for x in keep).encode())


def run(cfg: Config, run_dir: Path, resume: bool = False, progress: bool = True, stream=None) -> Batch:
    """Train cfg.train's learners in chunks, logging and checkpointing into run_dir; returns the final batch.

    In a multi-process run every process trains the same batch (each its slice) and only process 0 writes
    run_dir and draws the bar; resuming, every process reads the newest checkpoint, so run_dir must be shared.
    Raises NumericsError if a learner goes non-finite; the last good checkpoint stays on disk.
    """
    run_dir = Path(run_dir)
    table = learner_table(cfg.train)
    writer = jax.process_index() == 0
    if resume:
        # Process 0 writes the next checkpoint only after a gather that needs every process's loaded slice.
        batch, chunk = load_batch(run_dir, cfg)
        if writer:
            truncate_metrics(run_dir, chunk)
    else:
        batch, chunk = init_batch(cfg), 0
        if writer:
            run_dir.mkdir(parents=True, exist_ok=True)
            checkpoint.atomic_write_bytes(run_dir / checkpoint.CONFIG_FILE, to_json(cfg).encode())
            (run_dir / checkpoint.METRICS_FILE).unlink(missing_ok=True)
            write_checkpoint(run_dir, chunk, batch, cfg)
    budget = jnp.asarray(cfg.train.trials, jnp.int32)
    run_chunk = rollout.make_chunk(cfg, cfg.train.chunk_steps)
    total = cfg.train.trials * len(table)
    bar = Progress(total, "trials", stream=stream) if progress and writer else None
    eta = LearnerEta(cfg.train.trials)
    started = time.monotonic()

    def unfinished(states) -> bool:
        return int(np.min(np.asarray(states.trials))) < cfg.train.trials

    def dispatch(states, members, device_states=None):
        """Start the next chunk on the learners `members`; `device_states`, if given, already holds exactly them."""
        pick = lambda a: np.asarray(a)[members]  # noqa: E731
        conds, hypers = batch.conds, batch.hypers
        if len(members) < len(table):
            conds, hypers = jax.tree.map(pick, conds), jax.tree.map(pick, hypers)
        if device_states is None:
            device_states = jax.tree.map(pick, states)
        return run_chunk(device_states, conds, hypers, budget)

    states = jax.device_get(batch.states)
    members = chunk_members(np.asarray(states.trials), cfg.train.trials)
    running = None
    if unfinished(states):
        running = dispatch(states, members, batch.states if len(members) == len(table) else None)
    while running is not None:
        # The chunk's learners on this process (an all-gather across hosts with --multihost), copied to the host,
        # put back among the rest; learners outside the chunk ended no trial in it.
        finished, running = running, None
        states = merge_members(states, members, jax.device_get(rollout.to_host(finished)))
        chunk += 1
        ok = np.asarray(finite_learners(states))
        # Dispatch the next chunk before this one is logged and saved, so the devices never wait for the disk.
        if ok.all() and unfinished(states):
            following = chunk_members(np.asarray(states.trials), cfg.train.trials)
            # The devices already hold the learners of the next chunk unless the batch shrinks.
            reuse = finished if np.array_equal(following, members) else None
            members = following
            running = dispatch(states, members, reuse)
        if not ok.all():
            i = int(np.argmin(ok))
            cond, seed = table[i]
            last = checkpoint.checkpoint_path(run_dir, chunk - 1)  # written by process 0 after the last chunk
            raise NumericsError(
                f"learner {i} (condition {cond}, seed {seed}) became non-finite in chunk {chunk}; "
                f"last good checkpoint kept: {last}"
            )
        batch = batch._replace(states=states)
        rows = metrics_rows(states, table, chunk, time.monotonic() - started, cfg)
        if writer:  # one writer when several processes share the run directory
            checkpoint.append_lines(run_dir / checkpoint.METRICS_FILE, [json.dumps(r) for r in rows])
            write_checkpoint(run_dir, chunk, batch, cfg)
        if bar:
            left = eta.update(states.trials, time.monotonic())
            bar.update(int(np.minimum(np.asarray(states.trials), cfg.train.trials).sum()), status_line(rows), eta=left)
    if bar:
        bar.update(total, "done", force=True)
        bar.close()
    return batch


class UsageError(OneLineError):
    """Bad command-line input; the message is one line."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise UsageError(message)


def _whole_number(text: str, minimum: int, maximum: int = 2**31 - 1) -> int:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value) or value < minimum or value != int(value) or value > maximum:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number in [{minimum}, {maximum}]")
    return int(value)


def _positive_int(text: str) -> int:
    return _whole_number(text, 1)


def _hidden_pad(text: str) -> int:
    return _whole_number(text, 1, MAX_HIDDEN_PAD)


def _non_negative_int(text: str) -> int:
    return _whole_number(text, 0)


def _coordinator(text: str) -> str:
    host, sep, port = text.rpartition(":")
    if not sep or not host:
        raise argparse.ArgumentTypeError(f"{text!r} is not HOST:PORT")
    _whole_number(port, 1, 65535)
    return text


def _conditions(text: str) -> tuple[str, ...]:
    names = tuple(n for n in text.replace(",", " ").split() if n)
    bad = [n for n in names if n not in CONDITIONS]
    if bad or not names:
        raise argparse.ArgumentTypeError(
            f"unknown condition {bad[0] if bad else text!r}; choose from {','.join(CONDITIONS)}"
        )
    if len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(f"condition listed twice in {text!r}")
    return names


def _numbers(text: str, smallest: float, strict: bool) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of numbers") from None
    ok = all(math.isfinite(v) and (v > smallest if strict else v >= smallest) for v in values)
    if not values or not ok:
        raise argparse.ArgumentTypeError(f"{text!r} must list {'positive' if strict else 'non-negative'} numbers")
    return values


def _grid(text: str) -> tuple[float, ...]:
    return _numbers(text, 0.0, strict=True)


def _non_negative_grid(text: str) -> tuple[float, ...]:
    return _numbers(text, 0.0, strict=False)


def _setting(text: str) -> tuple[str, str, object]:
    """Parse SECTION.FIELD=JSON into (section, field, value), checked against the config's fields."""
    name, sep, raw = text.partition("=")
    section, dot, fname = name.strip().partition(".")
    sections = {f.name: f.default_factory for f in dataclasses.fields(Config) if f.name != "train"}
    if not sep or not dot or section not in sections:
        raise argparse.ArgumentTypeError(f"{text!r} is not SECTION.FIELD=VALUE with SECTION in {','.join(sections)}")
    default = {f.name: getattr(sections[section](), f.name) for f in dataclasses.fields(sections[section])}
    if fname not in default:
        raise argparse.ArgumentTypeError(f"{section} has no field {fname!r}")
    try:
        value = tuplify(json.loads(raw))
    except json.JSONDecodeError:
        raise argparse.ArgumentTypeError(f"{raw!r} is not a JSON value") from None
    want = default[fname]
    if isinstance(want, float) and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if type(value) is not type(want) or (isinstance(want, tuple) and len(value) != len(want)):
        raise argparse.ArgumentTypeError(f"{section}.{fname} must look like {json.dumps(want)}")
    if isinstance(value, float) and not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{section}.{fname} must be finite")
    return section, fname, value


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface of `python -m reach_jax.train`."""
    p = _Parser(prog="python -m reach_jax.train", description=__doc__.splitlines()[0])
    p.add_argument("--trials", type=_positive_int, help="trials per learner (2e6 in the paper)")
    p.add_argument("--seeds", type=_positive_int, help="networks per condition (2 in the paper)")
    p.add_argument("--conditions", type=_conditions, help=f"comma-separated subset of {','.join(CONDITIONS)}")
    p.add_argument("--seed", type=_non_negative_int, help="master PRNG seed (default 0)")
    p.add_argument("--chunk-steps", type=_positive_int, help="learner steps per compiled chunk")
    p.add_argument(
        "--hidden-pad",
        type=_hidden_pad,
        help="pad the first hidden layer to a multiple of this inside the compiled loop (speed only; 1 = off)",
    )
    p.add_argument("--lr", type=_grid, help="learning rate, or a comma-separated sweep grid")
    p.add_argument("--noise", type=_grid, help="exploration bound, or a comma-separated sweep grid")
    p.add_argument("--lam", type=_grid, help="lambda of eq. 3, or a comma-separated sweep grid")
    p.add_argument(
        "--noise-final-ratio",
        type=_grid,
        help="exploration bound after the anneal as a fraction of --noise (1 = no anneal), or a sweep grid",
    )
    p.add_argument(
        "--noise-anneal-delay",
        type=_non_negative_grid,
        metavar="TRIALS",
        help="trials from the first full field to the start of the anneal, or a comma-separated sweep grid",
    )
    p.add_argument(
        "--noise-anneal-trials",
        type=_grid,
        metavar="TRIALS",
        help="length of the anneal in trials, or a comma-separated sweep grid",
    )
    p.add_argument(
        "--keep-every",
        type=_non_negative_int,
        metavar="CHUNKS",
        help="also keep every CHUNKS-th checkpoint as a snapshot (default 0: only the newest two)",
    )
    p.add_argument(
        "--set",
        type=_setting,
        action="append",
        default=[],
        metavar="SECTION.FIELD=JSON",
        help="override a model constant",
    )
    p.add_argument("--out", type=Path, help="run directory (default runs/<name>)")
    p.add_argument("--resume", type=Path, metavar="RUN_DIR", help="continue a run from its newest checkpoint")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument(
        "--devices",
        type=_positive_int,
        help="CPU only: host devices to shard learners over, one per core at most (default: one per core)",
    )
    p.add_argument(
        "--multihost",
        action="store_true",
        help="join a multi-process run (jax.distributed.initialize); the three settings below come from their "
        "flags, else from JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES and JAX_PROCESS_ID, else from the cluster "
        "(SLURM, Open MPI); process 0 writes the run directory, which --resume needs on a shared file system",
    )
    p.add_argument(
        "--coordinator",
        type=_coordinator,
        metavar="HOST:PORT",
        help="with --multihost: address of process 0, where it serves the other processes",
    )
    p.add_argument("--num-processes", type=_positive_int, metavar="N", help="with --multihost: processes in the run")
    p.add_argument("--process-id", type=_non_negative_int, metavar="I", help="with --multihost: this process, 0 to N-1")
    p.add_argument(
        "--init-timeout",
        type=_positive_int,
        metavar="SECONDS",
        help="with --multihost: how long to wait for every process to connect "
        f"(default {rollout.Cluster._field_defaults['init_timeout']})",
    )
    return p


def _overrides(args) -> dict:
    names = {
        "trials": "trials",
        "seeds": "seeds",
        "conditions": "conditions",
        "seed": "seed",
        "chunk_steps": "chunk_steps",
        "hidden_pad": "hidden_pad",
        "lr": "lr_grid",
        "noise": "noise_grid",
        "lam": "lam_grid",
        "noise_final_ratio": "noise_final_ratio_grid",
        "noise_anneal_delay": "noise_anneal_delay_grid",
        "noise_anneal_trials": "noise_anneal_trials_grid",
        "keep_every": "keep_every",
    }
    return {field: getattr(args, arg) for arg, field in names.items() if getattr(args, arg) is not None}


def cluster_settings(args, environ=None) -> rollout.Cluster | None:
    """How to join a multi-process run: the flags, else the JAX_* variables of `environ`; None without --multihost.

    Raises UsageError for a malformed value, a process id out of range, or a cluster flag without --multihost.

    Args:
      args: the parsed command line.
      environ: environment to read (default os.environ).
    """
    if not args.multihost:
        given = [name for name in (*CLUSTER_ENV, "init_timeout") if getattr(args, name) is not None]
        if given:
            raise UsageError(f"--{given[0].replace('_', '-')} needs --multihost")
        return None
    environ = os.environ if environ is None else environ
    parse = {"coordinator": _coordinator, "num_processes": _positive_int, "process_id": _non_negative_int}
    found = {}
    for name, var in CLUSTER_ENV.items():
        value = getattr(args, name)
        if value is None and environ.get(var, "").strip():
            try:
                value = parse[name](environ[var].strip())
            except argparse.ArgumentTypeError as exc:
                raise UsageError(f"{var}: {exc}") from None
        found[name] = value
    n, i = found["num_processes"], found["process_id"]
    if n is not None and i is not None and i >= n:
        raise UsageError(f"process id {i} is not below the number of processes {n}")
    if args.init_timeout is not None:
        found["init_timeout"] = args.init_timeout
    return rollout.Cluster(**found)


def build_config(args) -> Config:
    """Config from the defaults, the --set overrides and the training flags."""
    cfg = Config()
    for section, fname, value in args.set:
        cfg = dataclasses.replace(cfg, **{section: dataclasses.replace(getattr(cfg, section), **{fname: value})})
    return dataclasses.replace(cfg, train=dataclasses.replace(TrainConfig(), **_overrides(args)))


def default_run_name(train: TrainConfig) -> str:
    """runs/<name> default: conditions, trials and seeds."""
    return f"{'-'.join(train.conditions)}_{train.trials}x{train.seeds}_seed{train.seed}"


class Invocation(NamedTuple):
    """A validated command line."""

    cfg: Config  # the run's config (the stored one when resuming)
    run_dir: Path  # where the run lives
    resume: bool  # continue from the newest checkpoint
    quiet: bool  # no progress bar


def _first_existing(path: Path) -> Path:
    for candidate in (path, *path.parents):
        if candidate.exists():
            return candidate
    return Path(".")


def parse(argv=None) -> Invocation:
    """Validate a command line without writing anything; raises UsageError or CheckpointError."""
    return validate(build_parser().parse_args(argv))


def validate(args: argparse.Namespace) -> Invocation:
    """Check parsed arguments against the config and the file system; writes nothing."""
    overrides = _overrides(args)
    if args.resume is not None:
        if args.out is not None:
            raise UsageError("--out cannot be combined with --resume")
        cfg = read_config(args.resume)
        asked = [("train", name, value) for name, value in overrides.items()] + list(args.set)
        for section, name, value in asked:
            stored = getattr(getattr(cfg, section), name)
            if value != stored:
                raise checkpoint.CheckpointError(
                    f"{args.resume / checkpoint.CONFIG_FILE}: field {section}.{name} is {stored!r}, not {value!r}"
                )
        load_batch(args.resume, cfg)
        return Invocation(cfg, args.resume, True, args.quiet)
    cfg = build_config(args)
    run_dir = args.out if args.out is not None else Path("runs") / default_run_name(cfg.train)
    existing = _first_existing(run_dir)
    if not existing.is_dir():
        raise UsageError(f"--out {run_dir}: {existing} is a file, not a directory")
    if (run_dir / checkpoint.CONFIG_FILE).exists():
        raise UsageError(f"--out {run_dir} already holds a run; use --resume {run_dir}")
    return Invocation(cfg, run_dir, False, args.quiet)


def main(argv=None) -> int:
    """CLI entry point; returns the exit status."""
    prog = build_parser().prog
    try:
        args = build_parser().parse_args(argv)
        # Device count and multi-process run must be fixed before JAX's first computation.
        rollout.configure_backend(args.devices, cluster_settings(args))
    except (UsageError, rollout.ClusterError) as exc:
        sys.stderr.write(error_line(prog, str(exc)))
        return EXIT_USAGE
    status = _validate_and_run(args, prog)
    if status and jax.distributed.is_initialized():
        # The other processes may never reach jax's shutdown barrier at exit (one of them is gone, or stopped
        # elsewhere); waiting there would block for its timeout and then abort. Leave at once instead.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
    return status


def _disagreement(inv: Invocation | None) -> UsageError | None:
    """Why a multi-process run must stop before process 0 writes: a process refused its command line (inv None
    there), or the processes were given different configs. Every process calls it after checking the run directory.
    """
    mine = -1 if inv is None else zlib.crc32(f"{inv.resume} {to_json(inv.cfg)}".encode()) & 0x7FFFFFFF
    tokens = rollout.gather_processes(np.array([mine], np.int32))
    if (tokens == -1).any():
        return UsageError(f"process {int(np.argmax(tokens == -1))} of the multi-process run refused its command line")
    if (tokens != mine).any():
        return UsageError("the processes of the multi-process run were given different configs")
    return None


def _validate_and_run(args: argparse.Namespace, prog: str) -> int:
    """Validate, then train; returns the exit status, after printing the one-line error of a failure."""
    try:
        inv, refused = validate(args), None
    except (UsageError, checkpoint.CheckpointError) as exc:
        inv, refused = None, exc
    try:
        if jax.distributed.is_initialized():
            stop = _disagreement(None if refused else inv)  # a collective: a process that refused joins it too
            refused = refused or stop
        if refused is not None:
            sys.stderr.write(error_line(prog, str(refused)))
            return EXIT_USAGE
        run(inv.cfg, inv.run_dir, resume=inv.resume, progress=not inv.quiet)
    except NumericsError as exc:
        sys.stderr.write(error_line(prog, str(exc)))
        return EXIT_NUMERICS
    except rollout.PeerLostError as exc:
        sys.stderr.write(error_line(prog, str(exc)))
        return EXIT_PEER
    except OSError as exc:
        sys.stderr.write(error_line(prog, f"write failed, last good checkpoint kept: {exc}"))
        return EXIT_IO
    if jax.process_index() == 0:
        print(f"run written to {inv.run_dir}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
