"""Before the first chunk: a run checked and what it starts from read once (`prepare`), then the run directory
opened and the learners made (`begin`)."""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import jax

from reach_jax.config import Config, TrainConfig
from reach_jax.config.schema import DEFAULT_SPEED, Speed
from reach_jax.engine import batch, native, xla_options
from reach_jax.store import run_dir as run_dir_io


def default_run_dir(train: TrainConfig) -> Path:
    """runs/<name>, where the name gives the conditions and protocols, trials, seeds and master seed."""
    return Path("runs") / f"{'-'.join(batch.learner_names(train))}_{train.trials}x{train.seeds}_seed{train.seed}"


class Prepared(NamedTuple):
    """A checked run and what it starts from, read once (`prepare`); `run` trains it without reading again."""

    cfg: Config  # the run's config
    run_dir: Path  # where the run lives
    resume: bool  # continue from the newest checkpoint
    speed: Speed  # how the compiled chunk runs
    engine: str  # the arithmetic it runs with (`distribute.engine`), stored with every checkpoint
    learners: batch.Batch | None  # resuming: the newest checkpoint's learners; else None (fresh ones)
    chunk: int  # chunks already trained
    networks: tuple | None  # train.init_from: the source run's (LearnerState, learner table), `load_networks`
    notice: str | None = None  # why the native engine is not used, said once at start (`native.resolve`)


def prepare(
    cfg: Config, run_dir: Path | None = None, *, resume: bool = False, speed: Speed = DEFAULT_SPEED
) -> Prepared:
    """Check a run and read the checkpoint or source networks it starts from; writes nothing.

    Raises CheckpointError for a checkpoint or source run that cannot be used (also a resume under a speed
    setting that changes results), FileExistsError for a fresh run into a directory that holds one, and
    ValueError when train.init_from lacks a network. Arguments as in `run`.
    """
    run_dir = default_run_dir(cfg.train) if run_dir is None else Path(run_dir)
    engine = xla_options.engine()
    speed, notice = native.resolve(cfg, speed)
    if resume:
        # Every process reads it: process 0 writes the next checkpoint only after a gather of every slice.
        learners, chunk = run_dir_io.load_batch(run_dir, cfg, speed=speed, engine=engine)
        return Prepared(cfg, run_dir, True, speed, engine, learners, chunk, None, notice)
    if jax.process_index() == 0 and run_dir_io.holds_run(run_dir):
        raise FileExistsError(f"{run_dir} already holds a run; resume it instead")
    networks = None
    if cfg.train.init_from:
        networks = run_dir_io.load_networks(cfg)
        batch.source_indices(networks[1], cfg)
    return Prepared(cfg, run_dir, False, speed, engine, None, 0, networks, notice)


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
        run_dir_io.write_checkpoint(prep.run_dir, 0, group, prep.cfg, prep.speed, prep.engine)
    return group
