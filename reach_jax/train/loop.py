"""The training loop: compiled chunks run one after another, each taken by the sinks between chunks (`run`).

Units: trials, steps (of cfg.arm.dt seconds), seconds."""

from __future__ import annotations

import contextlib
import functools
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from reach_jax.config import Config
from reach_jax.config.schema import DEFAULT_SPEED, Speed
from reach_jax.engine import batch, distribute
from reach_jax.engine.chunk import make_chunk
from reach_jax.store import checkpoint, run_lock
from reach_jax.store import run_dir as run_dir_io
from reach_jax.train import interrupt
from reach_jax.train.core import Finished, NumericsError, chunk_members, finite_learners, merge_members
from reach_jax.train.health import from_rows
from reach_jax.train.metrics import metrics_rows, trial_records
from reach_jax.train.prepare import Prepared, begin, prepare
from reach_jax.train.sinks import CheckpointSink, MetricsSink, ProgressSink, Sink


def member_inputs(group: batch.Batch, members: np.ndarray) -> tuple:
    """The plans and hypers of the learners `members`: the batch's own objects while every learner runs, so that the
    chunk places them on its devices once (`make_chunk`)."""
    if len(members) == len(jax.tree.leaves(group.hypers)[0]):
        return group.plans, group.hypers
    return jax.tree.map(lambda a: np.asarray(a)[members], (group.plans, group.hypers))


def dispatch(run_chunk, inputs: tuple, states, members: np.ndarray, budget, device_states=None):
    """Start a chunk on the learners `members` of the host `states`, with their plans and hypers `inputs`
    (`member_inputs`); `device_states`, if given, holds exactly those learners."""
    if device_states is None:
        device_states = jax.tree.map(lambda a: np.asarray(a)[members], states)
    return run_chunk(device_states, *inputs, budget)


def numerics_error(ok: np.ndarray, prep: Prepared, chunk: int) -> NumericsError:
    """The error for the first learner that is not finite after `chunk`."""
    i = int(np.argmin(ok))
    cond, seed = batch.learner_table(prep.cfg.train)[i]
    last = checkpoint.checkpoint_path(prep.run_dir, chunk - 1)  # written by process 0 after the last chunk
    return NumericsError(
        f"learner {i} (condition {cond}, seed {seed}) became non-finite in chunk {chunk}; "
        f"last good checkpoint kept: {last}"
    )


def chunks(prep: Prepared, group: batch.Batch, devices=None, stop: interrupt.Stop | None = None) -> Iterator[Finished]:
    """The run's compiled chunks from `group` until every learner has its trials, each once it has run.

    Each is yielded after the next one is dispatched, so the host's work on it overlaps the devices' work.
    Raises NumericsError, before anything of that chunk is yielded, when a learner goes non-finite. Once `stop`
    has caught a signal no chunk is dispatched; the one in flight is yielded, then Interrupted is raised.
    """
    stop = interrupt.Stop() if stop is None else stop
    budget = prep.cfg.train.trials
    run_chunk = make_chunk(prep.cfg, prep.cfg.train.chunk_steps, devices, prep.speed)
    start = functools.partial(dispatch, run_chunk, budget=jnp.asarray(budget, jnp.int32))
    states, index, running, asked = jax.device_get(group.states), prep.chunk, None, None
    members = chunk_members(np.asarray(states.env.trials), budget)
    if len(members):
        whole = len(members) == len(np.asarray(states.env.trials))
        inputs = member_inputs(group, members)
        running = start(inputs, states, members, device_states=group.states if whole else None)
    while running is not None:
        # The chunk's learners on this process (an all-gather across hosts with --multihost), copied to the host,
        # put back among the rest; learners outside the chunk ended no trial in it.
        (finished, log), running = running, None
        interrupt.wait_ready((finished, log))
        states = merge_members(states, members, jax.device_get(distribute.to_host(finished)))
        records = None if log is None else trial_records(distribute.to_host(log), members, index + 1)
        ran, index = len(members), index + 1
        ok = finite_learners(states)
        following = chunk_members(np.asarray(states.env.trials), budget)
        asked = stop.anywhere()
        # Dispatch the next chunk before this one is logged and saved, so the devices never wait for the disk;
        # the devices already hold its learners unless the batch shrinks. After a stop signal, dispatch none.
        if ok.all() and len(following) and asked is None:
            same = np.array_equal(following, members)
            reuse, inputs = (finished, inputs) if same else (None, member_inputs(group, following))
            members = following
            running = start(inputs, states, members, device_states=reuse)
        if not ok.all():
            raise numerics_error(ok, prep, index)
        yield Finished(index, states, records, ran)
    if asked is not None and len(chunk_members(np.asarray(states.env.trials), budget)):
        raise interrupt.Interrupted(asked, prep.run_dir, index)


def _sinks(prep: Prepared, group, table, progress: bool, devices, stream) -> list[Sink]:
    """The writing process's sinks: the metrics, the checkpoints and, with `progress`, the bar (`run`'s Args); it says
    the engine's notice first, if there is one (`native.resolve`)."""
    if prep.notice:
        print(prep.notice, file=sys.stderr if stream is None else stream, flush=True)
    sinks: list[Sink] = [MetricsSink(prep.run_dir), CheckpointSink(prep, group)]
    if progress:
        n_devices = len(devices if devices is not None else jax.devices())
        seen = run_dir_io.read_metrics(prep.run_dir, prep.chunk) if prep.chunk else []
        health = from_rows(seen, prep.cfg, table)  # a resumed run's learners as they stood
        sinks.append(ProgressSink(prep.cfg.train.trials, health, n_devices, stream))
    return sinks


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
    The writing process holds run_dir's lock throughout (`run_lock`; RunLockedError when another live process
    does). The first SIGTERM or SIGINT ends the run after the chunk in flight, its checkpoint written, with
    `interrupt.Interrupted`; a second ends the process at once.

    Args:
      cfg: the whole config (`config.Config`; `config.from_dict` builds one from JSON data), or a run that
        `prepare` checked, which then gives run_dir, resume and speed; its learners are used once.
      run_dir: where the run lives (default `default_run_dir(cfg.train)`); a fresh run refuses a directory
        that already holds one (FileExistsError).
      resume: continue the run in run_dir from its newest checkpoint; cfg must equal its config.json.
      progress: draw a progress bar on `stream` (default stderr).
      speed: how the compiled chunk runs (`reach_jax.config.Speed`); the defaults are what every committed run used.
      devices: devices to spread the learners over (default every device of every process).
    """
    if isinstance(cfg, Prepared) and (run_dir is not None or resume or speed != DEFAULT_SPEED):
        raise TypeError("a prepared run carries its run_dir, resume and speed")
    prep = cfg if isinstance(cfg, Prepared) else prepare(cfg, run_dir, resume=resume, speed=speed)
    writer = jax.process_index() == 0  # one writer when several processes share the run directory
    with run_lock.hold(prep.run_dir) if writer else contextlib.nullcontext(), interrupt.catch() as stop:
        group, table = begin(prep), batch.learner_table(prep.cfg.train)
        sinks = _sinks(prep, group, table, progress, devices, stream) if writer else []
        started = time.monotonic()
        try:
            for done in chunks(prep, group, devices, stop):
                rows = metrics_rows(done.states, group.hypers, table, done.index, time.monotonic() - started, prep.cfg)
                for sink in sinks:
                    sink.chunk(done, rows)
        except interrupt.Interrupted:
            for sink in sinks:
                sink.stop()
            raise
        for sink in sinks:
            sink.close()
    return prep.run_dir
