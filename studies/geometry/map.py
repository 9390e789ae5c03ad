"""Issue 62's geometry map, from an evaluated run of several visual fields (studies/geometry/README.md).

    python studies/geometry/map.py runs/geometry_map --out studies/geometry/map

One point per visual field and recipe, read in the mirrored frame from `eval/geometry_<k>/` (claims.json and
anatomy.json): D, the paper's plausible cells and the table's verdict, the claims, the unexpected field's cell
(none -> field, success / out / fail %, and the share of its movements that end folded on the elbow stop), the
no-field networks' learned damping along the field's pushing axis [N s/m] (the passive arm's beside it), stability
and collapses. Across points, per no-field network: Spearman's rho of that damping against the share of its
movements that the unexpected field throws out. Writes OUT.json, OUT.md and OUT.png (the fields drawn where they
sit, coloured by D, by the outs, by the folds; the damping against the outs).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from scipy import stats

from reach_jax.evaluate import anatomy, frames, geometry

SCRIPT = "studies/geometry/map.py"
FRAME = "viscous_mirror"  # the frame the map judges (config version 14's default)
BASE_CELL, BASE_NOISE = 0.04, 0.2  # [m], bound: the points that vary only the position, drawn as a heat map
PANELS = (("D", "D [points]", "viridis_r"), ("out", "none → field out %", "magma_r"), ("fold", "folded %", "magma_r"))


def _by_cell(rows: list[dict]) -> dict:
    return {(c["learning"], c["test"]): c for c in rows}


def points(run: Path) -> list[dict]:
    """One record per visual field and recipe of an evaluated run, in the frame FRAME."""
    index = json.loads((run / "eval" / f"{geometry.INDEX}.json").read_text())
    out = []
    for f in index["fields"]:
        sub = run / "eval" / f["folder"]
        claims = json.loads((sub / "claims.json").read_text())
        decided = {claims["frame"]: claims, **claims["frames"]}[FRAME]
        anat = anatomy.by_frame(json.loads((sub / "anatomy.json").read_text()))[FRAME]
        for r, recipe in enumerate(decided["recipes"]):
            field = _by_cell(recipe["cells"])[("none", frames.PAPER_FIELD)]  # a frame's field stands for the paper's
            moves = _by_cell(anat[r]["cells"])[("none", frames.PAPER_FIELD)]["shares"]
            damping = _by_cell(recipe["impedance"])[("none", "none")]
            plaus = recipe.get("plausibility") or {}
            learners = recipe["curriculum"]["learners"]
            out.append(
                {
                    "folder": f["folder"],
                    "recipe": r,
                    "centre_m": f["centre_m"],
                    "cell_m": f["cell_m"],
                    "noise": recipe["hypers"]["noise"],
                    "D": recipe["D"],
                    "plausible_cells": plaus.get("plausible_cells"),
                    "table_plausible": plaus.get("plausible"),
                    "claims": {c["claim"]: c["verdict"] for c in recipe["claims"]},
                    "holding": sum(c["verdict"] == "holds" for c in recipe["claims"]),
                    "none_field": {k: 100 * field[k]["mean"] for k in ("success", "out")},
                    "none_field_folded": 100 * moves["folded"]["mean"],
                    "none_field_out_per_network": [100 * v for v in field["out"]["values"]],
                    "damping": damping["damping_unstable"]["mean"],
                    "damping_per_network": damping["damping_unstable"]["values"],
                    "passive_damping": damping["passive_damping_unstable"]["mean"],
                    "stable": sum(p["stable"] for p in learners),
                    "learners": len(learners),
                    "collapsed": len(recipe["collapsed"]),
                }
            )
    return out


def explained(pts: list[dict]) -> dict:
    """Spearman's rho, over every no-field network of every point, of its damping against its outs in the field."""
    damping = [d for p in pts for d in p["damping_per_network"]]
    outs = [o for p in pts for o in p["none_field_out_per_network"]]
    rho = stats.spearmanr(damping, outs).statistic if len(set(damping)) > 1 and len(set(outs)) > 1 else None
    return {"networks": len(damping), "rho_damping_out": None if rho is None else float(rho)}


def _words(p: dict) -> str:
    plaus = "–" if p["plausible_cells"] is None else f"{p['plausible_cells']} of 8"
    nf = p["none_field"]
    return (
        f"| ({p['centre_m'][0]:+.3f}, {p['centre_m'][1]:.3f}) | {p['cell_m']:.3f} | {p['noise']:g} | {p['D']:.1f} | "
        f"{plaus} | {p['holding']} | {nf['success']:.1f} / {nf['out']:.1f} | {p['none_field_folded']:.1f} | "
        f"{p['damping']:.1f} ({p['passive_damping']:.1f}) | {p['stable']}/{p['learners']} | {p['collapsed']} |"
    )


