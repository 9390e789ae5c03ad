"""Protocols: blocks switch at trial boundaries, catch trials come at their rate, frozen blocks keep the weights,
networks start from another run, the per-trial log, its adaptation analysis, and resume after SIGKILL."""

from __future__ import annotations

import json

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from reach_jax import errors, evaluate, train
from reach_jax.config import condition, from_partial
from reach_jax.engine import batch
from reach_jax.engine.chunk import make_chunk
from reach_jax.env import protocol
from reach_jax.evaluate import adaptation
from reach_jax.store import checkpoint
from reach_jax.store import run_dir as run_dir_io
from reach_jax.train import cli as train_cli

SWITCH = [
    {"trials": 7, "condition": "none"},
    {"trials": 11, "condition": "viscous"},
    {"trials": 40, "condition": "random", "learning": False},
]


def config(blocks, trials=None, **train):
    """A config whose learners run the protocol `blocks` (named "p"), with 0.2 s trials, logging every trial."""
    total = sum(b["trials"] for b in blocks)
    return from_partial(
        {
            "task": {"max_trial_time": 0.2},
            "protocols": {"p": blocks},
            "train": {
                "trials": trials or total,
                "conditions": [],
                "protocols": ["p"],
                "seeds": 2,
                "trial_log_every": 1,
                "chunk_steps": 700,
                **train,
            },
        }
    )


def test_blocks_switch_on_their_trial():
    cfg = config(SWITCH)
    plan = protocol.make_plan("p", cfg)
    pick = jax.jit(lambda trial, draw: protocol.trial_condition(plan, trial, draw))
    viscous = np.asarray(condition(cfg, "viscous").viscous, np.float32)
    for trial, block, field, learning in ((0, 0, 0.0, True), (6, 0, 0.0, True), (7, 1, 1.0, True), (17, 1, 1.0, True)):
        cond, got = pick(jnp.int32(trial), jnp.float32(0.5))
        assert int(got.index) == block and bool(got.learning) == learning and not bool(got.catch)
        np.testing.assert_array_equal(np.asarray(cond.field.viscous), field * viscous)
    cond, got = pick(jnp.int32(18), jnp.float32(0.5))
    assert int(got.index) == 2 and not bool(got.learning) and float(cond.field.random[0]) == 8.0
    assert int(pick(jnp.int32(10**9), jnp.float32(0.5))[1].index) == 2  # past the end: the last block goes on

    # In the compiled chunk every logged trial ran in the block its index falls in.
    group = batch.init_batch(cfg)
    states, log = make_chunk(cfg, 700)(group.states, group.plans, group.hypers, jnp.int32(cfg.train.trials))
    records = train.trial_records(log, np.arange(2), 1)
    assert len(records["trial"]) > 2 * 20
    ends = np.cumsum([b["trials"] for b in SWITCH])
    np.testing.assert_array_equal(records["block"], np.searchsorted(ends, records["trial"], side="right"))
    for i in range(2):
        mine = records["trial"][records["learner"] == i]
        np.testing.assert_array_equal(mine, np.arange(len(mine)))  # every trial, in order, from the first
    assert set(records["outcome"]) <= {0.0, 1.0, 2.0}
    np.testing.assert_allclose(records["duration_s"], np.round(records["duration_s"] / cfg.arm.dt) * cfg.arm.dt)


def test_a_frozen_block_keeps_the_weights_and_a_learning_one_changes_them():
    outs = []
    for learning in (False, True):
        cfg = config([{"trials": 1000, "condition": "none", "learning": learning}])
        group = batch.init_batch(cfg)
        states, _ = make_chunk(cfg, 300)(
            jax.tree.map(jnp.copy, group.states), group.plans, group.hypers, jnp.int32(1000)
        )
        assert int(states.env.trials.min()) > 10
        outs.append((group.states.agent.params, states.agent.params))
    chex.assert_trees_all_equal(*outs[0])
    assert not all(np.array_equal(a, b) for a, b in zip(*(jax.tree.leaves(p) for p in outs[1]), strict=True))


def test_catch_trials_come_at_their_rate_in_the_catch_condition():
    rate = 0.25
    cfg = config([{"trials": 10**5, "condition": "viscous", "catch": rate, "catch_condition": "none"}], trials=10**5)
    plan = protocol.make_plan("p", cfg)
    cond, block = protocol.trial_condition(plan, jnp.int32(3), jnp.float32(0.2))
    assert bool(block.catch) and not np.asarray(cond.field.viscous).any()
    cond, block = protocol.trial_condition(plan, jnp.int32(3), jnp.float32(0.3))
    assert not bool(block.catch) and np.asarray(cond.field.viscous).any()

    group = batch.init_batch(cfg)
    _, log = make_chunk(cfg, 6000)(group.states, group.plans, group.hypers, jnp.int32(10**5))
    catch = train.trial_records(log, np.arange(2), 1)["catch"]
    n = len(catch)
    assert n > 1000  # enough trials that 4 standard deviations are under 0.06
    # Binomial: 4 standard deviations.
    assert abs(catch.mean() - rate) < 4 * np.sqrt(rate * (1 - rate) / n), (catch.mean(), n)


