"""One learner step and compiled chunks of steps, vmapped over learners (SPEC §5).

Units: arm state [rad, rad/s], torques [N m], positions [m], forces [N]; counts are steps or trials.
A step: observe, forward pass, TS update on the previous input, act, RK4. Trials end at the goal, at a
joint limit or at the safety cap, and reset inside the scan from the learner's own key.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from flax import struct

from reach_jax import arm, learner, network, task
from reach_jax.config import Config, n_inputs


@struct.dataclass
class Hyper:
    """Per-learner learning constants, so a sweep is just a batch of learners."""

    lr: jax.Array  # () SGD learning rate
    noise: jax.Array  # () exploration bound: rnd ~ U(-noise, noise)
    lam: jax.Array  # () lambda of eq. 3


def default_hyper(cfg: Config) -> Hyper:
    """Hyper from the config's learner defaults."""
    c = cfg.learner
    return Hyper(lr=jnp.asarray(c.lr), noise=jnp.asarray(c.noise), lam=jnp.asarray(c.lam))


class Stats(NamedTuple):
    """Counters of trials that ended since the last reset (one chunk)."""

    trials: jax.Array  # () trials ended
    goals: jax.Array  # () ended at the goal
    outs: jax.Array  # () ended at a joint limit
    caps: jax.Array  # () ended at the safety cap
    trial_steps: jax.Array  # () summed length of the ended trials [steps]
    drifted: jax.Array  # () ended trials whose target drifted


def zero_stats() -> Stats:
    """All counters at zero."""
    return Stats(*(jnp.array(0, jnp.int32) for _ in Stats._fields))


@struct.dataclass
class LearnerState:
    """Everything one learner carries from step to step."""

    params: dict  # network parameters
    key: jax.Array  # PRNG key
    arm: jax.Array  # (4,) arm state now
    prev_arm: jax.Array  # (4,) arm state one step before (the start state at a trial's first step)
    prev_tau: jax.Array  # (2,) torques one step before [N m] (0 at a trial's first step)
    target: jax.Array  # (2,) target position [m]
    force: jax.Array  # (2,) this trial's constant hand force [N]
    pending: learner.Pending  # the step awaiting its TS update
    t: jax.Array  # () steps taken in this trial
    drifted: jax.Array  # () bool: the target drifted in this trial
    n_max: jax.Array  # () N_max of eq. 3 [steps]
    distance: jax.Array  # () curriculum distance [m]
    trials: jax.Array  # () trials ended since the start of training
    steps: jax.Array  # () steps taken since the start of training
    stats: Stats  # counters since the last chunk boundary


class StepInfo(NamedTuple):
    """What one step did; collected only by `trace`."""

    x: jax.Array  # (125,) input
    out: jax.Array  # (3,) outputs before the update
    rnd: jax.Array  # (2,) exploration noise
    tau: jax.Array  # (2,) applied torques [N m]
    arm: jax.Array  # (4,) arm state after the step
    draws: task.TrialDraws  # draws for the trial that starts if this step ends one
    goal: jax.Array  # () bool
    out_of_range: jax.Array  # () bool
    cap: jax.Array  # () bool
    loss: jax.Array  # () squared-error loss of the update


def init_learner(key: jax.Array, cond: task.Condition, cfg: Config) -> LearnerState:
    """Fresh learner: new weights, first trial at the initial curriculum distance."""
    k_param, k_trial, k_run = jax.random.split(key, 3)
    distance = jnp.asarray(task.curriculum_bounds(cfg)[0])
    start, target, force = task.place_trial(task.draw_trial(k_trial, cfg), distance, cond.force_amplitude, cfg)
    return LearnerState(
        params=network.init_params(k_param, cfg),
        key=k_run,
        arm=start,
        prev_arm=start,
        prev_tau=jnp.zeros(2),
        target=target,
        force=force,
        pending=learner.empty_pending(n_inputs(cfg)),
        t=jnp.array(0, jnp.int32),
        drifted=jnp.array(False),
        n_max=jnp.asarray(cfg.learner.n_max_init),
        distance=distance,
        trials=jnp.array(0, jnp.int32),
        steps=jnp.array(0, jnp.int32),
        stats=zero_stats(),
    )


