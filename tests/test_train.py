"""The learner step, the chunked trainer and the training command line."""

from __future__ import annotations

import dataclasses
import json

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import default_hyper

from reach_jax import errors, train
from reach_jax.agent import exploration, learner, network
from reach_jax.config import (
    CONDITIONS,
    ConditionConfig,
    Config,
    LearnerConfig,
    TaskConfig,
    TrainConfig,
    compat,
    from_partial,
    hyper,
    n_inputs,
    n_past_inputs,
    to_dict,
)
from reach_jax.config.schema import DEFAULT_SPEED, Speed
from reach_jax.engine import batch, learner_state, random_stream, rollout
from reach_jax.engine.chunk import block_size, make_chunk, make_trace, narrow_hidden, widen_hidden
from reach_jax.engine.learner_state import init_learner
from reach_jax.env import curriculum, protocol, task
from reach_jax.physics import arm, encoding, fields, sensor
from reach_jax.store import run_dir as run_dir_io
from reach_jax.train import cli as train_cli

CFG = Config()
EQ2 = dataclasses.replace(CFG, learner=LearnerConfig(**compat.CHANGED_DEFAULTS[9]["learner"]))  # every form off


def without_stats(states):
    """states without the per-chunk counters."""
    return states.replace(counters=states.counters.replace(stats=None))


def tiny(**train_fields) -> Config:
    """Paper model with a short training schedule."""
    fields = {"trials": 20, "seeds": 1, "chunk_steps": 200, **train_fields}
    return dataclasses.replace(CFG, train=dataclasses.replace(TrainConfig(), **fields))


def test_ts_targets_follow_eq_1_and_2():
    lc = LearnerConfig()
    pending = learner.Pending(
        x=jnp.zeros(3),
        out=jnp.array([0.1, 0.2, -0.3]),
        rnd=jnp.array([0.05, -0.1]),
        valid=jnp.array(True),
        terminal=jnp.array(False),
        reward=jnp.array(0.0),
    )
    p_now, n_max = 0.25, 40.0
    got = learner.ts_targets(pending, jnp.array(p_now), jnp.array(n_max), lc)
    np.testing.assert_allclose(got[0], p_now - lc.p_range / n_max, rtol=1e-6)
    np.testing.assert_allclose(got[1:], [0.2 + 0.05 * (p_now - 0.1), -0.3 - 0.1 * (p_now - 0.1)], rtol=1e-6)
    # The actor's baseline (a departure from eq. 2): at 1 the signal is the critic's TD error; the critic is unchanged.
    td = p_now - lc.p_range / n_max - 0.1
    based = learner.ts_targets(pending, jnp.array(p_now), jnp.array(n_max), lc, jnp.array(1.0))
    np.testing.assert_allclose(based, [got[0], 0.2 + 0.05 * td, -0.3 - 0.1 * td], rtol=1e-6)


def test_terminal_reward_stands_in_for_p_and_floor_guards_only_non_terminal():
    lc = LearnerConfig()
    base = learner.Pending(
        x=jnp.zeros(3),
        out=jnp.array([-0.45, 0.0, 0.0]),
        rnd=jnp.array([0.1, 0.1]),
        valid=jnp.array(True),
        terminal=jnp.array(True),
        reward=jnp.array(lc.reward_out),
    )
    n_max = jnp.array(50.0)
    out_target = learner.ts_targets(base, jnp.array(0.3), n_max, lc)
    np.testing.assert_allclose(out_target[0], lc.reward_out - lc.p_range / 50.0, rtol=1e-6)
    # The out penalty pulls the actor away from the noise that led there: r - p(t-1) < 0 here.
    np.testing.assert_allclose(out_target[1:], 0.1 * (lc.reward_out + 0.45), rtol=1e-6)
    running = base._replace(terminal=jnp.array(False))
    low = learner.ts_targets(running, jnp.array(-0.49), n_max, lc)
    assert float(low[0]) == pytest.approx(lc.critic_floor)


def test_n_max_follows_eq_3():
    lam = jnp.array(0.9)
    assert float(learner.update_n_max(jnp.array(100.0), jnp.array(95), lam)) == 95.0
    assert float(learner.update_n_max(jnp.array(100.0), jnp.array(80), lam)) == pytest.approx(90.0)


