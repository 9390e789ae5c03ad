"""Test-session setup: the CPU compiler options that the command lines set, before JAX starts; shared fixtures."""

import importlib.util
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from reach_jax.config import hyper
from reach_jax.engine import xla_options
from reach_jax.store import checkpoint
from reach_jax.store import run_dir as run_dir_io
from reach_jax.train import cli

# A small run of 19 chunks for the tests of interrupted and resumed training.
ARGV = ["--trials", "60", "--seeds", "1", "--conditions", "none,random", "--chunk-steps", "300"]


ROOT = Path(__file__).resolve().parent.parent


def committed_runs(root: Path = ROOT) -> list[str]:
    """The names of the runs under root/runs that git tracks (by their config.json), never what a user has trained
    there: a run of the README's first command has no README, and tests of committed runs must not see it."""
    listed = subprocess.run(
        ["git", "ls-files", "-z", "--", "runs/*/config.json"], cwd=root, capture_output=True, text=True, check=True
    ).stdout
    return sorted(Path(p).parent.name for p in listed.split("\0") if p and len(Path(p).parts) == 3)


def snapshot(folder: Path) -> dict:
    """Every file under folder with its size and modification time."""
    return {str(p): (p.stat().st_size, p.stat().st_mtime_ns) for p in sorted(folder.rglob("*")) if p.is_file()}


def final_arrays(run_dir: Path) -> tuple[str, dict]:
    """The name and the arrays of a run's newest checkpoint."""
    path = checkpoint.list_checkpoints(run_dir)[-1]
    with np.load(path) as data:
        return path.name, {k: data[k] for k in data.files if k != "__meta__"}


def metrics_without_wall(run_dir: Path) -> list[dict]:
    """A run's metrics rows without their wall-clock times."""
    rows = run_dir_io.read_metrics(run_dir)
    return [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]


@pytest.fixture(scope="session")
def uninterrupted(tmp_path_factory) -> Path:
    """The ARGV run trained in one go, the reference of every interrupted one; it keeps every checkpoint (a snapshot
    each chunk, which changes no result), for the tests that resume it from an earlier one."""
    out = tmp_path_factory.mktemp("whole") / "run"
    assert cli.main([*ARGV, "--keep-every", "1", "--out", str(out), "--quiet"]) == 0
    return out


def _train_until(argv: list[str], out: Path, chunk: int, signum: int) -> subprocess.Popen:
    """Start `python -m reach_jax.train ARGV --out OUT --quiet` and send it `signum` once checkpoint `chunk` is on
    disk; its stderr is a pipe."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "reach_jax.train", *argv, "--out", str(out), "--quiet"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        done = checkpoint.list_checkpoints(out)
        if done and done[-1].name >= checkpoint.checkpoint_path(out, chunk).name:
            proc.send_signal(signum)
            return proc
        time.sleep(0.01)
    proc.kill()
    raise AssertionError(f"the run ended (status {proc.wait()}) before checkpoint {chunk}")


@pytest.fixture(scope="session")
def train_until():
    """train_until(argv, out, chunk, signum) -> the training process, sent signum once checkpoint `chunk` is on disk."""
    return _train_until


def _train_until_killed(argv: list[str], out: Path, chunk: int = 3) -> Path:
    """Run `python -m reach_jax.train ARGV --out OUT --quiet` and SIGKILL it once checkpoint `chunk` is on disk."""
    proc = _train_until(argv, out, chunk, signal.SIGKILL)
    assert proc.wait() == -signal.SIGKILL, "the run finished before it could be killed"
    return checkpoint.list_checkpoints(out)[-1]


@pytest.fixture
def train_until_killed():
    """train_until_killed(argv, out, chunk=3) -> the newest checkpoint of a training run killed after that chunk."""
    return _train_until_killed


def _load_tool(script: str):
    """SCRIPT.py (a path from the repository's root, such as tools/sync_docs) imported as a module: the tools and
    the studies are scripts, not a package."""
    path = Path(__file__).resolve().parent.parent / f"{script}.py"
    spec = importlib.util.spec_from_file_location(Path(script).name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def load_tool():
    """load_tool(script) -> SCRIPT.py (a path from the repository's root, without .py) imported as a module."""
    return _load_tool


def pytest_configure(config):
    """Give the test process (and the subprocesses it starts, which inherit XLA_FLAGS) the CLIs' backend flags, and
    one compilation cache."""
    xla_options.add_xla_flags()
    _share_compilations(config)
    # A suite started in the background (`nohup`, `cmd &`) inherits an ignored SIGINT, which the trainer rightly
    # leaves ignored; its tests of Ctrl-C need the terminal's disposition, here and in the processes they start.
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


# Every compiled program is kept, however small or quick: most of the suite's time is compiling the same small runs.
CACHE_SETTINGS = {"jax_persistent_cache_min_compile_time_secs": 0.0, "jax_persistent_cache_min_entry_size_bytes": 0}


def _share_compilations(config) -> None:
    """One XLA compilation cache for the session and every process it starts, removed at its end.

    Many tests compile the same program (the same small run trained in-process, in subprocesses and across
    processes); with the cache each is compiled once. It stores executables only: every test still runs its own.
    A cache already set (JAX_COMPILATION_CACHE_DIR) is used as it is: so the xdist workers, started after the
    controller set it, share the controller's.
    """
    if os.environ.get("JAX_COMPILATION_CACHE_DIR"):
        return
    folder = tempfile.mkdtemp(prefix="reach_jax-tests-xla-")
    config.add_cleanup(lambda: shutil.rmtree(folder, ignore_errors=True))
    os.environ["JAX_COMPILATION_CACHE_DIR"] = folder
    os.environ.update({name.upper(): str(value) for name, value in CACHE_SETTINGS.items()})
    jax.config.update("jax_compilation_cache_dir", folder)
    for name, value in CACHE_SETTINGS.items():
        jax.config.update(name, value)


def default_hyper(cfg) -> hyper.Hyper:
    """One learner's hyperparameters: the config's learner defaults, as () arrays."""
    return hyper.Hyper(**{name: jnp.asarray(float(getattr(cfg.learner, name))) for name in hyper.NAMES})
