"""The metrics log in both forms: old runs' metrics.jsonl and new runs' metrics.jsonl.gz read the same rows; each
learner's fixed columns are written once; a gzip member cut short is dropped on read and on resume; float32
measures are written at float32 precision."""

from __future__ import annotations

import gzip
import json
import shutil
import zlib

import jax
import numpy as np
import pytest

from reach_jax.config import Config, LearnerConfig, TrainConfig, hyper
from reach_jax.engine import batch
from reach_jax.store import checkpoint, metrics_log
from reach_jax.store import run_dir as run_dir_io
from reach_jax.train import metrics

N_LEARNERS, N_CHUNKS = 3, 4


def rows_of(chunk: int) -> list[dict]:
    """Metrics rows of one chunk, shaped as `metrics.metrics_rows` makes them: identity, hyperparameters, measures."""
    return [
        {
            "chunk": chunk,
            "learner": i,
            "condition": ("none", "viscous", "random")[i],
            "seed": i % 2,
            **{name: 300 * i if hyper.BY_NAME[name].integer else 0.2 + i for name in hyper.NAMES},
            "trials": 10 * chunk + i,
            "chunk_trials": 10 if i else 0,
            "success_rate": 7 / 30 if i else None,
            "n_max": 167.82059,
            "wall_s": 1.5 * chunk,
        }
        for i in range(N_LEARNERS)
    ]


ROWS = [r for chunk in range(1, N_CHUNKS + 1) for r in rows_of(chunk)]


def gzip_run(tmp_path):
    """A run directory whose metrics.jsonl.gz holds ROWS, one append a chunk."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    for chunk in range(1, N_CHUNKS + 1):
        run_dir_io.append_metrics(tmp_path, rows_of(chunk))
    return tmp_path / run_dir_io.METRICS_FILE


def members(path) -> list[str]:
    """The texts of a file's gzip members."""
    data, texts = path.read_bytes(), []
    while data:
        d = zlib.decompressobj(metrics_log.GZIP_WBITS)
        texts.append(d.decompress(data).decode())
        data = d.unused_data
    return texts


def test_old_jsonl_and_new_gzip_metrics_read_the_same_rows(tmp_path):
    old, new = tmp_path / "old", tmp_path / "new"
    old.mkdir()
    # An old run's file as the code before metrics.jsonl.gz wrote it: one json.dumps object a line.
    (old / run_dir_io.LEGACY_METRICS_FILE).write_text("".join(json.dumps(r) + "\n" for r in ROWS))
    gzip_run(new)
    assert not (new / run_dir_io.LEGACY_METRICS_FILE).exists()
    for up_to in (np.inf, 2):
        want = [r for r in ROWS if r["chunk"] <= up_to]
        got_old, got_new = run_dir_io.read_metrics(old, up_to), run_dir_io.read_metrics(new, up_to)
        assert got_old == got_new == want
        assert [list(r) for r in got_new] == [list(r) for r in want]  # the columns in their order, too
    # A resumed old run goes on appending JSON lines to its metrics.jsonl, and its file stays as it was.
    before = (old / run_dir_io.LEGACY_METRICS_FILE).read_bytes()
    run_dir_io.append_metrics(old, rows_of(N_CHUNKS + 1))
    assert (old / run_dir_io.LEGACY_METRICS_FILE).read_bytes().startswith(before)
    assert not (old / run_dir_io.METRICS_FILE).exists()
    assert run_dir_io.read_metrics(old) == ROWS + rows_of(N_CHUNKS + 1)


def test_an_old_runs_jsonl_gzipped_reads_the_same_rows_and_resumes_as_a_gzip_log(tmp_path):
    # tools/gzip_metrics.py turns the committed runs' metrics.jsonl into this form.
    src, run = tmp_path / "old.jsonl", tmp_path / "run"
    src.write_text("".join(json.dumps(r) + "\n" for r in ROWS))
    run.mkdir()
    metrics_log.gzip_lines(src, run / run_dir_io.METRICS_FILE, run_dir_io.LEARNER_COLUMNS)
    got = run_dir_io.read_metrics(run)
    assert got == ROWS and [list(r) for r in got] == [list(r) for r in ROWS]  # the columns in their order, too
    assert len(members(run / run_dir_io.METRICS_FILE)) == 1 + N_CHUNKS
    run_dir_io.truncate_metrics(run, 2)
    run_dir_io.append_metrics(run, rows_of(3))
    assert run_dir_io.read_metrics(run) == ROWS[: 3 * N_LEARNERS]
    # A column that a learner's rows do not all share (a resumed run gained it part way) stays in the rows.
    rows = [dict(r) for r in ROWS]
    for r in rows[:N_LEARNERS]:
        del r["noise_corr"]
    src.write_text("".join(json.dumps(r) + "\n" for r in rows))
    metrics_log.gzip_lines(src, tmp_path / "other.gz", run_dir_io.LEARNER_COLUMNS)
    assert metrics_log.read_members(tmp_path / "other.gz") == rows
    head = members(tmp_path / "other.gz")[0]
    assert "noise_corr" not in head and '"lr"' in head


def test_each_learners_fixed_columns_are_written_once_and_put_back(tmp_path):
    path = gzip_run(tmp_path)
    head, *chunks = members(path)
    assert len(chunks) == N_CHUNKS  # one gzip member per append
    (learners,) = [json.loads(line)["learners"] for line in head.splitlines()]
    assert learners == [{k: r[k] for k in run_dir_io.LEARNER_COLUMNS} for r in rows_of(1)]
    for text in chunks:
        columns, *values = map(json.loads, text.splitlines())
        assert columns["columns"][:2] == ["chunk", "learner"]
        assert not set(columns["columns"]) & set(run_dir_io.LEARNER_COLUMNS)
        assert len(values) == N_LEARNERS and all(len(v) == len(columns["columns"]) for v in values)
    assert "viscous" not in "".join(chunks) and head.count("viscous") == 1
    assert run_dir_io.read_metrics(tmp_path) == ROWS
    plain = len("".join(json.dumps(r) + "\n" for r in ROWS).encode())
    assert path.stat().st_size < plain / 2


