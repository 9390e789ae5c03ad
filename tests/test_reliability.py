"""One writer per run directory, readers beside a live run, and runs that stop cleanly on SIGTERM and SIGINT."""

from __future__ import annotations

import io
import os
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import ARGV, final_arrays, metrics_without_wall, snapshot

from reach_jax import errors, evaluate, train
from reach_jax.engine import batch
from reach_jax.engine.chunk import make_chunk
from reach_jax.evaluate import cli as evaluate_cli
from reach_jax.store import checkpoint, run_lock
from reach_jax.store import run_dir as run_dir_io
from reach_jax.train import cli as train_cli
from reach_jax.train import interrupt

HOST = socket.gethostname()
HOLD_AND_SLEEP = "import sys, time\nfrom reach_jax.store import run_lock\nwith run_lock.hold(sys.argv[1]):\n"
HOLD_AND_SLEEP += "    print('held', flush=True)\n    time.sleep(600)\n"


def test_the_lock_names_its_holder_refuses_a_second_and_ends_with_its_process(tmp_path):
    run = tmp_path / "run"
    assert run_lock.holder(run) is None and not run.exists()  # asking writes nothing
    with run_lock.hold(run):
        who = run_lock.holder(run)
        assert who == f"PID {os.getpid()} on host {HOST}"
        with pytest.raises(run_lock.RunLockedError) as exc, run_lock.hold(run):
            pass
        assert str(exc.value) == run_lock.locked_message(run, who) and "\n" not in str(exc.value)
        with pytest.raises(run_lock.RunLockedError):
            run_lock.check_free(run)
    assert not run_lock.lock_path(run).exists() and run_lock.holder(run) is None
    # A holder ended by SIGKILL leaves its file behind, but the OS has dropped its lock: the next one takes it at once.
    child = subprocess.Popen([sys.executable, "-c", HOLD_AND_SLEEP, str(run)], stdout=subprocess.PIPE, text=True)
    assert child.stdout.readline() == "held\n"
    assert run_lock.holder(run) == f"PID {child.pid} on host {HOST}"
    child.kill()
    child.wait()
    child.stdout.close()
    assert run_lock.lock_path(run).exists() and run_lock.holder(run) is None
    with run_lock.hold(run):
        assert run_lock.holder(run) == f"PID {os.getpid()} on host {HOST}"


def test_a_reader_passes_over_a_checkpoint_pruned_under_it_but_not_over_a_corrupt_one(
    uninterrupted, tmp_path, monkeypatch
):
    out = shutil.copytree(uninterrupted, tmp_path / "run")
    newest = checkpoint.list_checkpoints(out)[-1]
    real, listings = checkpoint.list_checkpoints, []

    def listed_then_pruned(run_dir):
        # The first listing names a checkpoint that a live writer prunes before the reader opens it.
        listings.append(real(run_dir) + ([] if listings else [checkpoint.checkpoint_path(out, 10**6)]))
        return listings[-1]

    monkeypatch.setattr(checkpoint, "list_checkpoints", listed_then_pruned)
    assert run_dir_io.load(out).chunk == checkpoint.checkpoint_chunk(newest) and len(listings) == 2
    monkeypatch.undo()
    # A gzip member cut short is an append in flight, of a chunk past every checkpoint.
    rows = run_dir_io.read_metrics(out)
    whole = (out / run_dir_io.METRICS_FILE).read_bytes()
    run_dir_io.append_metrics(out, [{**r, "chunk": 99} for r in rows if r["chunk"] == rows[-1]["chunk"]])
    (out / run_dir_io.METRICS_FILE).write_bytes((out / run_dir_io.METRICS_FILE).read_bytes()[: len(whole) + 30])
    assert run_dir_io.read_metrics(out) == rows
    newest.write_bytes(newest.read_bytes()[:100])
    with pytest.raises(checkpoint.CheckpointError, match="corrupt or truncated"):
        run_dir_io.load(out)


@pytest.fixture(scope="module")
def live_run(tmp_path_factory, train_until):
    """(process, run directory) of the ARGV run, paused by SIGSTOP after checkpoint 2: alive and holding its lock."""
    out = tmp_path_factory.mktemp("live") / "run"
    proc = train_until(ARGV, out, 2, signal.SIGSTOP)
    yield proc, out
    proc.kill()
    proc.communicate()


@pytest.mark.slow
def test_a_second_trainer_on_a_live_run_is_refused_in_one_line_and_writes_nothing(live_run, capsys):
    proc, out = live_run
    before = snapshot(out)
    for argv in (["--resume", str(out)], [*ARGV, "--out", str(out)]):
        assert train_cli.main([*argv, "--quiet"]) == errors.EXIT_USAGE
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and str(out) in err and f"(PID {proc.pid} on host {HOST})" in err, err
    assert snapshot(out) == before


@pytest.mark.slow
def test_evaluate_says_that_a_run_is_live_and_reads_a_whole_checkpoint(live_run, tmp_path, monkeypatch, capsys):
    proc, out = live_run
    evaluated = []
    # The episodes and files are test_evaluate's; here only what is read from the live run matters.
    monkeypatch.setattr(
        evaluate, "evaluate_run", lambda run: evaluated.append(run) or evaluate.Results({"anatomy": {}}, None)
    )
    monkeypatch.setattr(evaluate, "write_results", lambda *args: None)
    monkeypatch.setattr(evaluate_cli.report, "summary_text", lambda *args: "the closing screen")
    monkeypatch.setattr(evaluate_cli.anatomy_report, "headlines", lambda *args, **kw: {})
    assert evaluate_cli.main([str(out), "--out", str(tmp_path / "eval")]) == 0
    note, summary, written = capsys.readouterr().err.splitlines()
    (run,) = evaluated
    assert note == (
        f"python -m reach_jax.evaluate: {out} is still training (PID {proc.pid} on host {HOST}); "
        f"evaluating its checkpoint after chunk {run.chunk}"
    )
    assert run.chunk >= 2 and summary == "the closing screen" and written.startswith("evaluation written")
    assert max(r["chunk"] for r in run.metrics) == run.chunk