def test_curriculum_staircase_moves_and_stays_in_bounds():
    lo, hi = (float(b) for b in curriculum.bounds(task.geometry(CFG)))
    step = CFG.task.curriculum_step
    yes, no = jnp.array(True), jnp.array(False)

    def cur(d, goal, drifted=no, was_full=no, cfg=CFG):
        return float(curriculum.staircase(jnp.asarray(d), goal, drifted, was_full, task.geometry(cfg), cfg))

    assert cur(0.1, yes) == pytest.approx(0.1 + step)
    assert cur(0.1, no) == pytest.approx(0.1 - step)
    assert cur(0.1, yes, drifted=yes) == pytest.approx(0.1 - step)  # drift-aided, field never full: shrinks
    assert cur(0.1, yes, drifted=yes, was_full=yes) == pytest.approx(0.1)  # once full: neutral
    assert cur(0.1, no, drifted=yes, was_full=yes) == pytest.approx(0.1 - step)  # an out or cap still shrinks
    counting = dataclasses.replace(CFG, task=dataclasses.replace(CFG.task, drift_neutral_when_full=False))
    assert cur(0.1, yes, drifted=yes, was_full=yes, cfg=counting) == pytest.approx(0.1 - step)
    assert cur(lo, no) == pytest.approx(lo)
    assert cur(hi, yes) == pytest.approx(hi)


def test_new_trials_start_in_field_at_rest_with_untouched_target_in_the_box():
    lo, hi = (np.asarray(b) for b in sensor.field_bounds(CFG.sensor))
    keys = jax.random.split(jax.random.PRNGKey(3), 256)
    distance = jnp.array(0.08)
    draws = jax.vmap(lambda k: task.draw_trial(k, CFG))(keys)
    field = fields.make_field(ConditionConfig(random=(8.0, 8.0)))
    start, target, force = jax.vmap(lambda d: task.place_trial(d, distance, field, task.geometry(CFG), CFG))(draws)
    hand = jax.vmap(lambda s: arm.hand_position(s[:2], CFG.arm))(start)
    assert np.all(np.asarray(start[:, 2:]) == 0)
    assert np.all((hand >= lo - 1e-6) & (hand <= hi + 1e-6))
    assert np.all((target >= lo - 1e-6) & (target <= hi + 1e-6))
    assert np.all(np.abs(target - hand).max(axis=1) <= float(distance) + 1e-6)
    assert np.mean(np.asarray(task.touching(hand, target, task.goal_half_width(CFG)))) < 0.05
    assert np.all(np.abs(force) <= 8.0) and np.std(force) > 1.0


def test_conditions_are_data():
    conds = task.stack_conditions(CONDITIONS, CFG)
    chex.assert_tree_shape_prefix(conds, (4,))
    field_norms = np.abs(np.asarray(conds.field.viscous)).sum(axis=(1, 2))
    assert list(field_norms > 0) == [False, True, False, False]
    assert list(np.asarray(conds.field.random).min(axis=1) > 0) == [False, False, True, True]
    past = np.asarray(conds.input_mask)[:, n_inputs(CFG) - n_past_inputs(CFG) :]
    assert list(past.sum(axis=1)) == [60, 60, 60, 0]
    with pytest.raises(ValueError, match="unknown condition"):
        task.make_condition("sideways", CFG)


def test_trials_end_and_reset_inside_the_scan():
    # A 0.2 s cap forces trial ends within the trace, whatever the network does.
    cfg = dataclasses.replace(CFG, task=dataclasses.replace(TaskConfig(), max_trial_time=0.2))
    trace = make_trace(cfg, 60)
    n_now, n_past = n_inputs(cfg) - n_past_inputs(cfg), n_past_inputs(cfg)
    joints = n_past - 2 * cfg.encoding.tau_units
    for name in ("none", "random_nopast"):
        plan = protocol.make_plan(name, cfg)
        final, info = trace(init_learner(jax.random.PRNGKey(0), plan, cfg), plan, default_hyper(cfg))
        done = np.asarray(info.goal | info.out_of_range | info.cap)
        assert done.sum() >= 5
        stats = final.counters.stats
        assert int(final.env.trials) == done.sum() == int(stats.trials)
        assert int(stats.goals + stats.outs + stats.caps) == done.sum()
        x = np.asarray(info.x)
        first = np.flatnonzero(done[:-1]) + 1
        # The mechanism's counters (model §5): every step, the actor's outputs near f's bounds, the critic at each
        # trial's first step; the drift gate is off, so every trial ran with it open.
        out, starts = np.asarray(info.out), np.concatenate([[0], first])
        assert int(stats.steps) == 60 and int(stats.starts) == len(starts)
        assert int(stats.saturated) == np.sum(np.abs(out[:, 1:]) > cfg.train.saturated_output)
        assert float(stats.start_value) == pytest.approx(out[starts, 0].sum(), rel=1e-5, abs=1e-6)
        assert int(stats.gate_open) == int(stats.trials) and int(stats.clean_goals) <= int(stats.goals)
        columns = learner_state.mechanism_columns(jax.tree.map(lambda a: np.asarray(a)[None], final), cfg)
        clean, goals, outs, trials = (int(getattr(stats, k)) for k in ("clean_goals", "goals", "outs", "trials"))
        assert columns["clean_margin"] == [pytest.approx((clean - (goals - clean) - outs) / trials)]
        assert columns["start_value"] == [pytest.approx(float(stats.start_value) / len(starts))]
        assert columns["failure"] == [float(final.env.curriculum.failure)]
        kernel = np.asarray(final.agent.params["params"]["Dense_0"]["kernel"])
        assert columns["w1_norm"] == [pytest.approx(np.sqrt(np.sum(kernel.astype(float) ** 2)), rel=1e-6)]
        if name == "random_nopast":
            assert np.all(x[:, n_now:] == 0)
            continue
        # A fresh trial starts at rest, with "one step before" equal to now and zero past torque.
        np.testing.assert_array_equal(x[first, n_now : n_now + joints], x[first, n_now - joints : n_now])
        zero_tau = np.asarray(encoding.localize(jnp.array(0.0), -1.0, 1.0, cfg.encoding.tau_units))
        np.testing.assert_allclose(x[first, n_now + joints :], np.tile(zero_tau, (len(first), 2)), atol=1e-6)
        assert np.any(x[first - 1, n_now + joints :] != x[first, n_now + joints :])