def learner_step(state: LearnerState, cond: task.Condition, hyper: Hyper, cfg: Config):
    """One learning step of one learner; returns (new state, StepInfo)."""
    key, k_act, k_trial = jax.random.split(state.key, 3)
    x = task.observe(state.arm, state.prev_arm, state.prev_tau, state.target, cond.input_mask, cfg)
    params, out, loss = learner.ts_update(state.params, x, state.pending, state.n_max, hyper.lr, cfg)

    rnd = jax.random.uniform(k_act, (2,), minval=-hyper.noise, maxval=hyper.noise)
    tau = network.torque(out[1:], rnd, cfg)
    moved = arm.step(state.arm, tau, cond.field, state.force, cfg.arm)
    t = state.t + 1

    hand = arm.hand_position(moved[:2], cfg.arm)
    out_of_range = arm.is_out(moved, cfg.arm)
    goal = task.goal_reached(hand, arm.hand_velocity(moved, cfg.arm), state.target, cfg) & ~out_of_range
    cap_steps = round(cfg.task.max_trial_time / cfg.arm.dt)
    cap = (t >= cap_steps) & ~goal & ~out_of_range
    done = goal | out_of_range | cap
    lc = cfg.learner
    pending = learner.Pending(
        x=x,
        out=out,
        rnd=rnd,
        valid=~cap,
        terminal=goal | out_of_range,
        reward=jnp.where(goal, lc.reward_goal, 0.0) + jnp.where(out_of_range, lc.reward_out, 0.0),
    )

    # Continue the trial: the target drifts once the trial runs long.
    target, moved_target = task.drift_target(state.target, hand, t, cfg)
    cont = dict(
        arm=moved,
        prev_arm=state.arm,
        prev_tau=tau,
        target=target,
        force=state.force,
        t=t,
        drifted=state.drifted | moved_target,
    )

    # Or start a new one, with the curriculum and N_max updated by the trial that ended.
    n_max = jnp.where(goal, learner.update_n_max(state.n_max, t, hyper.lam), state.n_max)
    distance = jnp.where(done, task.update_curriculum(state.distance, goal & ~state.drifted, cfg), state.distance)
    draws = task.draw_trial(k_trial, cfg)
    start, new_target, force = task.place_trial(draws, distance, cond.force_amplitude, cfg)
    fresh = dict(
        arm=start,
        prev_arm=start,
        prev_tau=jnp.zeros(2),
        target=new_target,
        force=force,
        t=jnp.array(0, jnp.int32),
        drifted=jnp.array(False),
    )
    nxt = jax.tree.map(lambda a, b: jnp.where(done, a, b), fresh, cont)

    s = state.stats
    stats = Stats(
        trials=s.trials + done,
        goals=s.goals + goal,
        outs=s.outs + out_of_range,
        caps=s.caps + cap,
        trial_steps=s.trial_steps + jnp.where(done, t, 0),
        drifted=s.drifted + (done & state.drifted),
    )
    new = state.replace(
        params=params,
        key=key,
        pending=pending,
        n_max=n_max,
        distance=distance,
        trials=state.trials + done,
        steps=state.steps + 1,
        stats=stats,
        **nxt,
    )
    info = StepInfo(
        x=x, out=out, rnd=rnd, tau=tau, arm=moved, draws=draws, goal=goal, out_of_range=out_of_range, cap=cap, loss=loss
    )
    return new, info


def budgeted_step(state: LearnerState, cond: task.Condition, hyper: Hyper, budget: jax.Array, cfg: Config):
    """learner_step, except that a learner which has ended `budget` trials stays frozen."""
    new, info = learner_step(state, cond, hyper, cfg)
    active = state.trials < budget
    return jax.tree.map(lambda a, b: jnp.where(active, a, b), new, state), info


def make_chunk(cfg: Config, n_steps: int):
    """Compiled run of n_steps steps for a batch of learners: (states, conds, hypers, budget) -> states.

    The learner axis is the leading axis of every argument; `budget` is a () trial count per learner.
    Stats are reset at the start of the chunk, so they describe this chunk alone.
    """
    batched = jax.vmap(lambda s, c, h, b: budgeted_step(s, c, h, b, cfg)[0], in_axes=(0, 0, 0, None))

    def chunk(states, conds, hypers, budget):
        states = states.replace(stats=jax.tree.map(jnp.zeros_like, states.stats))

        def step_body(carry, _):
            return batched(carry, conds, hypers, budget), None

        states, _ = jax.lax.scan(step_body, states, None, length=n_steps)
        return states

    return jax.jit(chunk, donate_argnums=0)


def make_trace(cfg: Config, n_steps: int):
    """Compiled run of one learner that also returns the StepInfo of every step (for tests and plots)."""

    def trace(state, cond, hyper):
        def step_body(carry, _):
            return learner_step(carry, cond, hyper, cfg)

        return jax.lax.scan(step_body, state, None, length=n_steps)

    return jax.jit(trace)
