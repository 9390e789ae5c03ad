"""Training: a pure compiled core over a batch of learners, and an impure shell that runs it in chunks.

`train.run(config)` (or `python -m reach_jax.train`, `cli`) trains cfg.train's conditions x seeds as one batch.
`prepare` checks the run and reads what it starts from; `chunks` runs the compiled chunks one after another and
checks that every learner is still finite; between chunks, sinks take each one on the host: metrics, checkpoints,
the progress bar. Units: trials, steps (of cfg.arm.dt seconds), seconds.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from reach_jax import batch, checkpoint, distribute, exploration, hyper, learner_state, rollout, trial_log
from reach_jax import run_dir as run_dir_io
from reach_jax.chunk import make_chunk, scan_steps
from reach_jax.config import Config, TrainConfig
from reach_jax.progress import LearnerEta, Progress, pow2_batch
from reach_jax.speed import DEFAULT_SPEED, Speed


class NumericsError(RuntimeError):
    """A learner's parameters or state stopped being finite."""


def make_train(cfg: Config, n_steps: int):
    """Pure `train(key, plan, hyper) -> LearnerState` for one learner; jit(vmap(train)) trains many."""

    def train(key, plan, hyper):
        def step_body(carry, u):
            return (rollout.learner_step(carry[0], u, plan, hyper, cfg)[0], None), None

        return scan_steps(step_body, learner_state.init_learner(key, plan, cfg), n_steps, cfg)[0]

    return train


def finite_learners(states: learner_state.LearnerState) -> np.ndarray:
    """(L,) bool: every parameter and arm value of the learner is finite (on the host copy the shell holds)."""
    leaves = jax.tree.leaves((states.agent.params, states.env.trial.arm, states.agent.n_max))
    per_leaf = [np.isfinite(np.asarray(x).reshape(len(x), -1)).all(axis=1) for x in leaves]
    return np.all(per_leaf, axis=0)


def hyper_values(hypers: hyper.Hyper) -> list[dict]:
    """Each learner's hyperparameters as JSON values, read from the batch's float32 columns.

    A float is written as the shortest decimal that reads back to its float32 (0.2, not 0.20000000298023224:
    the config's value wherever float32 holds it exactly enough); a count (`hyper.Hyperparameter.integer`) as an int.

    Args:
      hypers: hyper.Hyper of (L,) float32 arrays, batch order.
    """
    columns = {name: np.asarray(getattr(hypers, name), np.float32) for name in hyper.NAMES}

    def value(name: str, x: np.float32):
        return int(x) if hyper.BY_NAME[name].integer else float(str(x))

    n_learners = len(columns[hyper.NAMES[0]])
    return [{name: value(name, columns[name][i]) for name in hyper.NAMES} for i in range(n_learners)]


def metrics_rows(states: learner_state.LearnerState, hypers: hyper.Hyper, table, chunk: int, wall: float, cfg: Config):
    """One metrics record (a dict) per learner for the chunk just run.

    Args:
      states: every learner after the chunk, learner axis first (host arrays).
      hypers: the batch's hyperparameters, (L,) each.
      table: (condition or protocol, seed index) per learner, `batch.learner_table`.
      chunk: chunks trained so far, this one included.
      wall: seconds since the run (or its resumption) started.
      cfg: the run's config.
    """
    counters, cur = states.counters, states.env.curriculum
    s = jax.device_get(counters.stats)
    trials, steps = np.asarray(states.env.trials), np.asarray(counters.steps)
    distance, n_max = np.asarray(cur.distance), np.asarray(states.agent.n_max)
    block = np.asarray(states.env.block.index)
    bound = np.asarray(exploration.schedule(hypers, states.env.trials, cur.full_at))
    mechanism = learner_state.mechanism_columns(states, cfg)
    rows = []
    for i, ((cond, seed), values) in enumerate(zip(table, hyper_values(hypers), strict=True)):
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
                **values,
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
                "block": int(block[i]),
                **{name: column[i] for name, column in mechanism.items()},
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
    size = pow2_batch(len(left), len(trials))
    done = np.flatnonzero(trials >= budget)
    return np.sort(np.concatenate([left, done[: size - len(left)]]))


