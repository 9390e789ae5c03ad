"""Test-session setup: the CPU compiler options that the command lines set, before JAX starts; shared fixtures."""

import importlib.util
import signal
import subprocess
import sys
import time
from pathlib import Path

import jax.numpy as jnp
import pytest

from reach_jax.config import hyper
from reach_jax.engine import distribute
from reach_jax.store import checkpoint


def _train_until_killed(argv: list[str], out: Path, chunk: int = 3) -> Path:
    """Run `python -m reach_jax.train ARGV --out OUT --quiet` and SIGKILL it once checkpoint `chunk` is on disk."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "reach_jax.train", *argv, "--out", str(out), "--quiet"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        done = checkpoint.list_checkpoints(out)
        if done and done[-1].name >= checkpoint.checkpoint_path(out, chunk).name:
            proc.send_signal(signal.SIGKILL)
            break
        time.sleep(0.01)
    assert proc.wait() == -signal.SIGKILL, "the run finished before it could be killed"
    return checkpoint.list_checkpoints(out)[-1]


@pytest.fixture
def train_until_killed():
    """train_until_killed(argv, out, chunk=3) -> the newest checkpoint of a training run killed after that chunk."""
    return _train_until_killed


def _load_tool(script: str):
    """SCRIPT.py (a path from the repository's root, such as tools/sync_readme) imported as a module: the tools and
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
    """Give the test process (and the subprocesses it starts, which inherit XLA_FLAGS) the CLIs' backend flags."""
    distribute.add_xla_flags()


def default_hyper(cfg) -> hyper.Hyper:
    """One learner's hyperparameters: the config's learner defaults, as () arrays."""
    return hyper.Hyper(**{name: jnp.asarray(float(getattr(cfg.learner, name))) for name in hyper.NAMES})
