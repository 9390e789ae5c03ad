"""One learner step and compiled chunks of steps, vmapped over learners (model §5).

Units: arm state [rad, rad/s], torques [N m], positions [m], forces [N]; counts are steps or trials.
A step: observe, forward pass, TS update on the previous input, act, RK4. Trials end at the goal, at a
joint limit or at the safety cap, and reset inside the scan from the learner's own key.

Scale: `make_chunk` shards the learner axis over devices (`distribute`). Learners never interact, so
each device runs its own slice with no communication; the same code runs on CPU host devices, GPU, TPU or
several hosts (after `jax.distributed.initialize`), only the device list changes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from flax import struct
from jax.sharding import PartitionSpec

from reach_jax import distribute, encoding, exploration, learner, network, protocol, task, trial_log
from reach_jax import env as env_lib
from reach_jax.config import Config, n_inputs
from reach_jax.hyper import Hyper

MAX_HIDDEN_PAD = 128  # largest Speed.hidden_pad: a TPU vector row of float32; wider only wastes memory


@dataclass(frozen=True)
class Speed:
    """How the compiled loops run. Results do not depend on it bit for bit, except for `sparse_layer1`, which
    only the lever benchmark turns off: a run stores that one (`RESULT_FIELDS`) and resumes only under it.

    `benchmarks/levers.py` measures what each one gives by switching it off.
    """

    hidden_pad: int = 8  # pad the first hidden layer to a multiple of this with inert units; 1 = off
    draw_block: int = 64  # steps whose uniforms are drawn in one call; the stream does not depend on it
    donate: bool = True  # a chunk reuses its input states' buffers for its output
    # Layer 1 and its update over the inputs that can be non-zero (about 1/3 of them), not all 125. Off, the
    # same terms are summed in another order: equal to float32 rounding, not bit for bit.
    sparse_layer1: bool = True

    def __post_init__(self):
        for name, top in (("hidden_pad", MAX_HIDDEN_PAD), ("draw_block", None)):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1 or (top is not None and value > top):
                raise ValueError(f"{name}: must be a whole number in [1, {top or 'inf'}]")


DEFAULT_SPEED = Speed()
RESULT_FIELDS = ("sparse_layer1",)  # the Speed fields that change results (float32 rounding)


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
class AgentState:
    """The network and what its learning carries from step to step."""

    params: dict  # network parameters
    pending: learner.Pending  # the step awaiting its TS update
    pending_learning: jax.Array  # () bool: the block of the pending step's trial updates the weights
    n_max: jax.Array  # () N_max of eq. 3 [steps]


@struct.dataclass
class Curriculum:
    """The staircase of start-target distances (model §5)."""

    distance: jax.Array  # () curriculum distance [m]
    full_at: jax.Array  # () trials ended when the distance first reached its maximum; -1 before


@struct.dataclass
class Counters:
    """How far the learner has come."""

    trials: jax.Array  # () trials ended since the start of training
    steps: jax.Array  # () steps taken since the start of training
    stats: Stats  # counters since the last chunk boundary


@struct.dataclass
class LearnerState:
    """Everything one learner carries from step to step: agent, trial and its condition, block, curriculum, counters."""

    key: jax.Array  # PRNG key of the learner's per-step draws (`step_uniforms`); fixed for its life
    agent: AgentState
    env: env_lib.EnvState  # this trial
    cond: task.Condition  # this trial's condition: the environment's parameters (`protocol.trial_condition`)
    block: protocol.BlockState  # this trial's place in the learner's protocol
    curriculum: Curriculum
    counters: Counters
    trace: trial_log.TrialTrace | None = None  # this trial's movement so far; None without a per-trial log


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
    ended: jax.Array  # () bool: this step ended a trial
    record: jax.Array | None  # (len(trial_log.COLUMNS),) the ended trial's record; None without a per-trial log


def init_learner(key: jax.Array, plan: protocol.Plan, cfg: Config) -> LearnerState:
    """Fresh learner: new weights, first trial at the initial curriculum distance in its plan's first condition."""
    k_param, k_trial, k_run = jax.random.split(key, 3)
    distance, full = (jnp.asarray(b) for b in task.curriculum_bounds(cfg))
    draws = task.draw_trial(k_trial, cfg)
    cond, block = protocol.trial_condition(plan, jnp.array(0, jnp.int32), draws.catch)
    start, target, force = task.place_trial(draws, distance, cond.field, cfg)
    rows = encoding.coded_support(start, start, jnp.zeros(2), cfg)
    return LearnerState(
        key=k_run,
        agent=AgentState(
            params=network.init_params(k_param, cfg),
            pending=learner.empty_pending(n_inputs(cfg), cfg.network.hidden[0], rows),
            pending_learning=block.learning,
            n_max=jnp.asarray(cfg.learner.n_max_init, dtype=float),  # strong-typed, as the chunk returns it
        ),
        env=env_lib.reset(start, target, force),
        cond=cond,
        block=block,
        curriculum=Curriculum(distance=distance, full_at=jnp.where(distance >= full, 0, -1).astype(jnp.int32)),
        counters=Counters(trials=jnp.array(0, jnp.int32), steps=jnp.array(0, jnp.int32), stats=zero_stats()),
        trace=trial_log.start_trace(start, target, cfg) if cfg.train.trial_log_every else None,
    )


