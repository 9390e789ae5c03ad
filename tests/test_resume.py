"""Long runs that survive interruption: resume, atomic checkpoints, numerics guard, clear errors."""

from __future__ import annotations

import dataclasses
import errno
import json
import os
import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import ARGV, final_arrays, metrics_without_wall, snapshot
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from reach_jax import errors, train
from reach_jax.config import (
    CONFIG_VERSION,
    BlockConfig,
    ConditionConfig,
    Config,
    TrainConfig,
    compat,
    from_dict,
    to_dict,
)
from reach_jax.config.schema import DEFAULT_SPEED, MAX_HIDDEN_PAD, Speed
from reach_jax.engine import batch, native, xla_options
from reach_jax.engine.chunk import make_chunk
from reach_jax.errors import error_line, printable
from reach_jax.store import checkpoint, run_lock
from reach_jax.store import run_dir as run_dir_io
from reach_jax.train import cli as train_cli

# A run of five chunks of one learner (its three trials end in the fifth 70-step chunk at today's defaults).
SHORT, SHORT_CHUNKS = ["--trials", "3", "--seeds", "1", "--conditions", "none", "--chunk-steps", "70"], 5


def cfg_of(argv) -> Config:
    return train_cli.parse([*argv, "--out", "/nonexistent-parse-only"]).cfg


def copy_run(src: Path, dst: Path) -> Path:
    """dst holding a byte copy of every file of the run in src."""
    for p in src.rglob("*"):
        if p.is_file():
            target = dst / p.relative_to(src)
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(p.read_bytes())
    return dst


