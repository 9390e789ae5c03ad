"""The host's work between chunks: how long the devices wait for the host, in a real training run, each chunk.

`python benchmarks/host_gap.py [--trials 1.5e5] [--against PATH] [--json PATH]`

Trains four short runs on 2 CPU devices with the default recipe, of 8, 4, 2 and 1 learners (the Table-2 batch and
its tail), with `loop.dispatch` and `interrupt.wait_ready` timed. Per chunk after the first few: its period
(dispatch to dispatch) and the devices' idle time in it. A chunk dispatched asynchronously idles from its
predecessor's states being ready to its own dispatch returning (the copy to the host, the merge, the next inputs,
the dispatch; the metrics, the checkpoint and the bar come after it, while the devices work). XLA:CPU runs a
program on one device inline, in the dispatching call, so a one-learner chunk idles for its period less that call.
The median time the dispatch call takes to return is kept beside them.
The idle medians, weighted by the chunks of each batch size in the table2-run JSON given by --against (the
README's run), give the share of that run the devices waited for the host. Run it on a quiet machine. Writes
benchmarks/results/host-gap-<UTC time>.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import io
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

from reach_jax.engine import distribute

sys.path.insert(0, str(Path(__file__).resolve().parent))

import throughput  # noqa: E402  (the sibling benchmark's results folder and code version)

SKIP = 5  # chunks at the start left out: compiling and warming
RUN = throughput.RESULTS / "table2-run-fresh-native-2e95236.json"  # the README's run
SIZES = {8: {}, 4: {"seeds": 1}, 2: {"conditions": ("none",)}, 1: {"conditions": ("none",), "seeds": 1}}


def parse(argv=None) -> argparse.Namespace:
    """Command line."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--trials", type=float, default=1.5e5, help="trials per learner of each run")
    p.add_argument("--against", type=Path, default=RUN, help="a table2-run JSON whose chunks weight the sizes")
    p.add_argument("--json", type=Path, help="write the results here (default: a new file in benchmarks/results)")
    return p.parse_args(argv)


def timed_run(cfg, events: dict) -> dict:
    """Train `cfg` into a scratch folder with the loop's dispatch and wait timed: idle time and period [ms]."""
    from reach_jax.train import loop

    events.clear()
    with tempfile.TemporaryDirectory() as scratch:
        start = time.perf_counter()
        loop.run(cfg, Path(scratch) / "run", stream=io.StringIO())
        wall = time.perf_counter() - start
    sent, ready = events["dispatch"], events["wait_ready"]
    idle, periods, calls = [], [], []
    for i in range(SKIP, len(sent) - 1):
        period, call = sent[i + 1][0] - sent[i][0], sent[i][1] - sent[i][0]
        inline = call > period / 2  # the chunk ran inside its dispatch call
        idle.append(1e3 * (period - call if inline else sent[i + 1][1] - ready[i][1]))
        periods.append(1e3 * period)
        calls.append(1e3 * call)
    return {
        "chunks": len(sent),
        "wall_s": wall,
        "idle_ms_median": statistics.median(idle),
        "idle_ms_p90": sorted(idle)[int(0.9 * len(idle))],
        "period_ms_median": statistics.median(periods),
        "dispatch_call_ms_median": statistics.median(calls),
    }


def main(argv=None) -> int:
    """Times the four runs, weights them by the committed run's chunks and writes the result."""
    args = parse(argv)
    distribute.setup_backend(2)
    from reach_jax.config import Config
    from reach_jax.train import interrupt, loop

    events: dict[str, list] = {}

    def timing(module, name):
        real = getattr(module, name)

        @functools.wraps(real)
        def wrapped(*a, **k):
            t = time.perf_counter()
            try:
                return real(*a, **k)
            finally:
                events.setdefault(name, []).append((t, time.perf_counter()))

        setattr(module, name, wrapped)

    timing(loop, "dispatch")
    timing(interrupt, "wait_ready")
    cfg = Config()
    runs = {}
    for size, fields in SIZES.items():
        train = dataclasses.replace(cfg.train, trials=int(args.trials), **fields)
        runs[str(size)] = r = timed_run(dataclasses.replace(cfg, train=train), events)
        print(
            f"batch {size}: {r['chunks']} chunks, the devices idle {r['idle_ms_median']:.2f} ms (median; p90 "
            f"{r['idle_ms_p90']:.2f}) of a {r['period_ms_median']:.1f} ms chunk; the dispatch call "
            f"{r['dispatch_call_ms_median']:.2f} ms"
        )
    composition = json.loads(args.against.read_text())["batch_step_us"]
    idle_s = sum(runs[n]["idle_ms_median"] / 1e3 * composition[n]["chunks"] for n in runs)
    chunks_s = sum(composition[n]["total_s"] for n in runs)
    print(f"{args.against.name}: the devices idle {idle_s:.1f} s of its chunks' {chunks_s:.1f} s")
    result = {
        "what": __doc__.splitlines()[0],
        "code": throughput.code_version(),
        "trials": args.trials,
        "runs": runs,
        "against": {"run": args.against.name, "idle_s": idle_s, "chunks_s": chunks_s, "idle_share": idle_s / chunks_s},
    }
    throughput.write_result(result, "host-gap", args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