def n_uniforms(cfg: Config) -> int:
    """Uniform draws one step consumes: 2 for the exploration noise, then one new trial's TrialDraws.

    The catch draw comes last: a longer draw leaves the earlier values unchanged (threefry is partitionable),
    so adding it left every earlier run's stream as it was.
    """
    return 2 + 2 + 2 * cfg.task.target_candidates + 2 + 1


def step_uniforms(key: jax.Array, first_step: jax.Array, n_steps: int, cfg: Config) -> jax.Array:
    """(n_steps, n_uniforms) draws in [0, 1) of one learner's steps first_step, first_step + 1, ...

    A step's draws depend only on the learner's key and the step's index, so blocks of any size (and
    chunks of any length) see the same stream.
    """
    return jax.vmap(lambda i: jax.random.uniform(jax.random.fold_in(key, i), (n_uniforms(cfg),)))(
        first_step + jnp.arange(n_steps)
    )


def split_uniforms(u: jax.Array, cfg: Config) -> tuple[jax.Array, task.TrialDraws]:
    """(n_uniforms,) draws in [0, 1) -> ((2,) noise draws in [-1, 1), TrialDraws of a possible new trial)."""
    k = cfg.task.target_candidates
    unit = 2.0 * u[:2] - 1.0
    draws = task.TrialDraws(
        start=u[2:4], target=u[4 : 4 + 2 * k].reshape(k, 2), force=u[4 + 2 * k : 6 + 2 * k], catch=u[6 + 2 * k]
    )
    return unit, draws


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
      u: (n_uniforms,) this step's draws in [0, 1) (`step_uniforms`).
      plan: its protocol, which picks the condition of each new trial.
      hyper: its learning constants.
      cfg: model config.
      active: optional () bool; False leaves the weights untouched (the caller keeps the rest of the state).
      speed: how the step is computed; only `sparse_layer1` changes the result, and only by float32 rounding.
    """
    agent, trial, counters, cur = state.agent, state.env, state.counters, state.curriculum
    unit, draws = split_uniforms(u, cfg)
    x = env_lib.observe(trial, state.cond, cfg)
    rows = encoding.coded_support(trial.arm, trial.prev_arm, trial.prev_tau, cfg)  # carried in the pending step
    learns = agent.pending_learning if active is None else active & agent.pending_learning
    lr = jnp.where(learns, hyper.lr, 0.0)
    sparse = speed.sparse_layer1
    pending_in = agent.pending if sparse else agent.pending._replace(rows=None)
    params, out, loss, u1 = learner.ts_step(
        agent.params, x, pending_in, agent.n_max, lr, cfg, rows if sparse else None, hyper.actor_baseline
    )
    carried, fresh = exploration.noise(unit, hyper, counters.trials, cur.full_at, out[0], agent.pending.rnd)
    rnd = carried + fresh
    tau = network.torque(out[1:] + carried, fresh, cfg)
    cont, outcome = env_lib.step(trial, tau, state.cond, cfg)
    goal, out_of_range, cap = outcome.goal, outcome.out_of_range, outcome.cap
    done = goal | out_of_range | cap
    lc = cfg.learner
    pending = learner.Pending(
        x=x,
        out=out,
        rnd=rnd,
        valid=~cap,
        terminal=goal | out_of_range,
        reward=jnp.where(goal, lc.reward_goal, 0.0) + jnp.where(out_of_range, lc.reward_out, 0.0),
        u1=u1,
        rows=rows,
    )

    # If the trial ended, a new one starts, with the curriculum and N_max updated by the one that ended.
    n_max = jnp.where(goal, learner.update_n_max(agent.n_max, cont.t, hyper.lam), agent.n_max)
    was_full = cur.full_at >= 0
    early = hyper.drift_neutral_early > 0
    grown = task.update_curriculum(cur.distance, goal, trial.drifted, was_full, cfg, early)
    distance = jnp.where(done, grown, cur.distance)
    first_full = ~was_full & (distance >= task.curriculum_bounds(cfg)[1])
    full_at = jnp.where(first_full, counters.trials + done, cur.full_at)
    new_cond, new_block = protocol.trial_condition(plan, counters.trials + done, draws.catch)
    start, new_target, force = task.place_trial(draws, distance, new_cond.field, cfg)
    fresh = {"env": env_lib.reset(start, new_target, force), "cond": new_cond, "block": new_block}
    kept = {"env": cont, "cond": state.cond, "block": state.block}
    record = None
    if state.trace is not None:
        traced = trial_log.advance(state.trace, outcome.hand, outcome.hand_vel, cont.t, cfg)
        record = trial_log.record(traced, state.block.index, state.block.catch, goal, out_of_range, cont.t, cfg)
        kept["trace"] = traced
        fresh["trace"] = trial_log.start_trace(start, new_target, cfg)
    nxt = jax.tree.map(lambda a, b: jnp.where(done, a, b), fresh, kept)

    s = counters.stats
    stats = Stats(
        trials=s.trials + done,
        goals=s.goals + goal,
        outs=s.outs + out_of_range,
        caps=s.caps + cap,
        trial_steps=s.trial_steps + jnp.where(done, cont.t, 0),
        drifted=s.drifted + (done & trial.drifted),
    )
    new = state.replace(
        agent=AgentState(params=params, pending=pending, pending_learning=state.block.learning, n_max=n_max),
        curriculum=Curriculum(distance=distance, full_at=full_at),
        counters=Counters(trials=counters.trials + done, steps=counters.steps + 1, stats=stats),
        **nxt,
    )
    info = StepInfo(
        x=x,
        out=out,
        rnd=rnd,
        tau=tau,
        arm=cont.arm,
        draws=draws,
        goal=goal,
        out_of_range=out_of_range,
        cap=cap,
        loss=loss,
        ended=done,
        record=record,
    )
    return new, info


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
      state, u, plan, hyper, speed: one learner, as for learner_step.
      budget: () trials per learner.
      cfg: model config.
    """
    active = state.counters.trials < budget
    new, info = learner_step(state, u, plan, hyper, cfg, active=active, speed=speed)
    # The weights of a frozen learner already stay put (zero step size), so the select skips the
    # largest arrays instead of copying them once more every step.
    rest = jax.tree.map(lambda a, b: jnp.where(active, a, b), without_params(new), without_params(state))
    return rest.replace(agent=rest.agent.replace(params=new.agent.params)), info._replace(ended=info.ended & active)


