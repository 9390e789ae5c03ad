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

from reach_jax import arm, distribute, encoding, learner, network, task
from reach_jax.config import Config, n_inputs

MAX_HIDDEN_PAD = 128  # largest Speed.hidden_pad: a TPU vector row of float32; wider only wastes memory


@dataclass(frozen=True)
class Speed:
    """How the compiled loops run. None of it is stored with a run: results do not depend on it bit for bit,
    except for `sparse_layer1`, which only the lever benchmark turns off.

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


@struct.dataclass
class Hyper:
    """Per-learner learning constants, so a sweep is just a batch of learners."""

    lr: jax.Array  # () SGD learning rate
    noise: jax.Array  # () exploration bound rnd ~ U(-noise, noise) until the anneal (learner.exploration_bound)
    lam: jax.Array  # () lambda of eq. 3
    noise_final_ratio: jax.Array  # () bound after the anneal as a fraction of `noise`; 1 = no anneal
    noise_anneal_delay: jax.Array  # () trials from the first full field to the start of the anneal
    noise_anneal_trials: jax.Array  # () trials the anneal lasts


def exploration_bound(hyper: Hyper, trials: jax.Array, full_at: jax.Array) -> jax.Array:
    """The learner's exploration bound after `trials` trials (`learner.exploration_bound` with its hyperparameters)."""
    return learner.exploration_bound(
        hyper.noise, hyper.noise_final_ratio, hyper.noise_anneal_delay, hyper.noise_anneal_trials, trials, full_at
    )


def default_hyper(cfg: Config) -> Hyper:
    """Hyper from the config's learner defaults."""
    c = cfg.learner
    return Hyper(
        lr=jnp.asarray(c.lr),
        noise=jnp.asarray(c.noise),
        lam=jnp.asarray(c.lam),
        noise_final_ratio=jnp.asarray(c.noise_final_ratio),
        noise_anneal_delay=jnp.asarray(float(c.noise_anneal_delay)),
        noise_anneal_trials=jnp.asarray(float(c.noise_anneal_trials)),
    )


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
    key: jax.Array  # PRNG key of the learner's per-step draws (`step_uniforms`); fixed for its life
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
    full_at: jax.Array  # () trials ended when the distance first reached its maximum; -1 before
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
    distance, full = (jnp.asarray(b) for b in task.curriculum_bounds(cfg))
    start, target, force = task.place_trial(task.draw_trial(k_trial, cfg), distance, cond.field, cfg)
    return LearnerState(
        params=network.init_params(k_param, cfg),
        key=k_run,
        arm=start,
        prev_arm=start,
        prev_tau=jnp.zeros(2),
        target=target,
        force=force,
        pending=learner.empty_pending(
            n_inputs(cfg), cfg.network.hidden[0], encoding.coded_support(start, start, jnp.zeros(2), cfg)
        ),
        t=jnp.array(0, jnp.int32),
        drifted=jnp.array(False),
        n_max=jnp.asarray(cfg.learner.n_max_init),
        distance=distance,
        full_at=jnp.where(distance >= full, 0, -1).astype(jnp.int32),
        trials=jnp.array(0, jnp.int32),
        steps=jnp.array(0, jnp.int32),
        stats=zero_stats(),
    )


def n_uniforms(cfg: Config) -> int:
    """Uniform draws one step consumes: 2 for the exploration noise, then one new trial's TrialDraws."""
    return 2 + 2 + 2 * cfg.task.target_candidates + 2


def step_uniforms(key: jax.Array, first_step: jax.Array, n_steps: int, cfg: Config) -> jax.Array:
    """(n_steps, n_uniforms) draws in [0, 1) of one learner's steps first_step, first_step + 1, ...

    A step's draws depend only on the learner's key and the step's index, so blocks of any size (and
    chunks of any length) see the same stream.
    """
    return jax.vmap(lambda i: jax.random.uniform(jax.random.fold_in(key, i), (n_uniforms(cfg),)))(
        first_step + jnp.arange(n_steps)
    )


