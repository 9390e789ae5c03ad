"""Replays every finished committed run's trial counts through the progress bar's estimator (`LearnerEta`) on the
tests' fake clock, over a grid of its relaxation toward the batch's median (`regress`, `regress_weight`).

For each grid point and run, by the tests' own replays (`tests/test_progress.py`): the worst error of the estimate
from 5% and from half of the run, and the share of the updates from a quarter of the run whose true time left lies in
the band; the tests' list of runs (COMMITTED_RUNS) is summed apart from the others. Beside them, per grid point, the
tests' two other replays: runs/dev_gain on its own wall clock and the simulated run whose learners' differences
persist.

    python benchmarks/eta_replay.py            # writes benchmarks/results/eta-replay-<date>.json
"""

from __future__ import annotations

import argparse
import inspect
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from reach_jax.train.progress import LearnerEta

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

import test_progress as tp  # noqa: E402  (the tests' replay: committed profiles, fake clock, batch sizes)
from conftest import committed_runs  # noqa: E402

# (regress, regress_weight): no relaxation (the estimator before it), then time constants x weights
GRID = [(0.0, 0.0)] + [(r, w) for r in (0.05, 0.1, 0.2, 0.4) for w in (0.25, 0.5, 0.75, 1.0)]


def replay(run: str, regress: float, weight: float) -> dict | None:
    """One run's record under one grid point, by the tests' replays (None for a run not finished): worst errors from
    5% and half, band coverage from a quarter, the band's widest half-width from half."""
    trials, _, budget, _ = tp.committed_profile(run)
    if not (trials[-1] >= budget).all():
        return None
    settings = {"regress": regress, "regress_weight": weight}
    worst = tp.worst_eta_errors(run, tp.fake_clock(run), **settings)
    coverage, widest = tp.band_record(run, **settings)
    return {"from_5pct": worst[0.05], "from_half": worst[0.5], "band_coverage": coverage, "band_widest": widest}


def other_checks(regress: float, weight: float) -> dict:
    """The tests' other replays under one grid point: runs/dev_gain on its own wall clock (worst from half and from
    85%), and the simulated run of persistent differences on clocks whose step is `fixed` of its cost at 8 learners
    (worst from half)."""
    real = tp.worst_eta_errors(
        "dev_gain", tp.wall_clock("dev_gain"), (0.5, 0.85), regress=regress, regress_weight=weight
    )
    return {
        "dev_gain_wall_clock": {"from_half": real[0.5], "from_85pct": real[0.85]},
        "simulated_from_half": {str(f): tp.simulated_errors(f, regress)[0] for f in (0.5, 0.65, 0.8, 1.0)},
    }


def grid_point(point: tuple[float, float]) -> dict:
    """Every finished committed run's record under one grid point."""
    runs = {run: replay(run, *point) for run in committed_runs()}
    return {"runs": {run: record for run, record in runs.items() if record is not None}, **other_checks(*point)}


def summary(records: dict) -> dict:
    """Counts over the tests' runs and the others: guards met (50% from 5%, 40% from half, band 90%), mean error."""
    out = {}
    for name, keep in (("tests_runs", True), ("other_runs", False)):
        chosen = [v for run, v in records.items() if (run in tp.COMMITTED_RUNS) == keep]
        out[name] = {
            "runs": len(chosen),
            "all_guards_met": int(
                sum(v["from_5pct"] <= 0.5 and v["from_half"] <= 0.4 and v["band_coverage"] >= 0.9 for v in chosen)
            ),
            "within_quarter_from_half": int(sum(v["from_half"] <= 0.25 for v in chosen)),
            "mean_from_half": float(np.mean([v["from_half"] for v in chosen])),
            "worst_from_half": max(v["from_half"] for v in chosen),
        }
    return out


def main() -> None:
    """Replays the grid (two processes) and writes the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", type=Path, default=ROOT / "benchmarks" / "results" / time.strftime("eta-replay-%Y%m%d.json")
    )
    args = parser.parse_args()
    with ProcessPoolExecutor(2) as pool:
        records = dict(zip(GRID, pool.map(grid_point, GRID), strict=True))
    signature = inspect.signature(LearnerEta).parameters
    result = {
        "what": __doc__.split("\n\n")[0],
        "command": "python benchmarks/eta_replay.py",
        "default": {name: signature[name].default for name in ("regress", "regress_weight")},
        "grid": [
            {"regress": r, "regress_weight": w, "summary": summary(records[r, w]["runs"]), **records[r, w]}
            for r, w in GRID
        ],
    }
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    for point in result["grid"]:
        s = point["summary"]
        print(
            f"regress {point['regress']:.2f} weight {point['regress_weight']:.2f} | others: guards "
            f"{s['other_runs']['all_guards_met']}/{s['other_runs']['runs']}, mean from half "
            f"{s['other_runs']['mean_from_half']:.3f} | tests' runs: guards {s['tests_runs']['all_guards_met']}/"
            f"{s['tests_runs']['runs']}, worst from half {s['tests_runs']['worst_from_half']:.2f}"
        )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