def test_a_gzip_member_cut_short_is_dropped_wherever_the_kill_fell(tmp_path):
    path = gzip_run(tmp_path)
    whole = path.read_bytes()
    run_dir_io.append_metrics(tmp_path, rows_of(N_CHUNKS + 1))
    last = path.read_bytes()[len(whole) :]
    for cut in range(len(last)):
        path.write_bytes(whole + last[:cut])
        assert run_dir_io.read_metrics(tmp_path) == ROWS, cut
    path.write_bytes(whole + last)
    assert run_dir_io.read_metrics(tmp_path) == ROWS + rows_of(N_CHUNKS + 1)
    # Bytes that are no gzip member are corruption, not a torn append: a one-line error naming the file.
    path.write_bytes(whole + b"not gzip")
    with pytest.raises(checkpoint.CheckpointError, match=f"{path}: corrupt gzip member at byte {len(whole)}"):
        run_dir_io.read_metrics(tmp_path)
    broken = bytearray(whole)
    broken[-6] ^= 0xFF  # the last member's CRC
    path.write_bytes(bytes(broken))
    with pytest.raises(checkpoint.CheckpointError, match="corrupt gzip member"):
        run_dir_io.read_metrics(tmp_path)


def test_resume_truncation_cuts_a_gzip_log_between_members(tmp_path):
    path = gzip_run(tmp_path / "a")
    keep = run_dir_io.read_metrics(tmp_path / "a", 2)
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    (tmp_path / "two").mkdir()
    for chunk in (1, 2):
        run_dir_io.append_metrics(tmp_path / "two", rows_of(chunk))
    two = (tmp_path / "two" / run_dir_io.METRICS_FILE).read_bytes()
    with open(path, "ab") as f:
        f.write(gzip.compress(b'{"columns":["chunk"]}\n[9]\n', mtime=0)[:-3])  # and a torn tail
    run_dir_io.truncate_metrics(tmp_path / "a", 2)
    assert path.read_bytes() == two and run_dir_io.read_metrics(tmp_path / "a") == keep
    run_dir_io.append_metrics(tmp_path / "a", rows_of(3))  # the resumed run appends after them
    assert run_dir_io.read_metrics(tmp_path / "a") == keep + rows_of(3)
    # Nothing past the checkpoint and no torn tail: the file stays as it is; before any chunk only the header stays.
    b = tmp_path / "b" / run_dir_io.METRICS_FILE
    before = b.read_bytes()
    run_dir_io.truncate_metrics(tmp_path / "b", N_CHUNKS)
    assert b.read_bytes() == before
    run_dir_io.truncate_metrics(tmp_path / "b", 0)
    assert run_dir_io.read_metrics(tmp_path / "b") == [] and len(members(b)) == 1
    # A header cut short by a kill (the first append is written whole, by rename, but say it was not): removed.
    b.write_bytes(before[:10])
    run_dir_io.truncate_metrics(tmp_path / "b", 0)
    assert not b.exists()
    run_dir_io.append_metrics(tmp_path / "b", rows_of(1))
    assert run_dir_io.read_metrics(tmp_path / "b") == rows_of(1)


def test_the_old_jsonl_form_still_truncates_as_before(tmp_path):
    path = tmp_path / run_dir_io.LEGACY_METRICS_FILE
    good = "".join(json.dumps(r) + "\n" for r in ROWS if r["chunk"] <= 2)
    later = "".join(json.dumps(r) + "\n" for r in ROWS if r["chunk"] > 2)
    path.write_text(good + later + '{"chunk": ')
    run_dir_io.truncate_metrics(tmp_path, 2)
    assert path.read_text() == good


def test_float32_measures_are_written_as_their_shortest_decimals(tmp_path):
    # A bound of 0.2, which float32 does not hold exactly, as versions 14-15's default.
    cfg = Config(learner=LearnerConfig(noise=0.2), train=TrainConfig(trials=5, seeds=2, conditions=("none",)))
    group = batch.init_batch(cfg)
    states = jax.device_get(group.states)
    rows = metrics.metrics_rows(states, group.hypers, batch.learner_table(cfg.train), 1, 0.0, cfg)
    assert rows[0]["distance_m"] == 0.064 and rows[0]["exploration"] == 0.2 and rows[0]["failure"] == 1.0
    kernel = np.asarray(states.agent.params["params"]["Dense_0"]["kernel"])
    norm = np.linalg.norm(kernel.reshape(len(kernel), -1), axis=1)[0]  # as `mechanism_columns` takes it
    assert norm.dtype == np.float32 and rows[0]["w1_norm"] == float(str(norm)) != float(norm)
    for r in rows:
        for name in ("distance_m", "n_max", "exploration", "failure", "w1_norm", "w2_norm", "w3_norm"):
            assert r[name] == metrics.float32_value(r[name]), name  # the shortest decimal of that float32
    run_dir_io.append_metrics(tmp_path, rows)
    text = gzip.decompress((tmp_path / run_dir_io.METRICS_FILE).read_bytes()).decode()
    assert ",0.064,100.0,0.2," in text and "0.06400000303983688" not in text and "0.20000000298" not in text
    assert run_dir_io.read_metrics(tmp_path) == rows
