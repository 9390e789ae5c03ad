"""One learner's step: observe, learn, act, and the environment's step (model §5).

Units: arm state [rad, rad/s], torques [N m], positions [m]; counts are steps or trials. The network takes its
TS update on the previous step's input as it sees the new one (`learner.ts_step`), then acts with exploration
noise; the environment (`env.step`) ends trials and starts the next. Compiled chunks of steps are in `chunk`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from reach_jax import env
from reach_jax.agent import exploration, learner, network
from reach_jax.config import Config
from reach_jax.config.hyper import Hyper
from reach_jax.config.schema import DEFAULT_SPEED, Speed
from reach_jax.engine import random_stream
from reach_jax.engine.learner_state import AgentState, LearnerState, Stats, without_params
from reach_jax.env import curriculum, protocol, task, trial_log
from reach_jax.physics import encoding


class StepInfo(NamedTuple):
    """What one step did; collected only by traces (`chunk.make_trace`)."""

    x: jax.Array  # (125,) input
    out: jax.Array  # (3,) outputs before the update
    rnd: jax.Array  # (2,) exploration noise
    tau: jax.Array  # (2,) applied torques [N m]
    arm: jax.Array  # (4,) arm state after the step, before any new trial
    draws: task.TrialDraws  # draws for the trial that starts if this step ends one
    goal: jax.Array  # () bool
    out_of_range: jax.Array  # () bool
    cap: jax.Array  # () bool
    loss: jax.Array  # () squared-error loss of the update
    ended: jax.Array  # () bool: this step ended a trial
    record: jax.Array | None  # (len(trial_log.COLUMNS),) the ended trial's record; None without a per-trial log


def act(
    state: LearnerState,
    x: jax.Array,
    rows: jax.Array,
    unit,
    hyper: Hyper,
    geom: task.Geometry,
    learns,
    cfg: Config,
    speed: Speed,
):
    """TS update on the pending step, then the torques of this one: (params, out, loss, u1, rnd, gain, tau).

    Args:
      state: the learner.
      x: (125,) this step's input.
      rows: this step's non-zero input rows (`encoding.coded_support`).
      unit: (2,) noise draws in [-1, 1).
      hyper: its learning constants.
      geom: its geometry, whose whole field the curriculum's shortfall is measured against.
      learns: () bool, the pending step updates the weights.
      cfg: model config.
      speed: only `sparse_layer1` changes the result, and only by float32 rounding.
    """
    agent = state.agent
    sparse = speed.sparse_layer1
    lr = jnp.where(learns, hyper.lr, 0.0)
    params, out, loss, u1 = learner.ts_step(
        agent.params,
        x,
        agent.pending,
        agent.n_max,
        lr,
        cfg,
        rows if sparse else None,
        hyper.actor_baseline,
        hyper.actor_target_bound,
    )
    cur = state.env.curriculum
    short = curriculum.shortfall(cur, geom)
    scale = exploration.value_scale(hyper, out[0], cur.full_at, short, state.env.trial.t)
    carried, fresh = exploration.noise(unit, hyper, state.env.trials, cur.full_at, scale, agent.pending.rnd)
    gain = exploration.actor_gain(hyper, scale)
    # The carried part joins the outputs before the torque map, in this order, as the oracle rounds it.
    return params, out, loss, u1, carried + fresh, gain, network.torque(out[1:] + carried, fresh, cfg)


def learner_step(
    state: LearnerState,
    u: jax.Array,
    plan: protocol.Plan,
    hyper: Hyper,
    cfg: Config,
    active=None,
    speed: Speed = DEFAULT_SPEED,
):
    """One learning step of one learner; returns (new state, StepInfo).

    Args:
      state: the learner.
      u: (n_uniforms,) this step's draws in [0, 1) (`random_stream.step_uniforms`).
      plan: its protocol, which picks the condition of each new trial.
      hyper: its learning constants.
      cfg: model config.
      active: optional () bool; False leaves the weights untouched (the caller keeps the rest of the state).
      speed: how the step is computed; only `sparse_layer1` changes the result, and only by float32 rounding.
    """
    agent, trial = state.agent, state.env.trial
    unit, draws = random_stream.split_uniforms(u, cfg)
    x = env.observe(state.env, plan.geometry, cfg)
    rows = encoding.coded_support(trial.arm, trial.prev_arm, trial.prev_tau, cfg)
    learns = agent.pending_learning if active is None else active & agent.pending_learning
    params, out, loss, u1, rnd, gain, tau = act(state, x, rows, unit, hyper, plan.geometry, learns, cfg, speed)
    params_env = env.env_params(plan, hyper)
    new_env, outcome = env.step(state.env, tau, draws, params_env, cfg)
    pending = _pending(outcome, cfg, x=x, out=out, rnd=rnd, u1=u1, gain=gain)
    # With hyper n_max_clean a drift-aided success leaves N_max as it is (eq. 3 on clean successes only).
    counted = outcome.goal & ~((hyper.n_max_clean > 0) & trial.drifted)
    n_max = jnp.where(counted, learner.update_n_max(agent.n_max, outcome.t, hyper.lam), agent.n_max)
    trace, record = trace_step(state, new_env, outcome, cfg)
    new = state.replace(
        agent=AgentState(params=params, pending=pending, pending_learning=state.env.block.learning, n_max=n_max),
        env=new_env,
        counters=state.counters.replace(
            steps=state.counters.steps + 1, stats=count(state, outcome, out, params_env.drift_gate, cfg)
        ),
        trace=trace,
    )
    info = StepInfo(
        arm=outcome.arm, goal=outcome.goal, out_of_range=outcome.out_of_range, cap=outcome.cap,
        ended=env.ended(outcome),
        record=record, x=x, out=out, rnd=rnd, tau=tau, draws=draws, loss=loss,
    )  # fmt: skip
    return new, info


def _pending(outcome: env.TrialStatus, cfg: Config, **step) -> learner.Pending:
    """This step as the next one learns from it: eq. 1's reward at its end, and no learning from a capped step.

    Args:
      outcome: the environment's step.
      cfg: model config (the rewards).
      **step: the step's x, out, rnd, u1 and gain (`learner.Pending`).
    """
    goal, out_of_range = outcome.goal, outcome.out_of_range
    reward = jnp.where(goal, cfg.learner.reward_goal, 0.0) + jnp.where(out_of_range, cfg.learner.reward_out, 0.0)
    reward = jnp.asarray(reward, float)  # strong-typed, as a fresh learner's: a chunk's states type as its input
    return learner.Pending(valid=~outcome.cap, terminal=goal | out_of_range, reward=reward, **step)


def count(state: LearnerState, outcome: env.TrialStatus, out: jax.Array, gate: jax.Array, cfg: Config) -> Stats:
    """The chunk's counters after a step with this outcome, network outputs `out` (3,) and hyper `drift_gate`."""
    s, done, trial = state.counters.stats, env.ended(outcome), state.env.trial
    first = trial.t == 0
    return Stats(
        trials=s.trials + done,
        goals=s.goals + outcome.goal,
        outs=s.outs + outcome.out_of_range,
        caps=s.caps + outcome.cap,
        trial_steps=s.trial_steps + jnp.where(done, outcome.t, 0),
        drifted=s.drifted + (done & trial.drifted),
        clean_goals=s.clean_goals + (outcome.goal & ~trial.drifted),
        gate_open=s.gate_open + (done & curriculum.drift_open(state.env.curriculum, gate)),
        steps=s.steps + 1,
        saturated=s.saturated + jnp.sum(jnp.abs(out[1:]) > cfg.train.saturated_output, dtype=jnp.int32),
        starts=s.starts + first,
        start_value=s.start_value + jnp.where(first, out[0], 0.0),
    )


