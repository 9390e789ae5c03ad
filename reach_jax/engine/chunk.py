"""Compiled chunks of learner steps: the scan, the padded layout, sharding, and a one-learner trace (model §5).

Learners never interact, so `make_chunk` shards the learner axis over devices (`distribute`) and each device runs
its own slice with no communication; the same code runs on CPU host devices, GPU, TPU or several hosts (after
`jax.distributed.initialize`), only the device list changes. Counts are steps or trials.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding, PartitionSpec

from reach_jax.agent import network
from reach_jax.config import Config
from reach_jax.config.schema import DEFAULT_SPEED, Speed
from reach_jax.engine import distribute, native, random_stream, rollout
from reach_jax.engine.learner_state import LearnerState
from reach_jax.env import trial_log


def scan_steps(
    step, state, n_steps: int, cfg: Config, batched: bool = False, speed: Speed = DEFAULT_SPEED, log=None, fold=None
):
    """lax.scan of `step(state, u) -> (state, info)` over n_steps, drawing uniforms in blocks.

    Drawing a block of steps' uniforms in one vectorised call keeps the random-number loop out of the per-step
    body, where it cost as many kernel launches as the rest of the step. The stream does not depend on the block
    size (`block_size`). The steps run on `widen_hidden` weights; the state goes in and comes out with the paper's
    widths.

    Args:
      step: one step of one learner, or of a batch when `batched`.
      state: LearnerState, learner axis first when `batched`.
      n_steps: steps to take.
      cfg: model config.
      batched: state and step carry a leading learner axis.
      speed: the draw block and the hidden padding.
      log: with `fold`, the log to fill (the per-trial log, `trial_log.TrialBuffer`).
      fold: None to stack every step's info; else `(log, infos) -> log`, called after each block of steps with
        their infos stacked, so that what writes the log stays out of the compiled step loop.

    Returns:
      (state after n_steps, the infos stacked over the steps), or with `fold`, (that state, the log).
    """

    def draws(s: LearnerState, n: int) -> jax.Array:
        if not batched:
            return random_stream.step_uniforms(s.key, s.counters.steps, n, cfg)
        u = jax.vmap(lambda k, first: random_stream.step_uniforms(k, first, n, cfg))(s.key, s.counters.steps)
        return jnp.swapaxes(u, 0, 1)

    def run_block(carry, n: int):
        s, kept = carry
        s, info = jax.lax.scan(step, s, draws(s, n))
        return ((s, kept), info) if fold is None else ((s, fold(kept, info)), None)

    block = block_size(n_steps, speed.draw_block)
    n_blocks, rest = divmod(n_steps, block)
    carry = (widen_hidden(state, speed.hidden_pad), log)
    carry, info = jax.lax.scan(lambda c, _: run_block(c, block), carry, None, length=n_blocks)
    info = jax.tree.map(lambda a: a.reshape(n_blocks * block, *a.shape[2:]), info)
    if rest:
        carry, tail = run_block(carry, rest)
        info = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), info, tail)
    state, log = carry
    state = narrow_hidden(state, cfg)
    return (state, info) if fold is None else (state, log)


def block_size(n_steps: int, most: int) -> int:
    """Steps whose uniforms one call draws in a run of n_steps, at most `most`.

    n_steps itself if it is at most `most`, else the largest divisor of n_steps from `most` / 2 to `most`, so that
    whole blocks take every step and the step body is compiled once (a remainder's scan compiles it a second time,
    a third of a small chunk's compile time); `most` if there is none, the rest of the steps in a second scan.
    """
    if n_steps <= most:
        return max(n_steps, 1)
    return next((b for b in range(most, (most - 1) // 2, -1) if n_steps % b == 0), most)


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


def chunk_body(cfg: Config, n_steps: int, speed: Speed):
    """Uncompiled chunk of one device: (states, plans, hypers, budget) -> (states, per-trial log or None).

    Stats are reset at the start of the chunk, so they describe this chunk alone.
    """
    every = cfg.train.trial_log_every
    batched = jax.vmap(
        lambda s, u, p, h, b: rollout.budgeted_step(s, u, p, h, b, cfg, speed), in_axes=(0, 0, 0, 0, None)
    )
    # A block's steps (leading axis) of every learner into that learner's buffer.
    fold = jax.vmap(lambda b, e: trial_log.log_block(b, *e, every), in_axes=(0, 1))

    def chunk(states, plans, hypers, budget):
        counters = states.counters
        states = states.replace(counters=counters.replace(stats=jax.tree.map(jnp.zeros_like, counters.stats)))
        n_learners = states.env.trials.shape[0]
        log = jax.vmap(lambda _: trial_log.empty_buffer(cfg))(jnp.arange(n_learners)) if every else None

        def step_body(s, u):
            new, info = batched(s, u, plans, hypers, budget)
            return new, ((info.ended, info.record, s.env.trials) if every else None)

        return scan_steps(
            step_body, states, n_steps, cfg, batched=True, speed=speed, log=log, fold=fold if every else None
        )

    return chunk


def native_chunk_body(cfg: Config, n_steps: int, speed: Speed):
    """Uncompiled chunk of one device on the native kernel: (states, plans, hypers, budget) -> (states, None).

    The same function as `chunk_body` without a per-trial log, bit for bit (`native.unsupported` says which learners
    it covers). One kernel call runs every step, its random draws included (the stream of `random_stream`). Stats are
    reset at its start.
    """
    name = native.target(cfg, speed)
    consts = native.layout.consts_vector(cfg)

    def chunk(states, plans, hypers, budget):
        counters = states.counters
        states = states.replace(counters=counters.replace(stats=jax.tree.map(jnp.zeros_like, counters.stats)))
        wide = widen_hidden(states, speed.hidden_pad)
        f, i = native.layout.pack_state(wide)
        pf, pi, n_blocks, n_cond = native.layout.pack_plan(plans, cfg.sensor.n_cells)
        call = jax.ffi.ffi_call(
            name,
            (jax.ShapeDtypeStruct(f.shape, jnp.float32), jax.ShapeDtypeStruct(i.shape, jnp.int32)),
            input_output_aliases={1: 0, 2: 1},
        )
        hy, budget = native.layout.pack_hyper(hypers), jnp.reshape(budget, (1,)).astype(jnp.int32)
        attrs = {"n_steps": np.int64(n_steps), "nb": np.int64(n_blocks), "ncond": np.int64(n_cond)}
        f, i = call(jnp.asarray(consts), f, i, hy, pf, pi, states.key, budget, **attrs)
        return narrow_hidden(native.layout.unpack_state(f, i, wide), cfg), None

    return chunk


def make_trace(cfg: Config, n_steps: int, speed: Speed = DEFAULT_SPEED):
    """Compiled run of one learner that keeps what every step did: `(state, plan, hyper) -> (state, StepInfo)`.

    The StepInfo fields are stacked over the n_steps steps; tests compare them with the NumPy oracle.
    """

    def trace(state, plan, hyper):
        return scan_steps(lambda s, u: rollout.learner_step(s, u, plan, hyper, cfg, speed=speed), state, n_steps, cfg)

    return jax.jit(trace)


def make_chunk(cfg: Config, n_steps: int, devices=None, speed: Speed = DEFAULT_SPEED):
    """Compiled run of n_steps steps for a batch of learners: (states, plans, hypers, budget) -> (states, log).

    The learner axis is the leading axis of every argument; `budget` is a () trial count per learner.
    `log` is a trial_log.TrialBuffer per learner of the trials logged in the chunk (cfg.train.trial_log_every),
    or None without a per-trial log. The learner axis is sharded over `distribute.learner_mesh(n_learners,
    devices)`; the states buffers are donated (speed.donate).

    Args:
      cfg: model config.
      n_steps: learner steps per call.
      devices: devices to shard over (default `jax.devices()`); a list of one device turns sharding off.
      speed: how the loop is compiled and its engine (`native.resolve` decides "auto"); the result does not
        depend on it.
    """
    speed = native.resolve(cfg, speed)[0] if speed.engine == "auto" else speed
    body = native_chunk_body if speed.engine == "native" else chunk_body
    chunk = body(cfg, n_steps, speed)
    compiled, donated, placed = {}, (0,) if speed.donate else (), {}

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
            states = distribute.on_mesh(states, mesh)
            plans, hypers, budget = _placed(placed, mesh, plans, hypers, budget)
        return fn(states, plans, hypers, budget)

    return run


def _placed(cache: dict, mesh, plans, hypers, budget):
    """plans and hypers split over `mesh` along the learner axis and the () budget whole on each device, placed once
    while the same objects come back: a run passes the same ones chunk after chunk, and placing them took ~10 ms of
    each chunk's dispatch, while the devices waited."""
    key = (mesh, id(plans), id(hypers), id(budget))
    if cache.get("key") != key:
        value = np.asarray(budget)  # made from host values, as `distribute.shard_learners` does, across processes too
        whole = jax.make_array_from_callback(value.shape, NamedSharding(mesh, PartitionSpec()), lambda i: value[i])
        # The objects are kept with their key, so that their ids are not reused while it stands.
        cache.update(key=key, given=(plans, hypers, budget), placed=(*distribute.on_mesh((plans, hypers), mesh), whole))
    return cache["placed"]
