"""The exploration trade-off as one table and one figure, from the committed claims.json of runs (issue 20 §4).

    python studies/exploration/exploration_map.py runs/heldout runs/table2 runs/dev_anneal runs/dev_gradual \
        runs/dev_delayed runs/screen --out studies/exploration/exploration_map

Writes OUT.md (the table), OUT.json (its rows) and OUT.png (the figure).

Per recipe of each run: the exploration it used, the learned hand damping along the viscous field's unstable
axis (no field) of each learning condition, the none -> viscous cell, the after-effect, the field's cost to
random-force and no-past networks, and how many learners stayed at the whole field late in training. The
figure puts the no-field networks' damping on the x axis: the field (+15.9 N s/m along that axis) can throw an
arm out only where the learned plus passive damping falls below it. Its last panel, and a line under the table,
take the same comparison network by network: each no-field network's damping against what the field costs it.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib
import numpy as np

from reach_jax.config import hyper
from reach_jax.evaluate import figures

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

# One baseline for every row, the default while the rounds ran (config version 8), so that a recipe of any era
# names its knobs in the same words.
ROUND_DEFAULTS = hyper.defaults(8)
SCRIPT = "studies/exploration/exploration_map.py"  # how its outputs name the command that made them

FIELD_UNSTABLE = 15.9  # the viscous field's eigenvalue along its unstable axis [N s/m] (docs/model.md §6)
PAPER_NONE_VISCOUS = 0.548  # the paper's none -> viscous success per network (1139 of 2080)
PAPER_FIELD_COST = 44.8  # the paper's success lost to an unexpected field by its no-field networks [points]
FULL_TRIALS = 2_000_000  # a full-length run (the paper's trials per network); shorter ones are screens


def _mean(cell: dict | None, name: str) -> float | None:
    return None if cell is None else cell[name]["mean"]


def recipe_rows(run: Path) -> list[dict]:
    """One record per recipe of a run, from its eval/claims.json."""
    data = json.loads((run / "eval" / "claims.json").read_text())
    table = json.loads((run / "eval" / "table2.json").read_text())
    learning = {r["learner"]: r["learning"] for r in table["per_network"]}
    rows = []
    for k, recipe in enumerate(data["recipes"]):
        cells = {(c["learning"], c["test"]): c for c in recipe["cells"]}
        damping = {c["learning"]: c["damping_unstable"]["mean"] for c in recipe["impedance"] if c["test"] == "none"}

        def drop(learning, cells=cells):
            on, off = cells.get((learning, "viscous")), cells.get((learning, "none"))
            return None if on is None or off is None else on["success"]["mean"] - off["success"]["mean"]

        after = {c["claim"]: c for c in recipe["claims"]}.get(3)
        judged = [p for p in recipe["curriculum"]["learners"] if p["tail_chunks"]]
        forced = [p for p in judged if learning[p["learner"]].startswith("random")]
        rows.append(
            {
                "run": str(run),
                "recipe": k,
                "exploration": hyper.describe(recipe["hypers"], ROUND_DEFAULTS),
                "networks": recipe["networks_per_condition"],
                "damping": damping,
                "none_viscous_success": _mean(cells.get(("none", "viscous")), "success"),
                "none_viscous_out": _mean(cells.get(("none", "viscous")), "out"),
                "aftereffect_success": None if after is None else after["numbers"]["success_change"]["mean"],
                "aftereffect_time": None if after is None else after["numbers"]["time_ratio"]["mean"],
                "field_cost": {c: drop(c) for c in ("none", "random", "random_nopast")},
                "stable": sum(p["stable"] for p in judged),
                "judged": len(judged),
                "stable_random": sum(p["stable"] for p in forced),
                "judged_random": len(forced),
            }
        )
    return rows


def network_points(run: Path) -> list[dict]:
    """One record per no-field network of a run: its damping along the unstable axis and the field's cost to it."""
    claims = json.loads((run / "eval" / "claims.json").read_text())
    impedance = json.loads((run / "eval" / "impedance.json").read_text())["per_network"]
    table = json.loads((run / "eval" / "table2.json").read_text())["per_network"]
    damping = {n["learner"]: n["damping_unstable"]["median"] for n in impedance if n["learning"] == n["test"] == "none"}
    cells = {(t["learner"], t["test"]): t for t in table if t["learning"] == "none"}
    points = []
    for learner, d in sorted(damping.items()):
        on, off = cells.get((learner, "viscous")), cells.get((learner, "none"))
        if on is None or off is None:
            continue
        pairs = on["success"] + on["out"] + on["fail"]
        points.append(
            {
                "run": str(run),
                "learner": learner,
                "full_length": claims["trials_per_network"] >= FULL_TRIALS,
                "damping": d,
                "success_lost": (off["success"] - on["success"]) / pairs,
                "out": on["out"] / pairs,
            }
        )
    return points


