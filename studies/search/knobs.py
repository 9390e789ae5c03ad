"""The objective D and the no-field damping against each knob of the search, a panel per knob and a point per recipe.

    python studies/search/knobs.py studies/search/stage1_ranking.json studies/search/stage2_ranking.json \
        --design studies/search/stage1.json --out studies/search/knobs

Reads rankings written by `objective.py --out` and the space of the design (its knobs, ranges and scales); writes
OUT.png (two rows: D above, the damping below) and OUT.md, each knob's Spearman rank correlation with D and with the
damping over the recipes of each ranking, so that which knobs matter can be read as numbers as well as seen.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib
import numpy as np
from scipy.stats import spearmanr

from reach_jax.config import hyper

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib import ticker  # noqa: E402

SCRIPT = "studies/search/knobs.py"
FIELD_UNSTABLE = 15.9  # the viscous field's push along its unstable axis [N s/m] (docs/model.md §6)
MARKERS = "os^D"  # one per ranking given, in order


def knob_value(label: dict[str, float], name: str) -> float:
    """A knob's value in a recipe label (`hyper.label` leaves out those at their neutral value)."""
    return float(label[name]) if name in label else float(hyper.BY_NAME[name].neutral)


def plotted(label: dict[str, float], knob: dict) -> float:
    """Where a recipe sits on a knob's axis: its value, or for a "log1m" knob (λ) the horizon 1 / (1 - value)."""
    v = knob_value(label, knob["name"])
    return 1.0 / (1.0 - v) if knob["scale"] == "log1m" else v


def table(rankings: list[dict], space: list[dict]) -> list[dict]:
    """Per ranking and knob: Spearman's rho of the knob with D and with the damping, over the ranking's recipes."""
    rows = []
    for k, ranking in enumerate(rankings):
        recs = ranking["ranked"]
        d = np.array([r["D"] for r in recs])
        damping = np.array([np.nan if r["damping_none"] is None else r["damping_none"] for r in recs])
        for s in space:
            x = np.array([knob_value(r["hypers"], s["name"]) for r in recs])
            has = ~np.isnan(damping)
            rows.append(
                {
                    "ranking": k,
                    "knob": s["name"],
                    "recipes": len(recs),
                    "rho_D": float(spearmanr(x, d).statistic),
                    "rho_damping": float(spearmanr(x[has], damping[has]).statistic),
                }
            )
    return rows


def figure(rankings: list[dict], names: list[str], space: list[dict], path: Path) -> None:
    """Two rows of a panel per knob: D, then the no-field damping, a point per recipe, a marker per ranking."""
    fig, axes = plt.subplots(2, len(space), figsize=(2.1 * len(space), 5.2), sharey="row", squeeze=False)
    for j, s in enumerate(space):
        for k, (ranking, name) in enumerate(zip(rankings, names, strict=True)):
            recs = ranking["ranked"]
            x = [plotted(r["hypers"], s) for r in recs]
            ys = ([r["D"] for r in recs], [np.nan if r["damping_none"] is None else r["damping_none"] for r in recs])
            is_default = [not r["knobs"] for r in recs]  # no knob off its default
            for row, y in enumerate(ys):
                marker = MARKERS[k % len(MARKERS)]
                axes[row, j].plot(x, y, marker, ms=4, mfc="none", label=name if j == 0 else None)
                # The default filled, so that every panel shows where it sits.
                xd = [xi for xi, d in zip(x, is_default, strict=True) if d]
                yd = [yi for yi, d in zip(y, is_default, strict=True) if d]
                label = "the default" if j == k == 0 else None
                axes[row, j].plot(xd, yd, marker, ms=5, color="k", label=label if xd else None)
        if s["scale"] != "linear":
            for row in range(2):
                axes[row, j].set_xscale("log")
                axes[row, j].xaxis.set_major_locator(ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
                axes[row, j].xaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
                axes[row, j].xaxis.set_minor_formatter(ticker.NullFormatter())
        axes[1, j].axhline(FIELD_UNSTABLE, color="0.5", lw=0.8, ls="--")
        axes[1, j].set_xlabel(s["name"] + (": 1/(1−λ)" if s["scale"] == "log1m" else ""), fontsize=8)
        for row in range(2):
            axes[row, j].tick_params(labelsize=7)
    axes[0, 0].set_ylabel("D [points]\n(lower is nearer the paper)", fontsize=8)
    axes[1, 0].set_ylabel("no-field damping [N s/m]\n(dashed: the field's +15.9)", fontsize=8)
    axes[0, 0].legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def markdown(rows: list[dict], names: list[str], command: str) -> str:
    """The correlations as a Markdown table, naming the command that made it."""
    lines = [
        f"Generated by `{command}`. Spearman's rank correlation of each knob with D (lower D is nearer the paper) and"
        " with the no-field networks' damping along the field's unstable axis, over each ranking's recipes.",
        "",
        "| ranking | recipes | knob | ρ with D | ρ with damping |",
        "|---|---|---|---|---|",
        *(
            f"| {names[r['ranking']]} | {r['recipes']} | `{r['knob']}` | {r['rho_D']:+.2f} | {r['rho_damping']:+.2f} |"
            for r in rows
        ),
    ]
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("rankings", nargs="+", type=Path, help="objective.py's OUT.json of each stage")
    p.add_argument("--design", type=Path, required=True, help="the design whose space (knobs, scales) is plotted")
    p.add_argument("--out", type=Path, required=True, help="output stem: writes OUT.png and OUT.md")
    args = p.parse_args(argv)
    rankings = [json.loads(r.read_text()) for r in args.rankings]
    names = [r.stem for r in args.rankings]
    space = json.loads(args.design.read_text())["space"]
    command = f"python {SCRIPT} " + " ".join(map(str, args.rankings)) + f" --design {args.design} --out {args.out}"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    figure(rankings, names, space, args.out.with_suffix(".png"))
    text = markdown(table(rankings, space), names, command)
    args.out.with_suffix(".md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