def without_params(state: LearnerState) -> LearnerState:
    """state with the network parameters left out (None)."""
    return state.replace(agent=state.agent.replace(params=None))


def scan_steps(step, state, n_steps: int, cfg: Config, batched: bool = False, speed: Speed = DEFAULT_SPEED, log=None):
    """lax.scan of `step((state, log), u) -> ((state, log), info)` over n_steps, drawing uniforms in blocks.

    Drawing speed.draw_block steps' uniforms in one vectorised call keeps the random-number loop out of the
    per-step body, where it cost as many kernel launches as the rest of the step. The stream does not depend on
    the block size. The steps run on `widen_hidden` weights; the state goes in and comes out with the paper's widths.

    Args:
      step: one step of one learner, or of a batch when `batched`.
      state: LearnerState, learner axis first when `batched`.
      n_steps: steps to take.
      cfg: model config.
      batched: state and step carry a leading learner axis.
      speed: the draw block and the hidden padding.
      log: carried alongside the state for the step to fill (the per-trial log, `TrialBuffer`), or None.

    Returns:
      (state after n_steps, log after them, info stacked over the steps).
    """

    def draws(s: LearnerState, n: int) -> jax.Array:
        if not batched:
            return step_uniforms(s.key, s.counters.steps, n, cfg)
        u = jax.vmap(lambda k, first: step_uniforms(k, first, n, cfg))(s.key, s.counters.steps)
        return jnp.swapaxes(u, 0, 1)

    def block_body(carry, _):
        return jax.lax.scan(step, carry, draws(carry[0], block))

    block = speed.draw_block
    n_blocks, rest = divmod(n_steps, block)
    carry = (widen_hidden(state, speed.hidden_pad), log)
    carry, info = jax.lax.scan(block_body, carry, None, length=n_blocks)
    info = jax.tree.map(lambda a: a.reshape(n_blocks * block, *a.shape[2:]), info)
    if rest:
        carry, tail = jax.lax.scan(step, carry, draws(carry[0], rest))
        info = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), info, tail)
    state, log = carry
    return narrow_hidden(state, cfg), log, info


