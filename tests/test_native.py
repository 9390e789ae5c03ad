"""The native engine (`engine.native`): each part of its kernel against its JAX function, and every kind of learner
trained by either engine, bit for bit; the fallback to the JAX engine without a compiler."""

from __future__ import annotations

import ctypes
import ctypes.util
import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from reach_jax import env
from reach_jax.config import Config, from_partial
from reach_jax.config.schema import DEFAULT_SPEED, Speed
from reach_jax.engine import batch, native, random_stream
from reach_jax.engine.chunk import make_chunk, widen_hidden
from reach_jax.engine.native import build, layout
from reach_jax.physics import arm, fields

pytestmark = pytest.mark.skipif(
    native.unsupported(Config(), DEFAULT_SPEED) is not None or build.compiler() is None,
    reason="the native engine does not run here",
)


def library(cfg: Config) -> ctypes.CDLL:
    """The kernel's library for cfg, with its test entry points typed."""
    lib = build.load(layout.header(cfg, DEFAULT_SPEED.hidden_pad))[0]
    lib.reach_native_observe.argtypes = [ctypes.c_void_p] * 5
    lib.reach_native_arm_step.argtypes = [ctypes.c_void_p] * 6
    lib.reach_native_draws.argtypes = [ctypes.c_void_p, ctypes.c_int32, ctypes.c_void_p]
    lib.reach_native_sincos.argtypes = [ctypes.c_void_p] * 3 + [ctypes.c_int32]
    return lib


def ptr(a: np.ndarray) -> ctypes.c_void_p:
    return a.ctypes.data_as(ctypes.c_void_p)


