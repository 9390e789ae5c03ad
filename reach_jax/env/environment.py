"""The reaching environment: it runs the trials, ends them and starts the next (model §1, §2, §5, §6, §12).

gymnax-style: frozen states and pure functions. A `Trial` is one movement of the arm toward a target; `step_trial`
moves it one RK4 step and reports how it stands, which is all a test episode needs (`episodes`). `EnvState` adds
what training carries between trials: the trial's condition and protocol block, the curriculum and the count of
trials. `step` ends a trial at the goal, at a joint limit or at the safety cap and starts the next one with a
select, placed by the curriculum in the condition that the learner's protocol (`EnvParams`) picks, so the agent
never sees how a trial ends. The NumPy oracle (`reach_jax.testing.reference`) mirrors it.
Units: arm state [rad, rad/s], torques [N m], positions [m], forces [N], time in steps.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from flax import struct

from reach_jax.config import Config
from reach_jax.config.hyper import Hyper
from reach_jax.env import curriculum, protocol, task
from reach_jax.physics import arm

# How a trial or a test movement ends: the codes that training, the per-trial log and the evaluation share.
SUCCESS, OUT, FAIL = 0, 1, 2  # at the goal; a joint left its range; neither in time (a trial's cap, a test's 4 s)
OUTCOME_NAMES = ("success", "out", "fail")  # indexed by the code


@struct.dataclass
class Trial:
    """The arm, the target and the trial under way."""

    arm: jax.Array  # (4,) arm state now
    prev_arm: jax.Array  # (4,) arm state one step before (the start state at a trial's first step)
    prev_tau: jax.Array  # (2,) torques one step before [N m] (0 at a trial's first step)
    target: jax.Array  # (2,) target position [m]
    force: jax.Array  # (2,) this trial's random hand force [N]
    t: jax.Array  # () steps taken in this trial
    drifted: jax.Array  # () bool: the target drifted in this trial


@struct.dataclass
class EnvState:
    """A learner's environment: the trial under way, its condition and block, the curriculum, the trials ended."""

    trial: Trial
    cond: task.Condition  # the trial's condition (`protocol.trial_condition`)
    block: protocol.BlockState  # the trial's place in the learner's protocol
    curriculum: curriculum.Curriculum
    trials: jax.Array  # () int32 trials ended since the start of training


@struct.dataclass
class EnvParams:
    """One learner's environment parameters: its protocol and how its curriculum treats drift."""

    plan: protocol.Plan
    drift_neutral_early: jax.Array  # () bool: a drift-aided success leaves the curriculum as it is from the start
    drift_gate: jax.Array  # () the failure share above which a target drifts; 0: every trial drifts
    failure_rate: jax.Array  # () weight of each ended trial in the failure share (`curriculum.failure_after`)


def env_params(plan: protocol.Plan, h: Hyper) -> EnvParams:
    """The environment parameters of a learner running `plan` with hyperparameters `h`."""
    return EnvParams(
        plan=plan,
        drift_neutral_early=h.drift_neutral_early > 0,
        drift_gate=h.drift_gate,
        failure_rate=1.0 / h.drift_gate_trials,
    )


class TrialStatus(NamedTuple):
    """How the trial stands after a step."""

    goal: jax.Array  # () bool: the hand rests on the target (section 4.2)
    out_of_range: jax.Array  # () bool: a joint left its range
    cap: jax.Array  # () bool: neither, and the trial reached cfg.task.max_trial_time
    hand: jax.Array  # (2,) hand position [m]
    hand_vel: jax.Array  # (2,) hand velocity [m/s]
    arm: jax.Array  # (4,) arm state after the step
    t: jax.Array  # () steps the trial has taken, this one included


def ended(outcome: TrialStatus) -> jax.Array:
    """() bool: the step ended its trial."""
    return outcome.goal | outcome.out_of_range | outcome.cap


def start_trial(start: jax.Array, target: jax.Array, force: jax.Array) -> Trial:
    """A trial from rest at arm state `start` (4,) toward `target` (2,) [m] with random hand force `force` (2,) [N]."""
    return Trial(
        arm=start,
        prev_arm=start,
        prev_tau=jnp.zeros(2),
        target=target,
        force=force,
        t=jnp.array(0, jnp.int32),
        drifted=jnp.array(False),
    )


def observe_trial(trial: Trial, cond: task.Condition, geom: task.Geometry, cfg: Config) -> jax.Array:
    """(125,) network input: the sensor image and the coded joints, masked by the condition's input mask."""
    return task.observe(trial.arm, trial.prev_arm, trial.prev_tau, trial.target, cond.input_mask, geom, cfg)


