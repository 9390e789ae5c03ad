"""The training command line's flags: the groups of --help, --sweep and --list-hyper over the hyperparameter table,
one stored config for one intent whatever its spelling, and resume under any spelling."""

from __future__ import annotations

import dataclasses
import json
import re
import shlex
import subprocess

import chex
import jax
import numpy as np
import pytest
from conftest import ROOT, committed_runs, final_arrays, snapshot

from reach_jax import errors
from reach_jax.config import Config, LearnerConfig, TrainConfig, compat, hyper
from reach_jax.config.schema import DEFAULT_SPEED
from reach_jax.engine import batch, xla_options
from reach_jax.store import checkpoint
from reach_jax.store import run_dir as run_dir_io
from reach_jax.store.checkpoint import CheckpointError
from reach_jax.train import arguments
from reach_jax.train import cli as train_cli

PROG = "python -m reach_jax.train: error:"
NOWHERE = ["--out", "/nonexistent-parse-only"]


def parsed(*argv: str) -> Config:
    """The config a command line stores, parsed only."""
    return train_cli.parse([*argv, *NOWHERE]).cfg


def with_learner(**fields) -> Config:
    """The default config with these learner fields."""
    return dataclasses.replace(Config(), learner=dataclasses.replace(LearnerConfig(), **fields))


def options(parser) -> list[str]:
    """Every option string of a parser (-h and --help are one option)."""
    return [a.option_strings[-1] for a in parser._actions if a.option_strings]