def random_arms(n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 4) arm states over the joints' ranges and beyond, a quarter of them on the elbow's stop and moving."""
    lo, hi = np.array([-0.2, -0.2, -6.0, -6.0]), np.array([1.8, np.pi, 6.0, 6.0])
    s = rng.uniform(lo, hi, (n, 4)).astype(np.float32)
    s[: n // 4, 1] = np.float32(np.pi)
    return s


def test_the_kernels_observation_equals_the_jax_one():
    cfg = Config()
    lib, rng = library(cfg), np.random.default_rng(1)
    group = batch.init_batch(dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, seeds=16)))
    states = group.states
    trial = states.env.trial
    n = trial.t.shape[0]
    trial = trial.replace(
        arm=jnp.asarray(random_arms(n, rng)),
        prev_arm=jnp.asarray(random_arms(n, rng)),
        prev_tau=jnp.asarray(rng.uniform(-6, 6, (n, 2)), jnp.float32),
        target=jnp.asarray(rng.uniform([-0.2, 0.25], [0.1, 0.5], (n, 2)), jnp.float32),
    )
    states = states.replace(env=states.env.replace(trial=trial))
    want = np.asarray(jax.jit(jax.vmap(lambda e, p: env.observe(e, p.geometry, cfg)))(states.env, group.plans))
    rows = np.asarray(layout.pack_state(widen_hidden(states, DEFAULT_SPEED.hidden_pad))[0])
    consts = layout.consts_vector(cfg)
    geoms = np.asarray(layout.pack_geometry(group.plans.geometry, cfg.sensor.n_cells))
    for i in range(n):
        x, support, row = np.zeros(want.shape[1], np.float32), np.zeros(20, np.int32), np.ascontiguousarray(rows[i])
        lib.reach_native_observe(ptr(consts), ptr(np.ascontiguousarray(geoms[i])), ptr(row), ptr(x), ptr(support))
        assert x.tobytes() == want[i].tobytes(), i
        assert set(np.flatnonzero(x[25:]) + 25) <= set(support)


def test_the_kernels_arm_step_equals_the_jax_one():
    cfg = Config()
    lib, rng, n = library(cfg), np.random.default_rng(2), 400
    s = random_arms(n, rng)
    tau = rng.uniform(-6, 6, (n, 2)).astype(np.float32)
    force = rng.uniform(-5, 5, (n, 2)).astype(np.float32)
    viscous = rng.uniform(-15, 15, (n, 2, 2)).astype(np.float32)
    stiffness = rng.uniform(-30, 30, (n, 2, 2)).astype(np.float32)
    anchor, constant = (rng.uniform(-1, 1, (n, 2)).astype(np.float32) for _ in range(2))
    field = fields.Field(viscous, stiffness, anchor, constant, np.zeros((n, 2), np.float32))
    want = np.asarray(jax.jit(jax.vmap(lambda *a: arm.step(*a, cfg.arm)))(s, tau, field, force))
    consts = layout.consts_vector(cfg)
    packed = np.concatenate([viscous.reshape(n, 4), stiffness.reshape(n, 4), anchor, constant, 0 * anchor], axis=1)
    for i in range(n):
        out, f = np.zeros(4, np.float32), np.ascontiguousarray(packed[i])
        args = (consts, np.ascontiguousarray(s[i]), np.ascontiguousarray(tau[i]), f, np.ascontiguousarray(force[i]))
        lib.reach_native_arm_step(*(ptr(a) for a in args), ptr(out))
        assert out.tobytes() == want[i].tobytes(), (i, out, want[i])


def test_the_kernels_sines_and_cosines_equal_libms():
    """The arm's sinf and cosf, in vectors where the CPU has FMA and AVX2, against this machine's libm: floats of
    [-130, 130] at random and on a grid, and the slow path's beyond 120. (Every float of [-130, 130] was checked once,
    on glibc 2.36 with FMA: too slow for the suite.)"""
    lib, rng = library(Config()), np.random.default_rng(3)
    libm = ctypes.CDLL(ctypes.util.find_library("m"))
    for f in (libm.sinf, libm.cosf):
        f.restype, f.argtypes = ctypes.c_float, [ctypes.c_float]
    top = 0x43020000  # 130.0f
    u = np.concatenate([rng.integers(0, top, 40_000), np.arange(0, top, top // 20_000)[:20_000]]).astype(np.uint32)
    x = np.concatenate([u, u | 0x80000000, np.float32([120, -121, 1e30, 3e38]).view(np.uint32)]).view(np.float32)
    s, c = np.empty_like(x), np.empty_like(x)
    lib.reach_native_sincos(ptr(x), ptr(s), ptr(c), len(x))
    assert s.tobytes() == np.float32([libm.sinf(v) for v in x]).tobytes()
    assert c.tobytes() == np.float32([libm.cosf(v) for v in x]).tobytes()


def test_the_kernels_draws_equal_the_random_stream():
    cfg = Config()
    lib, keys = library(cfg), batch.init_batch(cfg).states.key
    for key in np.asarray(keys):
        first = int(np.random.default_rng(int(key[0])).integers(0, 2**31 - 100))
        want = np.asarray(random_stream.step_uniforms(jnp.asarray(key), jnp.int32(first), 50, cfg))
        for s in range(50):
            got = np.zeros(want.shape[1], np.float32)
            lib.reach_native_draws(ptr(np.ascontiguousarray(key)), first + s, ptr(got))
            assert got.tobytes() == want[s].tobytes(), (key, first + s)


SWEEP = {  # per-learner hyperparameters that turn on each branch of the step, one learner each
    "noise_corr": 0.8,
    "quiet_every": 3.0,
    "noise_value_ratio": 0.3,
    "noise_value_gate": 0.5,
    "noise_value_steps": 20.0,
    "noise_value_after_full": 1.0,
    "actor_gain_power": 1.0,
    "actor_signal_gain": 1.5,
    "actor_target_bound": 0.3,
    "actor_baseline": 1.0,
    "drift_gate": 0.2,
    "drift_neutral_early": 1.0,
    "n_max_clean": 1.0,
    "noise_final_ratio": 0.2,
}


def learners(kind: str):
    """(cfg, Batch) of one kind of learner: the paper's conditions, a protocol, a sweep, arms on the elbow stop, or
    four visual fields (the task's geometry as data)."""
    if kind == "geometry":  # 4 fields: today's, (0.10, 0.45) m at x0.75, (-0.05, 0.41) m at x1.25, (0.00, 0.37) m
        fields = {
            "sensor_dx_grid": [0.0, 0.15, 0.0, 0.05],
            "sensor_dy_grid": [0.0, 0.08, 0.04, 0.0],
            "sensor_scale_grid": [1.0, 0.75, 1.25, 1.0],
        }
        cfg = from_partial({"train": {"seeds": 1, "zip_grids": True, **fields}})
        return cfg, batch.init_batch(cfg)
    if kind == "protocol":
        cfg = from_partial({"train": {"trials": 45_000, "seeds": 2, "conditions": [], "protocols": ["adaptation"]}})
        cfg = dataclasses.replace(
            cfg,
            protocols=tuple(
                dataclasses.replace(p, blocks=tuple(dataclasses.replace(b, trials=15) for b in p.blocks))
                for p in cfg.protocols
            ),
        )
        return cfg, batch.init_batch(cfg)
    cfg = from_partial({"train": {"seeds": 1 if kind != "sweep" else 4}})
    group = batch.init_batch(cfg)
    if kind == "sweep":
        columns = group.hypers._asdict()
        for i, (name, value) in enumerate(SWEEP.items()):
            columns[name] = columns[name].at[i].set(value)
            if name == "noise_final_ratio":
                columns["noise_anneal_trials"] = columns["noise_anneal_trials"].at[i].set(5.0)
        group = group._replace(hypers=type(group.hypers)(**columns))
    if kind == "elbow_stop":
        trial = group.states.env.trial
        on_stop = trial.arm.at[:, 1].set(np.float32(np.pi) - 0.01).at[:, 3].set(3.0)
        group = group._replace(states=group.states.replace(env=group.states.env.replace(trial=trial.replace(
            arm=on_stop, prev_arm=on_stop))))  # fmt: skip
    return cfg, group


@pytest.mark.parametrize("kind", ["conditions", "protocol", "sweep", "elbow_stop", "geometry"])
def test_every_kind_of_learner_trains_bit_identically_on_either_engine(kind):
    cfg, group = learners(kind)
    ends = {}
    for engine in ("jax", "native"):
        run = make_chunk(cfg, 1500, speed=Speed(engine=engine))
        states = group.states
        for budget in (10**6, 40):  # the second chunk freezes the learners that have their trials
            states = run(jax.tree.map(jnp.copy, states), group.plans, group.hypers, jnp.asarray(budget, jnp.int32))[0]
        ends[engine] = jax.device_get(states)
    trials = np.asarray(ends["jax"].env.trials)
    assert trials.min() > 5, trials
    pairs = zip(jax.tree_util.tree_leaves_with_path(ends["jax"]), jax.tree.leaves(ends["native"]), strict=True)
    for (path, a), b in pairs:
        assert np.asarray(a).tobytes() == np.asarray(b).tobytes(), jax.tree_util.keystr(path)


def test_learners_the_kernel_does_not_cover_train_on_the_jax_engine_with_a_notice():
    cfg = from_partial({"train": {"trial_log_every": 5}})
    speed, notice = native.resolve(cfg, DEFAULT_SPEED)
    assert speed.engine == "jax" and "per-trial log" in notice and "\n" not in notice
    speed, notice = native.resolve(Config(), dataclasses.replace(DEFAULT_SPEED, sparse_layer1=False))
    assert speed.engine == "jax" and "sparse layer 1" in notice
    assert native.resolve(Config(), Speed(engine="jax")) == (Speed(engine="jax"), None)
    assert native.resolve(Config(), DEFAULT_SPEED) == (Speed(engine="native"), None)


def test_without_a_compiler_training_runs_on_the_jax_engine(monkeypatch, tmp_path, capsys):
    from reach_jax.train import cli

    monkeypatch.setenv(build.ENV_COMPILER, "")
    monkeypatch.setenv(build.ENV_CACHE, str(tmp_path / "cache"))
    build.load.cache_clear()
    try:
        speed, notice = native.resolve(Config(), DEFAULT_SPEED)
        assert speed.engine == "jax" and "no C++ compiler" in notice
        argv = ["--trials", "4", "--seeds", "1", "--conditions", "none", "--chunk-steps", "100", "--quiet"]
        assert cli.main([*argv, "--out", str(tmp_path / "run")]) == 0
        assert capsys.readouterr().err.count("training on the JAX engine") == 1
        assert not (tmp_path / "cache").exists() or not list((tmp_path / "cache").rglob("*.so"))
    finally:
        build.load.cache_clear()