def test_draws_do_not_depend_on_how_steps_are_split():
    # 150 steps = three blocks of 50 draws; 61 + 89 splits them elsewhere, as one block of 61, then a block of 64
    # and a remainder of 25 in a second scan: every way `scan_steps` lays out its draws.
    assert [block_size(n, DEFAULT_SPEED.draw_block) for n in (150, 61, 89)] == [50, 61, 64]
    cfg = tiny()
    cond = protocol.make_plan("random", cfg)
    state = init_learner(jax.random.PRNGKey(3), cond, cfg)
    hyper = default_hyper(cfg)
    whole, info = make_trace(cfg, 150)(state, cond, hyper)
    half, first = make_trace(cfg, 61)(state, cond, hyper)
    split, second = make_trace(cfg, 89)(half, cond, hyper)
    chex.assert_trees_all_equal(split, whole)
    np.testing.assert_array_equal(np.concatenate([first.rnd, second.rnd]), np.asarray(info.rnd))
    assert len(np.unique(np.asarray(info.rnd)[:, 0])) == 150


def test_exploration_forms_at_their_neutral_values_are_white_noise_bit_for_bit():
    h = default_hyper(EQ2)
    unit = jax.random.uniform(jax.random.PRNGKey(0), (500, 2), minval=-1.0, maxval=1.0)
    p = jax.random.uniform(jax.random.PRNGKey(1), (500,), minval=-0.5, maxval=0.5)
    prev = jax.random.uniform(jax.random.PRNGKey(2), (500, 2), minval=-0.2, maxval=0.2)

    def rnd(u, v, q):
        scale = exploration.value_scale(h, v, jnp.asarray(-1), jnp.asarray(0.5), jnp.asarray(200))
        return exploration.noise(u, h, jnp.asarray(9), jnp.asarray(-1), scale, q)

    carried, fresh = jax.vmap(rnd)(unit, p, prev)
    assert not np.any(np.asarray(carried))
    np.testing.assert_array_equal(np.asarray(fresh), np.asarray(h.noise * unit))