def observe(state: EnvState, geom: task.Geometry, cfg: Config) -> jax.Array:
    """(125,) network input of the trial under way, seen by the learner's geometry `geom`."""
    return observe_trial(state.trial, state.cond, geom, cfg)


def step_trial(
    trial: Trial,
    tau: jax.Array,
    cond: task.Condition,
    geom: task.Geometry,
    cfg: Config,
    drift: bool | jax.Array = True,
) -> tuple[Trial, TrialStatus]:
    """The trial one step on under torque `tau` (2,) [N m]; whoever runs it starts a new one when the outcome ends it.

    Args:
      trial: the trial.
      tau: applied torques [N m].
      cond: the trial's condition, whose field pushes the hand.
      geom: the learner's geometry, whose goal square the hand must reach.
      cfg: model config.
      drift: move the target toward the hand once the trial runs long (training), or only where this () bool
        array is True (the drift gate); the tests have no drift (False).
    """
    moved = arm.step(trial.arm, tau, cond.field, trial.force, cfg.arm)
    t = trial.t + 1
    hand = arm.hand_position(moved[:2], cfg.arm)
    out_of_range = arm.is_out(moved, cfg.arm)
    hand_vel = arm.hand_velocity(moved, cfg.arm)
    goal = task.goal_reached(hand, hand_vel, trial.target, geom, cfg) & ~out_of_range
    cap = (t >= round(cfg.task.max_trial_time / cfg.arm.dt)) & ~goal & ~out_of_range
    no_drift = drift is False
    target, moved_target = (trial.target, False) if no_drift else task.drift_target(trial.target, hand, t, cfg, drift)
    new = trial.replace(
        arm=moved, prev_arm=trial.arm, prev_tau=tau, target=target, t=t, drifted=trial.drifted | moved_target
    )
    return new, TrialStatus(goal=goal, out_of_range=out_of_range, cap=cap, hand=hand, hand_vel=hand_vel, arm=moved, t=t)


def next_trial(draws: task.TrialDraws, cur: curriculum.Curriculum, trials: jax.Array, plan: protocol.Plan, cfg: Config):
    """The trial that starts after `trials` have ended: (Trial, its condition, its BlockState).

    Args:
      draws: the new trial's uniform draws.
      cur: the curriculum that places it.
      trials: () int32 index of the new trial.
      plan: the learner's protocol, which picks its condition, and its geometry, which places it.
      cfg: model config.
    """
    cond, block = protocol.trial_condition(plan, trials, draws.catch)
    start, target, force = task.place_trial(draws, cur.distance, cond.field, plan.geometry, cfg)
    return start_trial(start, target, force), cond, block


def reset(draws: task.TrialDraws, plan: protocol.Plan, cfg: Config) -> EnvState:
    """A learner's environment before its first trial: the initial curriculum and trial 0 of its protocol `plan`."""
    cur = curriculum.initial(plan.geometry, cfg)
    trials = jnp.array(0, jnp.int32)
    trial, cond, block = next_trial(draws, cur, trials, plan, cfg)
    return EnvState(trial=trial, cond=cond, block=block, curriculum=cur, trials=trials)


def step(
    state: EnvState, tau: jax.Array, draws: task.TrialDraws, params: EnvParams, cfg: Config
) -> tuple[EnvState, TrialStatus]:
    """The environment one step on under torque `tau` (2,) [N m]; a trial that ends gives way to the next.

    Args:
      state: the learner's environment.
      tau: applied torques [N m].
      draws: uniform draws that place the next trial if this step ends one (used only then).
      params: the learner's protocol, curriculum rule and drift gate.
      cfg: model config.
    """
    gate = curriculum.drift_open(state.curriculum, params.drift_gate)  # the failure share moves only between trials
    geom = params.plan.geometry
    cont, outcome = step_trial(state.trial, tau, state.cond, geom, cfg, gate)
    done = ended(outcome)
    early, rate, drifted = params.drift_neutral_early, params.failure_rate, state.trial.drifted
    cur = curriculum.after_step(state.curriculum, done, outcome.goal, drifted, state.trials, geom, cfg, early, rate)
    trials = state.trials + done
    fresh = next_trial(draws, cur, trials, params.plan, cfg)
    trial, cond, block = jax.tree.map(lambda a, b: jnp.where(done, a, b), fresh, (cont, state.cond, state.block))
    return EnvState(trial=trial, cond=cond, block=block, curriculum=cur, trials=trials), outcome
