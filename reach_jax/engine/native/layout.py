"""What the native kernel reads and writes: its compile-time sizes, its run-time constants, and the learner state,
plans and hyperparameters packed into one float32 and one int32 row per learner.

Units as in `physics` and `env`: lengths [m], angles [rad], time [s]; every constant is rounded to float32 as XLA
rounds it in the JAX step (a constant of Python floats is computed in double, then rounded; a division by a
constant is a multiplication by its float32 reciprocal, as XLA's simplifier rewrites it).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from reach_jax.config import Config, n_inputs, workspace
from reach_jax.config.hyper import NAMES as HYPER_NAMES
from reach_jax.engine import random_stream
from reach_jax.engine.learner_state import LearnerState, Stats
from reach_jax.physics import arm

F32 = np.float32
N_FIELD = 14  # a Field's floats: viscous (2, 2), stiffness (2, 2), anchor, constant, random
# The hyperparameters the kernel's step reads (its HY_ order); a learner's geometry travels in its plan instead.
STEP_HYPERS = tuple(name for name in HYPER_NAMES if name not in workspace.GEOMETRY_HYPERS)
INT_FIELDS = (
    "valid", "terminal", "pending_learning", "t", "drifted", "trials", "full_at", "block_index", "block_learning",
    "block_catch", "steps",
)  # fmt: skip
STATS_INTS = tuple(n for n in Stats._fields if n != "start_value")


def _codes(cfg: Config) -> list[tuple[float, float, int]]:
    """(lo, hi, units) of each localized code, in input order (`encoding._codes`)."""
    e, (t1, t2) = cfg.encoding, cfg.arm.tau_max
    joints = [
        (*e.theta_ranges[0], e.theta_units[0]),
        (*e.theta_ranges[1], e.theta_units[1]),
        (-e.omega_range, e.omega_range, e.omega_units),
        (-e.omega_range, e.omega_range, e.omega_units),
    ]
    return [*joints, *joints, (-t1, t1, e.tau_units), (-t2, t2, e.tau_units)]


def constants(cfg: Config) -> dict[str, np.ndarray]:
    """Every constant of the step, by its name in the kernel (C_<NAME>), each a float32 vector."""
    a, s, t, lc = cfg.arm, cfg.sensor, cfg.task, cfg.learner
    m1, m2 = a.mass
    l1, l2 = a.length
    s2 = a.com_fraction * l2
    i1, i2 = a.inertia_factor * m1 * l1**2, a.inertia_factor * m2 * l2**2
    enc, offset = [], s.n_cells**2
    for c_lo, c_hi, n in _codes(cfg):
        enc += [c_lo, c_hi, F32(1) / F32((c_hi - c_lo) / (n - 1)), n, offset]
        offset += n
    tau_max = np.asarray(a.tau_max, F32)
    values = {
        "DT_HALF": 0.5 * a.dt, "DT": a.dt, "DT6": a.dt / 6.0,
        "L1": l1, "L2": l2, "NEG_L1": -l1, "NEG_L2": -l2,
        "M2L1S2": m2 * l1 * s2, "TWO_M2L1S2": 2 * m2 * l1 * s2, "I2": i2, "M11_C": F32(i1 + i2) + F32(m2 * l1**2),
        "B1": a.joint_viscosity[0], "B2": a.joint_viscosity[1],
        "TAU_MAX": tau_max, "TWO_TAU": F32(2) * tau_max,
        "TH1_LO": a.theta1_range[0], "TH1_HI": a.theta1_range[1], "TH2_MIN": a.theta2_min,
        "TH2_STOP": a.theta2_stop, "STOP_SHARE": arm._stop_share(a), "ONE_LINK": float(a.one_link_stop),
        "ENC": np.asarray(enc, F32),
        "GOAL_SPEED": t.goal_speed, "MAX_STEPS": round(t.max_trial_time / a.dt),
        "DRIFT_AFTER": t.drift_after, "DRIFT_PER_STEP": t.drift_per_step,
        "CUR_STEP": t.curriculum_step,
        "NEUTRAL_FULL": float(t.drift_neutral_when_full),
        "IK_SHIFT": -(F32(l1**2) + F32(l2**2)), "IK_SCALE": F32(1) / F32(2 * l1 * l2),
        "P_RANGE": lc.p_range, "CRITIC_FLOOR": lc.critic_floor, "REWARD_GOAL": lc.reward_goal,
        "REWARD_OUT": lc.reward_out, "BIAS_INPUT": 1.0 if cfg.network.use_bias else 0.0,
        "SAT": cfg.train.saturated_output,
    }  # fmt: skip
    return {name: np.atleast_1d(np.asarray(v, F32)) for name, v in values.items()}


def hidden_width(cfg: Config, pad: int) -> int:
    """The first hidden layer's width inside the loop (`chunk.widen_hidden`)."""
    return -(-cfg.network.hidden[0] // pad) * pad


def header(cfg: Config, pad: int) -> str:
    """consts.h for `cfg`: the sizes and the index of every constant in the kernel's `consts` vector."""
    sizes = {
        "NCELL": cfg.sensor.n_cells, "NVIS": cfg.sensor.n_cells**2, "NIN": n_inputs(cfg), "H1": hidden_width(cfg, pad),
        "H2": cfg.network.hidden[1], "NO": cfg.network.n_out, "K": cfg.task.target_candidates,
        "NCODE": len(_codes(cfg)), "NFIELD": N_FIELD, "NU": random_stream.n_uniforms(cfg),
        "NHYPER": len(STEP_HYPERS),
    }  # fmt: skip
    lines = [f"#define {k} {v}" for k, v in sizes.items()]
    index = 0
    for name, v in constants(cfg).items():
        lines.append(f"#define C_{name} {index}")
        index += len(v)
    lines.append(f"#define N_CONSTS {index}")
    index = 0
    for name, n in geometry_block(cfg.sensor.n_cells).items():
        lines.append(f"#define G_{name} {index}")
        index += n
    return "\n".join(["#pragma once", *lines, f"#define NGEOM {index}", ""])


def geometry_block(n_cells: int) -> dict[str, int]:
    """The lengths of the parts of a learner's geometry row (`pack_geometry`), by their names in the kernel (G_)."""
    edges = dict.fromkeys(("XE", "YE", "XE_HI", "YE_HI"), n_cells)
    return {"LO": 2, "HI": 2, "SPAN": 2, **edges, "HALF": 1, "INV_AREA": 1, "GHW": 1, "CUR_LO": 1, "CUR_HI": 1,
            "INV_CUR_HI": 1}  # fmt: skip


def pack_geometry(geom, n_cells: int) -> jax.Array:
    """(L, NGEOM) float32 rows of the learners' geometries (`task.Geometry`, learner axis first), each part computed
    as the JAX step computes it from the same data (`sensor.cell_edges`, `place_trial`, `curriculum`), so that the
    kernel reads the same bits."""
    s = geom.sensor
    k = jnp.arange(n_cells) * s.cell[:, None]
    lo_edges, hi_edges = k[:, None] + s.lo[:, :, None], k[:, None] + (s.lo + s.cell[:, None])[:, :, None]
    parts = [s.lo, s.hi, s.hi - s.lo, lo_edges[:, 0], lo_edges[:, 1], hi_edges[:, 0], hi_edges[:, 1]]
    scalars = (0.5 * s.cell, s.inv_cell_area, geom.goal_half, geom.start_distance, geom.full_distance,
               geom.inv_full_distance)  # fmt: skip
    return jnp.concatenate([*parts, *(v[:, None] for v in scalars)], axis=1).astype(jnp.float32)


def consts_vector(cfg: Config) -> np.ndarray:
    """The `consts` vector the kernel reads, in `header`'s order."""
    return np.concatenate(list(constants(cfg).values()))


def _field_rows(field) -> list[jax.Array]:
    lead = field.anchor.shape[:-1]
    return [field.viscous.reshape(*lead, 4), field.stiffness.reshape(*lead, 4), field.anchor, field.constant,
            field.random]  # fmt: skip


def _params(params) -> list[jax.Array]:
    p = params["params"]
    return [p[f"Dense_{i}"][k] for i in range(3) for k in ("kernel", "bias")]


def pack_state(states: LearnerState) -> tuple[jax.Array, jax.Array]:
    """(L, NF) float32 and (L, NI) int32 rows of widened learner states (`chunk.widen_hidden`), as the kernel reads."""
    a, e = states.agent, states.env
    n = e.trials.shape[0]
    tr, pend = e.trial, a.pending
    floats = [
        *_params(a.params), pend.x, pend.out, pend.rnd, pend.reward, pend.u1, pend.gain, a.n_max,
        tr.arm, tr.prev_arm, tr.prev_tau, tr.target, tr.force, *_field_rows(e.cond.field), e.cond.input_mask,
        e.curriculum.distance, e.curriculum.failure, states.counters.stats.start_value,
    ]  # fmt: skip
    ints = [
        pend.valid, pend.terminal, a.pending_learning, tr.t, tr.drifted, e.trials, e.curriculum.full_at,
        e.block.index, e.block.learning, e.block.catch, states.counters.steps,
        *(getattr(states.counters.stats, k) for k in STATS_INTS),
    ]  # fmt: skip
    f = jnp.concatenate([jnp.reshape(x, (n, -1)).astype(jnp.float32) for x in floats], axis=1)
    i = jnp.concatenate([jnp.reshape(x, (n, -1)).astype(jnp.int32) for x in ints], axis=1)
    return f, i


def unpack_state(f: jax.Array, i: jax.Array, like: LearnerState) -> LearnerState:
    """The learner states of `pack_state`'s rows, shaped and typed as `like`."""
    rows = {"f": f, "i": i}
    at = {"f": 0, "i": 0}

    def take(kind: str, old: jax.Array) -> jax.Array:
        size = int(np.prod(old.shape[1:], dtype=int))
        part = rows[kind][:, at[kind] : at[kind] + size]
        at[kind] += size
        return part.reshape(old.shape).astype(old.dtype)

    a, e = like.agent, like.env
    tr, pend, st = e.trial, a.pending, like.counters.stats
    p = like.agent.params["params"]
    dense = {f"Dense_{k}": {n: take("f", p[f"Dense_{k}"][n]) for n in ("kernel", "bias")} for k in range(3)}
    px, pout, prnd, prew, pu1, pgain, nmax = (take("f", x) for x in (pend.x, pend.out, pend.rnd, pend.reward, pend.u1,
                                                                     pend.gain, a.n_max))  # fmt: skip
    arm_, parm, ptau, tgt, force = (take("f", x) for x in (tr.arm, tr.prev_arm, tr.prev_tau, tr.target, tr.force))
    fd = e.cond.field
    field = fd.replace(**{k: take("f", getattr(fd, k)) for k in ("viscous", "stiffness", "anchor", "constant",
                                                                 "random")})  # fmt: skip
    mask = take("f", e.cond.input_mask)
    dist, fail, sval = (take("f", x) for x in (e.curriculum.distance, e.curriculum.failure, st.start_value))
    valid, term, plearn, t, drifted, trials, full_at, bindex, blearn, bcatch, steps = (
        take("i", x) for x in (pend.valid, pend.terminal, a.pending_learning, tr.t, tr.drifted, e.trials,
                               e.curriculum.full_at, e.block.index, e.block.learning, e.block.catch,
                               like.counters.steps)
    )  # fmt: skip
    stats = st._replace(**{k: take("i", getattr(st, k)) for k in STATS_INTS}, start_value=sval)
    pending = pend._replace(x=px, out=pout, rnd=prnd, reward=prew, u1=pu1, gain=pgain, valid=valid, terminal=term)
    return like.replace(
        agent=a.replace(params={**a.params, "params": dense}, pending=pending, pending_learning=plearn, n_max=nmax),
        env=e.replace(
            trial=tr.replace(arm=arm_, prev_arm=parm, prev_tau=ptau, target=tgt, force=force, t=t, drifted=drifted),
            cond=e.cond.replace(field=field, input_mask=mask),
            block=e.block.replace(index=bindex, learning=blearn, catch=bcatch),
            curriculum=e.curriculum.replace(distance=dist, full_at=full_at, failure=fail),
            trials=trials,
        ),
        counters=like.counters.replace(steps=steps, stats=stats),
    )


def pack_plan(plans, n_cells: int) -> tuple[jax.Array, jax.Array, int, int]:
    """(L, C (14 + NIN) + B + NGEOM) float32, (L, 4 B) int32 rows of the learners' plans (their geometry last), B
    blocks and C conditions."""
    n, n_cond = plans.ends.shape[0], plans.conds.input_mask.shape[1]
    conds = jnp.concatenate([*_field_rows(plans.conds.field), plans.conds.input_mask], axis=-1).reshape(n, -1)
    f = jnp.concatenate([conds, plans.catch.astype(jnp.float32), pack_geometry(plans.geometry, n_cells)], axis=1)
    i = jnp.concatenate([plans.ends, plans.cond, plans.catch_cond, plans.learning.astype(jnp.int32)], axis=1)
    return f, i.astype(jnp.int32), plans.ends.shape[1], n_cond


def pack_hyper(hypers) -> jax.Array:
    """(L, len(STEP_HYPERS)) float32 rows of the hyperparameters the step reads, in `hyper.TABLE`'s order."""
    return jnp.stack([jnp.asarray(getattr(hypers, k), jnp.float32) for k in STEP_HYPERS], axis=1)