TWO_BLOCKS = [{"trials": 30, "condition": "none"}, {"trials": 30, "condition": "viscous", "catch": 0.3}]


def protocol_argv(tmp_path):
    path = tmp_path / "protocol.json"
    path.write_text(json.dumps({"protocols": {"two": TWO_BLOCKS}}))
    return [
        "--config",
        str(path),
        "--protocol",
        "two",
        "--seeds",
        "1",
        "--chunk-steps",
        "300",
        "--trial-log-every",
        "1",
    ]


@pytest.mark.slow
def test_a_two_block_protocol_resumes_bit_identically_after_sigkill(tmp_path, train_until_killed):
    argv = protocol_argv(tmp_path)
    whole = tmp_path / "whole"
    assert train_cli.main([*argv, "--out", str(whole), "--quiet"]) == 0
    assert run_dir_io.read_config(whole).train.trials == 60  # the protocol's length

    out = tmp_path / "killed"
    train_until_killed(argv, out)
    assert train_cli.main(["--resume", str(out), "--quiet"]) == 0

    final, want = (checkpoint.list_checkpoints(r)[-1] for r in (out, whole))
    assert final.name == want.name
    with np.load(final) as a, np.load(want) as b:
        for k in b.files:
            if k != "__meta__":
                np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    got, expected = run_dir_io.read_trials(out), run_dir_io.read_trials(whole)
    for k in expected:
        np.testing.assert_array_equal(got[k], expected[k], err_msg=k)
    assert len(expected["trial"]) == 60 and set(expected["block"]) == {0.0, 1.0}
    assert expected["catch"][expected["block"] == 0].sum() == 0 < expected["catch"][expected["block"] == 1].sum()


@pytest.mark.slow
def test_networks_start_from_another_run_and_a_missing_one_is_a_one_line_error(tmp_path, capsys):
    source = tmp_path / "source"
    argv = ["--trials", "30", "--seeds", "2", "--conditions", "none,random", "--chunk-steps", "300", "--quiet"]
    assert train_cli.main([*argv, "--out", str(source)]) == 0
    out = tmp_path / "adapt"
    protocol_args = protocol_argv(tmp_path)
    assert (
        train_cli.main([*protocol_args, "--init-from", str(source), "--keep-every", "1", "--out", str(out), "--quiet"])
        == 0
    )
    src, _ = run_dir_io.load_params(source)
    first = run_dir_io.load_batch(out, run_dir_io.read_config(out), checkpoint.checkpoint_path(out, 0))[0]
    # The one learner (seed 0) took the network of condition none, seed 0: learner 0 of the source.
    chex.assert_trees_all_equal(first.states.agent.params, jax.tree.map(lambda a: a[:1], src))
    assert int(first.states.env.trials[0]) == 0
    capsys.readouterr()

    for extra, needle in (
        (["--seeds", "3"], "no network of condition none and seed 2"),
        (["--set", "network.hidden=[20,10]"], "another network section"),
    ):
        bad = tmp_path / "bad"
        status = train_cli.main([*protocol_args, *extra, "--init-from", str(source), "--out", str(bad), "--quiet"])
        err = capsys.readouterr().err
        assert status == errors.EXIT_USAGE and err.count("\n") == 1 and needle in err, err
        assert not bad.exists()


@pytest.mark.parametrize(
    "setting, needle",
    [
        ('protocols.two=[{"trials": 5, "condition": "curl"}]', "protocols.two[0].condition"),
        ('protocols.two=[{"trials": 60, "catch": 1.5}]', "protocols.two[0].catch"),
        ('protocols.none=[{"trials": 60}]', "a condition has that name"),
        ('protocols.two=[{"trials": 60, "speed": 1}]', "protocols.two[0].speed: unknown field"),
        ("train.trials=61", "protocol two lasts 60 trials"),
        ("protocols.two=[]", "expected a list of blocks"),
    ],
)
def test_bad_protocols_are_one_line_errors(setting, needle, tmp_path, capsys):
    status = train_cli.main([*protocol_argv(tmp_path), "--set", setting, "--out", str(tmp_path / "r"), "--quiet"])
    err = capsys.readouterr().err
    assert status == errors.EXIT_USAGE and err.count("\n") == 1 and needle in err, err
    assert not (tmp_path / "r").exists()


