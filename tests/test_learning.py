"""Learning works: a short run of TS actor-critic learning turns a still arm into one that reaches nearby targets."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pytest

from reach_jax import env, evaluate, train
from reach_jax.config import Config, TrainConfig
from reach_jax.engine import batch
from reach_jax.evaluate import episodes
from reach_jax.store import run_dir as run_dir_io

CFG = dataclasses.replace(
    Config(), train=dataclasses.replace(TrainConfig(), trials=5000, seeds=2, conditions=("none",), chunk_steps=25_000)
)


def _near_successes(group, starts, targets) -> np.ndarray:
    """(networks,) successes of the noise-free test protocol, without the field, on the given pairs."""
    ep, _ = jax.device_get(
        episodes.run_episodes(
            episodes.network_policy(CFG),
            group.states.agent.params,
            group.conds.input_mask,
            jax.tree.map(lambda a: a[:1], evaluate.test_fields(CFG)),
            starts,
            targets,
            CFG,
        )
    )
    return np.sum(ep.outcome[:, 0] == env.SUCCESS, axis=-1)


@pytest.mark.slow
def test_a_short_run_learns_to_reach_nearby_targets(tmp_path):
    starts, targets = evaluate.test_pairs(CFG)
    # Test pairs inside the initial curriculum box (1.6 cells), where this much training takes place.
    near = np.all(np.abs(targets - starts) <= CFG.task.curriculum_init_cells * CFG.sensor.cell_size, axis=1)
    starts, targets = starts[near], targets[near]
    assert len(starts) == 320

    before = _near_successes(batch.init_batch(CFG), starts, targets)
    run_dir = train.run(CFG, tmp_path / "run", progress=False)
    assert run_dir == tmp_path / "run"
    after = _near_successes(run_dir_io.load(run_dir).batch, starts, targets)
    # The initial actor outputs 0 (output weights start at 0), so the arm never moves by itself.
    assert before.tolist() == [0, 0]
    assert np.all(after >= 50), after

    # The training metrics tell the same story: trials get shorter as the arm learns to reach on its own.
    rows = run_dir_io.read_metrics(tmp_path / "run")
    first = [r["mean_trial_s"] for r in rows if r["chunk"] == 1]
    # Each learner's last whole chunk: the one before its last with trials, which may be cut short by its budget.
    last = [[r for r in rows if r["learner"] == k and r["chunk_trials"] > 0][-2]["mean_trial_s"] for k in (0, 1)]
    assert np.mean(last) < 0.7 * np.mean(first), (first, last)