def test_help_shows_at_most_24_options_in_the_core_and_infrastructure_groups(capsys):
    parser = arguments.build_train_parser()
    assert len(options(parser)) <= 24
    with pytest.raises(SystemExit) as exit_:
        train_cli.main(["--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    listed = set(re.findall(r"^  (?:-h, )?(--[a-z-]+)", text, re.M))
    assert listed == set(options(parser)) and len(listed) <= 24
    groups = {g.title: [a.option_strings[-1] for a in g._group_actions] for g in parser._action_groups}
    core = {"--help", "--config", "--trials", "--seeds", "--conditions", "--protocol", "--seed", "--out", "--resume"}
    core |= {"--set", "--quiet", "--lr", "--noise", "--lam", "--sweep", "--list-hyper"}
    assert set(groups["core"]) == core
    infra = {"--devices", "--chunk-steps", "--keep-every", "--trial-log-every", "--init-from", "--hidden-pad"}
    infra |= {"--engine"}
    assert set(groups["infrastructure"]) == infra | {"--multihost"}
    assert not groups.get("options") and not groups.get("positional arguments")
    # The research knobs of the recipe search have no flag of their own any more.
    assert all(
        f"--{h.name.replace('_', '-')}" not in listed for h in hyper.TABLE if h.name not in ("lr", "noise", "lam")
    )


def test_list_hyper_prints_the_table_and_exits_0_writing_nothing(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_:
        train_cli.main(["--list-hyper", "--trials", "10"])
    assert exit_.value.code == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ["name", "default", "range", "help"]
    assert [line.split()[0] for line in lines[1:]] == list(hyper.NAMES)
    row = {line.split()[0]: line for line in lines[1:]}
    assert row["lam"].split()[1:3] == ["0.999", "(0,"] and "correlation" in row["noise_corr"]
    assert "whole, [0, inf)" in row["quiet_every"] and "(0, inf)" in row["lr"]
    assert row["n_max_clean"].split()[1:3] == ["false", "true/false"]
    assert list(tmp_path.iterdir()) == []


def test_describe_words_a_recipe_from_the_table_naming_only_what_is_set_and_on():
    # Every entry has its words, and a part of a form is named only while that form is on.
    assert all(h.words for h in hyper.TABLE)
    assert all(h.part_of in hyper.BY_NAME and h.part_of != h.name for h in hyper.TABLE if h.part_of)
    assert hyper.describe({}) == "bound 0.25"
    # Float32 values, as a batch stores them, print as their float32 shortest.
    label = {"noise": 0.2, "lr": 1.0, "noise_value_ratio": np.float32(0.5), "drift_gate": np.float32(0.3)}
    assert hyper.describe(label) == "bound 0.2; ×0.5 near the goal; drift only above 0.3 recent failure"
    # Versions 8 and 11 had today's recipe but its bound, which is always said: nothing more against their defaults.
    today = hyper.describe(label)
    assert hyper.describe(label, hyper.defaults(8)) == hyper.describe(label, hyper.defaults(11)) == today
    # Against the defaults of another time (versions 9 and 13: lr 1.6), what differed from them is said, and no more.
    assert (
        hyper.describe(label, hyper.defaults(9))
        == hyper.describe(label, hyper.defaults(13))
        == "bound 0.2; learning rate 1; ×0.5 near the goal; drift only above 0.3 recent failure"
    )
    off = {"noise": 0.1, "noise_anneal_trials": 100_000, "drift_gate_trials": 50, "n_max_clean": 1.0}
    assert hyper.describe(off) == "bound 0.1; N_max from clean successes"
    on = {**off, "noise_final_ratio": 0.5, "drift_gate": 0.2}
    assert hyper.describe(on) == (
        "bound 0.1; annealed to ×0.5; the anneal over 100,000 trials; drift only above 0.2 recent failure; "
        "the failure share over 50 trials; N_max from clean successes"
    )


def test_zipped_grids_pair_point_by_point_and_must_share_a_length():
    # A space-filling design's draws (studies/search): recipe k takes the k-th value of every grid given.
    argv = ["--sweep", "lr=0.5,1,2", "--sweep", "noise=0.15,0.2,0.3", "--seeds", "2", "--conditions", "none,random"]
    crossed, zipped = parsed(*argv), parsed(*argv, "--set", "train.zip_grids=true")
    assert len(batch.hyper_grid(crossed)) == 9 and len(batch.learner_table(crossed.train)) == 9 * 2 * 2
    points = [(h["lr"], h["noise"], h["lam"]) for h in batch.hyper_grid(zipped)]
    assert points == [(0.5, 0.15, 0.999), (1.0, 0.2, 0.999), (2.0, 0.3, 0.999)]  # an unswept one at its default
    assert len(batch.learner_table(zipped.train)) == len(batch.learner_hypers(zipped)) == 3 * 2 * 2
    assert np.asarray(batch.hyper_columns(zipped).noise).tolist() == pytest.approx(
        [0.15] * 2 + [0.2] * 2 + [0.3] * 2 + [0.15] * 2 + [0.2] * 2 + [0.3] * 2
    )
    with pytest.raises(errors.UsageError, match="train.noise_grid: 2 values, but train.lr_grid has 3"):
        parsed("--sweep", "lr=0.5,1,2", "--sweep", "noise=0.1,0.2", "--set", "train.zip_grids=true")
    with pytest.raises(errors.UsageError, match="noise_value_lo: must lie below noise_value_hi in every sweep point"):
        parsed(
            "--sweep", "noise_value_lo=0.1,0.5", "--sweep", "noise_value_hi=0.6,0.4", "--set", "train.zip_grids=true"
        )
    # Crossed, the first pair of grids would fail too (0.5 > 0.4); zipped, each point is judged on its own.
    assert parsed(
        "--sweep", "noise_value_lo=0.1,0.2", "--sweep", "noise_value_hi=0.6,0.4", "--set", "train.zip_grids=true"
    )


def test_sweep_with_one_value_sets_the_learners_default_and_with_several_sweeps_it():
    cfg = parsed("--sweep", "noise_value_ratio=0.5", "--sweep", "quiet_every=3")
    assert cfg == with_learner(noise_value_ratio=0.5, quiet_every=3)
    assert type(cfg.learner.quiet_every) is int
    cfg = parsed("--sweep", "noise_value_ratio=0.5,0.25", "--sweep", "quiet_every=0,2", "--noise", "0.1,0.2")
    assert (cfg.train.noise_value_ratio_grid, cfg.train.quiet_every_grid) == ((0.5, 0.25), (0, 2))
    assert cfg.train.noise_grid == (0.1, 0.2) and cfg.learner == LearnerConfig()
    assert len(batch.learner_hypers(cfg)) == 8 * 2 * 4  # 2 x 2 x 2 sweep points x seeds x the four conditions
    # A switch is a boolean: true/false as well as 1/0, any case.
    on = parsed("--sweep", "n_max_clean=true", "--sweep", "drift_neutral_early=1")
    assert on == with_learner(n_max_clean=1.0, drift_neutral_early=1.0)
    assert parsed("--sweep", "noise_value_after_full=False,TRUE").train.noise_value_after_full_grid == (0.0, 1.0)
    assert parsed("--set", "learner.n_max_clean=true") == with_learner(n_max_clean=1.0)


@pytest.mark.parametrize(
    "spelling",
    [
        ["--lr", "0.5"],
        ["--sweep", "lr=0.5"],
        ["--set", "learner.lr=0.5"],
        ["--set", "train.lr_grid=[0.5]"],
        ["--set", "train.lr_grid=[0.3,0.7]", "--set", "learner.lr=0.5"],  # one value after a grid: that value
    ],
)
def test_one_value_stores_one_config_whatever_its_spelling(spelling):
    cfg = parsed(*spelling)
    assert cfg == with_learner(lr=0.5) and cfg.train.lr_grid == ()


def test_several_values_store_one_config_whatever_their_spelling():
    want = dataclasses.replace(Config(), train=dataclasses.replace(TrainConfig(), lam_grid=(0.99, 0.999)))
    for spelling in (["--lam", "0.99,0.999"], ["--sweep", "lam=0.99,0.999"], ["--set", "train.lam_grid=[0.99,0.999]"]):
        assert parsed(*spelling) == want, spelling


def test_a_one_value_grid_and_the_learners_default_are_the_same_learners():
    grid = dataclasses.replace(Config(), train=dataclasses.replace(TrainConfig(), quiet_every_grid=(3.0,)))
    default = with_learner(quiet_every=3)
    assert batch.learner_table(grid.train) == batch.learner_table(default.train)
    chex.assert_trees_all_equal(batch.hyper_columns(grid), batch.hyper_columns(default))


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--sweep", "noise_valu_ratio=0.5"], "no hyperparameter 'noise_valu_ratio'; closest: noise_value_ratio"),
        (["--sweep", "lrr=0.5"], "closest: lr"),
        (["--sweep", "zzz=1"], "no hyperparameter 'zzz' (--list-hyper lists them)"),
        (["--set", "learner.nosie=0.1"], "learner.nosie: unknown field; closest: noise"),
        (["--sweep", "noise_corr=1"], "noise_corr='1': must lie in [0, 1)"),
        (["--sweep", "noise_value_ratio=0.5,1.5"], "noise_value_ratio='1.5': must lie in [0, 1]"),
        (["--sweep", "quiet_every=2.5"], "quiet_every='2.5': must be a whole number"),
        (["--sweep", "drift_gate_trials=0"], "drift_gate_trials='0': must be positive"),
        (["--sweep", "lam=fast"], "lam='fast' is not a number"),
        (["--sweep", "n_max_clean=yes"], "n_max_clean='yes' is not true, false, 0 or 1"),
        (["--sweep", "n_max_clean=0.5"], "must be 0 or 1"),
        (["--set", "learner.n_max_clean=0.5"], "learner.n_max_clean: must be 0 or 1"),
        (["--sweep", "lr=nan"], "lr='nan': must be positive"),
        (["--sweep", "lr="], "lr='': no value"),
        (["--sweep", "lr"], "'lr' is not NAME=V[,V...]"),
        (["--lr", "-1"], "lr='-1': must be positive"),
        (["--lr", "0.5", "--sweep", "lr=1"], "hyperparameter lr given twice"),
        (["--sweep", "noise_value_lo=0.4"], "must lie below noise_value_hi"),
    ],
)
def test_bad_hyperparameter_names_and_values_fail_in_one_line_and_write_nothing(
    argv, message, tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)  # the default run directory would be under runs/ here
    assert train_cli.main([*argv, "--trials", "20", "--quiet"]) == errors.EXIT_USAGE
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(PROG) and message in err, err
    assert list(tmp_path.iterdir()) == []


def fresh_run(run_dir, cfg: Config) -> None:
    """A run directory as a fresh run leaves it before its first chunk: config.json and checkpoint 0."""
    run_dir_io.create(run_dir, cfg)
    run_dir_io.write_checkpoint(
        run_dir, 0, jax.device_get(batch.init_batch(cfg)), cfg, DEFAULT_SPEED, xla_options.engine()
    )


SPELLINGS = [[], ["--lr", "0.5"], ["--sweep", "lr=0.5"], ["--set", "learner.lr=0.5"], ["--set", "train.lr_grid=[0.5]"]]


@pytest.mark.parametrize("stored", ["learner", "grid"])
def test_a_run_resumes_under_any_spelling_of_its_setting(stored, tmp_path):
    # "grid": as a run made before --lr stored learner.lr (runs/dev_gain and others hold one-value grids).
    cfg = dataclasses.replace(Config(), train=dataclasses.replace(TrainConfig(), trials=20, seeds=1))
    if stored == "grid":
        cfg = dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, lr_grid=(0.5,)))
    else:
        cfg = dataclasses.replace(cfg, learner=dataclasses.replace(cfg.learner, lr=0.5))
    run = tmp_path / "run"
    fresh_run(run, cfg)
    before = snapshot(tmp_path)
    for spelling in SPELLINGS:
        inv = train_cli.parse(["--resume", str(run), *spelling])
        assert inv.prepared.resume and inv.cfg == cfg, spelling  # trains on as stored, bit for bit
    for other in (["--lr", "0.25"], ["--sweep", "lr=0.5,1"], ["--set", "learner.lr=1"]):
        with pytest.raises(errors.OneLineError, match="field (learner.lr|train.lr_grid) is"):
            train_cli.parse(["--resume", str(run), *other])
    assert snapshot(tmp_path) == before


