"""The pure core of training: one learner's whole run as a function, the check that learners stay finite, and
which learners a chunk runs as the batch finishes (counts in trials and steps)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import numpy as np

from reach_jax.config import Config
from reach_jax.engine import learner_state, rollout
from reach_jax.engine.chunk import scan_steps
from reach_jax.train.progress import pow2_batch


class NumericsError(RuntimeError):
    """A learner's parameters or state stopped being finite."""


def make_train(cfg: Config, n_steps: int):
    """Pure `train(key, plan, hyper) -> LearnerState` for one learner; jit(vmap(train)) trains many."""

    def train(key, plan, hyper):
        def step_body(state, u):
            return rollout.learner_step(state, u, plan, hyper, cfg)[0], None

        return scan_steps(step_body, learner_state.init_learner(key, plan, cfg), n_steps, cfg)[0]

    return train


def finite_learners(states: learner_state.LearnerState) -> np.ndarray:
    """(L,) bool: every parameter and arm value of the learner is finite (on the host copy the shell holds)."""
    leaves = jax.tree.leaves((states.agent.params, states.env.trial.arm, states.agent.n_max))
    per_leaf = [np.isfinite(np.asarray(x).reshape(len(x), -1)).all(axis=1) for x in leaves]
    return np.all(per_leaf, axis=0)


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


class Finished(NamedTuple):
    """A compiled chunk that has run, on the host."""

    index: int  # chunks trained so far, this one included
    states: learner_state.LearnerState  # every learner after it (host arrays, learner axis first)
    records: dict[str, np.ndarray] | None  # its per-trial log (`trial_records`); None without one
    ran: int  # learners it ran