def _ranks(x: np.ndarray) -> np.ndarray:
    """Ranks 1..n, ties sharing their mean rank."""
    order = np.argsort(x, kind="stable")
    ranks = np.empty(len(x))
    ranks[order] = np.arange(1, len(x) + 1)
    for value in np.unique(x):
        tied = x == value
        ranks[tied] = ranks[tied].mean()
    return ranks


def network_summary(points: list[dict]) -> dict:
    """Spearman's rank correlation of damping with the success that the field costs and with the outs, and both
    means on either side of the field's +15.9 N s/m, over the given no-field networks."""
    d = np.array([p["damping"] for p in points])
    lost = np.array([p["success_lost"] for p in points])
    out = np.array([p["out"] for p in points])
    below = d < FIELD_UNSTABLE

    def rho(y):
        return float(np.corrcoef(_ranks(d), _ranks(y))[0, 1])

    return {
        "networks": len(points),
        "below": int(below.sum()),
        "rho_lost": rho(lost),
        "rho_out": rho(out),
        "lost_below": float(lost[below].mean()) if below.any() else None,
        "lost_above": float(lost[~below].mean()) if (~below).any() else None,
        "out_below": float(out[below].mean()) if below.any() else None,
        "out_above": float(out[~below].mean()) if (~below).any() else None,
    }


def _summary_line(name: str, s: dict) -> str:
    return (
        f"{name}: {s['networks']} networks, {s['below']} below +15.9 N s/m; Spearman ρ of damping with the field's"
        f" cost in success {s['rho_lost']:+.2f}, with its outs {s['rho_out']:+.2f}; below / above +15.9, it costs"
        f" {_num(None if s['lost_below'] is None else 100 * s['lost_below'], '.1f')} /"
        f" {_num(None if s['lost_above'] is None else 100 * s['lost_above'], '.1f')} points with"
        f" {_pct(s['out_below'])} / {_pct(s['out_above'])}% out."
    )


def screen(rows: list[dict]) -> list[dict]:
    """The screening rule fixed before the search (README, second round): a recipe passes when its no-field
    networks' mean damping along the unstable axis is below the field's 15.9 N s/m and every learner was judged
    and stayed at the whole field; those that pass rank by lower none -> viscous success. Returns the rows with
    "passes" and "rank" (1 = best; None for a recipe that fails)."""
    for r in rows:
        compliant = r["damping"].get("none") is not None and r["damping"]["none"] < FIELD_UNSTABLE
        stable = r["judged"] > 0 and r["stable"] == r["judged"]
        r["passes"] = bool(compliant and stable and r["none_viscous_success"] is not None)
    passing = sorted((r for r in rows if r["passes"]), key=lambda r: r["none_viscous_success"])
    for r in rows:
        r["rank"] = passing.index(r) + 1 if r["passes"] else None
    return rows


def _pct(x: float | None) -> str:
    return "–" if x is None else f"{100 * x:.0f}"


def _num(x: float | None, fmt: str = ".0f") -> str:
    return "–" if x is None else format(x, fmt)


