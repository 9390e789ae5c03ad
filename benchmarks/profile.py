"""Where a learner-step's time goes: the step's parts timed alone, at two batch sizes on one device.

`python benchmarks/profile.py [--learners 16 64] [--steps 2000] [--json PATH]`

Each part of `rollout.learner_step` runs alone in a compiled `lax.scan` over steps, vmapped over the batch, on one
device: the random draws, the observation (sensor and encoding), the network's TS step (forward pass and update),
the arm's step (RK4, goal test, drift), the environment's step with its trial reset, and the whole step (the
trainer's chunk). The marginal cost of a part is the growth of its time per step from the smaller batch to the
larger, per learner; the fixed cost is what is left at one learner. A JAX profiler trace cannot do this on CPU:
recording each kernel launch costs about 2.6 ms a step, which swamps a 30-110 us step.
Writes benchmarks/results/profile-<UTC time>.json unless --json names one.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

from reach_jax.engine import distribute

sys.path.insert(0, str(Path(__file__).resolve().parent))

import throughput  # noqa: E402  (batches, results folder and code version)

REPS = 5  # timed calls per figure


def parse(argv=None) -> argparse.Namespace:
    """Command line."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--learners", type=int, nargs=2, default=[16, 64], help="the two batch sizes (default 16 64)")
    p.add_argument("--steps", type=int, default=2000, help="steps of a timed call (default 2000)")
    p.add_argument("--json", type=Path, help="write the results here (default: a new file in benchmarks/results)")
    return p.parse_args(argv)


def parts(cfg):
    """Name -> one learner's part of a step, (state, u) -> state, to scan and vmap."""
    import jax.numpy as jnp

    from reach_jax import env
    from reach_jax.agent import exploration, learner, network
    from reach_jax.engine import random_stream, rollout
    from reach_jax.env import curriculum, task
    from reach_jax.physics import encoding

    geom = task.geometry(cfg)  # the config's own sensor, as every learner of the profiled batch has

    # Each part's result feeds the carried state in full, so that the compiler removes none of it.
    def draws(s, u):
        return s.replace(counters=s.counters.replace(steps=s.counters.steps + (jnp.sum(u) > 1e9)))

    def observe(s, u):  # the arm moves a little, so the observation cannot be hoisted out of the loop
        trial = s.env.trial.replace(arm=s.env.trial.arm + 1e-6 * u[0])
        x = env.observe_trial(trial, s.env.cond, geom, cfg)
        return s.replace(env=s.env.replace(trial=trial), agent=s.agent.replace(n_max=s.agent.n_max + jnp.sum(x)))

    def ts_step(s, u):
        trial = s.env.trial.replace(arm=s.env.trial.arm + 1e-6 * u[0])
        s = s.replace(env=s.env.replace(trial=trial))
        x = env.observe(s.env, geom, cfg)
        rows = encoding.coded_support(trial.arm, trial.prev_arm, trial.prev_tau, cfg)
        params, out, _, u1 = learner.ts_step(s.agent.params, x, s.agent.pending, s.agent.n_max, 1.0, cfg, rows)
        pending = s.agent.pending._replace(x=x, out=out, u1=u1)
        return s.replace(agent=s.agent.replace(params=params, pending=pending))

    def arm_step(s, u):
        unit, _ = random_stream.split_uniforms(u, cfg)
        trial, _ = env.step_trial(s.env.trial, network.torque(unit, 0.0, cfg), s.env.cond, geom, cfg)
        return s.replace(env=s.env.replace(trial=trial))

    def env_step(s, u, plan, hyper):
        unit, draws_ = random_stream.split_uniforms(u, cfg)
        cur = s.env.curriculum
        scale = exploration.value_scale(hyper, 0.0, cur.full_at, curriculum.shortfall(cur, geom), s.env.trial.t)
        carried, fresh = exploration.noise(unit, hyper, s.env.trials, cur.full_at, scale, unit)
        params = env.env_params(plan, hyper)
        new, _ = env.step(s.env, network.torque(carried, fresh, cfg), draws_, params, cfg)
        return s.replace(env=new)

    def whole(s, u, plan, hyper):
        return rollout.learner_step(s, u, plan, hyper, cfg)[0]

    return {
        "random draws": draws,
        "observation": observe,
        "network TS step (with observation)": ts_step,
        "arm step": arm_step,
        "environment step with reset": env_step,
        "whole step": whole,
    }


def time_part(part, n_learners: int, n_steps: int, cfg) -> float:
    """Median us per step of `part` over a batch of n_learners on one device, draws included."""
    import jax

    from reach_jax.engine import chunk

    learners = throughput.batch_of(n_learners, cfg)
    takes_plan = part.__code__.co_argcount == 4

    def one(s, u, plan, hyper):
        return part(s, u, plan, hyper) if takes_plan else part(s, u)

    step = jax.vmap(one)

    def run(states, plans, hypers):
        def body(states, u):
            return step(states, u, plans, hypers), None

        return chunk.scan_steps(body, states, n_steps, cfg, batched=True)[0]

    compiled = jax.jit(run)
    states = jax.block_until_ready(compiled(learners.states, learners.plans, learners.hypers))
    times = []
    for _ in range(REPS):
        t0 = time.perf_counter()
        states = jax.block_until_ready(compiled(states, learners.plans, learners.hypers))
        times.append(time.perf_counter() - t0)
    return statistics.median(times) / n_steps * 1e6


def main(argv=None) -> int:
    """Time every part at both batch sizes, print, write the JSON."""
    args = parse(argv)
    distribute.setup_backend(1)
    import jax

    from reach_jax.config import Config

    cfg = Config()
    small, large = args.learners
    result = {"learners": [small, large], "steps": args.steps, "parts": {}}
    for name, part in parts(cfg).items():
        a, b = (time_part(part, n, args.steps, cfg) for n in (small, large))
        slope = (b - a) / (large - small)
        result["parts"][name] = {
            f"us_per_step_at_{small}": round(a, 2),
            f"us_per_step_at_{large}": round(b, 2),
            "marginal_us_per_learner_step": round(slope, 3),
            "fixed_us_per_step": round(a - slope * small, 2),
        }
        print(name, result["parts"][name], flush=True)
    result.update(code=throughput.code_version(), jax=jax.__version__, backend=jax.default_backend())
    throughput.write_result(result, "profile", args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