def test_exploration_scales_with_the_critics_value_and_rests_on_quiet_trials():
    h = default_hyper(EQ2)._replace(
        noise_value_ratio=jnp.asarray(0.25), noise_value_hi=jnp.asarray(0.3), noise_value_lo=jnp.asarray(0.1)
    )
    scale = jax.jit(lambda p, full_at, h=h: exploration.value_scale(h, p, full_at))
    for p, want in ((-0.4, 1.0), (0.1, 1.0), (0.2, 0.625), (0.3, 0.25), (0.45, 0.25)):
        assert float(scale(p, -1)) == pytest.approx(want, abs=1e-6), p
    # From the first full field only: the whole bound before it, scaled after it.
    after = h._replace(noise_value_after_full=jnp.asarray(1.0))
    assert float(scale(0.45, -1, after)) == 1.0 and float(scale(0.45, 30, after)) == pytest.approx(0.25)
    # Gated by the curriculum: relaxed linearly with its shortfall from the whole field, fully at the gate.
    gated = jax.jit(lambda p, s, g: exploration.value_scale(h._replace(noise_value_gate=g), p, 30, s))
    for short, want in ((0.0, 0.25), (0.05, 0.625), (0.1, 1.0), (0.6, 1.0)):
        assert float(gated(0.45, short, 0.1)) == pytest.approx(want, abs=1e-6), short
    assert float(gated(0.2, 0.05, 0.1)) == pytest.approx(0.625 + 0.375 * 0.5, abs=1e-6)  # times the value's ramp
    assert float(gated(0.45, 0.6, 0.0)) == pytest.approx(0.25)  # gate 0: off, whatever the shortfall
    # Off from step n of a trial on: the whole bound once a trial runs long.
    late = jax.jit(lambda t, n: exploration.value_scale(h._replace(noise_value_steps=n), 0.45, 30, 0.0, t))
    assert [float(late(t, 40.0)) for t in (0, 39, 40, 200)] == pytest.approx([0.25, 0.25, 1.0, 1.0])
    assert float(late(200, 0.0)) == pytest.approx(0.25)  # n = 0: never
    # The actor's gain undoes the factor to its power; 1 at power 0 and where the factor is 0.
    gain = jax.jit(lambda s, k: exploration.actor_gain(h._replace(actor_gain_power=k), s))
    assert [float(gain(0.25, k)) for k in (0.0, 1.0, 2.0)] == pytest.approx([1.0, 4.0, 16.0])
    assert float(gain(1.0, 2.0)) == 1.0 and float(gain(0.0, 2.0)) == 1.0
    quiet = jax.jit(lambda t, k: exploration.quiet(h._replace(quiet_every=jnp.asarray(k)), t))
    assert [bool(quiet(t, 3.0)) for t in range(7)] == [False, False, True, False, False, True, False]
    assert not any(bool(quiet(t, 0.0)) for t in range(7))
    carried, fresh = exploration.noise(
        jnp.ones(2), h._replace(quiet_every=jnp.asarray(3.0), noise_corr=jnp.asarray(0.5)), 2, -1, 1.0, jnp.ones(2)
    )
    assert not np.any(np.asarray(carried)) and not np.any(np.asarray(fresh))  # quiet: the carried share too


def test_correlated_exploration_keeps_the_spread_of_white_noise():
    rho = 0.8
    h = default_hyper(CFG)._replace(noise_corr=jnp.asarray(rho))
    unit = jax.random.uniform(jax.random.PRNGKey(5), (200_000, 2), minval=-1.0, maxval=1.0)

    def body(prev, u):
        carried, fresh = exploration.noise(u, h, 0, -1, 1.0, prev)
        return carried + fresh, carried + fresh

    rnd = np.asarray(jax.lax.scan(body, jnp.zeros(2), unit)[1])[1000:]
    white_sd = CFG.learner.noise / np.sqrt(3.0)  # sd of U(-b, b)
    assert rnd.std(axis=0) == pytest.approx([white_sd, white_sd], rel=0.03)
    lag1 = [np.corrcoef(rnd[:-1, j], rnd[1:, j])[0, 1] for j in range(2)]
    assert lag1 == pytest.approx([rho, rho], abs=0.01)


def test_exploration_anneals_once_the_curriculum_is_full():
    lc = LearnerConfig(noise=0.2, noise_final_ratio=0.5, noise_anneal_delay=0, noise_anneal_trials=1000)
    hyper = default_hyper(dataclasses.replace(CFG, learner=lc))
    bound = jax.jit(lambda t, f, h=hyper: exploration.schedule(h, t, f))
    assert float(bound(5000, -1)) == pytest.approx(0.2)  # curriculum not full yet: no anneal, however long
    assert float(bound(100, 100)) == pytest.approx(0.2)
    assert float(bound(600, 100)) == pytest.approx(0.15)
    assert float(bound(1100, 100)) == pytest.approx(0.1)
    assert float(bound(10**6, 100)) == pytest.approx(0.1)
    # With a delay the anneal starts that many trials after the field was first full.
    delayed = hyper._replace(noise_anneal_delay=jnp.asarray(2000.0))
    assert float(bound(2100, 100, delayed)) == pytest.approx(0.2)
    assert float(bound(2600, 100, delayed)) == pytest.approx(0.15)
    assert float(bound(3100, 100, delayed)) == pytest.approx(0.1)

    # In a rollout, full_at records the trial count when the distance first reaches its maximum, once.
    cfg = tiny()
    hi = float(curriculum.bounds(task.geometry(cfg))[1])
    cond, hyper = protocol.make_plan("none", cfg), default_hyper(cfg)
    start = init_learner(jax.random.PRNGKey(0), cond, cfg)
    assert int(start.env.curriculum.full_at) == -1
    one, many = make_trace(cfg, 1), make_trace(cfg, 300)
    at_top = start.replace(
        env=start.env.replace(
            curriculum=start.env.curriculum.replace(distance=jnp.asarray(hi)), trials=jnp.asarray(7, jnp.int32)
        )
    )
    reached = one(at_top, cond, hyper)[0]
    assert int(reached.env.curriculum.full_at) == 7
    later, info = many(reached, cond, hyper)
    assert np.any(info.out_of_range | info.cap)  # failures moved the distance down, and full_at stayed
    assert float(later.env.curriculum.distance) < hi and int(later.env.curriculum.full_at) == 7
    full_cfg = dataclasses.replace(cfg, task=dataclasses.replace(cfg.task, curriculum_init_cells=cfg.sensor.n_cells))
    cond = protocol.make_plan("none", full_cfg)  # the plan's geometry holds the initial distance
    assert int(init_learner(jax.random.PRNGKey(0), cond, full_cfg).env.curriculum.full_at) == 0

    # The rollout explores within the annealed bound: full from the start, halved after one trial.
    annealed = dataclasses.replace(
        full_cfg, learner=dataclasses.replace(EQ2.learner, noise_final_ratio=0.5, noise_anneal_trials=1)
    )
    start = init_learner(jax.random.PRNGKey(0), cond, annealed)
    start = start.replace(env=start.env.replace(trials=jnp.asarray(1, jnp.int32)))
    hyper = default_hyper(annealed)
    rnd = np.abs(np.asarray(make_trace(annealed, 200)(start, cond, hyper)[1].rnd))
    assert rnd.max() <= 0.5 * annealed.learner.noise and rnd.max() > 0.45 * annealed.learner.noise


