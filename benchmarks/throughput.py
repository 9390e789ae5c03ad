"""Throughput of the jitted trainer against the NumPy reference loop, on this machine, in one run.

`python benchmarks/throughput.py [--quick] [--json PATH] [--run RUN_DIR] [--devices N] [--compare OLD.json]`

Units: learner-steps per second (one learner advancing one step of cfg.arm.dt, learning included), seconds.
Every figure is the median of several timed calls of an already compiled chunk. Compile time is the first
call's time minus that median. The Table-2 estimate takes the trial lengths that a training run reached
(its metrics.jsonl) and the measured steps per second at the Table-2 batch of 8 learners.
`--compare` makes this a regression benchmark: it exits with status 1 if a batch size fell below
REGRESSION_FLOOR of the old JSON's figure. It is never part of the test suite: speed is measured, not asserted.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import sys
import time
from pathlib import Path

from reach_jax import distribute, rollout
from reach_jax import run_dir as run_dir_io

BATCHES = (1, 8, 32, 128, 512)  # learners per batch; 8 is Table 2 (4 conditions x 2 networks)
TABLE2_LEARNERS = 8  # networks trained for Table 2
TABLE2_TRIALS = 2_000_000  # trials per network (section 4.4)
TARGET_SECONDS = 0.4  # wall time of one timed call: long enough that timer noise is < 1%
REPS, QUICK_REPS = 7, 3  # timed calls per figure
REFERENCE_STEPS, QUICK_REFERENCE_STEPS = 3000, 500  # NumPy reference steps per timed call
TAIL_CHUNKS = 5  # chunks at the end of a run whose mean trial length extrapolates the rest
REGRESSION_FLOOR = 0.7  # --compare fails below this fraction of the old figure (the machine is shared, noisy)
DEFAULT_RUN = Path("runs/table2")


def parse(argv=None) -> argparse.Namespace:
    """Command line of the benchmark."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="short timings; the whole run takes under a minute")
    p.add_argument("--json", type=Path, help="write the results here")
    p.add_argument("--run", type=Path, default=DEFAULT_RUN, help="training run whose trial lengths to use")
    p.add_argument("--devices", type=int, default=os.cpu_count(), help="CPU host devices (default: one per core)")
    p.add_argument("--compare", type=Path, help="earlier JSON: exit 1 if any batch fell below the floor")
    return p.parse_args(argv)


def batch_of(n_learners: int, cfg):
    """A Batch of n_learners learners cycling through the four conditions."""
    import jax
    import jax.numpy as jnp

    from reach_jax import batch

    seeds = -(-n_learners // 4)
    cfg = dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, seeds=seeds))
    return jax.tree.map(lambda a: jnp.copy(a[:n_learners]), batch.init_batch(cfg))


def time_chunk(
    n_learners: int,
    devices,
    cfg,
    quick: bool,
    n_steps: int | None = None,
    speed: rollout.Speed = rollout.DEFAULT_SPEED,
) -> dict:
    """Median learner-steps/s and compile time of make_chunk for one batch size on the given devices.

    Args:
      n_learners: batch size.
      devices: devices to shard over.
      cfg: model config.
      quick: shorter timings.
      n_steps: steps per timed call; None picks enough for TARGET_SECONDS (the probe's length if quick).
      speed: make_chunk's speed settings.

    Returns:
      {"steps_per_s": learner-steps/s, "compile_s": s, "steps": steps per call, "devices": devices used}.
    """
    import jax
    import jax.numpy as jnp

    learners = batch_of(n_learners, cfg)
    budget = jnp.asarray(2**31 - 1, jnp.int32)
    probe = 200
    chunk = rollout.make_chunk(cfg, probe, devices, speed)
    t0 = time.perf_counter()
    states = jax.block_until_ready(chunk(learners.states, learners.plans, learners.hypers, budget)[0])
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    states = jax.block_until_ready(chunk(states, learners.plans, learners.hypers, budget)[0])
    per_step = (time.perf_counter() - t0) / probe
    compile_s = first - per_step * probe

    if n_steps is None:  # a chunk long enough that each timed call lasts TARGET_SECONDS; --quick keeps the probe
        n_steps = probe if quick else max(probe, int(TARGET_SECONDS / per_step))
    if n_steps != probe:
        chunk = rollout.make_chunk(cfg, n_steps, devices, speed)
        states = jax.block_until_ready(chunk(states, learners.plans, learners.hypers, budget)[0])  # compile, warm
    times = []
    for _ in range(QUICK_REPS if quick else REPS):
        t0 = time.perf_counter()
        states = jax.block_until_ready(chunk(states, learners.plans, learners.hypers, budget)[0])
        times.append(time.perf_counter() - t0)
    used = len(states.env.arm.sharding.device_set)
    return {
        "steps_per_s": n_learners * n_steps / statistics.median(times),
        "compile_s": compile_s,
        "steps": n_steps,
        "devices": used,
    }


def time_reference(cfg, quick: bool) -> float:
    """Median steps/s of reach_jax.reference.run_reference (one NumPy learner, float64)."""
    from reach_jax import reference

    n = QUICK_REFERENCE_STEPS if quick else REFERENCE_STEPS
    times = []
    for seed in range(QUICK_REPS if quick else REPS):
        t0 = time.perf_counter()
        reference.run_reference(n, seed=seed, cfg=cfg)
        times.append(time.perf_counter() - t0)
    return n / statistics.median(times)


