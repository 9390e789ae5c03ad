"""Latency and throughput of the jitted trainer against the NumPy reference loop, on this machine, in one run.

`python benchmarks/throughput.py [--quick] [--batches N ...] [--json PATH] [--run RUN] [--devices N] [--compare OLD]`

Units: learner-steps per second (one learner advancing one step of cfg.arm.dt, learning included), microseconds,
seconds. Every figure is the median of several timed calls of an already compiled chunk. Compile time is the first
call's time minus that median. Latency is the wall time of one step of the whole batch, learners / (steps/s): the
batch runs in lockstep, so a chain of dependent steps takes that long per step, whatever the number of devices.
Under --quick, batches up to SMALL_BATCH are still timed with LATENCY_STEPS-step chunks: short calls time dispatch.
The Table-2 figures take the steps that each learner of a training run needed (its metrics.jsonl): the critical
path is the slowest learner's steps times the latency of one learner on one device, the floor for any number of
devices; the schedule walks the learners' finishing order as the trainer does, each stretch of steps at the
latency of the batch it runs (`progress.pow2_batch` of the unfinished learners), the estimate of the run itself.
Each run writes its own JSON, benchmarks/results/throughput-<UTC time>.json unless --json names one, so the
measurements accumulate instead of overwriting each other.
`--compare` makes this a regression benchmark: it exits with status 1 if a batch size fell below
REGRESSION_FLOOR of the old JSON's figure. It is never part of the test suite: speed is measured, not asserted.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from reach_jax.config.schema import DEFAULT_SPEED, Speed
from reach_jax.engine import chunk as chunk_lib
from reach_jax.engine import distribute
from reach_jax.store import run_dir as run_dir_io
from reach_jax.train.progress import pow2_batch

BATCHES = (1, 2, 4, 8, 32, 128, 512)  # learners per batch; 1-8: the Table-2 batch (4 conditions x 2 seeds) and its tail
TABLE2_TRIALS = 2_000_000  # trials per network (section 4.4)
TARGET_SECONDS = 0.4  # wall time of one timed call: long enough that timer noise is < 1%
LATENCY_BATCH = 1  # the learners whose step time is the critical path's latency: one, on one device
LATENCY_STEPS = 20_000  # steps per timed call of a small batch under --quick (~0.2 s at 10 us a step)
SMALL_BATCH = 8  # batches up to this size (the Table-2 batch and its tail) get LATENCY_STEPS under --quick
REPS, QUICK_REPS = 7, 3  # timed calls per figure
REFERENCE_STEPS, QUICK_REFERENCE_STEPS = 3000, 500  # NumPy reference steps per timed call
TAIL_CHUNKS = 5  # chunks at the end of a run whose mean trial length extrapolates the rest
REGRESSION_FLOOR = 0.7  # --compare fails below this fraction of the old figure (the machine is shared, noisy)
DEFAULT_RUN = Path("runs/table2")
RESULTS = Path(__file__).resolve().parent / "results"  # one JSON per measurement


def write_result(result: dict, name: str, path: Path | None = None) -> Path:
    """Write a benchmark's result as JSON to `path`, else to a new benchmarks/results/<name>-<UTC time>.json."""
    path = path or RESULTS / f"{name}-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {path}")
    return path


