"""Runs side by side: one row per frame of the field and recipe of each evaluated run, from its `eval/claims.json`.

    python -m reach_jax.evaluate.compare RUN_DIR [RUN_DIR ...] [--json FILE]

A row holds the frame it judges (the condition that stands for the paper's field, `frames`; "–" for an evaluation
made before frames, which judged "viscous"), the recipe in words (`config.hyper.describe`), its networks per
condition, the verdict of each claim, the Table-2 cells near the paper's, D and the paper's plausibility
(`plausibility`), the learners that stayed at the whole field late in training, the networks that collapsed
(`collapse`), the unexpected field's cell (no-field networks tested in the viscous field) and the learned hand
damping along the field's unstable axis without the field, per learning condition. Nothing is recomputed: the rows
are the run's own evaluation, so runs evaluated by any version of the code compare as they were decided; the
collapsed networks of an evaluation made before they were named come from its `eval/table2.json`, and D and the
plausibility of one made before them from its cells' per-network values.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from reach_jax.config import Config, hyper
from reach_jax.errors import EXIT_IO, EXIT_USAGE, Parser, UsageError, error_line
from reach_jax.evaluate import collapse, plausibility, report
from reach_jax.store import run_dir as run_dir_io

CLAIMS = "eval/claims.json"  # each run's decided claims, written by `python -m reach_jax.evaluate`
CONDITIONS = ("none", "viscous", "random", "random_nopast")  # the learning conditions, in the paper's order
SHORT = {"holds": "holds", "holds in part": "part", "does not hold": "no"}  # a verdict in a table cell


def recipe_rows(run_dir: Path) -> list[dict]:
    """One record per frame and recipe of an evaluated run; raises FileNotFoundError without `eval/claims.json`.

    A record holds the run, the `frame` (None before frames), the recipe's index and words, `networks`, `chunk`,
    `verdicts` (claim number ->
    verdict), `cells_near` of the `cells` the paper has, `D` [points], `plausible_cells` (None with too few
    networks) and `plausible` (the paper's table as a whole; None likewise), `stable` of `judged` learners (None:
    none judged yet),
    `collapsed` (the collapsed networks' names, `collapse.names`; "" for none, None where unknown),
    `none_viscous` (mean success and out per network, fractions) and `damping` (learning condition -> mean damping
    along the field's unstable axis [N s/m]).

    Args:
        run_dir: a run directory that `python -m reach_jax.evaluate` has evaluated.
    """
    data = json.loads((Path(run_dir) / CLAIMS).read_text())
    rows = []
    for frame, decided in {data.get("frame"): data, **data.get("frames", {})}.items():
        rows += _frame_rows(run_dir, frame, {**decided, "chunk": data["chunk"]})
    return rows


def _frame_rows(run_dir: Path, frame: str | None, data: dict) -> list[dict]:
    """`recipe_rows` of one frame's decided recipes (`data`, with the evaluated chunk)."""
    rows = []
    collapsed = collapsed_of(Path(run_dir), data)
    for k, recipe in enumerate(data["recipes"]):
        judged = [p for p in recipe["curriculum"]["learners"] if p["tail_chunks"]]
        judged_cells, near = report.paper_cells(recipe["cells"])
        field = next((c for c in recipe["cells"] if (c["learning"], c["test"]) == ("none", "viscous")), None)
        if "D" not in recipe:  # evaluated before D and the plausibility were written: from the cells' values
            recipe = {
                **recipe,
                "D": plausibility.distance(recipe["cells"]),
                "plausibility": plausibility.judge(recipe["cells"], recipe["level"]),
            }
        record = recipe["plausibility"]
        rows.append(
            {
                "run": str(run_dir),
                "frame": frame,
                "recipe": k,
                "words": hyper.describe(recipe["hypers"]),
                "networks": recipe["networks_per_condition"],
                "chunk": data["chunk"],
                "verdicts": {c["claim"]: c["verdict"] for c in recipe["claims"]},
                "cells_near": len(near),
                "cells": len(judged_cells),
                "D": recipe["D"],
                "plausible_cells": None if record is None else record["plausible_cells"],
                "plausible": None if record is None else record["plausible"],
                "stable": sum(p["stable"] for p in judged) if judged else None,
                "judged": len(judged),
                "collapsed": None if collapsed is None else collapse.names([n for n in collapsed if n["recipe"] == k]),
                "none_viscous": None
                if field is None
                else {"success": field["success"]["mean"], "out": field["out"]["mean"]},
                "damping": {
                    c["learning"]: c["damping_unstable"]["mean"] for c in recipe["impedance"] if c["test"] == "none"
                },
            }
        )
    return rows


def collapsed_of(run_dir: Path, claims: dict) -> list[dict] | None:
    """Every recipe's collapsed networks: as the evaluation named them in claims.json, else from its table2.json
    under the run's criteria (the defaults' for a folder without config.json); None without either."""
    if all("collapsed" in r for r in claims["recipes"]):
        return [n for r in claims["recipes"] for n in r["collapsed"]]
    if not (run_dir / "eval" / "table2.json").is_file():
        return None
    cfg = run_dir_io.read_config(run_dir) if run_dir_io.holds_run(run_dir) else Config()
    table = json.loads((run_dir / "eval" / "table2.json").read_text())
    return collapse.of_table(table, cfg)


def markdown(rows: list[dict]) -> str:
    """The records of `recipe_rows` as one Markdown table, with a line that says how to read it."""
    lines = [
        "Frame: the condition that stands for the paper's field (– before frames: viscous). "
        "Claims: holds / part (holds in part) / no. Near: Table-2 cells within the target. D: mean distance to the "
        "paper's cells, points. Plausible: cells where the paper lies in the range of our networks' pairs, and "
        "whether its D is plausible for two networks of ours (docs/claims.md; – below 3 networks). Stable: of the "
        "learners in their last 20% of trials, those that stayed at the whole field. Collapsed: networks below 50% "
        "success in their own condition's test (the null field's for random forces). none → viscous: mean success / "
        "out per network in the frame's field (paper 55% / 45%). Damping: mean learned hand damping along the frame's "
        "unstable axis, no field, N s/m, per learning condition (none / the frame's field / random / random_nopast; "
        "the field's eigenvalue there is +15.9).",
        "",
        "| run | frame | recipe | exploration | seeds | chunk | 1 | 2 | 3 | 4 | 5 | near | D | plausible | stable "
        "| collapsed | none → viscous | damping |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        verdicts = " | ".join(SHORT[r["verdicts"][k]] if k in r["verdicts"] else "–" for k in range(1, 6))
        stable = "not yet judged" if r["stable"] is None else f"{r['stable']}/{r['judged']}"
        field = r["none_viscous"]
        field = "–" if field is None else f"{100 * field['success']:.0f}% / {100 * field['out']:.0f}%"
        collapsed = "–" if r["collapsed"] is None else r["collapsed"] or "none"
        damping = " / ".join(f"{r['damping'][c]:.0f}" for c in CONDITIONS if c in r["damping"])
        d = "–" if r["D"] is None else f"{r['D']:.1f}"
        plausible = "–"
        if r["plausible"] is not None:
            plausible = f"{r['plausible_cells']}/{r['cells']}, table {'yes' if r['plausible'] else 'no'}"
        lines.append(
            f"| `{r['run']}` | {r['frame'] or '–'} | {r['recipe']} | {r['words']} | {r['networks']} | {r['chunk']} | "
            f"{verdicts} | {r['cells_near']}/{r['cells']} | {d} | {plausible} | {stable} | {collapsed} | {field} | "
            f"{damping} |"
        )
    return "\n".join(lines) + "\n"


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface of `python -m reach_jax.evaluate.compare`."""
    p = Parser(prog="python -m reach_jax.evaluate.compare", description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", type=Path, metavar="RUN_DIR", help="evaluated run directories")
    p.add_argument("--json", type=Path, metavar="FILE", help="also write the rows as JSON to FILE")
    return p


def main(argv=None) -> int:
    """`python -m reach_jax.evaluate.compare`: the table on stdout; returns the exit status."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        missing = [str(r) for r in args.runs if not (r / CLAIMS).is_file()]
        if missing:
            raise UsageError(f"no {CLAIMS} in {', '.join(missing)} (run python -m reach_jax.evaluate RUN_DIR first)")
        rows = []
        for run in args.runs:
            try:
                rows += recipe_rows(run)
            except (ValueError, KeyError, TypeError) as exc:  # not JSON, or not the evaluation's
                raise UsageError(f"{run / CLAIMS} cannot be read: {type(exc).__name__}: {exc}") from None
    except UsageError as exc:
        sys.stderr.write(error_line(parser.prog, str(exc)))
        return EXIT_USAGE
    if args.json:
        try:
            args.json.write_text(json.dumps(rows, indent=1) + "\n")
        except OSError as exc:
            sys.stderr.write(error_line(parser.prog, f"{args.json}: write failed ({exc})"))
            return EXIT_IO
    words = " ".join(str(r) for r in args.runs)
    sys.stdout.write(f"Generated by `python -m reach_jax.evaluate.compare {words}` from each run's `{CLAIMS}`.\n")
    sys.stdout.write(markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