def edit_meta(path: Path, edit) -> None:
    """Rewrite a checkpoint's JSON `__meta__` entry through edit(meta), which changes it in place."""
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(arrays["__meta__"].tobytes())
    edit(meta)
    arrays["__meta__"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    np.savez(path, **arrays)


def test_resume_after_sigkill_is_bit_identical(uninterrupted, tmp_path, train_until_killed):
    out = tmp_path / "run"
    killed_at = train_until_killed(ARGV, out)
    # The killed holder's lock file stays, but the OS dropped its lock: the run resumes at once.
    assert run_lock.lock_path(out).exists() and run_lock.holder(out) is None
    assert train_cli.main(["--resume", str(out), "--quiet"]) == 0
    name, arrays = final_arrays(out)
    want_name, want = final_arrays(uninterrupted)
    assert name == want_name and name > killed_at.name
    assert arrays.keys() == want.keys()
    for k in want:
        np.testing.assert_array_equal(arrays[k], want[k], err_msg=k)
    assert metrics_without_wall(out) == metrics_without_wall(uninterrupted)
    assert not run_lock.lock_path(out).exists()
    assert len(checkpoint.list_checkpoints(out)) == 1  # finished: its final checkpoint alone


def older_copy(uninterrupted: Path, tmp_path: Path) -> tuple[Path, Path]:
    """A copy of the uninterrupted run without its newest checkpoint, and the checkpoint it would resume from."""
    out = copy_run(uninterrupted, tmp_path / "run")
    *_, older, newest = checkpoint.list_checkpoints(out)
    newest.unlink()
    return out, older


def edit_config(out: Path, edit) -> None:
    """Rewrite a run's config.json through edit(data), which changes it in place."""
    data = json.loads((out / run_dir_io.CONFIG_FILE).read_text())
    edit(data)
    (out / run_dir_io.CONFIG_FILE).write_text(json.dumps(data))


def assert_resumes_to(uninterrupted: Path, out: Path, *flags: str) -> None:
    """Resuming out (with flags) ends in the uninterrupted run's final checkpoint, bit for bit."""
    assert train_cli.main(["--resume", str(out), *flags, "--quiet"]) == 0
    name, arrays = final_arrays(out)
    want_name, want = final_arrays(uninterrupted)
    assert name == want_name
    for k in want:
        np.testing.assert_array_equal(arrays[k], want[k], err_msg=k)


def test_a_checkpoint_from_before_a_new_config_field_resumes_it_at_its_default(uninterrupted, tmp_path):
    out, older = older_copy(uninterrupted, tmp_path)
    # Written (by config version 1) before `train.keep_every` existed: neither the config file nor the checkpoint
    # names it.
    edit_config(out, lambda data: (data["train"].pop("keep_every"), data.update(version=1)))
    edit_meta(older, lambda meta: (meta["config"]["train"].pop("keep_every"), meta["config"].update(version=1)))
    assert_resumes_to(uninterrupted, out)
    # A config of the current version that lacks a field is refused, naming it.
    edit_config(out, lambda data: data.update(version=CONFIG_VERSION))
    assert train_cli.main(["--resume", str(out), "--quiet"]) == errors.EXIT_USAGE


def test_a_run_that_stored_the_retired_hidden_pad_resumes_with_another_pad_bit_identically(uninterrupted, tmp_path):
    out, older = older_copy(uninterrupted, tmp_path)
    # Runs made before the speed settings left the config stored train.hidden_pad = 8.
    edit_config(out, lambda data: data["train"].update(hidden_pad=8) or data.update(version=1))
    edit_meta(older, lambda meta: meta["config"]["train"].update(hidden_pad=8) or meta["config"].update(version=1))
    assert_resumes_to(uninterrupted, out, "--hidden-pad", "1")


def test_a_checkpoint_from_before_a_new_hyperparameter_resumes_it_from_the_config(uninterrupted, tmp_path):
    out, older = older_copy(uninterrupted, tmp_path)
    # Written before the anneal delay was a per-learner hyperparameter: the checkpoint lacks its array.
    with np.load(older) as data:
        arrays = {k: data[k] for k in data.files if k != "['hypers'].noise_anneal_delay"}
    assert len(arrays) < len(np.load(older).files)
    np.savez(older, **arrays)
    assert_resumes_to(uninterrupted, out)


def test_a_resume_under_another_sparse_layer1_is_refused_and_an_unstored_one_means_on(uninterrupted, tmp_path):
    out, older = older_copy(uninterrupted, tmp_path)
    with np.load(older) as data:
        assert json.loads(data["__meta__"].tobytes())["speed"] == {
            "sparse_layer1": True,
            "engine": xla_options.engine(),
            "loop": native.resolve(run_dir_io.read_config(out), DEFAULT_SPEED)[0].engine,
        }
    cfg, dense = run_dir_io.read_config(out), Speed(sparse_layer1=False)
    before = snapshot(out)
    with pytest.raises(checkpoint.CheckpointError, match="speed.sparse_layer1 is True; resuming with False") as exc:
        train.run(cfg, out, resume=True, progress=False, speed=dense)
    assert "\n" not in str(exc.value) and snapshot(out) == before
    # A run stored with it off resumes only with it off.
    edit_meta(older, lambda meta: meta["speed"].update(sparse_layer1=False))
    assert train_cli.main(["--resume", str(out), "--quiet"]) == errors.EXIT_USAGE
    # Checkpoints written before the setting was stored were all made with it on.
    edit_meta(older, lambda meta: meta["speed"].pop("sparse_layer1"))
    with pytest.raises(checkpoint.CheckpointError, match="speed.sparse_layer1"):
        train.prepare(cfg, out, resume=True, speed=dense)
    assert_resumes_to(uninterrupted, out)


def test_a_run_resumes_only_under_the_engine_that_trained_it(uninterrupted, tmp_path, capsys):
    out, older = older_copy(uninterrupted, tmp_path)
    edit_meta(older, lambda meta: meta["speed"].update(engine="cpu-fma"))
    cfg, before = run_dir_io.read_config(out), snapshot(out)
    with pytest.raises(
        checkpoint.CheckpointError, match=f"speed.engine is 'cpu-fma'; resuming with '{xla_options.engine()}'"
    ):
        train.run(cfg, out, resume=True, progress=False)
    # A checkpoint that stored no engine was trained by the code before it, which no longer lives here: the error
    # names the commit that can resume it, in one line, and nothing is written.
    edit_meta(older, lambda meta: meta.pop("speed"))
    before = snapshot(out)
    assert train_cli.main(["--resume", str(out), "--quiet"]) == errors.EXIT_USAGE
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'cpu-fma-kernels'" in err and "c0a0a95" in err, err
    assert snapshot(out) == before
    edit_meta(older, lambda meta: meta.update(speed={"sparse_layer1": True, "engine": xla_options.engine()}))
    assert_resumes_to(uninterrupted, out)


def loop_engine(path: Path) -> str:
    """The step loop's engine that wrote a checkpoint (`Speed.engine`)."""
    with np.load(path) as data:
        return json.loads(data["__meta__"].tobytes())["speed"]["loop"]


@pytest.mark.parametrize("engine", ["jax", "native"])
def test_a_run_resumes_under_either_engine_bit_identically(uninterrupted, tmp_path, engine):
    # The run trained on the default engine (native where it runs); its last chunk on either ends the same.
    out, older = older_copy(uninterrupted, tmp_path)
    assert loop_engine(older) == native.resolve(run_dir_io.read_config(out), DEFAULT_SPEED)[0].engine
    assert_resumes_to(uninterrupted, out, "--engine", engine)
    want = engine if native.resolve(run_dir_io.read_config(out), Speed(engine=engine))[1] is None else "jax"
    assert loop_engine(checkpoint.list_checkpoints(out)[-1]) == want


def test_a_resume_reads_its_checkpoint_once_and_builds_no_fresh_batch(uninterrupted, tmp_path, monkeypatch):
    out, _ = older_copy(uninterrupted, tmp_path)
    calls = {"load": 0, "init_batch": 0, "added_state_defaults": 0}

    def counted(name, real):
        def wrapper(*args, **kwargs):
            calls[name] += 1
            return real(*args, **kwargs)

        return wrapper

    monkeypatch.setattr(checkpoint, "load", counted("load", checkpoint.load))
    monkeypatch.setattr(batch, "init_batch", counted("init_batch", batch.init_batch))
    monkeypatch.setattr(
        run_dir_io, "added_state_defaults", counted("added_state_defaults", run_dir_io.added_state_defaults)
    )
    assert_resumes_to(uninterrupted, out)  # validation, then training, of a run with a chunk left
    # The checkpoint gives every state, its shapes come from tracing, and nothing is made for fields it holds.
    assert calls == {"load": 1, "init_batch": 0, "added_state_defaults": 0}
    # A fresh run from another run's networks reads that run's checkpoint once too.
    argv = ["--trials", "2", "--seeds", "1", "--conditions", "none,random", "--chunk-steps", "300", "--quiet"]
    calls.update(load=0)
    assert train_cli.main([*argv, "--init-from", str(uninterrupted), "--out", str(tmp_path / "from")]) == 0
    assert calls["load"] == 1


def test_a_prepared_run_carries_its_own_settings(uninterrupted, tmp_path):
    prepared = train.prepare(run_dir_io.read_config(uninterrupted), uninterrupted, resume=True)
    assert prepared.chunk == checkpoint.checkpoint_chunk(checkpoint.list_checkpoints(uninterrupted)[-1])
    with pytest.raises(TypeError, match="carries its run_dir"):
        train.run(prepared, tmp_path / "elsewhere")


@pytest.mark.slow
def test_snapshots_are_kept_every_n_chunks_and_a_finished_run_keeps_its_final_checkpoint(tmp_path):
    out = tmp_path / "run"
    assert train_cli.main([*ARGV, "--keep-every", "3", "--out", str(out), "--quiet"]) == 0
    chunks = [checkpoint.checkpoint_chunk(p) for p in checkpoint.list_checkpoints(out)]
    last = max(chunks)
    assert last > 7 and last % 3 != 0
    assert chunks == sorted({c for c in range(last + 1) if c % 3 == 0} | {last})


def test_a_finished_run_keeps_its_final_checkpoint_only(tmp_path):
    out = tmp_path / "run"
    assert train_cli.main([*SHORT, "--out", str(out), "--quiet"]) == 0
    assert [p.name for p in checkpoint.list_checkpoints(out)] == [f"chunk_{SHORT_CHUNKS:07d}.npz"]


def test_a_training_run_keeps_its_newest_two_checkpoints_and_a_finished_one_its_last(tmp_path):
    tree = {"w": np.zeros(2)}
    for chunk in range(5):
        checkpoint.save(tmp_path, chunk, tree, {})
    assert [checkpoint.checkpoint_chunk(p) for p in checkpoint.list_checkpoints(tmp_path)] == [3, 4]
    checkpoint.prune(tmp_path, checkpoint.KEEP_FINISHED)
    assert [checkpoint.checkpoint_chunk(p) for p in checkpoint.list_checkpoints(tmp_path)] == [4]
    for chunk in range(5, 12):
        checkpoint.save(tmp_path, chunk, tree, {}, keep_every=4)
    checkpoint.prune(tmp_path, checkpoint.KEEP_FINISHED, keep_every=4)
    assert [checkpoint.checkpoint_chunk(p) for p in checkpoint.list_checkpoints(tmp_path)] == [4, 8, 11]


def test_metrics_past_the_checkpoint_and_a_torn_gzip_member_are_dropped_on_resume(tmp_path):
    out = tmp_path / "run"
    assert train_cli.main([*SHORT, "--out", str(out), "--quiet"]) == 0
    path = out / run_dir_io.METRICS_FILE
    good, rows = path.read_bytes(), run_dir_io.read_metrics(out)
    assert max(r["chunk"] for r in rows) == SHORT_CHUNKS
    later = [{**r, "chunk": SHORT_CHUNKS + 1} for r in rows if r["chunk"] == SHORT_CHUNKS]
    run_dir_io.append_metrics(out, later)  # a chunk whose checkpoint was never written
    run_dir_io.append_metrics(out, later)
    path.write_bytes(path.read_bytes()[:-7])  # and an append cut short by a kill
    assert run_dir_io.read_metrics(out) == rows + later
    assert train_cli.main(["--resume", str(out), "--quiet"]) == 0
    assert path.read_bytes() == good


def test_corrupt_truncated_and_wrong_version_checkpoints_are_refused(uninterrupted, tmp_path, capsys):
    def broken_copy(name):
        dst = copy_run(uninterrupted, tmp_path / name)
        return dst, checkpoint.list_checkpoints(dst)[-1]

    run, newest = broken_copy("truncated")
    newest.write_bytes(newest.read_bytes()[: newest.stat().st_size // 2])
    cases = [(run, str(newest))]
    run, newest = broken_copy("garbage")
    newest.write_bytes(b"not a checkpoint at all")
    cases.append((run, str(newest)))
    run, newest = broken_copy("version")
    edit_meta(newest, lambda meta: meta.update(format_version=compat.CHECKPOINT_VERSION + 1))
    cases.append((run, "format_version"))
    run, _ = broken_copy("config_version")
    data = json.loads((run / run_dir_io.CONFIG_FILE).read_text())
    data["version"] = 99
    (run / run_dir_io.CONFIG_FILE).write_text(json.dumps(data))
    cases.append((run, "version"))
    run, _ = broken_copy("edited_config")
    data = json.loads((run / run_dir_io.CONFIG_FILE).read_text())
    data["learner"]["lr"] = 0.123
    (run / run_dir_io.CONFIG_FILE).write_text(json.dumps(data))
    cases.append((run, "config.learner.lr"))
    run, newest = broken_copy("stored_config")
    edit_meta(newest, lambda meta: meta["config"]["train"].update(bogus=1))
    cases.append((run, "train.bogus"))
    run, _ = broken_copy("flag_disagrees")
    cases.append((run, "train.trials"))
    for run, must_name in cases:
        before = snapshot(run)
        extra = ["--trials", "151"] if run.name == "flag_disagrees" else []
        assert train_cli.main(["--resume", str(run), *extra, "--quiet"]) == errors.EXIT_USAGE
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and must_name in err, (run.name, err)
        assert snapshot(run) == before


class _Injected:
    """Chunk wrapper that turns learner 1's parameters to NaN on its third call."""

    def __init__(self, real):
        self.real, self.calls = real, 0

    def __call__(self, states, *args):
        states, log = self.real(states, *args)
        self.calls += 1
        if self.calls == 3:
            params = jax.tree.map(lambda x: x.at[1].set(jnp.nan), states.agent.params)
            states = states.replace(agent=states.agent.replace(params=params))
        return states, log


def test_non_finite_learner_stops_the_run_and_keeps_the_last_good_checkpoint(tmp_path, monkeypatch, capsys):
    real = make_chunk
    monkeypatch.setattr(train.loop, "make_chunk", lambda cfg, n, *rest: _Injected(real(cfg, n, *rest)))
    out = tmp_path / "run"
    assert train_cli.main([*ARGV, "--out", str(out), "--quiet"]) == errors.EXIT_NUMERICS
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "learner 1 (condition random, seed 0)" in err
    newest = checkpoint.list_checkpoints(out)[-1]
    assert newest == checkpoint.checkpoint_path(out, 2)
    group, _ = run_dir_io.load_batch(out, run_dir_io.read_config(out))
    assert bool(np.all(np.asarray(train.finite_learners(group.states))))
    assert max(r["chunk"] for r in run_dir_io.read_metrics(out)) == 2


def test_failed_write_stops_cleanly_and_keeps_the_previous_checkpoint(tmp_path, monkeypatch, capsys):
    real_fsync, calls = os.fsync, {"n": 0}

    def failing_fsync(fd):
        # Fail while the fourth checkpoint's temporary file is being flushed.
        if os.readlink(f"/proc/self/fd/{fd}").endswith(".chunk_0000003.npz.tmp"):
            raise OSError(errno.ENOSPC, "No space left on device")
        calls["n"] += 1
        return real_fsync(fd)

    monkeypatch.setattr(os, "fsync", failing_fsync)
    out = tmp_path / "run"
    assert train_cli.main([*ARGV, "--out", str(out), "--quiet"]) == errors.EXIT_IO
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "No space left on device" in err
    newest = checkpoint.list_checkpoints(out)[-1]
    assert newest == checkpoint.checkpoint_path(out, 2)
    run_dir_io.load_batch(out, run_dir_io.read_config(out))


FLAGS = [
    "--trials",
    "--seeds",
    "--conditions",
    "--seed",
    "--chunk-steps",
    "--hidden-pad",
    "--out",
    "--resume",
    "--lr",
    "--noise",
    "--lam",
    "--sweep",
    "--list-hyper",
    "--set",
    "--config",
    "--quiet",
]
VALUES = st.one_of(
    st.text(max_size=12),
    st.sampled_from(
        [
            "0",
            "-1",
            "1e9",
            "2e6",
            "nan",
            "inf",
            "3.5",
            "none,viscous",
            "random_nopast",
            "sideways",
            "task.drift_after=2",
            'arm.dt="x"',
            "learner.lr=1",
            "lr=0.5",
            "noise_corr=0.8,0.2",
            "n_max_clean=true",
            "quiet_every=2.5",
            "lrr=1",
            "x.y=1",
            "train.hidden_pad=4",
            "0.5,1",
            "",
        ]
    ),
    st.integers(-5, 10**10).map(str),
)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(argv=st.lists(st.one_of(st.sampled_from(FLAGS), VALUES), max_size=6))
def test_fuzzed_command_lines_never_crash(argv, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    before = snapshot(tmp_path)
    try:
        inv = train_cli.parse(argv)
    except (errors.UsageError, checkpoint.CheckpointError) as exc:
        assert str(exc) and "\n" not in str(exc)
    except SystemExit as exc:  # --help and friends
        assert exc.code == 0
    else:
        assert isinstance(inv.cfg, Config) and inv.cfg.train.trials >= 1
    assert snapshot(tmp_path) == before


JSONISH = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(), st.floats(allow_nan=True), st.text(max_size=5)),
    lambda children: st.one_of(
        st.lists(children, max_size=4), st.dictionaries(st.text(max_size=12), children, max_size=4)
    ),
    max_leaves=12,
)
SECTIONS = {
    f.name: f.default_factory() for f in dataclasses.fields(Config) if f.name not in ("conditions", "protocols")
}


@settings(max_examples=300, deadline=None)
@example(section="train", field="sensor_dx_grid", value=[True])  # a visual field out of reach, set by a grid
@given(
    section=st.sampled_from(sorted(SECTIONS)),
    field=st.one_of(
        st.text(max_size=8), st.sampled_from([f.name for s in SECTIONS.values() for f in dataclasses.fields(s)])
    ),
    value=JSONISH,
)
def test_fuzzed_config_files_parse_or_fail_with_one_line(section, field, value):
    data = json.loads(json.dumps(to_dict(Config())))
    data[section][field] = value
    try:
        cfg = from_dict(data)
    except ValueError as exc:
        assert str(exc) and "\n" not in str(exc) and printable(field) in str(exc)
    else:
        assert isinstance(cfg, Config)
        assert isinstance(cfg.train, TrainConfig)


def parsed_or_named_one_line_error(data: dict, field: str, name: str) -> Config | None:
    """from_dict(data), or None after checking that it failed with one line naming `field` or `name`."""
    try:
        return from_dict(data)
    except ValueError as exc:
        assert str(exc) and "\n" not in str(exc)
        assert printable(field) in str(exc) or printable(name) in str(exc)
        return None


@settings(max_examples=300, deadline=None)
@given(
    name=st.one_of(st.sampled_from(["none", "viscous", "curl"]), st.text(max_size=6)),
    field=st.one_of(st.text(max_size=8), st.sampled_from([f.name for f in dataclasses.fields(ConditionConfig)])),
    value=JSONISH,
)
def test_fuzzed_conditions_parse_or_fail_with_one_line(name, field, value):
    data = json.loads(json.dumps(to_dict(Config())))
    data["conditions"].setdefault(name, {})[field] = value
    cfg = parsed_or_named_one_line_error(data, field, name)
    assert cfg is None or name in [c.name for c in cfg.conditions]


@settings(max_examples=300, deadline=None)
@given(
    name=st.one_of(st.sampled_from(["adaptation", "none", "mine"]), st.text(max_size=6)),
    field=st.one_of(st.text(max_size=8), st.sampled_from([f.name for f in dataclasses.fields(BlockConfig)])),
    value=JSONISH,
)
def test_fuzzed_protocols_parse_or_fail_with_one_line(name, field, value):
    data = json.loads(json.dumps(to_dict(Config())))
    data["protocols"][name] = [{"trials": 10, "condition": "viscous"}, {field: value}]
    cfg = parsed_or_named_one_line_error(data, field, name)
    assert cfg is None or name in [p.name for p in cfg.protocols]


@settings(max_examples=300, deadline=None)
@given(text=st.text())
def test_error_text_stays_on_one_line_and_escaping_is_idempotent(text):
    once = printable(text)
    assert len(once.splitlines()) <= 1 and printable(once) == once
    assert error_line("prog", text).count("\n") == 1


@pytest.mark.parametrize("field", ["noise", "noise_final_ratio", "noise_anneal_delay", "noise_anneal_trials"])
def test_negative_exploration_settings_are_rejected(field):
    data = json.loads(json.dumps(to_dict(Config())))
    data["learner"][field] = -1 if field.startswith("noise_anneal") else -0.5
    with pytest.raises(ValueError, match=f"learner.{field}: must not be negative"):
        from_dict(data)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--hidden-pad", "0"], "not a whole number in [1, "),
        (["--hidden-pad", str(MAX_HIDDEN_PAD + 1)], "not a whole number in [1, "),
        (["--set", "train.hidden_pad=4"], "no longer a config field"),
    ],
)
def test_hidden_pad_is_a_checked_speed_setting_not_a_config_field(argv, message):
    with pytest.raises(errors.UsageError, match=re.escape(message)):
        train_cli.parse([*ARGV, *argv, "--out", "/nonexistent-parse-only"])
    with pytest.raises(ValueError, match="hidden_pad"):
        Speed(hidden_pad=MAX_HIDDEN_PAD + 1)
    assert "hidden_pad" not in to_dict(Config())["train"]


@pytest.mark.parametrize("run", ["table2_rerun", "adaptation", "screen2"])
def test_committed_checkpoints_of_earlier_state_layouts_load(run):
    """Format 2: runs/table2_rerun stored the learner state flat and before protocols, runs/adaptation flat with
    protocol fields, runs/screen2 grouped, with the trial, its condition, block and curriculum beside the agent.
    None holds the actor's gain, which came later and reads as 1 (what they trained with), nor the drift gate's
    failure share and the chunk counters added with it, which read as a fresh learner's (the share 1, the counters
    0)."""
    root = Path(__file__).resolve().parent.parent / "runs" / run
    loaded = run_dir_io.load(root)
    newest = checkpoint.list_checkpoints(root)[-1]
    with np.load(newest) as data:
        stored = {k: data[k] for k in data.files}
    got = checkpoint.flatten({"states": loaded.batch.states})
    for name, value in got.items():
        old = [a for a in compat.state_aliases(name, 2) if a in stored]
        if old:
            np.testing.assert_array_equal(value, stored[old[0]], err_msg=name)
        else:  # a field added since: the run's own condition, block 0, learning on; the actor's gain, 1; ...
            assert compat.is_added_state_field(name), name
            later = name.endswith(("pending.gain", "curriculum.failure")) or ".counters.stats." in name
            assert run != "screen2" or later, name
    assert "['states'].agent.params['params']['Dense_0']['kernel']" in got
    np.testing.assert_array_equal(np.asarray(loaded.batch.states.agent.pending.gain), 1.0)
    np.testing.assert_array_equal(np.asarray(loaded.batch.states.env.curriculum.failure), 1.0)
    states = loaded.batch.states
    if run == "table2":
        field = np.asarray(states.env.cond.field.viscous)
        want = np.asarray(loaded.batch.conds.field.viscous)
        np.testing.assert_array_equal(field, want)  # each learner's trials run in its own condition
        assert not np.asarray(states.env.block.index).any() and np.asarray(states.env.block.learning).all()


@pytest.mark.slow
@pytest.mark.parametrize(
    "train_cfg",
    [
        {"conditions": ["none", "random_nopast"], "seeds": 2, "drift_gate_grid": [0.0, 0.3]},
        {"conditions": [], "protocols": ["adaptation"], "seeds": 1, "trial_log_every": 5},
    ],
)
def test_a_reader_fills_the_fields_old_checkpoints_lack_as_a_fresh_batch_has_them(train_cfg):
    # The reader takes them from a compiled program that keeps only these leaves, not from a fresh batch built op by
    # op; they must be the same bits (conditions and blocks of a sweep and of a protocol's first block, constants).
    cfg = Config(
        train=TrainConfig(trials=10, **{k: tuple(v) if isinstance(v, list) else v for k, v in train_cfg.items()})
    )
    fresh = checkpoint.flatten({"states": batch.init_batch(cfg).states})
    defaults = run_dir_io.added_state_defaults(cfg)
    assert set(defaults) == {name for name in fresh if compat.is_added_state_field(name)}
    assert any(".env.cond." in name for name in defaults) and any(".env.block." in name for name in defaults)
    for name, value in defaults.items():
        assert value.dtype == fresh[name].dtype and value.shape == fresh[name].shape, name
        np.testing.assert_array_equal(value, fresh[name], err_msg=name)
