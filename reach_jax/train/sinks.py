"""What the host does with each chunk that has run (brax-style callbacks): metrics, checkpoints, the progress bar."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from reach_jax.engine import batch
from reach_jax.store import checkpoint
from reach_jax.store import run_dir as run_dir_io
from reach_jax.train.core import Finished
from reach_jax.train.health import Health
from reach_jax.train.metrics import status_line
from reach_jax.train.prepare import Prepared
from reach_jax.train.progress import LearnerEta, Progress


class Sink:
    """What the host does with each chunk that has run (brax-style callbacks); the base does nothing."""

    def chunk(self, done: Finished, rows: list[dict]) -> None:
        """Take a chunk that has run and its metrics rows (`metrics_rows`)."""

    def close(self) -> None:
        """The last chunk has run."""

    def stop(self) -> None:
        """The run stops on a signal before its end (`interrupt`), after its last chunk was taken."""


class MetricsSink(Sink):
    """Appends each chunk's metrics rows and per-trial log to the run directory."""

    def __init__(self, run_dir: Path):
        self.run_dir = run_dir

    def chunk(self, done: Finished, rows: list[dict]) -> None:
        """Append the chunk's rows to the metrics log and its records to trials/."""
        run_dir_io.append_metrics(self.run_dir, rows)
        if done.records is not None:
            run_dir_io.append_trials(self.run_dir, done.records)


class CheckpointSink(Sink):
    """Writes a checkpoint after each chunk; once the run has finished, keeps its final one and its snapshots."""

    def __init__(self, prep: Prepared, group: batch.Batch):
        self.prep, self.group = prep, group

    def chunk(self, done: Finished, rows: list[dict]) -> None:
        """Save the learners after the chunk."""
        learners = self.group._replace(states=done.states)
        run_dir_io.write_checkpoint(
            self.prep.run_dir, done.index, learners, self.prep.cfg, self.prep.speed, self.prep.engine
        )

    def close(self) -> None:
        """Keep the final checkpoint and the snapshots: the second-newest was kept for safety while the run trained."""
        checkpoint.prune(self.prep.run_dir, checkpoint.KEEP_FINISHED, self.prep.cfg.train.keep_every)


class ProgressSink(Sink):
    """Draws the progress bar with the time left until the slowest learner is done (`LearnerEta`), and the count
    of learners collapsed and set back now (`health.Health`)."""

    def __init__(self, budget: int, health: Health, n_devices: int, stream=None):
        n_learners = len(health.learners)
        self.budget, self.total, self.health = budget, budget * n_learners, health
        self.bar = Progress(self.total, "trials", stream=stream)
        self.eta = LearnerEta(budget, devices=min(n_devices, n_learners))

    def chunk(self, done: Finished, rows: list[dict]) -> None:
        """Redraw with the trials done, each condition's recent success rate and the learners in trouble."""
        trials = np.asarray(done.states.env.trials)
        left = self.eta.update(trials, done.states.counters.steps, time.monotonic(), done.ran)
        self.health.update(rows)
        collapsed, set_back = self.health.counts()
        line = status_line(rows) + (f" | {collapsed} collapsed, {set_back} set back" if collapsed or set_back else "")
        self.bar.update(int(np.minimum(trials, self.budget).sum()), line, eta=left, eta_range=self.eta.band)

    def close(self) -> None:
        """Draw the bar full and end its line."""
        self.bar.update(self.total, "done", force=True)
        self.bar.close()

    def stop(self) -> None:
        """End the bar's line as it stands, so that what is printed next starts on a line of its own."""
        self.bar.close()