def schedule_steps(run_dir: Path) -> tuple[float | None, str]:
    """Steps the slowest Table-2 learner needs for 2e6 trials, from a run's metrics, and how it was found.

    A learner that has not reached 2e6 trials is extrapolated with the mean trial length of its last
    TAIL_CHUNKS chunks. The batch runs until its slowest learner is done, so the maximum counts.
    """
    path = Path(run_dir) / run_dir_io.METRICS_FILE
    rows = run_dir_io.read_metrics(run_dir)
    if not rows:
        return None, f"no rows in {path}: no schedule estimate"
    by_learner: dict[int, list[dict]] = {}
    for r in rows:
        by_learner.setdefault(r["learner"], []).append(r)
    needed, notes = [], []
    for learner, rs in sorted(by_learner.items()):
        rs.sort(key=lambda r: r["chunk"])
        last = rs[-1]
        tail = rs[-TAIL_CHUNKS:]
        ended = sum(r["chunk_trials"] for r in tail)
        mean_len = sum(r["chunk_trials"] * (r["mean_trial_steps"] or 0.0) for r in tail) / max(ended, 1)
        left = max(TABLE2_TRIALS - last["trials"], 0)
        needed.append(last["steps"] + left * mean_len)
        notes.append((learner, last["trials"], mean_len))
    done = min(t for _, t, _ in notes)
    how = f"{path}: {len(notes)} learners at {done:,}+ trials; " + (
        "complete"
        if done >= TABLE2_TRIALS
        else f"extrapolated to {TABLE2_TRIALS:,} trials with the mean trial length of each learner's last "
        f"{TAIL_CHUNKS} chunks ({min(m for *_, m in notes):.1f}-{max(m for *_, m in notes):.1f} steps)"
    )
    return max(needed), how


def main(argv=None) -> int:
    """Run every measurement, print the table, write the JSON; returns the exit status."""
    args = parse(argv)
    distribute.setup_backend(args.devices)
    import jax

    from reach_jax.config import Config

    started = time.perf_counter()
    cfg = Config()
    every = jax.devices()
    one = every[:1]
    rows = {}
    for n in BATCHES:
        rows[n] = {"all": time_chunk(n, every, cfg, args.quick)}
        sharded = distribute.learner_mesh(n, every).size > 1
        rows[n]["one"] = time_chunk(n, one, cfg, args.quick) if sharded else rows[n]["all"]
        print(f"measured {n} learners", file=sys.stderr, flush=True)
    ref = time_reference(cfg, args.quick)
    steps, how = schedule_steps(args.run)
    rate8 = rows[TABLE2_LEARNERS]["all"]["steps_per_s"]
    estimate = None if steps is None else steps * TABLE2_LEARNERS / rate8

    print(f"jax {jax.__version__}, {jax.default_backend()}, {len(every)} devices, {os.cpu_count()} cores")
    header = ("learners", "1 device", f"{len(every)} devices", "scaling", "vs NumPy", "compile")
    print("{:>8} {:>14} {:>14} {:>8} {:>9} {:>8}".format(*header))
    for n, r in rows.items():
        a, o = r["all"], r["one"]
        print(
            f"{n:8d} {o['steps_per_s']:14,.0f} {a['steps_per_s']:14,.0f} {a['steps_per_s'] / o['steps_per_s']:7.2f}x "
            f"{a['steps_per_s'] / ref:8.0f}x {a['compile_s']:7.2f}s"
        )
    print(f"NumPy reference loop (reach_jax.reference.run_reference): {ref:,.0f} steps/s")
    if estimate is None:
        print(how)
    else:
        print(f"Table-2 schedule (8 x 2e6 trials): {estimate:,.0f} s = {estimate / 60:.1f} min; {how}")

    result = {
        "learner_steps_per_s": {str(n): r["all"]["steps_per_s"] for n, r in rows.items()},
        "learner_steps_per_s_one_device": {str(n): r["one"]["steps_per_s"] for n, r in rows.items()},
        "devices_used": {str(n): r["all"]["devices"] for n, r in rows.items()},
        "compile_s": {str(n): r["all"]["compile_s"] for n, r in rows.items()},
        "numpy_reference_steps_per_s": ref,
        "speedup_vs_reference_at_8": rate8 / ref,
        "devices": len(every),
        "table2_schedule_steps": steps,
        "table2_schedule_estimate_s": estimate,
        "table2_schedule_source": how,
        "quick": args.quick,
        "jax": jax.__version__,
        "backend": jax.default_backend(),
        "cores": os.cpu_count(),
        "benchmark_wall_s": time.perf_counter() - started,
    }
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    if args.compare:
        old = json.loads(args.compare.read_text())["learner_steps_per_s"]
        slow = [n for n, v in result["learner_steps_per_s"].items() if n in old and v < REGRESSION_FLOOR * old[n]]
        for n in result["learner_steps_per_s"]:
            if n in old:
                print(f"{n:>8} learners: {result['learner_steps_per_s'][n] / old[n]:.2f}x of {args.compare}")
        if slow:
            print(f"regression: {', '.join(slow)} learners below {REGRESSION_FLOOR:.0%} of {args.compare}")
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