def parse(argv=None) -> argparse.Namespace:
    """Command line of the benchmark."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="shorter timings: large batches with the probe, fewer calls")
    p.add_argument("--batches", type=int, nargs="+", default=BATCHES, help=f"learners per batch (default {BATCHES})")
    p.add_argument("--json", type=Path, help="write the results here (default: a new file in benchmarks/results)")
    p.add_argument("--run", type=Path, default=DEFAULT_RUN, help="training run whose trial lengths to use")
    p.add_argument("--devices", type=int, default=os.cpu_count(), help="CPU host devices (default: one per core)")
    p.add_argument("--compare", type=Path, help="earlier JSON: exit 1 if any batch fell below the floor")
    p.add_argument(
        "--engines", nargs="+", choices=("native", "jax"), default=["native", "jax"],
        help="the step loop's engines to measure, each in turn (default both; the first gives the top-level figures)",
    )  # fmt: skip
    return p.parse_args(argv)


def batch_of(n_learners: int, cfg):
    """A Batch of n_learners learners cycling through the four conditions."""
    import jax
    import jax.numpy as jnp

    from reach_jax.engine import batch

    seeds = -(-n_learners // 4)
    cfg = dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, seeds=seeds))
    return jax.tree.map(lambda a: jnp.copy(a[:n_learners]), batch.init_batch(cfg))


def time_chunk(
    n_learners: int,
    devices,
    cfg,
    quick: bool,
    n_steps: int | None = None,
    speed: Speed = DEFAULT_SPEED,
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
      {"steps_per_s": learner-steps/s, "latency_us": us per step of the batch, "compile_s": s,
      "steps": steps per call, "devices": devices used}.
    """
    import jax
    import jax.numpy as jnp

    learners = batch_of(n_learners, cfg)
    budget = jnp.asarray(2**31 - 1, jnp.int32)
    probe = 200
    chunk = chunk_lib.make_chunk(cfg, probe, devices, speed)
    t0 = time.perf_counter()
    states = jax.block_until_ready(chunk(learners.states, learners.plans, learners.hypers, budget)[0])
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    states = jax.block_until_ready(chunk(states, learners.plans, learners.hypers, budget)[0])
    per_step = (time.perf_counter() - t0) / probe
    compile_s = first - per_step * probe

    if n_steps is None:  # each timed call lasts TARGET_SECONDS; --quick times large batches with the probe
        n_steps = max(probe, int(TARGET_SECONDS / per_step))
        if quick:
            n_steps = LATENCY_STEPS if n_learners <= SMALL_BATCH else probe
    if n_steps != probe:
        chunk = chunk_lib.make_chunk(cfg, n_steps, devices, speed)
        states = jax.block_until_ready(chunk(states, learners.plans, learners.hypers, budget)[0])  # compile, warm
    times = []
    for _ in range(QUICK_REPS if quick else REPS):
        t0 = time.perf_counter()
        states = jax.block_until_ready(chunk(states, learners.plans, learners.hypers, budget)[0])
        times.append(time.perf_counter() - t0)
    used = len(states.env.trial.arm.sharding.device_set)
    return {
        "steps_per_s": n_learners * n_steps / statistics.median(times),
        "latency_us": statistics.median(times) / n_steps * 1e6,
        "compile_s": compile_s,
        "steps": n_steps,
        "devices": used,
    }


def time_reference(cfg, quick: bool) -> float:
    """Median steps/s of reach_jax.testing.reference.run_reference (one NumPy learner, float64)."""
    from reach_jax.testing import reference

    n = QUICK_REFERENCE_STEPS if quick else REFERENCE_STEPS
    times = []
    for seed in range(QUICK_REPS if quick else REPS):
        t0 = time.perf_counter()
        reference.run_reference(n, seed=seed, cfg=cfg)
        times.append(time.perf_counter() - t0)
    return n / statistics.median(times)


def schedule_steps(run_dir: Path) -> tuple[list[float] | None, str]:
    """Steps each Table-2 learner needs for 2e6 trials, from a run's metrics, and how they were found.

    A learner that has not reached 2e6 trials is extrapolated with the mean trial length of its last
    TAIL_CHUNKS chunks.
    """
    path = run_dir_io.metrics_path(run_dir)
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
    return needed, how


def code_version() -> str:
    """The commit of the reach_jax that this process imported, "-dirty" if its tree has changes, or "unknown"."""
    try:
        done = subprocess.run(
            ["git", "describe", "--always", "--dirty"],
            capture_output=True,
            text=True,
            check=True,
            cwd=Path(chunk_lib.__file__).parent,
        )
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return done.stdout.strip()


def table2_figures(rows: dict, needed: list[float] | None) -> dict:
    """The Table-2 critical path and schedule [s] from each learner's steps, or None where a batch is unmeasured."""
    one = rows.get(LATENCY_BATCH, {}).get("one")
    critical = None if needed is None or one is None else max(needed) * one["latency_us"] * 1e-6
    schedule = None
    if needed and all(pow2_batch(k, len(needed)) in rows for k in range(1, len(needed) + 1)):
        schedule, done = 0.0, 0.0
        for k, s in zip(range(len(needed), 0, -1), sorted(needed), strict=True):
            schedule += (s - done) * rows[pow2_batch(k, len(needed))]["all"]["latency_us"] * 1e-6
            done = s
    return {"table2_critical_path_s": critical, "table2_schedule_s": schedule}