def merge_members(states, members: np.ndarray, ran):
    """Host states of every learner after a chunk that ran only `members`: theirs from `ran`, the others as they
    were but with zeroed chunk counters."""
    counters = states.counters
    states = states.replace(counters=counters.replace(stats=jax.tree.map(np.zeros_like, counters.stats)))
    if len(members) == len(np.asarray(states.env.trials)):
        return jax.tree.map(np.asarray, ran)

    def put(whole, part):
        whole = np.array(whole)
        whole[members] = part
        return whole

    return jax.tree.map(put, states, ran)


def trial_records(log: trial_log.TrialBuffer, members: np.ndarray, chunk: int) -> dict[str, np.ndarray]:
    """The per-trial log of a chunk as columns (`run_dir.trial_columns`): learner by learner, trials in order."""
    log = jax.device_get(log)
    counts = np.asarray(log.count)
    keep = np.arange(log.trial.shape[1])[None, :] < counts[:, None]
    rows = np.asarray(log.rows)[keep]
    columns = {name: rows[:, k] for k, name in enumerate(trial_log.COLUMNS)}
    return {
        "learner": np.repeat(members, counts),
        "trial": np.asarray(log.trial)[keep],
        "chunk": np.full(int(counts.sum()), chunk),
        **columns,
    }


def default_run_dir(train: TrainConfig) -> Path:
    """runs/<name>, where the name gives the conditions and protocols, trials, seeds and master seed."""
    return Path("runs") / f"{'-'.join(batch.learner_names(train))}_{train.trials}x{train.seeds}_seed{train.seed}"


class Prepared(NamedTuple):
    """A checked run and what it starts from, read once (`prepare`); `run` trains it without reading again."""

    cfg: Config  # the run's config
    run_dir: Path  # where the run lives
    resume: bool  # continue from the newest checkpoint
    speed: Speed  # how the compiled chunk runs
    learners: batch.Batch | None  # resuming: the newest checkpoint's learners; else None (fresh ones)
    chunk: int  # chunks already trained
    networks: tuple | None  # train.init_from: the source run's (LearnerState, learner table), `load_networks`


def prepare(
    cfg: Config, run_dir: Path | None = None, *, resume: bool = False, speed: Speed = DEFAULT_SPEED
) -> Prepared:
    """Check a run and read the checkpoint or source networks it starts from; writes nothing.

    Raises CheckpointError for a checkpoint or source run that cannot be used (also a resume under a speed
    setting that changes results), FileExistsError for a fresh run into a directory that holds one, and
    ValueError when train.init_from lacks a network. Arguments as in `run`.
    """
    run_dir = default_run_dir(cfg.train) if run_dir is None else Path(run_dir)
    if resume:
        # Every process reads it: process 0 writes the next checkpoint only after a gather of every slice.
        learners, chunk = run_dir_io.load_batch(run_dir, cfg, speed=speed)
        return Prepared(cfg, run_dir, True, speed, learners, chunk, None)
    if jax.process_index() == 0 and run_dir_io.holds_run(run_dir):
        raise FileExistsError(f"{run_dir} already holds a run; resume it instead")
    networks = None
    if cfg.train.init_from:
        networks = run_dir_io.load_networks(cfg)
        batch.source_indices(networks[1], cfg)
    return Prepared(cfg, run_dir, False, speed, None, 0, networks)


def begin(prep: Prepared) -> batch.Batch:
    """The learners the run starts from; process 0 opens the run directory (drops the logs past the checkpoint
    it resumes from, or writes config.json and checkpoint 0)."""
    writer = jax.process_index() == 0
    if prep.resume:
        if writer:
            run_dir_io.truncate_metrics(prep.run_dir, prep.chunk)
            run_dir_io.truncate_trials(prep.run_dir, prep.chunk)
        return prep.learners
    group = batch.init_batch(prep.cfg)
    if prep.networks is not None:
        group = group._replace(states=batch.start_from(group.states, *prep.networks, prep.cfg))
    if writer:
        run_dir_io.create(prep.run_dir, prep.cfg)
        run_dir_io.write_checkpoint(prep.run_dir, 0, group, prep.cfg, prep.speed)
    return group


