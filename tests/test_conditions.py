"""Conditions are data: a user-defined field in JSON trains, evaluates and draws with no Python change."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

from reach_jax import errors, evaluate
from reach_jax.config import (
    CONDITIONS,
    PAPER_CONDITIONS,
    PROTOCOLS,
    Config,
    LearnerConfig,
    ProtocolConfig,
    TaskConfig,
    compat,
    condition,
    from_dict,
    from_partial,
    to_dict,
)
from reach_jax.env import task
from reach_jax.evaluate import claims
from reach_jax.store import run_dir as run_dir_io
from reach_jax.train import cli as train_cli

CURL = [[0.0, 13.0], [-13.0, 0.0]]  # [N s/m], a curl field: the force turns the hand velocity by 90 degrees


def test_a_user_condition_is_added_to_the_shipped_ones_and_round_trips():
    cfg = from_partial({"conditions": {"curl": {"viscous": CURL}, "viscous": {"constant": [1, 2]}}})
    assert [c.name for c in cfg.conditions] == ["none", "viscous", "random", "random_nopast", "viscous_mirror", "curl"]
    assert condition(cfg, "curl").viscous == ((0.0, 13.0), (-13.0, 0.0))
    # A field given for a paper condition changes that field only.
    assert condition(cfg, "viscous").viscous == PAPER_CONDITIONS[1].viscous
    assert condition(cfg, "viscous").constant == (1.0, 2.0) and isinstance(condition(cfg, "viscous").constant[0], float)
    assert from_dict(json.loads(json.dumps(to_dict(cfg)))) == cfg
    field = task.make_condition("curl", cfg).field
    np.testing.assert_array_equal(np.asarray(field.viscous), CURL)
    np.testing.assert_array_equal(np.asarray(field.random), 0.0)


def test_a_stored_force_section_becomes_the_paper_conditions_fields():
    # Configs written before conditions were data held the viscous matrix and the random bound in `force`; they
    # came before the drift-neutral staircase and the recipes of config versions 9 and 12 too.
    old = {"version": 1, "force": {"viscous": [[-10.1, -11.2], [-11.2, 11.1]], "random_amplitude": 8.0}}
    then = compat.CHANGED_DEFAULTS[12]
    task_then = TaskConfig(drift_neutral_when_full=False, **then["task"])
    arm_then = dataclasses.replace(Config().arm, one_link_stop=False)  # the clamp, before config version 13
    want = dataclasses.replace(Config(), learner=LearnerConfig(**then["learner"]), task=task_then, arm=arm_then)

    # The field trained and judged in the frame as applied, before config version 14.
    def as_applied(block):
        return dataclasses.replace(block, condition="viscous") if block.condition == "viscous_mirror" else block

    want = dataclasses.replace(
        want,
        train=dataclasses.replace(want.train, conditions=CONDITIONS),
        eval=dataclasses.replace(want.eval, frames=("viscous", "viscous_mirror")),
        protocols=tuple(ProtocolConfig(p.name, tuple(map(as_applied, p.blocks))) for p in PROTOCOLS),
    )
    assert from_dict(old) == want
    changed = from_dict({"version": 1, "force": {"random_amplitude": 5.0}})
    assert condition(changed, "random").random == (5.0, 5.0) == condition(changed, "random_nopast").random


def test_the_mirrored_field_is_the_paper_field_with_y_reversed():
    # Both readings of the paper's coordinates (model §6): B' = S B S, S = diag(1, -1), the same eigenvalues with the
    # pushing axis mirrored about x, from about 113 degrees to about 67.
    s = np.diag([1.0, -1.0])
    b, mirrored = (np.asarray(condition(Config(), n).viscous) for n in ("viscous", "viscous_mirror"))
    np.testing.assert_array_equal(mirrored, s @ b @ s)
    (lo, hi), vectors = np.linalg.eigh(b)
    (lo_m, hi_m), vectors_m = np.linalg.eigh(mirrored)
    assert (lo, hi) == pytest.approx((lo_m, hi_m)) and hi == pytest.approx(15.9, abs=0.05)
    angle = np.degrees(np.arctan2(vectors[1, 1], vectors[0, 1])) % 180
    angle_m = np.degrees(np.arctan2(vectors_m[1, 1], vectors_m[0, 1])) % 180
    assert angle == pytest.approx(113, abs=1) and angle_m == pytest.approx(180 - angle)
    assert Config().eval.frames == ("viscous_mirror", "viscous")  # the mirrored frame judged first (version 14)


@pytest.mark.parametrize(
    "setting, message",
    [
        (["--conditions", "none,curl"], "train.conditions: must be distinct names from"),
        (["--set", "conditions.curl.viscous=[[0, 1]]"], "conditions.curl.viscous"),
        (["--set", "conditions.curl.constant=[NaN, 0]"], "conditions.curl.constant"),
        (["--set", "conditions.curl.spring=1"], "conditions.curl.spring: unknown field"),
        (["--set", 'eval.test_conditions=["none", "twist"]'], "eval.test_conditions"),
        (["--set", 'eval.frames=["viscous", "twist"]'], "eval.frames"),
        (["--set", "conditions.a,b.constant=[1, 1]"], "without commas or spaces"),
    ],
)
def test_bad_conditions_are_one_line_errors_with_nothing_written(setting, message, tmp_path, capsys):
    out = tmp_path / "run"
    assert train_cli.main(["--trials", "5", *setting, "--out", str(out), "--quiet"]) == errors.EXIT_USAGE
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
    assert not out.exists()


@pytest.mark.slow
def test_a_fifth_condition_trains_and_evaluates_from_a_config_file(tmp_path):
    spec = {
        "conditions": {"curl": {"viscous": CURL}},
        "train": {"trials": 20, "seeds": 1, "conditions": ["none", "curl"], "chunk_steps": 300},
        # A 4 x 4 lattice (the paper's is 8 x 8): 12 pairs instead of 1,040, enough for a condition's way through.
        "eval": {"test_conditions": ["none", "viscous", "curl"], "lattice": 4},
    }
    (tmp_path / "curl.json").write_text(json.dumps(spec))
    run = tmp_path / "run"
    # Each command in its own process, as a user runs them.
    train = ["train", "--config", str(tmp_path / "curl.json"), "--out", str(run), "--quiet"]
    for argv in (train, ["evaluate", str(run)]):
        done = subprocess.run(
            [sys.executable, "-m", f"reach_jax.{argv[0]}", *argv[1:]], capture_output=True, text=True, timeout=600
        )
        assert done.returncode == 0, done.stderr[-3000:]
    loaded = run_dir_io.load(run)
    assert loaded.learners == [("none", 0), ("curl", 0)]
    np.testing.assert_array_equal(np.asarray(loaded.batch.conds.field.viscous[1]), CURL)
    out = run / evaluate.EVAL_DIR
    t2 = json.loads((out / "table2.json").read_text())
    # Every network is also tested in the mirrored frame of the paper's field (eval.frames), a column after the rest;
    # the main files judge the mirrored frame, claims["frames"] the frame as applied.
    assert [(r["learning"], r["test"]) for r in t2["rows"]] == [
        (c, t) for c in ("none", "curl") for t in ("none", "viscous", "curl", "viscous_mirror")
    ]
    claims = json.loads((out / "claims.json").read_text())
    cells = claims["recipes"][0]["cells"]
    assert ("curl", "curl") in {(c["learning"], c["test"]) for c in cells}
    applied = claims["frames"]["viscous"]["recipes"][0]["cells"]  # the field as applied as the paper's column
    assert {(c["learning"], c["test"]) for c in applied} == {(c["learning"], c["test"]) for c in cells}
    assert all(c["paper"] is None for c in cells if "curl" in (c["learning"], c["test"]))
    assert "| curl → curl |" in (out / "table2.md").read_text()
    for name in ("fig4.png", "fig5.png", "learning_curves.png", "impedance.png"):
        assert (out / name).stat().st_size > 10_000


def test_no_claim_is_judged_without_both_of_the_papers_test_conditions():
    row = {"seed": 0, "success": 1000, "out": 0, "fail": 40, "mean_time_s": 1.0}
    rows = [{**row, "learning": learning, "test": "none"} for learning in ("none", "viscous", "random")]
    assert claims.recipe_claims(claims.Cells(rows, 1040), {}, Config()) == []
    both = rows + [{**r, "test": "viscous"} for r in rows]
    assert len(claims.recipe_claims(claims.Cells(both, 1040), {}, Config())) == 4