def test_frozen_after_budget():
    cfg = tiny(trials=1)
    group = batch.init_batch(cfg)
    chunk = make_chunk(cfg, 400)
    states, log = chunk(group.states, group.plans, group.hypers, jnp.array(1))
    assert log is None  # no per-trial log unless train.trial_log_every asks
    assert int(states.env.trials[0]) == 1
    again, _ = chunk(jax.tree.map(jnp.copy, states), group.plans, group.hypers, jnp.array(1))
    chex.assert_trees_all_equal(again.agent.params, states.agent.params)
    assert int(again.counters.steps[0]) == int(states.counters.steps[0])


def test_a_fresh_batch_has_the_types_that_a_chunk_returns():
    # A weak-typed leaf in the fresh state made the second chunk of every run compile the loop again. Shape, dtype
    # and weak type are compared: the rest of jax.typeof (its abstract sharding) differed once between two test
    # workers that share one compilation cache, which says nothing about the fresh state.
    cfg = tiny()
    group = batch.init_batch(cfg)

    def types(tree):
        return [(a.shape, a.dtype, jax.typeof(a).weak_type) for a in jax.tree.leaves(tree)]

    states, _ = make_chunk(cfg, 400)(group.states, group.plans, group.hypers, jnp.array(10**6))
    assert types(group.states) == types(states)


def test_matvec2_rounds_as_the_dot_it_replaced():
    # fields.matvec2 stands for 2x2 @ (2,) products inside the compiled step; it must round as XLA's dot did,
    # or every committed run would stop being reproducible. Float32, jitted and vmapped as in the step.
    rng = np.random.default_rng(0)
    a = jnp.asarray(rng.standard_normal((20_000, 2, 2)), jnp.float32)
    v = jnp.asarray(rng.standard_normal((20_000, 2)), jnp.float32)
    fused = jax.jit(jax.vmap(fields.matvec2))(a, v)
    dot = jax.jit(jax.vmap(jnp.matmul))(a, v)
    np.testing.assert_array_equal(np.asarray(fused), np.asarray(dot))


@pytest.mark.slow
def test_batched_chunk_matches_pure_single_learner_train():
    cfg = tiny(conditions=("none", "viscous", "random", "random_nopast"), seeds=2)
    n_steps = 60
    group = batch.init_batch(cfg)
    chunked, _ = make_chunk(cfg, n_steps)(group.states, group.plans, group.hypers, jnp.array(10**6))
    keys = jnp.stack([batch.learner_key(cfg.train.seed, s) for _, s in batch.learner_table(cfg.train)])
    pure = jax.jit(jax.vmap(train.make_train(cfg, n_steps)))(keys, group.plans, group.hypers)
    # Same learner, same draws: batching may only reorder float32 sums.
    chex.assert_trees_all_close(pure.agent.params, chunked.agent.params, rtol=1e-4, atol=1e-6)
    np.testing.assert_array_equal(np.asarray(pure.env.trials), np.asarray(chunked.env.trials))
    # Seed s starts from the same weights in every condition; conditions then drive them apart.
    first = jax.tree.leaves(jax.vmap(lambda k: network.init_params(k, cfg))(keys[::2]))[0]
    np.testing.assert_array_equal(first[0], first[1])
    moved = [float(jnp.abs(a[0] - a[2]).max()) for a in jax.tree.leaves(chunked.agent.params)]
    assert max(moved) > 0


