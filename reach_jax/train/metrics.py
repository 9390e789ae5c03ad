"""What the shell records of each chunk: one metrics row per learner, the progress bar's status, the per-trial log
as columns (rates as fractions of the chunk's trials, times [s], distances [m])."""

from __future__ import annotations

import jax
import numpy as np

from reach_jax.agent import exploration
from reach_jax.config import Config, hyper
from reach_jax.engine import learner_state
from reach_jax.env import trial_log


def float32_value(x) -> float:
    """x's float32 as the shortest decimal that reads back to it (0.2, not 0.20000000298023224)."""
    return float(str(np.float32(x)))


def hyper_values(hypers: hyper.Hyper) -> list[dict]:
    """Each learner's hyperparameters as JSON values, read from the batch's float32 columns.

    A float is written as the shortest decimal that reads back to its float32 (`float32_value`: the config's value
    wherever float32 holds it exactly enough); a count (`hyperparameter.Hyperparameter.integer`) as an int.

    Args:
      hypers: hyper.Hyper of (L,) float32 arrays, batch order.
    """
    columns = {name: np.asarray(getattr(hypers, name), np.float32) for name in hyper.NAMES}

    def value(name: str, x: np.float32):
        return int(x) if hyper.BY_NAME[name].integer else float32_value(x)

    n_learners = len(columns[hyper.NAMES[0]])
    return [{name: value(name, columns[name][i]) for name in hyper.NAMES} for i in range(n_learners)]


def metrics_rows(states: learner_state.LearnerState, hypers: hyper.Hyper, table, chunk: int, wall: float, cfg: Config):
    """One metrics record (a dict) per learner for the chunk just run; a float32 measure as `float32_value`.

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
        rows.append(
            {
                "chunk": chunk,
                "learner": i,
                "condition": cond,
                "seed": seed,
                **values,
                "trials": int(trials[i]),
                "steps": int(steps[i]),
                **_chunk_rates(s, i, cfg.arm.dt),
                "distance_m": float32_value(distance[i]),
                "n_max": float32_value(n_max[i]),
                "exploration": float32_value(bound[i]),
                "block": int(block[i]),
                **{name: _measure(column[i]) for name, column in mechanism.items()},
                "wall_s": round(wall, 3),
            }
        )
    return rows


def _chunk_rates(stats, i: int, dt: float) -> dict:
    """Learner i's trials ended in the chunk, the shares of them that met each outcome and their mean length.

    Args:
      stats: the chunk's counters (`learner_state.Stats`), learner axis first (host arrays).
      i: the learner.
      dt: the step [s].

    Returns:
      chunk_trials, then success, out, cap and drift rates, mean_trial_steps and mean_trial_s: None where no trial
      ended.
    """
    ended = int(stats.trials[i])

    def per(counter):
        return float(counter[i]) / ended if ended else None

    mean_steps = per(stats.trial_steps)
    return {
        "chunk_trials": ended,
        "success_rate": per(stats.goals),
        "out_rate": per(stats.outs),
        "cap_rate": per(stats.caps),
        "drift_rate": per(stats.drifted),
        "mean_trial_steps": mean_steps,
        "mean_trial_s": None if mean_steps is None else mean_steps * dt,
    }


def _measure(x):
    """A float32 measure as its shortest decimal (`float32_value`); any other value as it is."""
    return float32_value(x) if isinstance(x, np.float32) else x


def status_line(rows: list[dict]) -> str:
    """Recent success rate per condition, for the progress bar."""
    by_cond: dict[str, list[float]] = {}
    for r in rows:
        if r["success_rate"] is not None:
            by_cond.setdefault(r["condition"], []).append(r["success_rate"])
    return " ".join(f"{c} {np.mean(v):.2f}" for c, v in by_cond.items()) or "no trial ended yet"


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
