"""Learners that collapsed or fell back, read from their metrics rows while they train (docs/claims.md).

Units: trials; distances [m]. A learner has *collapsed* while its success over its last `claims.collapse_trials`
trials (whole chunks, counted back from the newest) is below `claims.collapse_success`, once its curriculum has
first reached the whole field; the collapse began with the first of its trailing chunks below that rate. A chunk
is a *setback* when the learner's curriculum is below `claims.curriculum_min_fraction` of the whole field after
it first reached it; a learner that has reached it *fell back* when more than `claims.curriculum_max_setbacks` of
its chunks in the last `claims.curriculum_tail` of its trials are below that bound, the rule of the claims'
stability verdict (`evaluate.verdicts.curriculum_stability`), which also judges a learner that never reached it.
The evaluation names a collapse from the test instead (`evaluate.collapse`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from reach_jax.config import Config
from reach_jax.engine import batch
from reach_jax.store import run_dir as run_dir_io


def tail_rows(rows: list[dict], trials: int, tail: float) -> list[dict]:
    """A learner's metrics rows that the stability verdict judges: chunks that ended a trial, in the last `tail`
    of its `trials`.

    Args:
        rows: one learner's rows of metrics.jsonl, in chunk order.
        trials: trials planned per learner.
        tail: the judged fraction of them (cfg.claims.curriculum_tail).
    """
    return [r for r in rows if r["chunk_trials"] > 0 and r["trials"] > (1.0 - tail) * trials]


def whole_field(cfg: Config) -> float:
    """The curriculum distance that spans the whole field [m]."""
    return cfg.sensor.n_cells * cfg.sensor.cell_size


def is_setback(row: dict, cfg: Config) -> bool:
    """The chunk of `row` ended with the curriculum below cfg.claims.curriculum_min_fraction of the whole field."""
    return row["distance_m"] < cfg.claims.curriculum_min_fraction * whole_field(cfg)


@dataclasses.dataclass
class LearnerHealth:
    """One learner's state as its chunks come in (`Health.update`)."""

    full: bool = False  # its curriculum has reached the whole field
    recent: list = dataclasses.field(default_factory=list)  # (trials at its start, ended trials, successes) of
    # the newest chunks that ended a trial, enough to cover collapse_trials
    low_since: int | None = None  # trials at the start of the trailing chunks below collapse_success
    tail_chunks: int = 0  # judged chunks in the tail of its trials
    tail_setbacks: int = 0  # setback chunks among them
    first_tail_setback: int | None = None  # trials at the start of the first
    set_back: bool = False  # its newest chunk is a setback


class Health:
    """Every learner's collapse and setbacks, updated chunk by chunk from the metrics rows."""

    def __init__(self, cfg: Config, learners: list[tuple[str, int]]):
        self.cfg, self.learners = cfg, learners
        self.state = [LearnerHealth() for _ in learners]

    def update(self, rows: list[dict]) -> None:
        """Take one chunk's rows (`train.metrics.metrics_rows`), one per learner."""
        c, full = self.cfg.claims, whole_field(self.cfg)
        for r in rows:
            h = self.state[r["learner"]]
            if r["chunk_trials"] == 0:
                continue
            start = r["trials"] - r["chunk_trials"]
            h.full = h.full or r["distance_m"] >= full * (1.0 - 1e-6)
            h.recent.append((start, r["chunk_trials"], r["success_rate"] * r["chunk_trials"]))
            while len(h.recent) > 1 and sum(n for _, n, _ in h.recent[1:]) >= c.collapse_trials:
                h.recent.pop(0)
            low = r["success_rate"] < c.collapse_success
            h.low_since = (start if h.low_since is None else h.low_since) if low else None
            setback = is_setback(r, self.cfg)
            h.set_back = h.full and setback
            if r["trials"] > (1.0 - c.curriculum_tail) * self.cfg.train.trials:  # as `tail_rows` takes them
                h.tail_chunks += 1
                h.tail_setbacks += setback
                if setback and h.first_tail_setback is None:
                    h.first_tail_setback = start

    def collapsed(self, i: int) -> bool:
        """Learner i has collapsed (the module's rule)."""
        h, c = self.state[i], self.cfg.claims
        trials = sum(n for _, n, _ in h.recent)
        return h.full and trials > 0 and sum(s for *_, s in h.recent) < c.collapse_success * trials

    def fell_back(self, i: int) -> bool:
        """Learner i reached the whole field and fell back too often in the tail of its trials (the verdict's rule)."""
        h = self.state[i]
        return (
            h.full and h.tail_chunks > 0 and h.tail_setbacks / h.tail_chunks > self.cfg.claims.curriculum_max_setbacks
        )

    def counts(self) -> tuple[int, int]:
        """(learners collapsed now, learners set back now but not collapsed), for the progress bar."""
        collapsed = [self.collapsed(i) for i in range(len(self.state))]
        set_back = sum(h.set_back and not k for h, k in zip(self.state, collapsed, strict=True))
        return sum(collapsed), set_back

    def summary(self) -> list[str]:
        """One line per learner that collapsed or fell back, naming it and the trial at which it began."""
        lines = []
        for i, (name, seed) in enumerate(self.learners):
            h, who = self.state[i], f"learner {i} ({name}, seed {seed})"
            since = h.low_since if h.low_since is not None else h.recent[0][0] if h.recent else 0
            if self.collapsed(i):
                rate = self.cfg.claims.collapse_success
                lines.append(f"{who} collapsed: success below {rate:.0%} from trial {since:,}")
            elif self.fell_back(i):
                lines.append(
                    f"{who} fell back: {h.tail_setbacks} of its last {h.tail_chunks} chunks below the bound, the first "
                    f"from trial {h.first_tail_setback:,}"
                )
        return lines


def of_run(run_dir: Path) -> Health:
    """The health of the learners of a run directory at its newest metrics row."""
    cfg = run_dir_io.read_config(run_dir)
    return from_rows(run_dir_io.read_metrics(run_dir), cfg, batch.learner_table(cfg.train))


def from_rows(rows: list[dict], cfg: Config, learners: list[tuple[str, int]]) -> Health:
    """The health of a run from its metrics rows (in chunk order), as the trainer saw it at their last chunk."""
    health = Health(cfg, learners)
    chunks: dict[int, list[dict]] = {}
    for r in rows:
        chunks.setdefault(r["chunk"], []).append(r)
    for k in sorted(chunks):
        health.update(chunks[k])
    return health