@pytest.mark.slow
def test_the_live_run_continued_ends_as_if_alone_while_readers_read_it(live_run, uninterrupted):
    proc, out = live_run
    cfg = run_dir_io.read_config(out)
    fresh = batch.init_batch(cfg)
    template = {"states": fresh.states, "hypers": fresh.hypers}
    proc.send_signal(signal.SIGCONT)
    chunks = []
    while proc.poll() is None:  # checkpoints are pruned under these reads all along
        chunks.append(checkpoint.load_newest(out, template)[1]["chunk"])
        run_dir_io.read_metrics(out, chunks[-1])
    assert proc.wait() == 0 and chunks == sorted(chunks)
    name, arrays = final_arrays(out)
    want_name, want = final_arrays(uninterrupted)
    assert name == want_name and arrays.keys() == want.keys()
    for k in want:
        np.testing.assert_array_equal(arrays[k], want[k], err_msg=k)
    rows = run_dir_io.read_metrics(out)
    assert len({(r["learner"], r["chunk"]) for r in rows}) == len(rows)
    assert metrics_without_wall(out) == metrics_without_wall(uninterrupted)
    assert not run_lock.lock_path(out).exists()


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_signal_checkpoints_and_exits_and_the_resumed_run_is_bit_identical(
    signum, uninterrupted, tmp_path, train_until
):
    out = tmp_path / "run"
    proc = train_until(ARGV, out, 2, signum)
    err = proc.communicate()[1]
    assert proc.returncode == errors.EXIT_INTERRUPTED, err
    chunk = checkpoint.checkpoint_chunk(checkpoint.list_checkpoints(out)[-1])
    assert err.splitlines() == [
        f"python -m reach_jax.train: stopped by {signal.Signals(signum).name} after chunk {chunk}, its checkpoint "
        f"written; resume with: python -m reach_jax.train --resume {shlex.quote(str(out))}"
    ]
    assert max(r["chunk"] for r in run_dir_io.read_metrics(out)) == chunk
    assert train_cli.main(["--resume", str(out), "--quiet"]) == 0
    name, arrays = final_arrays(out)
    want_name, want = final_arrays(uninterrupted)
    assert name == want_name and arrays.keys() == want.keys()
    for k in want:
        np.testing.assert_array_equal(arrays[k], want[k], err_msg=k)
    assert metrics_without_wall(out) == metrics_without_wall(uninterrupted)


def caught_signals(pid: int) -> int:
    """The mask of signals that process `pid` has a handler for (Linux)."""
    status = Path(f"/proc/{pid}/status").read_text()
    return int(next(line.split()[1] for line in status.splitlines() if line.startswith("SigCgt:")), 16)


@pytest.mark.slow
def test_a_second_signal_ends_the_run_at_once(tmp_path, train_until):
    out = tmp_path / "run"
    # Long chunks, so that the first signal finds one in flight and the run is still in it at the second.
    proc = train_until([*ARGV[:-1], "30000"], out, 0, signal.SIGTERM)
    term = 1 << (signal.SIGTERM - 1)
    deadline = time.monotonic() + 120
    while caught_signals(proc.pid) & term and time.monotonic() < deadline:  # until the first has been taken
        time.sleep(0.01)
    proc.send_signal(signal.SIGTERM)
    err = proc.communicate()[1]
    assert proc.returncode == -signal.SIGTERM and "resume with" not in err


class Terminal(io.StringIO):
    """A stream that says it is a terminal, where the bar redraws one line."""

    def isatty(self) -> bool:
        return True


@pytest.mark.slow
def test_an_interrupted_run_ends_the_bars_line_and_puts_the_handlers_back(tmp_path, monkeypatch):
    def signalling_chunk(cfg, n_steps, *rest):
        run, calls = make_chunk(cfg, n_steps, *rest), []

        def chunk(*args):
            calls.append(1)
            if len(calls) == 2:  # while chunk 1 is on the devices, as a SIGINT from the keyboard comes
                os.kill(os.getpid(), signal.SIGINT)
            return run(*args)

        return chunk

    monkeypatch.setattr(train.loop, "make_chunk", signalling_chunk)
    out, bar = tmp_path / "run", Terminal()
    small = ["--trials", "12", "--seeds", "1", "--conditions", "none", "--chunk-steps", "300"]
    cfg = train_cli.parse([*small, "--out", str(out)])
    before = {s: signal.getsignal(s) for s in interrupt.SIGNALS}
    with pytest.raises(interrupt.Interrupted) as exc:
        train.run(cfg.cfg, out, stream=bar)
    assert (exc.value.signum, exc.value.chunk) == (signal.SIGINT, 2)
    assert checkpoint.list_checkpoints(out)[-1] == checkpoint.checkpoint_path(out, 2)
    last = bar.getvalue().split("\r")[-1]
    assert last.startswith("[") and last.endswith("\n") and last.count("\n") == 1 and "done" not in last
    assert {s: signal.getsignal(s) for s in interrupt.SIGNALS} == before
    assert not run_lock.lock_path(out).exists()