def split_uniforms(u: jax.Array, noise: jax.Array, cfg: Config) -> tuple[jax.Array, task.TrialDraws]:
    """(n_uniforms,) draws in [0, 1) -> ((2,) rnd ~ U(-noise, noise), TrialDraws of a possible new trial)."""
    k = cfg.task.target_candidates
    rnd = noise * (2.0 * u[:2] - 1.0)
    draws = task.TrialDraws(start=u[2:4], target=u[4 : 4 + 2 * k].reshape(k, 2), force=u[4 + 2 * k : 6 + 2 * k])
    return rnd, draws


def learner_step(
    state: LearnerState,
    u: jax.Array,
    cond: task.Condition,
    hyper: Hyper,
    cfg: Config,
    active=None,
    speed: Speed = DEFAULT_SPEED,
):
    """One learning step of one learner; returns (new state, StepInfo).

    Args:
      state: the learner.
      u: (n_uniforms,) this step's draws in [0, 1) (`step_uniforms`).
      cond: its condition.
      hyper: its learning constants.
      cfg: model config.
      active: optional () bool; False leaves the weights untouched (the caller keeps the rest of the state).
      speed: how the step is computed; only `sparse_layer1` changes the result, and only by float32 rounding.
    """
    bound = exploration_bound(hyper, state.trials, state.full_at)
    rnd, draws = split_uniforms(u, bound, cfg)
    x = task.observe(state.arm, state.prev_arm, state.prev_tau, state.target, cond.input_mask, cfg)
    rows = encoding.coded_support(state.arm, state.prev_arm, state.prev_tau, cfg)  # carried in the pending step
    lr = hyper.lr if active is None else jnp.where(active, hyper.lr, 0.0)
    sparse = speed.sparse_layer1
    pending_in = state.pending if sparse else state.pending._replace(rows=None)
    params, out, loss, u1 = learner.ts_step(state.params, x, pending_in, state.n_max, lr, cfg, rows if sparse else None)

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
        u1=u1,
        rows=rows,
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
    was_full = state.full_at >= 0
    distance = jnp.where(
        done, task.update_curriculum(state.distance, goal, state.drifted, was_full, cfg), state.distance
    )
    first_full = ~was_full & (distance >= task.curriculum_bounds(cfg)[1])
    full_at = jnp.where(first_full, state.trials + done, state.full_at)
    start, new_target, force = task.place_trial(draws, distance, cond.field, cfg)
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
        pending=pending,
        n_max=n_max,
        distance=distance,
        full_at=full_at,
        trials=state.trials + done,
        steps=state.steps + 1,
        stats=stats,
        **nxt,
    )
    info = StepInfo(
        x=x, out=out, rnd=rnd, tau=tau, arm=moved, draws=draws, goal=goal, out_of_range=out_of_range, cap=cap, loss=loss
    )
    return new, info


def budgeted_step(
    state: LearnerState,
    u: jax.Array,
    cond: task.Condition,
    hyper: Hyper,
    budget: jax.Array,
    cfg: Config,
    speed: Speed = DEFAULT_SPEED,
):
    """learner_step, except that a learner which has ended `budget` trials stays frozen.

    Args:
      state, u, cond, hyper, speed: one learner, as for learner_step.
      budget: () trials per learner.
      cfg: model config.
    """
    active = state.trials < budget
    new, info = learner_step(state, u, cond, hyper, cfg, active=active, speed=speed)
    # The weights of a frozen learner already stay put (zero step size), so the select skips the
    # largest arrays instead of copying them once more every step.
    rest = jax.tree.map(lambda a, b: jnp.where(active, a, b), new.replace(params=None), state.replace(params=None))
    return rest.replace(params=new.params), info


