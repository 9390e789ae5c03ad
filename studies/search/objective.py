"""Round 4's objective and ranking (studies/search/PLAN.md): each recipe's distance D to the paper's Table 2.

    python studies/search/objective.py runs/search_stage1 --out studies/search/stage1_ranking
    python studies/search/objective.py runs/heldout          # D of the default's held-out run: 24.4

D is the mean over the paper's 8 Table-2 cells of |success − paper| + |out − paper| in percentage points, a
recipe's success and out in a cell being the means over its networks of each network's rate (`eval/claims.json`;
`reach_jax.evaluate.plausibility.distance`).
Ranked by D; recipes within TIE_POINTS of each other by stable share, then by fewer knobs off their defaults.
Beside D: the claims' verdicts, the cells near the paper, the stable share, the no-field damping along the field's
unstable axis and the time ratio of none → viscous to none → none. With --out, writes OUT.md and OUT.json.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from reach_jax.config import hyper
from reach_jax.evaluate.plausibility import distance
from reach_jax.store import run_dir

ROUND_DEFAULTS = hyper.defaults(8)  # the default recipe while the rounds ran: config version 8, before round 4's pick

SCRIPT = "studies/search/objective.py"
TIE_POINTS = 0.5  # recipes whose D differ by less than this are tied (PLAN.md)
VERDICT_WORDS = {"holds": "yes", "holds in part": "part", "does not hold": "no"}


def short_learners(run: Path) -> list[int]:
    """The learners of a run that ended below its trial budget (PLAN.md ranks a run only at its full length)."""
    budget = float(run_dir.read_config(run).train.trials)
    trials: dict[int, float] = {}
    for row in run_dir.read_metrics(run):
        trials[row["learner"]] = max(trials.get(row["learner"], 0.0), row["trials"])
    return sorted(k for k, t in trials.items() if t < budget)


def require_finished(run: Path) -> None:
    """Exits with a one-line error when a run has learners below its trial budget."""
    if short := short_learners(run):
        raise SystemExit(
            f"{SCRIPT}: {run} has not finished: {len(short)} learners below its trial budget (first: {short[0]});"
            f" resume it with python -m reach_jax.train --resume {run}, then evaluate it again"
        )


def records(run: Path) -> list[dict]:
    """One record per recipe of an evaluated run: D and what is reported beside it."""
    data = json.loads((run / "eval" / "claims.json").read_text())
    out = []
    for k, recipe in enumerate(data["recipes"]):
        cells = {(c["learning"], c["test"]): c for c in recipe["cells"]}
        learners = recipe["curriculum"]["learners"]
        damping = next(
            (
                c["damping_unstable"]["mean"]
                for c in recipe["impedance"]
                if (c["learning"], c["test"]) == ("none", "none")
            ),
            None,
        )
        times = [cells.get(("none", t), {}).get("mean_time_s", {}).get("mean") for t in ("viscous", "none")]
        out.append(
            {
                "run": str(run),
                "recipe": k,
                "hypers": recipe["hypers"],
                "knobs": hyper.changed(recipe["hypers"], ROUND_DEFAULTS),
                "networks": recipe["networks_per_condition"],
                "D": distance(recipe["cells"]),
                "stable": sum(p["stable"] for p in learners) / len(learners),
                "verdicts": {c["claim"]: c["verdict"] for c in recipe["claims"]},
                "cells_near": sum(bool(c["near_paper"]) and all(c["near_paper"].values()) for c in recipe["cells"]),
                "none_viscous": {k: cells[("none", "viscous")][k]["mean"] for k in ("success", "out")},
                "damping_none": damping,
                "time_ratio": times[0] / times[1] if None not in times else None,
            }
        )
    return out


def ranked(recs: list[dict]) -> list[dict]:
    """Records best first: lowest D, ties within TIE_POINTS by stable share, then by fewer knobs changed."""
    by_d = sorted(recs, key=lambda r: r["D"])
    groups: list[list[dict]] = []
    for r in by_d:
        if groups and r["D"] - groups[-1][0]["D"] < TIE_POINTS:
            groups[-1].append(r)
        else:
            groups.append([r])
    return [r for g in groups for r in sorted(g, key=lambda r: (-r["stable"], len(r["knobs"]), r["D"]))]


def _row(place: int, r: dict) -> str:
    verdicts = " ".join(f"{k}:{VERDICT_WORDS[v]}" for k, v in sorted(r["verdicts"].items()))
    damping = "–" if r["damping_none"] is None else f"{r['damping_none']:.1f}"
    ratio = "–" if r["time_ratio"] is None else f"{r['time_ratio']:.2f}"
    nv = r["none_viscous"]
    return (
        f"| {place} | `{r['run']}` {r['recipe']} | {r['D']:.1f} | {r['stable']:.0%} | {r['cells_near']}/8 |"
        f" {verdicts} | {100 * nv['success']:.1f} / {100 * nv['out']:.1f} | {ratio} | {damping} |"
        f" {hyper.describe(r['hypers'], ROUND_DEFAULTS)} |"
    )


def markdown(recs: list[dict], command: str) -> str:
    """The ranking as Markdown, naming the command that made it."""
    lines = [
        f"Generated by `{command}` from each run's `eval/claims.json` (studies/search/PLAN.md). D: the mean over the"
        " 8 Table-2 cells of |success − paper| + |out − paper| [points], lower is nearer; ties within"
        f" {TIE_POINTS} points by stable share. none → viscous: success / out %; the paper 54.8 / 44.5. Time ratio:"
        " none → viscous over none → none (the paper 6.3). Damping: the no-field networks' along the field's unstable"
        " axis [N s/m] (the field pushes at +15.9).",
        "",
        "| rank | run, recipe | D | stable | cells near | claims | none → viscous | time ratio | damping | recipe |",
        "|---|---|---|---|---|---|---|---|---|---|",
        *(_row(i + 1, r) for i, r in enumerate(recs)),
    ]
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", type=Path, help="evaluated runs whose recipes are ranked together")
    p.add_argument("--out", type=Path, help="writes OUT.md and OUT.json")
    args = p.parse_args(argv)
    for run in args.runs:
        require_finished(run)
    recs = ranked([r for run in args.runs for r in records(run)])
    command = f"python {SCRIPT} " + " ".join(map(str, args.runs)) + (f" --out {args.out}" if args.out else "")
    text = markdown(recs, command)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.with_suffix(".md").write_text(text)
        args.out.with_suffix(".json").write_text(json.dumps({"command": command, "ranked": recs}, indent=1) + "\n")
    print(text)


if __name__ == "__main__":
    main()