def markdown(pts: list[dict], found: dict, command: str) -> str:
    """OUT.md: the points, lowest D first, and what explains the outs."""
    rho = found["rho_damping_out"]
    rho_text = "–" if rho is None else f"{rho:+.2f}"
    lines = [
        f"# The geometry map, frame {FRAME}",
        "",
        f"Made by `{command}`. One row per visual field and recipe, lowest D first: D in points from the paper's "
        "Table 2, the paper's cells plausible as a two-network draw from ours (– where a condition has too few "
        "networks for it), the claims that hold, the unexpected field's cell (none → field success / out %, and the "
        "% of its movements that end folded on the elbow stop), "
        "the no-field networks' learned damping along the field's pushing axis [N s/m] (the passive arm's), the "
        "stable learners and the collapsed networks.",
        "",
        "| centre [m] | cell [m] | bound | D | plausible | claims holding | none → field S / O % | folded % "
        "| damping (passive) | stable | collapsed |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
        *(_words(p) for p in sorted(pts, key=lambda p: p["D"])),
        "",
        f"Across the {found['networks']} no-field networks of every point, Spearman's ρ of the learned damping along "
        f"the pushing axis against the share of movements the unexpected field throws out: {rho_text}.",
    ]
    return "\n".join(lines) + "\n"


def _is_base(p: dict) -> bool:
    return bool(np.isclose(p["cell_m"], BASE_CELL) and np.isclose(p["noise"], BASE_NOISE))


def _value(p: dict, key: str) -> float:
    return {"D": p["D"], "out": p["none_field"]["out"], "fold": p["none_field_folded"]}[key]


def _heat(ax, pts: list[dict], key: str, label: str, cmap: str, fig: Figure) -> None:
    """One measure over the positions, as a grid of centres (lateral x forward), its values written in."""
    xs = sorted({p["centre_m"][0] for p in pts})
    ys = sorted({p["centre_m"][1] for p in pts})
    grid = np.full((len(ys), len(xs)), np.nan)
    for p in pts:
        grid[ys.index(p["centre_m"][1]), xs.index(p["centre_m"][0])] = _value(p, key)
    image = ax.imshow(grid, origin="lower", cmap=cmap, aspect="auto")
    for (i, j), v in np.ndenumerate(grid):
        if not np.isnan(v):
            ax.text(j, i, f"{v:.1f}", ha="center", va="center", fontsize=9, bbox={"fc": "w", "alpha": 0.7, "lw": 0})
    ax.set_xticks(range(len(xs)), [f"{x:+.3f}" for x in xs])
    ax.set_yticks(range(len(ys)), [f"{y:.2f}" for y in ys])
    ax.set(xlabel="field centre, lateral x [m]", ylabel="field centre, forward y [m]", title=f"{label}, by position")
    fig.colorbar(image, ax=ax, label=label)


def _variants(ax, pts: list[dict], key: str, label: str) -> None:
    """One measure at each centre that a size or a bound varies: today's cell and bound, then each variant."""
    base = {tuple(p["centre_m"]): p for p in pts if _is_base(p)}
    others = [p for p in pts if not _is_base(p)]
    names, values = [], []
    for c in dict.fromkeys(tuple(p["centre_m"]) for p in others):
        at = [base[c]] if c in base else []
        for p in at + [q for q in others if tuple(q["centre_m"]) == c]:
            what = (
                "today's"
                if _is_base(p)
                else (f"bound {p['noise']:g}" if np.isclose(p["cell_m"], BASE_CELL) else f"cell {p['cell_m']:.3f}")
            )
            names.append(f"({c[0]:+.3f}, {c[1]:.2f}) {what}")
            values.append(_value(p, key))
    bars = ax.barh(range(len(values)), values, color=["0.6" if n.endswith("today's") else "C0" for n in names])
    ax.bar_label(bars, fmt="%.1f", fontsize=7)
    ax.set_yticks(range(len(names)), names, fontsize=7)
    ax.invert_yaxis()
    ax.set(xlabel=label, title=f"{label}, sizes and bounds (grey: today's)")


def figure(pts: list[dict]) -> Figure:
    """Heat maps of D, the unexpected field's outs and folds over the positions; the sizes and bounds beside their
    centres; each no-field network's damping against its outs."""
    fig = Figure(figsize=(15, 11), layout="constrained")
    axes = fig.subplots(3, 3)
    positions = [p for p in pts if _is_base(p)]
    for col, (key, label, cmap) in enumerate(PANELS):
        _heat(axes[0, col], positions, key, label, cmap, fig)
        _variants(axes[1, col], pts, key, label)
    for ax in axes[2, 1:]:
        ax.remove()
    ax = axes[2, 0]
    for p in pts:
        ax.scatter(p["damping_per_network"], p["none_field_out_per_network"], s=18)
    ax.set(xlabel="no-field damping along the pushing axis [N s/m]", ylabel="none → field out %", title="per network")
    return fig


def main(argv=None) -> None:
    """Command line."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", type=Path, help="an evaluated run of several visual fields")
    p.add_argument("--out", type=Path, required=True, help="write OUT.json, OUT.md and OUT.png")
    args = p.parse_args(argv)
    pts = points(args.run)
    found = explained(pts)
    command = f"python {SCRIPT} {args.run} --out {args.out}"
    args.out.with_suffix(".json").write_text(json.dumps({"points": pts, **found}, indent=2) + "\n")
    args.out.with_suffix(".md").write_text(markdown(pts, found, command))
    figure(pts).savefig(args.out.with_suffix(".png"), dpi=90)


if __name__ == "__main__":
    main()