def scan_steps(step, state, n_steps: int, cfg: Config, batched: bool = False, speed: Speed = DEFAULT_SPEED):
    """lax.scan of `step(state, u) -> (state, info)` over n_steps, drawing uniforms speed.draw_block steps at a time.

    Drawing a block in one vectorised call keeps the random-number loop out of the per-step body, where it
    cost as many kernel launches as the rest of the step. The stream does not depend on the block size.
    The steps run on `widen_hidden` weights; the state goes in and comes out with the paper's widths.

    Args:
      step: one step of one learner, or of a batch when `batched`.
      state: LearnerState, learner axis first when `batched`.
      n_steps: steps to take.
      cfg: model config.
      batched: state and step carry a leading learner axis.
      speed: the draw block and the hidden padding.

    Returns:
      (state after n_steps, info stacked over the steps).
    """

    def draws(s: LearnerState, n: int) -> jax.Array:
        if not batched:
            return step_uniforms(s.key, s.steps, n, cfg)
        u = jax.vmap(lambda k, first: step_uniforms(k, first, n, cfg))(s.key, s.steps)
        return jnp.swapaxes(u, 0, 1)

    def block_body(s, _):
        return jax.lax.scan(step, s, draws(s, block))

    block = speed.draw_block
    n_blocks, rest = divmod(n_steps, block)
    state = widen_hidden(state, speed.hidden_pad)
    state, info = jax.lax.scan(block_body, state, None, length=n_blocks)
    info = jax.tree.map(lambda a: a.reshape(n_blocks * block, *a.shape[2:]), info)
    if rest:
        state, tail = jax.lax.scan(step, state, draws(state, rest))
        info = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), info, tail)
    return narrow_hidden(state, cfg), info


def widen_hidden(state: LearnerState, multiple: int) -> LearnerState:
    """state in the layout of the compiled loops: first hidden layer padded to a multiple of `multiple`, u1 with it.

    Rows of a multiple of 8 float32 fill whole vector registers: the step runs 1.1-1.25x faster with 32 hidden
    units than with 30 (benchmarks/levers.py), and `network.pad_hidden` keeps the added units inert.
    Works with or without a leading learner axis.
    """
    params = network.pad_hidden(state.params, multiple)
    u1 = state.pending.u1
    grow = network.dense_layers(params)[0][0].shape[-1] - u1.shape[-1]
    u1 = jnp.pad(u1, [(0, 0)] * (u1.ndim - 1) + [(0, grow)])
    return state.replace(params=params, pending=state.pending._replace(u1=u1))


def narrow_hidden(state: LearnerState, cfg: Config) -> LearnerState:
    """Inverse of `widen_hidden`: the paper's layer widths again, exactly."""
    u1 = state.pending.u1[..., : cfg.network.hidden[0]]
    return state.replace(params=network.unpad_hidden(state.params, cfg), pending=state.pending._replace(u1=u1))


def make_chunk(cfg: Config, n_steps: int, devices=None, speed: Speed = DEFAULT_SPEED):
    """Compiled run of n_steps steps for a batch of learners: (states, conds, hypers, budget) -> states.

    The learner axis is the leading axis of every argument; `budget` is a () trial count per learner.
    Stats are reset at the start of the chunk, so they describe this chunk alone. The learner axis is
    sharded over `distribute.learner_mesh(n_learners, devices)`; the states buffers are donated (speed.donate).

    Args:
      cfg: model config.
      n_steps: learner steps per call.
      devices: devices to shard over (default `jax.devices()`); a list of one device turns sharding off.
      speed: how the loop is compiled; the result does not depend on it.
    """
    batched = jax.vmap(lambda s, u, c, h, b: budgeted_step(s, u, c, h, b, cfg, speed)[0], in_axes=(0, 0, 0, 0, None))

    def chunk(states, conds, hypers, budget):
        states = states.replace(stats=jax.tree.map(jnp.zeros_like, states.stats))

        def step_body(carry, u):
            return batched(carry, u, conds, hypers, budget), None

        return scan_steps(step_body, states, n_steps, cfg, batched=True, speed=speed)[0]

    compiled, donated = {}, (0,) if speed.donate else ()

    def run(states, conds, hypers, budget):
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
            states, conds, hypers = (distribute.on_mesh(t, mesh) for t in (states, conds, hypers))
        return fn(states, conds, hypers, budget)

    return run


def make_trace(cfg: Config, n_steps: int, speed: Speed = DEFAULT_SPEED):
    """Compiled run of one learner that also returns the StepInfo of every step (for tests and plots)."""

    def trace(state, cond, hyper):
        def step_body(carry, u):
            return learner_step(carry, u, cond, hyper, cfg, speed=speed)

        return scan_steps(step_body, state, n_steps, cfg, speed=speed)

    return jax.jit(trace)
