"""Backend setup is explicit: importing the package changes nothing, and a flag a jaxlib rejects only warns."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import jax.numpy as jnp
import pytest

from reach_jax.engine import xla_options


def _child(code: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    proc = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], env=env, capture_output=True, text=True, timeout=300, check=False
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_imports_leave_the_environment_and_jax_alone_and_setup_sets_the_flags():
    got = _child(
        """
        import json, os, warnings
        import jax
        from reach_jax import agent, config, engine, env, evaluate, physics, store, train
        from reach_jax.engine import distribute, rollout, xla_options
        from reach_jax.evaluate import cli as evaluate_cli, figures
        from reach_jax.train import cli as train_cli
        after_import = (os.environ.get("XLA_FLAGS"), xla_options.jax_started(), jax.config.jax_num_cpu_devices)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            rejected = xla_options.add_xla_flags(("--xla_reach_jax_no_such_flag=1",))
        after_reject = os.environ.get("XLA_FLAGS")
        distribute.setup_backend(2)
        import jax.numpy as jnp
        total = float(jnp.arange(4.0).sum())
        started = xla_options.jax_started()
        print(json.dumps({
            "after_import": after_import, "rejected": rejected, "after_reject": after_reject,
            "warnings": [str(w.message) for w in caught], "flags": os.environ.get("XLA_FLAGS"),
            "devices": len(jax.devices()), "total": total, "started": started,
        }))
        """
    )
    assert got["after_import"] == [None, False, -1]  # asking left the device count alone
    assert got["rejected"] is False and got["after_reject"] is None
    assert len(got["warnings"]) == 1 and "rejects" in got["warnings"][0] and "no_such_flag" in got["warnings"][0]
    assert got["flags"] == " ".join(xla_options.CPU_XLA_FLAGS)
    assert got["devices"] == 2 and got["total"] == 6.0 and got["started"] is True


def test_flags_asked_for_after_jax_started_warn_and_change_nothing(monkeypatch):
    jnp.zeros(1).block_until_ready()
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    with pytest.warns(UserWarning, match="JAX already started"):
        assert xla_options.add_xla_flags() is False
    assert "XLA_FLAGS" not in os.environ