def markdown(rows: list[dict], networks: list[dict], command: str) -> str:
    """The map as a Markdown table, with the per-network comparison under it."""
    lines = [
        "**The exploration trade-off**",
        "",
        f"Generated by `{command}` from each run's `eval/claims.json`. Damping: mean learned hand damping along"
        " the field's unstable axis without the field [N s/m], none / random / random_nopast networks (the field"
        " pushes there at +15.9). none → viscous: success / out % per network (paper 55 / 45). After-effect:"
        " viscous → none minus viscous → viscous, success points and time ratio (paper −8.0, 1.70×). Field cost:"
        " success under the field minus without it, points, of none / random / random_nopast networks (paper −44.8"
        " / −9.8 / −34.7). Stable: learners that stayed at the whole field in their last 20% of trials. Screen:"
        " the screening rule (damping of the none networks below 15.9 and every learner stable), with the rank of"
        " those that pass by lower none → viscous success.",
        "",
        "| run | recipe | exploration | seeds | damping | none → viscous | after-effect | field cost | stable"
        " | screen |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        damping = " / ".join(_num(r["damping"].get(c)) for c in ("none", "random", "random_nopast"))
        cost = " / ".join(_num(None if v is None else 100 * v, "+.1f") for v in r["field_cost"].values())
        after = f"{_num(None if r['aftereffect_success'] is None else 100 * r['aftereffect_success'], '+.1f')}, "
        after += "–" if r["aftereffect_time"] is None else f"{r['aftereffect_time']:.2f}×"
        lines.append(
            f"| `{r['run']}` | {r['recipe']} | {r['exploration']} | {r['networks']} | {damping} | "
            f"{_pct(r['none_viscous_success'])} / {_pct(r['none_viscous_out'])} | {after} | {cost} | "
            f"{r['stable']}/{r['judged']} | {'pass, rank ' + str(r['rank']) if r['passes'] else 'no'} |"
        )
    full = [p for p in networks if p["full_length"]]
    lines += [
        "",
        "Network by network (the no-field networks of these runs; the paper's lost"
        f" {PAPER_FIELD_COST:g} points, 45% out):",
        "",
        f"- {_summary_line('all runs', network_summary(networks))}",
    ]
    if full:
        lines.append(f"- {_summary_line('full-length runs only', network_summary(full))}")
    return "\n".join(lines) + "\n"


def _stable_share(r: dict, forced: bool) -> float | None:
    """The share of a recipe's judged learners, with random forces or without, that stayed at the whole field."""
    judged = r["judged_random"] if forced else r["judged"] - r["judged_random"]
    stable = r["stable_random"] if forced else r["stable"] - r["stable_random"]
    return stable / judged if judged else None


def figure(rows: list[dict], networks: list[dict]):
    """Four panels against the no-field networks' damping: per recipe, none -> viscous success, the random-force
    learners' stability, their damping (filled: every no-field learner of the recipe stable; open: not); per
    network, the field's cost to it."""
    fig, axes = plt.subplots(1, 4, figsize=(17, 4.8))
    points = [r for r in rows if r["damping"].get("none") is not None]
    runs = sorted({r["run"] for r in points})
    # Ten colours by four shapes tell up to 40 runs apart.
    colours = {run: plt.cm.tab10(i % 10) for i, run in enumerate(runs)}
    shapes = {run: "o^sD"[i // 10 % 4] for i, run in enumerate(runs)}
    panels = (
        ("none → viscous success [%]", lambda r: r["none_viscous_success"], 100.0, 100 * PAPER_NONE_VISCOUS),
        ("random-force learners stable late in training [%]", lambda r: _stable_share(r, True), 100.0, None),
        ("random-force networks' damping [N s/m]", lambda r: r["damping"].get("random"), 1.0, None),
    )
    for ax, (label, value, scale, paper) in zip(axes[:3], panels, strict=True):
        for r in points:
            y = value(r)
            if y is None:
                continue
            calm = _stable_share(r, False) == 1.0
            face = colours[r["run"]] if calm else "none"
            ax.scatter(
                r["damping"]["none"],
                scale * y,
                facecolors=face,
                edgecolors=colours[r["run"]],
                marker=shapes[r["run"]],
                s=30,
                zorder=3,
            )
        ax.axvline(FIELD_UNSTABLE, color="0.5", ls="--", lw=1)
        if paper is not None:
            ax.axhline(paper, color="tab:red", ls=":", lw=1)
        ax.set_xlabel("no-field networks' damping, unstable axis [N s/m]")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    handles = [
        axes[0].scatter([], [], color=colours[run], marker=shapes[run], label=run.replace("runs/", "")) for run in runs
    ]
    fig.legend(handles=handles, fontsize=7, loc="lower center", ncol=min(len(runs), 12), frameon=False)
    axes[0].text(FIELD_UNSTABLE, 0.02, " field +15.9", fontsize=7, color="0.4", transform=axes[0].get_xaxis_transform())
    ax = axes[3]
    for full, colour, label in ((False, "0.6", "screens (under 2M trials)"), (True, "tab:blue", "full length (2M)")):
        chosen = [p for p in networks if p["full_length"] == full]
        ax.scatter(
            [p["damping"] for p in chosen],
            [100 * p["success_lost"] for p in chosen],
            s=12,
            color=colour,
            label=label,
            zorder=3,
        )
    ax.axvline(FIELD_UNSTABLE, color="0.5", ls="--", lw=1)
    ax.axhline(PAPER_FIELD_COST, color="tab:red", ls=":", lw=1)
    ax.set_xlabel("no-field network's damping, unstable axis [N s/m]")
    ax.set_ylabel("success lost to the field, per network [points]")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.suptitle(
        "Exploration: a compliant arm against stable learning (panels 1-3: one point per recipe; panel 4:"
        " one per no-field network)",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, 0.04 * (1 + (len(runs) - 1) // 12), 1, 1))
    return fig


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", type=Path)
    p.add_argument("--out", type=Path, required=True, help="writes OUT.md, OUT.json and OUT.png")
    args = p.parse_args()
    rows = screen([r for run in args.runs for r in recipe_rows(run)])
    networks = [p for run in args.runs for p in network_points(run)]
    command = f"python {SCRIPT} " + " ".join(str(r) for r in args.runs) + f" --out {args.out}"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    text = markdown(rows, networks, command)
    args.out.with_suffix(".md").write_text(text)
    args.out.with_suffix(".json").write_text(json.dumps({"recipes": rows, "networks": networks}, indent=1) + "\n")
    args.out.with_suffix(".png").write_bytes(figures.png_bytes(figure(rows, networks)))
    print(text)


if __name__ == "__main__":
    main()
