"""--multihost: two processes on this machine (gloo collectives, one CPU device each) train exactly as one
process with two devices; process 0 alone writes the run, a killed process stops the other, and the run resumes.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from reach_jax import errors
from reach_jax.engine import distribute
from reach_jax.store import checkpoint
from reach_jax.store import run_dir as run_dir_io
from reach_jax.train import cli as train_cli

# Two learners on two devices; the viscous one finishes first (chunk 6), so the tail runs one learner on each process.
ARGV = ["--trials", "150", "--seeds", "1", "--conditions", "none,viscous", "--chunk-steps", "1000", "--quiet"]
TIMEOUT = 180  # [s] for any one command, so that a hang fails the test instead of stalling the suite
PROG = "python -m reach_jax.train: error:"
# The caller's environment without cluster settings.
ENV = {k: v for k, v in os.environ.items() if k not in distribute.CLUSTER_ENV.values()}


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def command(argv) -> list[str]:
    return [sys.executable, "-m", "reach_jax.train", *argv]


def start_processes(argv, logs: Path, n: int = 2) -> list[subprocess.Popen]:
    """n processes of one run on 127.0.0.1: process 0 is configured by flags, the others by JAX_* variables.

    Their output goes to files in `logs` (a pipe that nobody reads would stall a process, and so all of them).
    """
    address = f"127.0.0.1:{free_port()}"
    logs.mkdir(parents=True, exist_ok=True)
    procs = []
    for i in range(n):
        env, cluster = dict(ENV), f"coordinator={address},num_processes={n},process_id={i},"
        if i:
            env.update(JAX_COORDINATOR_ADDRESS=address, JAX_NUM_PROCESSES=str(n), JAX_PROCESS_ID=str(i))
            cluster = ""
        with open(logs / f"{i}.log", "w") as log:
            cmd = command([*argv, "--multihost", f"{cluster}init_timeout=60", "--devices", "1"])
            procs.append(subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT))
    return procs


def finish(procs: list[subprocess.Popen], logs: Path) -> list[tuple[int, str]]:
    """(exit status, output) of every process; kills them all if one outlives TIMEOUT."""
    deadline = time.monotonic() + TIMEOUT
    try:
        for p in procs:
            p.wait(timeout=max(deadline - time.monotonic(), 1))
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    return [(p.returncode, (logs / f"{i}.log").read_text()) for i, p in enumerate(procs)]


def final_arrays(run_dir: Path) -> tuple[str, dict]:
    path = checkpoint.list_checkpoints(run_dir)[-1]
    with np.load(path) as data:
        return path.name, {k: data[k] for k in data.files}


def metrics_without_wall(run_dir: Path) -> list[dict]:
    rows = run_dir_io.read_metrics(run_dir)
    return [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]


@pytest.mark.slow
def test_two_processes_train_exactly_like_one_process_with_two_devices(tmp_path):
    # Through a fresh start, a SIGKILL of process 1 and a resume, which a run must survive anyway; the reference
    # is the same command in one process with two CPU devices.
    want = tmp_path / "one_process"
    proc = subprocess.run(
        command([*ARGV, "--devices", "2", "--out", str(want)]), env=ENV, capture_output=True, timeout=TIMEOUT
    )
    assert proc.returncode == 0, proc.stderr[-3000:]

    out = tmp_path / "two_processes"
    procs = start_processes([*ARGV, "--out", str(out)], tmp_path / "logs")
    deadline = time.monotonic() + TIMEOUT
    # Checkpoint 3 comes before the viscous learner is done, while both processes hold a slice of the batch.
    while time.monotonic() < deadline and procs[1].poll() is None:
        done = checkpoint.list_checkpoints(out)
        if done and done[-1].name >= checkpoint.checkpoint_path(out, 3).name:
            procs[1].send_signal(signal.SIGKILL)
            break
        time.sleep(0.01)
    (status, output), (killed, _) = finish(procs, tmp_path / "logs")
    assert killed == -signal.SIGKILL, "process 1 finished before it could be killed"
    assert status == errors.EXIT_PEER, output[-3000:]
    assert output.splitlines()[-1].startswith(f"{PROG} lost another process") and "Traceback" not in output

    results = finish(start_processes(["--resume", str(out), "--quiet"], tmp_path / "resumed"), tmp_path / "resumed")
    assert [s for s, _ in results] == [0, 0], results
    assert "run written to" in results[0][1] and "run written to" not in results[1][1]
    (name, arrays), (want_name, want_arrays) = final_arrays(out), final_arrays(want)
    assert name == want_name and arrays.keys() == want_arrays.keys()
    for k in want_arrays:
        np.testing.assert_array_equal(arrays[k], want_arrays[k], err_msg=k)
    assert (out / run_dir_io.CONFIG_FILE).read_bytes() == (want / run_dir_io.CONFIG_FILE).read_bytes()
    assert metrics_without_wall(out) == metrics_without_wall(want)


@pytest.mark.parametrize(
    ("argv", "env", "message"),
    [
        (["--multihost", "process_idd=0"], {}, "'process_idd=0' is not KEY=VALUE (closest: process_id; keys:"),
        (["--multihost", "process_id"], {}, "'process_id' is not KEY=VALUE"),
        (["--multihost", "num_processes=two"], {}, "'two' is not a number"),
        (["--multihost", "num_processes=0"], {}, "not a whole number in [1,"),
        (["--multihost", "init_timeout=0"], {}, "not a whole number in [1,"),
        (["--multihost", "coordinator=localhost"], {}, "'localhost' is not HOST:PORT"),
        (["--multihost", "coordinator=localhost:70000"], {}, "'70000' is not a whole number in [1, 65535]"),
        (["--multihost", "num_processes=2,process_id=2"], {}, "process id 2 is not below"),
        (["--multihost"], {"JAX_NUM_PROCESSES": "2", "JAX_PROCESS_ID": "2"}, "process id 2 is not below"),
        (["--multihost"], {"JAX_PROCESS_ID": "-1"}, "JAX_PROCESS_ID: '-1' is not a whole number"),
        (["--multihost", "process_id=1"], {"JAX_NUM_PROCESSES": "1"}, "process id 1 is not below"),
    ],
)
def test_bad_cluster_settings_fail_in_one_line_and_write_nothing(argv, env, message, tmp_path, monkeypatch, capsys):
    for name in distribute.CLUSTER_ENV.values():
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    assert train_cli.main([*argv, "--out", str(tmp_path / "run"), "--quiet"]) == errors.EXIT_USAGE
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(PROG) and message in err, err
    assert list(tmp_path.iterdir()) == []


def test_multihost_outside_a_cluster_without_settings_fails_in_one_line(tmp_path):
    # jax.distributed.initialize must run before JAX computes, so this one needs a fresh process.
    proc = subprocess.run(
        command(["--multihost", "--out", str(tmp_path / "run")]), env=ENV, capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == errors.EXIT_USAGE, proc.stderr[-3000:]
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith(f"{PROG} cannot join the multi-process run")
    assert list(tmp_path.iterdir()) == []