class Finished(NamedTuple):
    """A compiled chunk that has run, on the host."""

    index: int  # chunks trained so far, this one included
    states: learner_state.LearnerState  # every learner after it (host arrays, learner axis first)
    records: dict[str, np.ndarray] | None  # its per-trial log (`trial_records`); None without one
    ran: int  # learners it ran


def dispatch(run_chunk, group: batch.Batch, states, members: np.ndarray, budget, device_states=None):
    """Start a chunk on the learners `members` of the host `states`; `device_states`, if given, holds exactly them."""

    def pick(a):
        return np.asarray(a)[members]

    plans, hypers = group.plans, group.hypers
    if len(members) < len(np.asarray(states.env.trials)):
        plans, hypers = jax.tree.map(pick, plans), jax.tree.map(pick, hypers)
    if device_states is None:
        device_states = jax.tree.map(pick, states)
    return run_chunk(device_states, plans, hypers, budget)


def numerics_error(ok: np.ndarray, prep: Prepared, chunk: int) -> NumericsError:
    """The error for the first learner that is not finite after `chunk`."""
    i = int(np.argmin(ok))
    cond, seed = batch.learner_table(prep.cfg.train)[i]
    last = checkpoint.checkpoint_path(prep.run_dir, chunk - 1)  # written by process 0 after the last chunk
    return NumericsError(
        f"learner {i} (condition {cond}, seed {seed}) became non-finite in chunk {chunk}; "
        f"last good checkpoint kept: {last}"
    )


def chunks(prep: Prepared, group: batch.Batch, devices=None) -> Iterator[Finished]:
    """The run's compiled chunks from `group` until every learner has its trials, each once it has run.

    Each is yielded after the next one is dispatched, so the host's work on it overlaps the devices' work.
    Raises NumericsError, before anything of that chunk is yielded, when a learner goes non-finite.
    """
    budget = prep.cfg.train.trials
    run_chunk = make_chunk(prep.cfg, prep.cfg.train.chunk_steps, devices, prep.speed)
    start = functools.partial(dispatch, run_chunk, group, budget=jnp.asarray(budget, jnp.int32))
    states, index, running = jax.device_get(group.states), prep.chunk, None
    members = chunk_members(np.asarray(states.env.trials), budget)
    if len(members):
        whole = len(members) == len(np.asarray(states.env.trials))
        running = start(states, members, device_states=group.states if whole else None)
    while running is not None:
        # The chunk's learners on this process (an all-gather across hosts with --multihost), copied to the host,
        # put back among the rest; learners outside the chunk ended no trial in it.
        (finished, log), running = running, None
        states = merge_members(states, members, jax.device_get(distribute.to_host(finished)))
        records = None if log is None else trial_records(distribute.to_host(log), members, index + 1)
        ran, index = len(members), index + 1
        ok = finite_learners(states)
        following = chunk_members(np.asarray(states.env.trials), budget)
        # Dispatch the next chunk before this one is logged and saved, so the devices never wait for the disk;
        # the devices already hold its learners unless the batch shrinks.
        if ok.all() and len(following):
            reuse = finished if np.array_equal(following, members) else None
            members = following
            running = start(states, members, device_states=reuse)
        if not ok.all():
            raise numerics_error(ok, prep, index)
        yield Finished(index, states, records, ran)


class Sink:
    """What the host does with each chunk that has run (brax-style callbacks); the base does nothing."""

    def chunk(self, done: Finished, rows: list[dict]) -> None:
        """Take a chunk that has run and its metrics rows (`metrics_rows`)."""

    def close(self) -> None:
        """The last chunk has run."""