class TrialBuffer(NamedTuple):
    """One learner's per-trial records of a chunk (`trial_log`), filled from the front."""

    rows: jax.Array  # (capacity, len(trial_log.COLUMNS)) float32 records
    trial: jax.Array  # (capacity,) int32 index of each recorded trial over the learner's life
    count: jax.Array  # () int32 records written


def empty_buffer(cfg: Config) -> TrialBuffer:
    """A buffer that holds every logged trial of one chunk: at most one trial ends per step."""
    capacity = cfg.train.chunk_steps // max(cfg.train.trial_log_every, 1) + 1
    return TrialBuffer(
        rows=jnp.zeros((capacity, len(trial_log.COLUMNS)), jnp.float32),
        trial=jnp.zeros(capacity, jnp.int32),
        count=jnp.array(0, jnp.int32),
    )


def log_trial(buffer: TrialBuffer, info: StepInfo, trial: jax.Array, every: int) -> TrialBuffer:
    """buffer with the trial that `info`'s step ended, if it ended one whose index `trial` is a multiple of `every`."""
    keep = info.ended & (trial % every == 0)
    i = jnp.minimum(buffer.count, buffer.trial.shape[0] - 1)
    return TrialBuffer(
        rows=buffer.rows.at[i].set(jnp.where(keep, info.record, buffer.rows[i])),
        trial=buffer.trial.at[i].set(jnp.where(keep, trial, buffer.trial[i])),
        count=buffer.count + keep,
    )


def widen_hidden(state: LearnerState, multiple: int) -> LearnerState:
    """state in the layout of the compiled loops: first hidden layer padded to a multiple of `multiple`, u1 with it.

    Rows of a multiple of 8 float32 fill whole vector registers: the step runs 1.1-1.25x faster with 32 hidden
    units than with 30 (benchmarks/levers.py), and `network.pad_hidden` keeps the added units inert.
    Works with or without a leading learner axis.
    """
    agent = state.agent
    params = network.pad_hidden(agent.params, multiple)
    u1 = agent.pending.u1
    grow = network.dense_layers(params)[0][0].shape[-1] - u1.shape[-1]
    u1 = jnp.pad(u1, [(0, 0)] * (u1.ndim - 1) + [(0, grow)])
    return state.replace(agent=agent.replace(params=params, pending=agent.pending._replace(u1=u1)))