def synthetic_log(effects: dict, n_networks: int, rng, per_block: int = 3000) -> tuple[dict, list]:
    """A per-trial log whose field-aligned errors follow `effects` (cm per window), with noise, for the shipped
    adaptation protocol shortened to `per_block` trials a block."""
    cfg = from_partial(
        {
            "protocols": {
                "adaptation": [
                    {"trials": per_block, "condition": "none"},
                    {"trials": per_block, "condition": "viscous", "catch": 0.2},
                    {"trials": per_block, "condition": "none"},
                ]
            },
            "eval": {"adaptation_window": 300},
            "train": {"trials": 3 * per_block, "conditions": [], "protocols": ["adaptation"], "seeds": n_networks},
        }
    )
    field = condition(cfg, "viscous")
    columns = {name: [] for name in run_dir_io.trial_columns()}
    for learner in range(n_networks):
        trial = np.arange(3 * per_block)
        block = trial // per_block
        catch = (block == 1) & (rng.random(len(trial)) < 0.2)
        phase = (trial % per_block) / per_block
        aligned = np.select(
            [block == 0, (block == 1) & catch, block == 1, block == 2],
            [
                effects["baseline"] + 0 * phase,
                effects["catch"] + 0 * phase,
                effects["field_start"] + (effects["field_end"] - effects["field_start"]) * phase,
                effects["washout_start"] * (1 - phase),
            ],
        )
        aligned = aligned + rng.normal(0.0, 0.3, len(trial))
        aim = rng.uniform(-np.pi, np.pi, len(trial))
        values = {
            "learner": np.full(len(trial), learner),
            "trial": trial,
            "chunk": np.ones(len(trial)),
            "block": block,
            "catch": catch,
            "outcome": np.zeros(len(trial)),
            "duration_s": np.full(len(trial), 0.5),
            "perp_error_m": aligned / 100.0 * adaptation.field_sign(aim, field),
            "direction_error_rad": np.zeros(len(trial)),
            "aim_rad": aim,
            "distance_m": np.full(len(trial), 0.1),
            "peak_speed": np.full(len(trial), 0.3),
        }
        for name in columns:
            columns[name].append(values[name])
    log = {name: np.concatenate(v).astype(run_dir_io.trial_columns()[name]) for name, v in columns.items()}
    return log, cfg


HUMAN = {"baseline": 0.0, "field_start": 2.0, "field_end": 0.3, "catch": -1.0, "washout_start": -1.5}
NO_FIELD = {"baseline": 0.0, "field_start": 0.0, "field_end": 0.0, "catch": 0.0, "washout_start": 0.0}


def test_the_adaptation_verdicts_follow_the_errors():
    rng = np.random.default_rng(0)
    human, cfg = synthetic_log(HUMAN, 6, rng)
    results = adaptation.analyse(human, batch.learner_table(cfg.train), cfg)["protocols"]["adaptation"]
    assert {v["key"]: v["holds"] for v in results["pattern"]} == {k: True for k, *_ in adaptation.PATTERN}
    deflection = next(v for v in results["pattern"] if v["key"] == "deflected")["difference_cm"]["mean"]
    assert deflection == pytest.approx(2.0 - 0.05 * 1.7, abs=0.1)  # the first 300 of 3000 trials of the ramp
    flat, _ = synthetic_log(NO_FIELD, 6, rng)
    results = adaptation.analyse(flat, batch.learner_table(cfg.train), cfg)["protocols"]["adaptation"]
    assert not any(v["holds"] for v in results["pattern"])
    md = adaptation.markdown({"protocols": {"adaptation": results}}, "synthetic")
    assert md.count("| no |") == len(adaptation.PATTERN)


def test_field_sign_points_along_the_push():
    curl = from_partial({"conditions": {"curl": {"viscous": [[0, 13], [-13, 0]]}}})
    aim = np.linspace(-np.pi, np.pi, 17)
    # A curl field F = B v with B = [[0, 13], [-13, 0]] pushes every movement to its right.
    np.testing.assert_array_equal(adaptation.field_sign(aim, condition(curl, "curl")), -1.0)
    viscous = condition(curl, "viscous")
    u = np.stack([np.cos(aim), np.sin(aim)], 1)
    push = u @ np.asarray(viscous.viscous).T
    left = np.einsum("ij,ij->i", np.stack([-u[:, 1], u[:, 0]], 1), push)
    np.testing.assert_array_equal(adaptation.field_sign(aim, viscous), np.sign(left))


@pytest.mark.slow
def test_a_protocol_run_evaluates_into_adaptation_files(tmp_path):
    out = tmp_path / "run"
    assert (
        train_cli.main([*protocol_argv(tmp_path), "--set", "eval.adaptation_window=5", "--out", str(out), "--quiet"])
        == 0
    )
    results = evaluate.evaluate(out)
    p = results["adaptation"]["protocols"]["two"]
    assert p["field_block"] == 1 and p["control"] is None and len(p["networks"]) == 1
    assert [v["key"] for v in p["pattern"]] == [k for k, *_ in adaptation.PATTERN]
    assert all(v["holds"] is None for v in p["pattern"])  # one network: no interval
    for name in ("adaptation.json", "adaptation.md", "adaptation.png"):
        assert (out / evaluate.EVAL_DIR / name).stat().st_size > 0
    log = run_dir_io.read_trials(out)
    assert set(log) == set(run_dir_io.trial_columns())
    np.testing.assert_array_equal(log["trial"], np.arange(60))  # every trial of the one learner, once, in order