RUNS = committed_runs()


def test_the_committed_runs_are_those_git_tracks_not_a_users_run_beside_them(tmp_path):
    # The README's first command leaves runs/<name>/ with a config and no README; the tests of committed runs
    # (this file's, parametrized over RUNS) must not pick it up.
    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    for name in ("kept", "users"):
        (tmp_path / "runs" / name).mkdir(parents=True)
        (tmp_path / "runs" / name / "config.json").write_text("{}")
    (tmp_path / "runs" / "kept" / "README.md").write_text("# kept")
    subprocess.run(["git", "-C", str(tmp_path), "add", "runs/kept"], check=True)
    assert committed_runs(tmp_path) == ["kept"]
    assert "table2" in RUNS and all((ROOT / "runs" / run / "README.md").is_file() for run in RUNS)


def readme_command(run: str) -> list[str]:
    """The arguments of the training command in runs/RUN/README.md, without --out and --devices (not stored)."""
    text = (ROOT / "runs" / run / "README.md").read_text()
    command = re.search(r"^python -m reach_jax\.train (.*?[^\\])$", text, re.M | re.S)[1]
    argv = shlex.split(command.replace("\\\n", " "))
    for flag in ("--out", "--devices"):
        if flag in argv:
            del argv[argv.index(flag) : argv.index(flag) + 2]
    return argv