def narrow_hidden(state: LearnerState, cfg: Config) -> LearnerState:
    """Inverse of `widen_hidden`: the paper's layer widths again, exactly."""
    agent = state.agent
    u1 = agent.pending.u1[..., : cfg.network.hidden[0]]
    params = network.unpad_hidden(agent.params, cfg)
    return state.replace(agent=agent.replace(params=params, pending=agent.pending._replace(u1=u1)))


def make_chunk(cfg: Config, n_steps: int, devices=None, speed: Speed = DEFAULT_SPEED):
    """Compiled run of n_steps steps for a batch of learners: (states, plans, hypers, budget) -> (states, log).

    The learner axis is the leading axis of every argument; `budget` is a () trial count per learner.
    Stats are reset at the start of the chunk, so they describe this chunk alone. `log` is a TrialBuffer per
    learner of the trials logged in the chunk (cfg.train.trial_log_every), or None without a per-trial log.
    The learner axis is sharded over `distribute.learner_mesh(n_learners, devices)`; the states buffers are
    donated (speed.donate).

    Args:
      cfg: model config.
      n_steps: learner steps per call.
      devices: devices to shard over (default `jax.devices()`); a list of one device turns sharding off.
      speed: how the loop is compiled; the result does not depend on it.
    """
    every = cfg.train.trial_log_every
    batched = jax.vmap(lambda s, u, p, h, b: budgeted_step(s, u, p, h, b, cfg, speed), in_axes=(0, 0, 0, 0, None))

    def chunk(states, plans, hypers, budget):
        counters = states.counters
        states = states.replace(counters=counters.replace(stats=jax.tree.map(jnp.zeros_like, counters.stats)))
        n_learners = counters.trials.shape[0]
        log = jax.vmap(lambda _: empty_buffer(cfg))(jnp.arange(n_learners)) if every else None

        def step_body(carry, u):
            s, buffers = carry
            new, info = batched(s, u, plans, hypers, budget)
            if buffers is not None:
                buffers = jax.vmap(lambda b, i, n: log_trial(b, i, n, every))(buffers, info, s.counters.trials)
            return (new, buffers), None

        states, log, _ = scan_steps(step_body, states, n_steps, cfg, batched=True, speed=speed, log=log)
        return states, log

    compiled, donated = {}, (0,) if speed.donate else ()

    def run(states, plans, hypers, budget):
        n_learners = jax.tree.leaves(states)[0].shape[0]
        mesh = distribute.learner_mesh(n_learners, devices)
        if mesh.size not in compiled:
            if mesh.size == 1:
                compiled[mesh.size] = (None, jax.jit(chunk, donate_argnums=donated))
            else:
                spec = PartitionSpec("learners")
                mapped = jax.shard_map(
                    chunk, mesh=mesh, in_specs=(spec, spec, spec, PartitionSpec()), out_specs=spec, check_vma=False
                )
                compiled[mesh.size] = (mesh, jax.jit(mapped, donate_argnums=donated))
        mesh, fn = compiled[mesh.size]
        if mesh is not None:
            states, plans, hypers = (distribute.on_mesh(t, mesh) for t in (states, plans, hypers))
        return fn(states, plans, hypers, budget)

    return run


def make_trace(cfg: Config, n_steps: int, speed: Speed = DEFAULT_SPEED):
    """Compiled run of one learner that also returns the StepInfo of every step (for tests and plots)."""

    def trace(state, plan, hyper):
        def step_body(carry, u):
            new, info = learner_step(carry[0], u, plan, hyper, cfg, speed=speed)
            return (new, None), info

        state, _, info = scan_steps(step_body, state, n_steps, cfg, speed=speed)
        return state, info

    return jax.jit(trace)