def trace_step(state: LearnerState, new_env: env.EnvState, outcome: env.TrialStatus, cfg: Config):
    """(the trace after a step, the ended trial's record); (None, None) without a per-trial log."""
    if state.trace is None:
        return None, None
    traced = trial_log.advance(state.trace, outcome.hand, outcome.hand_vel, outcome.t, cfg)
    block = state.env.block
    record = trial_log.record(traced, block.index, block.catch, outcome.goal, outcome.out_of_range, outcome.t, cfg)
    started = trial_log.start_trace(new_env.trial.arm, new_env.trial.target, cfg)
    return jax.tree.map(lambda a, b: jnp.where(env.ended(outcome), a, b), started, traced), record


def budgeted_step(
    state: LearnerState,
    u: jax.Array,
    plan: protocol.Plan,
    hyper: Hyper,
    budget: jax.Array,
    cfg: Config,
    speed: Speed = DEFAULT_SPEED,
):
    """learner_step, except that a learner which has ended `budget` trials stays frozen.

    Args:
      state: one learner, as for learner_step.
      u: one learner, as for learner_step.
      plan: one learner, as for learner_step.
      hyper: one learner, as for learner_step.
      speed: one learner, as for learner_step.
      budget: () trials per learner.
      cfg: model config.
    """
    active = state.env.trials < budget
    new, info = learner_step(state, u, plan, hyper, cfg, active=active, speed=speed)
    # The weights of a frozen learner already stay put (zero step size), so the select skips the
    # largest arrays instead of copying them once more every step.
    rest = jax.tree.map(lambda a, b: jnp.where(active, a, b), without_params(new), without_params(state))
    return rest.replace(agent=rest.agent.replace(params=new.agent.params)), info._replace(ended=info.ended & active)
