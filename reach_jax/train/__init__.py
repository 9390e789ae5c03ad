"""Training: a pure compiled core over a batch of learners, and an impure shell that runs it in chunks.

`train.run(config)` (or `python -m reach_jax.train`, `cli`) trains cfg.train's conditions x seeds as one batch.
The shell, between compiled chunks, draws the progress bar, appends metrics, writes checkpoints and
checks that every learner is still finite. Units: trials, steps (of cfg.arm.dt seconds), seconds.
"""

from __future__ import annotations

import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from reach_jax import batch, checkpoint, distribute, exploration, learner_state, rollout, trial_log
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


def metrics_rows(states: learner_state.LearnerState, table, chunk: int, wall: float, cfg: Config) -> list[dict]:
    """One metrics record per learner for the chunk just run."""
    counters, cur = states.counters, states.env.curriculum
    s = jax.device_get(counters.stats)
    trials, steps = np.asarray(states.env.trials), np.asarray(counters.steps)
    distance, n_max, block = (
        np.asarray(cur.distance),
        np.asarray(states.agent.n_max),
        np.asarray(states.env.block.index),
    )
    hypers = batch.learner_hypers(cfg)
    bound = np.asarray(exploration.schedule(batch.hyper_columns(cfg), states.env.trials, cur.full_at))
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
                "block": int(block[i]),
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


def run(
    cfg: Config,
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
    Raises NumericsError if a learner goes non-finite; the last good checkpoint stays on disk.

    Args:
      cfg: the whole config (`config.Config`; `config.from_dict` builds one from JSON data).
      run_dir: where the run lives (default `default_run_dir(cfg.train)`); a fresh run refuses a directory
        that already holds one (FileExistsError).
      resume: continue the run in run_dir from its newest checkpoint; cfg must equal its config.json.
      progress: draw a progress bar on `stream` (default stderr).
      speed: how the compiled chunk runs (`reach_jax.speed.Speed`); the defaults are what every committed run used.
      devices: devices to spread the learners over (default every device of every process).
    """
    run_dir = default_run_dir(cfg.train) if run_dir is None else Path(run_dir)
    table = batch.learner_table(cfg.train)
    writer = jax.process_index() == 0
    if resume:
        # Process 0 writes the next checkpoint only after a gather that needs every process's loaded slice.
        group, chunk = run_dir_io.load_batch(run_dir, cfg)
        if writer:
            run_dir_io.truncate_metrics(run_dir, chunk)
            run_dir_io.truncate_trials(run_dir, chunk)
    else:
        if writer and run_dir_io.holds_run(run_dir):
            raise FileExistsError(f"{run_dir} already holds a run; resume it instead")
        group, chunk = batch.init_batch(cfg), 0
        if cfg.train.init_from:
            source = run_dir_io.load_networks(cfg)
            group = group._replace(states=batch.start_from(group.states, *source, cfg))
        if writer:
            run_dir_io.create(run_dir, cfg)
            run_dir_io.write_checkpoint(run_dir, chunk, group, cfg)
    budget = jnp.asarray(cfg.train.trials, jnp.int32)
    run_chunk = make_chunk(cfg, cfg.train.chunk_steps, devices, speed)
    total = cfg.train.trials * len(table)
    bar = Progress(total, "trials", stream=stream) if progress and writer else None
    eta = LearnerEta(cfg.train.trials)
    started = time.monotonic()

    def unfinished(states) -> bool:
        return int(np.min(np.asarray(states.env.trials))) < cfg.train.trials

    def dispatch(states, members, device_states=None):
        """Start the next chunk on the learners `members`; `device_states`, if given, already holds exactly them."""

        def pick(a):
            return np.asarray(a)[members]

        plans, hypers = group.plans, group.hypers
        if len(members) < len(table):
            plans, hypers = jax.tree.map(pick, plans), jax.tree.map(pick, hypers)
        if device_states is None:
            device_states = jax.tree.map(pick, states)
        return run_chunk(device_states, plans, hypers, budget)

    states = jax.device_get(group.states)
    members = chunk_members(np.asarray(states.env.trials), cfg.train.trials)
    running = None
    if unfinished(states):
        running = dispatch(states, members, group.states if len(members) == len(table) else None)
    while running is not None:
        # The chunk's learners on this process (an all-gather across hosts with --multihost), copied to the host,
        # put back among the rest; learners outside the chunk ended no trial in it.
        (finished, log), running = running, None
        states = merge_members(states, members, jax.device_get(distribute.to_host(finished)))
        records = None if log is None else trial_records(distribute.to_host(log), members, chunk + 1)
        ran = len(members)
        chunk += 1
        ok = finite_learners(states)
        # Dispatch the next chunk before this one is logged and saved, so the devices never wait for the disk.
        if ok.all() and unfinished(states):
            following = chunk_members(np.asarray(states.env.trials), cfg.train.trials)
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
        group = group._replace(states=states)
        rows = metrics_rows(states, table, chunk, time.monotonic() - started, cfg)
        if writer:  # one writer when several processes share the run directory
            run_dir_io.append_metrics(run_dir, rows)
            if records is not None:
                run_dir_io.append_trials(run_dir, records)
            run_dir_io.write_checkpoint(run_dir, chunk, group, cfg)
        if bar:
            done = np.asarray(states.env.trials)
            left = eta.update(done, states.counters.steps, time.monotonic(), ran)
            bar.update(int(np.minimum(done, cfg.train.trials).sum()), status_line(rows), eta=left)
    if bar:
        bar.update(total, "done", force=True)
        bar.close()
    return run_dir