@pytest.mark.slow
def test_padded_hidden_units_stay_inert_and_change_nothing():
    cfg = tiny(conditions=("viscous", "random"))
    group = batch.init_batch(cfg)
    one = jax.tree.map(lambda a: a[0], group.states)
    wide = widen_hidden(one, DEFAULT_SPEED.hidden_pad)
    (w1, b1), (w2, _), _ = network.dense_layers(wide.agent.params)
    assert w1.shape == (n_inputs(cfg), 32) and b1.shape == (32,) and w2.shape == (32, 10)
    assert wide.agent.pending.u1.shape == (32,)
    chex.assert_trees_all_equal(narrow_hidden(wide, cfg), one)
    assert DEFAULT_SPEED.hidden_pad == 8

    @jax.jit
    def learn(state, cond, hyper):
        def body(s, u):
            return rollout.learner_step(s, u, cond, hyper, cfg)[0], None

        return jax.lax.scan(body, state, random_stream.step_uniforms(state.key, state.counters.steps, 2000, cfg))[0]

    cond, hyper = (jax.tree.map(lambda a: a[0], t) for t in (group.plans, group.hypers))
    learned = learn(wide, cond, hyper)
    assert int(learned.env.trials) > 5
    (w1, b1), (w2, _), _ = network.dense_layers(learned.agent.params)
    for pad in (w1[:, 30:], b1[30:], w2[30:], learned.agent.pending.u1[30:]):
        np.testing.assert_array_equal(pad, 0.0)
    assert float(jnp.abs(w1[:, :30] - network.dense_layers(wide.agent.params)[0][0][:, :30]).max()) > 1e-3

    # The padded layout, like the other Speed settings, is a speed choice only: the results are the same bit for bit.
    budget = jnp.array(10**6)
    speeds = [DEFAULT_SPEED] + [
        Speed(**{name: value}) for name, value in (("hidden_pad", 1), ("draw_block", 7), ("donate", False))
    ]

    def run(speed, steps=700):
        return make_chunk(cfg, steps, speed=speed)(
            jax.tree.map(jnp.copy, group.states), group.plans, group.hypers, budget
        )[0]

    runs = [run(speed) for speed in speeds]
    assert network.dense_layers(runs[0].agent.params)[0][0].shape == (2, n_inputs(cfg), 30)
    for speed, other in zip(speeds[1:], runs[1:], strict=True):
        chex.assert_trees_all_equal(runs[0], other, custom_message=str(speed))
    # The dense layer 1 sums the same non-zero terms in another order: equal to float32 rounding, not bit for bit.
    # Learning amplifies a rounding difference from step to step (at most 2.4e-7 after 50 steps, 2e-5 after 700), so
    # the two are compared after 50 steps, by which every layer's weights have moved by 1e-4 or more.
    chex.assert_trees_all_close(run(DEFAULT_SPEED, 50), run(Speed(sparse_layer1=False), 50), rtol=1e-6, atol=1e-6)


def test_cli_rejects_bad_input_in_one_line_and_writes_nothing(tmp_path, capsys):
    a_file = tmp_path / "file"
    a_file.write_text("x")
    commented = tmp_path / "comment.json"
    commented.write_text('{"comment": 3, "learner": {"lr": 0.5}}')
    cases = [
        ["--trials", "0"],
        ["--trials", "-3"],
        ["--trials", "nan"],
        ["--trials", "ten"],
        ["--trials", "2.5"],
        ["--seeds", "0"],
        ["--hidden-pad", "0"],
        ["--hidden-pad", "1000"],
        ["--conditions", "none,sideways"],
        ["--sweep", "noise_final_ratio=-0.5"],
        ["--sweep", "noise_anneal_delay=-1"],
        ["--sweep", "noise_anneal_trials=-5,1000"],
        ["--sweep", "noise_value_ratio=1.5"],
        ["--sweep", "noise_corr=1"],
        ["--sweep", "actor_baseline=0,2"],
        ["--sweep", "quiet_every=-1"],
        ["--sweep", "quiet_every=2.5"],
        ["--sweep", "noise_value_lo=0.4"],
        ["--sweep", "noise_value_after_full=2"],
        ["--sweep", "no_such_knob=1"],
        ["--set", "learner.no_such_knob=1"],
        ["--keep-every", "-2"],
        ["--out", str(a_file)],
        ["--out", str(a_file / "sub")],
        ["--resume", str(tmp_path / "missing")],
        ["--set", 'arm.dt="fast"'],
        ["--set", "arm.dt=NaN"],
        ["--set", "arm.length=[0.3]"],
        ["--set", "arm.no_such_field=1"],
        ["--set", "nosection.x=1"],
        ["--set", "train.trials=0"],
        ["--set", "learner.noise=-1"],
        ["--config", str(a_file)],
        ["--config", str(tmp_path / "missing.json")],
        ["--config", str(commented)],
    ]
    for argv in cases:
        out_dir = ["--out", str(tmp_path / "run")] if "--out" not in argv and "--resume" not in argv else []
        status = train_cli.main([*argv, *out_dir, "--quiet"])
        err = capsys.readouterr().err
        assert status == errors.EXIT_USAGE, argv
        assert err.count("\n") == 1 and err.startswith("python -m reach_jax.train: error:"), (argv, err)
        assert "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["comment.json", "file"]


