"""Sharding the learner axis over devices changes nothing in the results (CPU with 2 host devices).

Each case runs in a subprocess, because the host device count is fixed when JAX's backend starts.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from reach_jax.store import checkpoint

N_DEVICES = 2  # host devices in the subprocess; one per core of the CI machine


def _run(code: str) -> str:
    proc = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=600, check=False
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout


@pytest.mark.slow
def test_sharded_chunk_equals_unsharded():
    out = _run(
        f"""
        import dataclasses
        from reach_jax.engine import distribute
        distribute.setup_backend({N_DEVICES})
        import jax, jax.numpy as jnp, numpy as np
        from reach_jax.engine import batch
        from reach_jax.engine.chunk import make_chunk
        from reach_jax.config import Config, TrainConfig

        assert len(jax.devices()) == {N_DEVICES}
        cfg = dataclasses.replace(Config(), train=dataclasses.replace(TrainConfig(), trials=10**6, seeds=2))
        group = batch.init_batch(cfg)  # 4 conditions x 2 seeds = 8 learners
        budget = jnp.asarray(10**6)
        fresh = lambda: jax.tree.map(jnp.copy, group.states)
        one = make_chunk(cfg, 300, devices=jax.devices()[:1])
        many = make_chunk(cfg, 300)
        a = one(one(fresh(), group.plans, group.hypers, budget)[0], group.plans, group.hypers, budget)[0]
        b = many(many(fresh(), group.plans, group.hypers, budget)[0], group.plans, group.hypers, budget)[0]
        assert len(a.env.trial.arm.sharding.device_set) == 1
        assert len(b.env.trial.arm.sharding.device_set) == {N_DEVICES}
        for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
        assert int(np.asarray(a.env.trials).sum()) > 0
        print("identical")
        """
    )
    assert out.strip().endswith("identical")


@pytest.mark.slow
def test_cli_devices_flag_gives_the_same_run(tmp_path):
    argv = ["--trials", "30", "--seeds", "1", "--conditions", "none,random", "--chunk-steps", "300", "--quiet"]
    for devices in (1, N_DEVICES):
        out = tmp_path / f"d{devices}"
        _run(
            f"""
            import sys
            from reach_jax.train import cli
            sys.exit(cli.main({[*argv, "--devices", str(devices), "--out", str(out)]!r}))
            """
        )
    names = [checkpoint.list_checkpoints(tmp_path / f"d{d}")[-1] for d in (1, N_DEVICES)]
    assert names[0].name == names[1].name
    with np.load(names[0]) as a, np.load(names[1]) as b:
        assert a.files == b.files
        for k in a.files:
            if k != "__meta__":
                np.testing.assert_array_equal(a[k], b[k], err_msg=k)