def main(argv=None) -> int:
    """Run every measurement, print the table, write the JSON; returns the exit status."""
    args = parse(argv)
    distribute.setup_backend(args.devices)
    import jax

    from reach_jax.config import Config
    from reach_jax.engine import native

    started = time.perf_counter()
    cfg = Config()
    every = jax.devices()
    one = every[:1]
    engines = [e for e in args.engines if native.resolve(cfg, Speed(engine=e))[0].engine == e]
    by_engine = {}
    for engine in engines:
        speed, rows = dataclasses.replace(DEFAULT_SPEED, engine=engine), {}
        for n in args.batches:
            rows[n] = {"all": time_chunk(n, every, cfg, args.quick, speed=speed)}
            sharded = distribute.learner_mesh(n, every).size > 1
            rows[n]["one"] = time_chunk(n, one, cfg, args.quick, speed=speed) if sharded else rows[n]["all"]
            print(f"measured {n} learners on the {engine} engine", file=sys.stderr, flush=True)
        by_engine[engine] = rows
    rows = by_engine[engines[0]]
    ref = time_reference(cfg, args.quick)
    needed, how = schedule_steps(args.run)
    table2 = table2_figures(rows, needed)

    print(f"jax {jax.__version__}, {jax.default_backend()}, {len(every)} devices, {os.cpu_count()} cores")
    header = ("learners", "latency 1 dev", f"latency {len(every)} dev", "1 device", f"{len(every)} devices")
    for engine, engine_rows in by_engine.items():
        print(f"{engine} engine")
        print("{:>8} {:>14} {:>14} {:>14} {:>14} {:>9} {:>8}".format(*header, "vs NumPy", "compile"))
        for n, r in engine_rows.items():
            a, o = r["all"], r["one"]
            print(
                f"{n:8d} {o['latency_us']:11.2f} us {a['latency_us']:11.2f} us {o['steps_per_s']:14,.0f} "
                f"{a['steps_per_s']:14,.0f} {a['steps_per_s'] / ref:8.0f}x {a['compile_s']:7.2f}s"
            )
    print(f"NumPy reference loop (testing.reference.run_reference): {ref:,.0f} steps/s, {1e6 / ref:.0f} us a step")
    print(how)
    for key, label in (("table2_critical_path_s", "critical path"), ("table2_schedule_s", "schedule")):
        if table2[key] is not None:
            print(f"Table-2 {label} (8 x 2e6 trials): {table2[key]:,.0f} s = {table2[key] / 60:.1f} min")

    def per_batch(which: str, key: str, rows: dict = rows) -> dict:
        return {str(n): r[which][key] for n, r in rows.items()}

    keys = {"latency_us": ("all", "latency_us"), "latency_us_one_device": ("one", "latency_us"),
            "learner_steps_per_s": ("all", "steps_per_s"), "learner_steps_per_s_one_device": ("one", "steps_per_s"),
            "compile_s": ("all", "compile_s")}  # fmt: skip
    result = {
        "engine": engines[0],
        "by_engine": {e: {k: per_batch(*w, rows=r) for k, w in keys.items()} for e, r in by_engine.items()},
        "latency_us": per_batch("all", "latency_us"),
        "latency_us_one_device": per_batch("one", "latency_us"),
        "learner_steps_per_s": per_batch("all", "steps_per_s"),
        "learner_steps_per_s_one_device": per_batch("one", "steps_per_s"),
        "steps_per_call": per_batch("all", "steps"),
        "devices_used": per_batch("all", "devices"),
        "compile_s": per_batch("all", "compile_s"),
        "numpy_reference_steps_per_s": ref,
        "devices": len(every),
        "table2_learner_steps": needed,
        **table2,
        "table2_schedule_source": how,
        "quick": args.quick,
        "code": code_version(),
        "jax": jax.__version__,
        "backend": jax.default_backend(),
        "cores": os.cpu_count(),
        "benchmark_wall_s": time.perf_counter() - started,
    }
    write_result(result, "throughput", args.json)
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