def test_config_file_set_and_flags_build_the_config_in_that_order_through_from_dict(tmp_path):
    data = to_dict(Config())
    data["task"]["goal_speed"] = 0.2
    data["train"].update(trials=70, seeds=3)
    path = tmp_path / "cfg.json"
    path.write_text(json.dumps(data))
    cfg = train_cli.parse(["--config", str(path), "--set", "train.seeds=4", "--out", str(tmp_path / "r")]).cfg
    assert (cfg.task.goal_speed, cfg.train.trials, cfg.train.seeds) == (0.2, 70, 4)
    cfg = train_cli.parse(
        ["--config", str(path), "--set", "train.seeds=4", "--seeds", "5", "--out", str(tmp_path / "r")]
    ).cfg
    assert cfg.train.seeds == 5
    # A hand-written file may hold a few fields, no version and a comment for its reader; the rest are the defaults.
    path.write_text(json.dumps({"comment": ["why", "this"], "learner": {"lr": 0.5}}))
    cfg = train_cli.parse(["--config", str(path), "--out", str(tmp_path / "r")]).cfg
    assert cfg == dataclasses.replace(Config(), learner=dataclasses.replace(LearnerConfig(), lr=0.5))
    # --set takes an int for a float field, as from_dict does, and checks the result the same way.
    assert train_cli.parse(["--set", "arm.dt=1", "--out", str(tmp_path / "r")]).cfg.arm.dt == 1.0
    with pytest.raises(errors.UsageError, match="arm.length"):
        train_cli.parse(["--set", "arm.length=[1, 2, 3]", "--out", str(tmp_path / "r")])
    assert not (tmp_path / "r").exists()


def test_a_sweep_is_one_batch_of_learners_with_their_own_anneal(tmp_path):
    argv = ["--trials", "30", "--seeds", "2", "--conditions", "none", "--chunk-steps", "300", "--noise", "0.2"]
    sweep = ["--sweep", "noise_final_ratio=0.5,1", "--sweep", "noise_anneal_delay=0,5"]
    sweep += ["--sweep", "noise_anneal_trials=10"]
    cfg = train_cli.parse([*argv, *sweep, "--out", "/nonexistent-parse-only"]).cfg
    table, hypers = batch.learner_table(cfg.train), batch.learner_hypers(cfg)
    assert len(table) == len(hypers) == 2 * 2 * 2  # ratios x delays x seeds
    assert [s for _, s in table] == [0, 1] * 4
    assert {(h["noise_final_ratio"], h["noise_anneal_delay"]) for h in hypers} == {(0.5, 0), (0.5, 5), (1, 0), (1, 5)}
    group = batch.init_batch(cfg)
    # Seed s starts from the same weights at every sweep point.
    w = np.asarray(group.states.agent.params["params"]["Dense_0"]["kernel"])
    np.testing.assert_array_equal(w[0], w[2])
    assert not np.array_equal(w[0], w[1])
    out = tmp_path / "run"
    assert train_cli.main([*argv, *sweep, "--out", str(out), "--quiet"]) == 0
    rows = run_dir_io.read_metrics(out)
    last = [r for r in rows if r["chunk"] == max(q["chunk"] for q in rows)]
    for r in last:
        assert r["noise_final_ratio"] in (0.5, 1) and r["noise_anneal_trials"] == 10
        if r["noise_final_ratio"] == 1:
            assert r["exploration"] == pytest.approx(0.2)


def test_metrics_rows_read_the_batchs_hyperparameters_spelled_as_the_config():
    cfg = tiny(seeds=2, conditions=("none",))
    group = batch.init_batch(cfg)
    hypers = group.hypers._replace(noise=jnp.asarray([0.213, 0.35], jnp.float32))
    rows = train.metrics_rows(jax.device_get(group.states), hypers, batch.learner_table(cfg.train), 1, 0.0, cfg)
    assert [r["noise"] for r in rows] == [0.213, 0.35]  # the batch's, not the config's 0.2 twice
    assert rows[1]["exploration"] == 0.35  # not annealed yet: the batch's bound, at its float32 precision
    first = json.dumps({k: rows[0][k] for k in hyper.NAMES})
    spelled = {**batch.learner_hypers(cfg)[0], "noise": 0.213}
    assert first == json.dumps(spelled)  # 0.213 and 300000, not 0.21299999952 or 300000.0