def stored_engine(run: str) -> str:
    """The engine that trained a run, as its newest checkpoint says."""
    with np.load(checkpoint.list_checkpoints(f"runs/{run}")[-1]) as data:
        speed = json.loads(data["__meta__"].tobytes()).get("speed", {})
    return speed.get("engine", compat.SPEED_BEFORE_STORED["engine"])


@pytest.mark.parametrize("run", RUNS)
def test_the_committed_runs_resume_bare_and_with_their_readmes_command(run, monkeypatch):
    # Their config.json may hold one-value grids (written before --sweep); their READMEs spell the new flags. Each
    # resumes from its newest checkpoint, or, trained under another engine, is refused for that alone: the engine
    # is checked last, once the checkpoint has been read and its config has matched.
    monkeypatch.chdir(ROOT)
    assert {"table2", "heldout", "heldout_round2"} <= set(RUNS) and len(RUNS) > 10
    newest = checkpoint.checkpoint_chunk(checkpoint.list_checkpoints(f"runs/{run}")[-1])
    for argv in ([], readme_command(run)):
        if stored_engine(run) != xla_options.engine():
            with pytest.raises(CheckpointError, match=f"speed.engine is '{stored_engine(run)}'"):
                train_cli.parse(["--resume", f"runs/{run}", *argv])
            continue
        inv = train_cli.parse(["--resume", f"runs/{run}", *argv])
        assert inv.prepared.resume and inv.cfg == run_dir_io.read_config(f"runs/{run}"), argv
        assert inv.prepared.chunk == newest, argv


@pytest.mark.slow
def test_runs_under_two_spellings_are_one_run_bit_for_bit_and_resume_under_each_others(tmp_path, capsys):
    argv = ["--trials", "40", "--seeds", "1", "--conditions", "none", "--chunk-steps", "300", "--quiet"]
    flags = ["--lr", "0.5", "--sweep", "quiet_every=3"]
    sets = ["--set", "learner.lr=0.5", "--set", "learner.quiet_every=3"]
    a, b = tmp_path / "a", tmp_path / "b"
    assert train_cli.main([*argv, *flags, "--out", str(a)]) == 0
    # The summary names the learners in trouble (tests/test_collapse.py), even with --quiet.
    assert capsys.readouterr().err.splitlines()[-3:] == [
        "python -m reach_jax.train: no learner collapsed or fell back",
        f"run written to {a}",
        f"evaluate it: python -m reach_jax.evaluate {a}",
    ]
    assert train_cli.main([*argv, *sets, "--out", str(b)]) == 0
    assert (a / run_dir_io.CONFIG_FILE).read_bytes() == (b / run_dir_io.CONFIG_FILE).read_bytes()
    (name, got), (want_name, want) = final_arrays(b), final_arrays(a)
    assert name == want_name and got.keys() == want.keys()
    for k in want:
        np.testing.assert_array_equal(got[k], want[k], err_msg=k)
    for run, other in ((a, sets), (b, flags)):
        assert train_cli.main(["--resume", str(run), *other, "--quiet"]) == 0
        assert final_arrays(run)[0] == name