class MetricsSink(Sink):
    """Appends each chunk's metrics rows and per-trial log to the run directory."""

    def __init__(self, run_dir: Path):
        self.run_dir = run_dir

    def chunk(self, done: Finished, rows: list[dict]) -> None:
        """Append the chunk's rows to metrics.jsonl and its records to trials/."""
        run_dir_io.append_metrics(self.run_dir, rows)
        if done.records is not None:
            run_dir_io.append_trials(self.run_dir, done.records)


class CheckpointSink(Sink):
    """Writes a checkpoint after each chunk."""

    def __init__(self, prep: Prepared, group: batch.Batch):
        self.prep, self.group = prep, group

    def chunk(self, done: Finished, rows: list[dict]) -> None:
        """Save the learners after the chunk."""
        learners = self.group._replace(states=done.states)
        run_dir_io.write_checkpoint(self.prep.run_dir, done.index, learners, self.prep.cfg, self.prep.speed)


class ProgressSink(Sink):
    """Draws the progress bar with the time left until the slowest learner is done (`LearnerEta`)."""

    def __init__(self, budget: int, n_learners: int, n_devices: int, stream=None):
        self.budget, self.total = budget, budget * n_learners
        self.bar = Progress(self.total, "trials", stream=stream)
        self.eta = LearnerEta(budget, devices=min(n_devices, n_learners))

    def chunk(self, done: Finished, rows: list[dict]) -> None:
        """Redraw with the trials done and each condition's recent success rate."""
        trials = np.asarray(done.states.env.trials)
        left = self.eta.update(trials, done.states.counters.steps, time.monotonic(), done.ran)
        self.bar.update(int(np.minimum(trials, self.budget).sum()), status_line(rows), eta=left)

    def close(self) -> None:
        """Draw the bar full and end its line."""
        self.bar.update(self.total, "done", force=True)
        self.bar.close()


def run(
    cfg: Config | Prepared,
    run_dir: Path | None = None,
    *,
    resume: bool = False,
    progress: bool = True,
    stream=None,
    speed: Speed = DEFAULT_SPEED,
    devices=None,
) -> Path:
    """Train cfg.train's learners in chunks, logging and checkpointing into run_dir; returns run_dir.

    In a multi-process run every process trains the same batch (each its slice) and only process 0 writes
    run_dir and draws the bar; resuming, every process reads the newest checkpoint, so run_dir must be shared.
    Raises NumericsError if a learner goes non-finite; the last good checkpoint stays on disk. A resume under
    another `speed.sparse_layer1` than the run's is refused (CheckpointError): it would change the results.

    Args:
      cfg: the whole config (`config.Config`; `config.from_dict` builds one from JSON data), or a run that
        `prepare` checked, which then gives run_dir, resume and speed; its learners are used once.
      run_dir: where the run lives (default `default_run_dir(cfg.train)`); a fresh run refuses a directory
        that already holds one (FileExistsError).
      resume: continue the run in run_dir from its newest checkpoint; cfg must equal its config.json.
      progress: draw a progress bar on `stream` (default stderr).
      speed: how the compiled chunk runs (`reach_jax.speed.Speed`); the defaults are what every committed run used.
      devices: devices to spread the learners over (default every device of every process).
    """
    if isinstance(cfg, Prepared) and (run_dir is not None or resume or speed != DEFAULT_SPEED):
        raise TypeError("a prepared run carries its run_dir, resume and speed")
    prep = cfg if isinstance(cfg, Prepared) else prepare(cfg, run_dir, resume=resume, speed=speed)
    group = begin(prep)
    table = batch.learner_table(prep.cfg.train)
    sinks: list[Sink] = []
    if jax.process_index() == 0:  # one writer when several processes share the run directory
        sinks = [MetricsSink(prep.run_dir), CheckpointSink(prep, group)]
        if progress:
            n_devices = len(devices if devices is not None else jax.devices())
            sinks.append(ProgressSink(prep.cfg.train.trials, len(table), n_devices, stream))
    started = time.monotonic()
    for done in chunks(prep, group, devices):
        rows = metrics_rows(done.states, group.hypers, table, done.index, time.monotonic() - started, prep.cfg)
        for sink in sinks:
            sink.chunk(done, rows)
    for sink in sinks:
        sink.close()
    return prep.run_dir