def test_chunk_members_shrink_to_the_unfinished_learners():
    trials = np.array([10, 3, 10, 10, 2, 10, 10, 10])
    np.testing.assert_array_equal(train.chunk_members(trials, 10), [1, 4])
    np.testing.assert_array_equal(train.chunk_members(trials, 11), np.arange(8))
    np.testing.assert_array_equal(train.chunk_members(np.array([1, 10, 1, 1, 10, 10]), 10), [0, 1, 2, 3])
    assert len(train.chunk_members(np.full(5, 10), 10)) == 0


@pytest.mark.slow
def test_a_learner_ends_the_same_whatever_its_batch(tmp_path):
    # Learners finish their trials in different chunks, so the batch shrinks in the tail; each learner must end
    # exactly as it does when trained alone.
    argv = ["--trials", "40", "--chunk-steps", "300", "--quiet"]
    assert train_cli.main([*argv, "--seeds", "3", "--conditions", "none,random", "--out", str(tmp_path / "all")]) == 0
    rows = run_dir_io.read_metrics(tmp_path / "all")
    finish = {r["learner"]: r["chunk"] for r in rows if r["trials"] >= 40 and r["chunk_trials"] > 0}
    assert len(set(finish.values())) > 1  # the tail ran with fewer learners
    cfg = run_dir_io.read_config(tmp_path / "all")
    whole, _ = run_dir_io.load_batch(tmp_path / "all", cfg)
    assert train_cli.main([*argv, "--seeds", "2", "--conditions", "random", "--out", str(tmp_path / "one")]) == 0
    alone, _ = run_dir_io.load_batch(tmp_path / "one", run_dir_io.read_config(tmp_path / "one"))
    for i in range(2):
        got = jax.tree.map(lambda a, i=i: np.asarray(a)[3 + i], without_stats(whole.states))
        want = jax.tree.map(lambda a, i=i: np.asarray(a)[i], without_stats(alone.states))
        chex.assert_trees_all_equal(got, want)


def test_cli_run_writes_config_metrics_and_checkpoints(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["--trials", "2e1", "--seeds", "1", "--conditions", "none,random_nopast", "--chunk-steps", "300"]
    assert train_cli.main([*argv, "--out", str(out), "--quiet"]) == 0
    cfg = run_dir_io.read_config(out)
    assert cfg.train.trials == 20 and cfg.train.conditions == ("none", "random_nopast")
    assert cfg == tiny(conditions=("none", "random_nopast"), chunk_steps=300)
    rows = run_dir_io.read_metrics(out)
    chunks = max(r["chunk"] for r in rows)
    assert len(rows) == 2 * chunks
    need = {"trials", "steps", "success_rate", "mean_trial_steps", "distance_m", "n_max", "condition", "seed"}
    assert all(need <= set(r) for r in rows)
    assert all(r["trials"] >= 20 for r in rows if r["chunk"] == chunks)
    group, chunk = run_dir_io.load_batch(out, cfg)
    assert chunk == chunks
    np.testing.assert_array_equal(
        np.asarray(group.states.env.trials), [r["trials"] for r in rows if r["chunk"] == chunks]
    )
    assert train_cli.main([*argv, "--out", str(out), "--quiet"]) == errors.EXIT_USAGE
    assert "--resume" in capsys.readouterr().err


@pytest.mark.slow
def test_the_compiled_fresh_batch_is_the_op_by_op_one_bit_for_bit():
    # Every run before the fresh batch was compiled began from the op-by-op one; a batch of every kind of learner
    # (each condition, a protocol, two seeds, moved and scaled visual fields) must begin from the same bits.
    cfg = from_partial(
        {
            "train": {
                "trials": 45_000,  # the adaptation protocol's length
                "seeds": 2,
                "protocols": ["adaptation"],
                "zip_grids": True,
                "sensor_dx_grid": [0.0, 0.15],
                "sensor_scale_grid": [1.0, 0.75],
            }
        }
    )
    compiled = batch.fresh_states(cfg)
    with jax.disable_jit():
        op_by_op = batch.fresh_states(cfg)
    assert len(jax.tree.leaves(compiled)) == len(jax.tree.leaves(op_by_op))
    for a, b in zip(jax.tree.leaves(compiled), jax.tree.leaves(op_by_op), strict=True):
        a, b = np.asarray(a), np.asarray(b)
        assert a.dtype == b.dtype and a.shape[0] == 20  # 5 names x 2 grid points x 2 seeds
        np.testing.assert_array_equal(a.view(np.uint8), b.view(np.uint8))
