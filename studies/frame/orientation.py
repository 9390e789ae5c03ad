"""What sets the unexpected field's effect: the field turned in steps, against each arm's learned damping (issue 56 §3).

    python studies/frame/orientation.py runs/collapse_heldout runs/heldout runs/heldout_round2 \
        runs/heldout_round3 runs/search_heldout --out studies/frame/orientation

For the no-field networks of each run: the Table-2 test (the 1040 lattice pairs) in the paper's field B turned by
phi, R(phi) B R(phi)^T, for phi = 0, 15, ..., 165 degrees (B is symmetric, so phi and phi + 180 are one field) and
for the turn that gives the mirrored frame (B symmetric, S B S is B turned by 134 degrees), its pushing axis (the
eigenvector of +15.9 N s/m) then at 113 + phi degrees; and the network's hand damping, learned
plus passive, in every direction: the median over the states of its own movements without a field of u^T D u, u
the unit vector at that angle (`impedance.measure`, as the evaluation measures it). A rotation explains the effect;
it is not a knob: only phi = 0 (the frame as applied) and the mirrored frame (B' = S B S, its pushing axis at 67
degrees) are readings of the paper. Writes OUT.json, OUT.md and OUT.png (one polar panel per network: its damping
in every direction, the field's eigenvalue as a dashed circle, and the out share at each pushing axis).
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np
from scipy import stats

from reach_jax.config import condition
from reach_jax.engine import distribute
from reach_jax.env.environment import OUT, SUCCESS
from reach_jax.evaluate import episodes, impedance, lattice
from reach_jax.physics import fields
from reach_jax.store import run_dir as run_dir_io

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

SCRIPT = "studies/frame/orientation.py"
STEP_TURNS = np.arange(0, 180, 15)  # phi [deg]: B turned by each, and by the mirrored frame's turn (`turns`)
PROFILE = np.arange(0, 180, 5)  # directions [deg] in which each network's damping is read
BINS = (0.0, 10.0, 15.9, 25.0, 40.0, np.inf)  # damping along the pushing axis [N s/m], for the table


def turned(b: np.ndarray, phi_deg: float) -> np.ndarray:
    """R(phi) B R(phi)^T: the field with its axes turned by phi [deg] counter-clockwise."""
    c, s = np.cos(np.radians(phi_deg)), np.sin(np.radians(phi_deg))
    r = np.array([[c, -s], [s, c]])
    return r @ b @ r.T


def pushing_axis(b: np.ndarray) -> float:
    """Direction [deg, 0-180] of the eigenvector of B's largest eigenvalue (where the field pushes with the motion)."""
    axis = impedance.field_axes(b)[1][0]
    return float(np.degrees(np.arctan2(axis[1], axis[0])))


def turns(b: np.ndarray, mirrored: np.ndarray) -> np.ndarray:
    """The turns [deg] to test: STEP_TURNS and the one that makes B the mirrored frame's field."""
    mirror = (pushing_axis(mirrored) - pushing_axis(b)) % 180
    np.testing.assert_allclose(turned(b, mirror), mirrored, atol=1e-9)  # a symmetric B: a mirror is a turn
    return np.sort(np.append(STEP_TURNS, mirror))


@functools.cache
def _outcomes(cfg):
    """Compiled (params, masks, fields, starts, targets) -> outcomes (N, C, P) of noise-free test episodes.

    `episodes.run_episodes` without its trajectories: for 13 fields, every step's state of 8 networks is about a
    gigabyte.
    """
    one = functools.partial(episodes.run_episode, episodes.network_policy(cfg), cfg=cfg)
    pairs = jax.vmap(one, in_axes=(None, None, None, 0, 0))
    tests = jax.vmap(pairs, in_axes=(None, None, 0, None, None))
    nets = jax.vmap(tests, in_axes=(0, 0, None, None, None))
    return jax.jit(lambda *a: nets(*a)[0].outcome)


def damping_profiles(data, nets: list[int], cfg) -> tuple[np.ndarray, np.ndarray]:
    """(learned + passive, passive) hand damping [N s/m] of each network along each of PROFILE, (n, len(PROFILE)):
    medians over the states of its own test movements without a field."""
    null = dataclasses.replace(cfg, eval=dataclasses.replace(cfg.eval, test_conditions=("none",), frames=()))
    starts, targets = lattice.test_pairs(cfg)
    params = jax.tree.map(lambda a: a[np.array(nets)], data.batch.states.agent.params)
    masks = np.asarray(data.batch.conds.input_mask)[nets]
    policy = episodes.network_policy(null)
    ep, traj = episodes.run_episodes(policy, params, masks, lattice.test_fields(null), starts, targets, null)
    gains = impedance.measure(policy, params, masks, jax.device_get(ep), jax.device_get(traj), starts, targets, null)
    units = np.stack([np.cos(np.radians(PROFILE)), np.sin(np.radians(PROFILE))], axis=-1)
    total, passive = [], []
    for i in range(len(nets)):
        ok = gains["valid"][i, 0]
        d, p = gains["damping"][i, 0][ok], gains["passive"][i, 0][ok]
        total.append([np.median(impedance.along(d + p, u)) for u in units])
        passive.append([np.median(impedance.along(p, u)) for u in units])
    return np.array(total), np.array(passive)


def run_records(run: Path) -> list[dict]:
    """One record per no-field network of a run: its out and success shares at each turn, and its damping."""
    data = run_dir_io.load(run)
    cfg = data.cfg
    nets = [i for i, (name, _) in enumerate(data.learners) if name == "none"]
    b = np.asarray(condition(cfg, "viscous").viscous)
    phis = turns(b, np.asarray(condition(cfg, "viscous_mirror").viscous))
    specs = [dataclasses.replace(condition(cfg, "viscous"), viscous=tuple(map(tuple, turned(b, p)))) for p in phis]
    stacked = jax.tree.map(lambda *f: jnp.stack(f), *(fields.make_field(s) for s in specs))
    starts, targets = lattice.test_pairs(cfg)
    params = jax.tree.map(lambda a: a[np.array(nets)], data.batch.states.agent.params)
    masks = np.asarray(data.batch.conds.input_mask)[nets]
    args = (params, jnp.asarray(masks), stacked, jnp.asarray(starts), jnp.asarray(targets))
    outcome = np.asarray(_outcomes(cfg)(*args))
    total, passive = damping_profiles(data, nets, cfg)
    recipes, recipe_of = lattice.recipe_index(data.batch.hypers)
    return [
        {
            "run": str(run),
            "learner": i,
            "seed": data.learners[i][1],
            "recipe_index": recipe_of[i],
            "recipe": recipes[recipe_of[i]],
            "turn_deg": phis.tolist(),
            "axis_deg": [pushing_axis(turned(b, p)) for p in phis],
            "out": np.mean(outcome[k] == OUT, axis=-1).tolist(),
            "success": np.mean(outcome[k] == SUCCESS, axis=-1).tolist(),
            "profile_deg": PROFILE.tolist(),
            "damping": total[k].tolist(),
            "passive_damping": passive[k].tolist(),
        }
        for k, i in enumerate(nets)
    ]


def along_axis(rec: dict) -> np.ndarray:
    """A network's damping [N s/m] along the pushing axis of each turn (read off its profile, every 5 degrees)."""
    profile = np.asarray(rec["damping"])
    return np.array([profile[int(round(a / 5)) % len(PROFILE)] for a in rec["axis_deg"]])


def summary(records: list[dict], mirror_axis: float, field_value: float) -> dict:
    """What the map says: out against the damping along the pushing axis, pooled over networks and the 15-degree
    turns (the mirrored frame's turn is reported on its own)."""
    steps = [k for k, t in enumerate(records[0]["turn_deg"]) if t in STEP_TURNS]
    d = np.concatenate([along_axis(r)[steps] for r in records])
    out = np.concatenate([np.asarray(r["out"])[steps] for r in records])
    rho, p = stats.spearmanr(d, out)
    bins = []
    for lo, hi in zip(BINS[:-1], BINS[1:], strict=True):
        sel = (d >= lo) & (d < hi)
        bins.append({"lo": lo, "hi": None if np.isinf(hi) else hi, "cases": int(sel.sum()), "out": _mean(out[sel])})
    frames = {}
    mirror = int(np.argmin([abs(a - mirror_axis) for a in records[0]["axis_deg"]]))
    for name, k in (("as applied", 0), ("mirrored", mirror)):
        frames[name] = {
            "turn_deg": records[0]["turn_deg"][k],
            "axis_deg": records[0]["axis_deg"][k],
            "out": _mean(np.array([r["out"][k] for r in records])),
            "damping_along_axis": _mean(np.array([along_axis(r)[k] for r in records])),
        }
    lowest = [float(np.asarray(r["damping"]).min()) for r in records]
    weakest = [float(PROFILE[int(np.argmin(r["damping"]))]) for r in records]
    return {
        "networks": len(records),
        "spearman_rho": float(rho),
        "spearman_p": float(p),
        "bins": bins,
        "frames": frames,
        "field_eigenvalue": field_value,
        "least_damped_direction_deg": {
            "median": float(np.median(weakest)),
            "q25": float(np.percentile(weakest, 25)),
            "q75": float(np.percentile(weakest, 75)),
        },
        "least_damping": {"median": float(np.median(lowest))},
    }


def _mean(x: np.ndarray) -> float | None:
    return float(np.mean(x)) if x.size else None


def markdown(result: dict, command: str) -> str:
    """The map's table in words."""
    s = result["summary"]
    lines = [
        f"Generated by `{command}`.",
        "",
        f"{s['networks']} no-field networks, each tested on the 1040 lattice pairs in the paper's field turned by"
        " 0-165 degrees in steps of 15. Out share against the network's hand damping (learned plus passive, no"
        f" field) along the turned field's pushing axis (+{s['field_eigenvalue']:.1f} N s/m there):",
        "",
        "| damping along the pushing axis [N s/m] | cases (network × turn) | mean out |",
        "|---|---|---|",
        *(
            f"| {b['lo']:g}–{'' if b['hi'] is None else format(b['hi'], 'g')} | {b['cases']} | "
            + ("–" if b["out"] is None else f"{100 * b['out']:.1f}%")
            + " |"
            for b in s["bins"]
        ),
        "",
        f"Spearman ρ between the damping along the pushing axis and the out share: {s['spearman_rho']:.2f}"
        f" (p = {s['spearman_p']:.1g}). The least damped direction of these arms lies at"
        f" {s['least_damped_direction_deg']['median']:.0f}° (quartiles {s['least_damped_direction_deg']['q25']:.0f}–"
        f"{s['least_damped_direction_deg']['q75']:.0f}°).",
        "",
        "| frame | pushing axis | mean out | mean damping along it [N s/m] |",
        "|---|---|---|---|",
        *(
            f"| {name} (turn {f['turn_deg']:.0f}°) | {f['axis_deg']:.0f}° | {100 * f['out']:.1f}% | "
            f"{f['damping_along_axis']:.1f} |"
            for name, f in s["frames"].items()
        ),
    ]
    return "\n".join(lines) + "\n"


def figure(records: list[dict], field_value: float, axes_deg: dict):
    """One polar panel per network: damping in every direction (both halves), the field's eigenvalue, the out share
    at each pushing axis (colour), the two frames' pushing axes."""
    n = len(records) + 1  # a panel per network, and the pooled scatter, two panels wide
    cols = 8
    rows = -(-(n + 1) // cols)
    fig = plt.figure(figsize=(2.3 * cols, 2.5 * rows + 0.8))
    theta = np.radians(np.concatenate([PROFILE, PROFILE + 180, [360]]))
    for k, rec in enumerate(records):
        ax = fig.add_subplot(rows, cols, k + 1, projection="polar")
        prof = np.asarray(rec["damping"])
        scale = max(float(prof.max()), 2 * field_value)  # each panel its own radius; the field's circle stays visible
        ax.plot(theta, np.concatenate([prof, prof, prof[:1]]), color="0.2", lw=1)
        pas = np.asarray(rec["passive_damping"])
        ax.plot(theta, np.concatenate([pas, pas, pas[:1]]), color="0.6", lw=0.6)
        ax.plot(np.radians(np.arange(361)), np.full(361, field_value), "--", color="tab:blue", lw=0.6)
        axis = np.radians(rec["axis_deg"])
        ax.scatter(
            np.concatenate([axis, axis + np.pi]),
            np.full(2 * len(axis), 0.85 * scale),
            c=np.concatenate([rec["out"], rec["out"]]),
            cmap="Reds",
            vmin=0,
            vmax=1,
            s=14,
            edgecolors="0.4",
            linewidths=0.3,
        )
        for name, deg in axes_deg.items():
            colour = "tab:green" if name == "as applied" else "tab:purple"
            ax.plot([np.radians(deg)] * 2, [0, scale], color=colour, lw=0.8)
        ax.set_ylim(0, scale)
        ax.set_yticklabels([])
        ax.set_xticks(np.radians([0, 90, 180, 270]))
        ax.set_xticklabels(["x", "y", "", ""], fontsize=6)
        ax.set_title(f"{Path(rec['run']).name} r{rec['recipe_index']} s{rec['seed']}", fontsize=7)
    ax = fig.add_subplot(rows, cols, (n, n + 1))
    steps = [i for i, t in enumerate(records[0]["turn_deg"]) if t in STEP_TURNS]
    ax.scatter(
        np.concatenate([along_axis(r)[steps] for r in records]),
        100 * np.concatenate([np.asarray(r["out"])[steps] for r in records]),
        s=4,
        color="tab:red",
        alpha=0.4,
        label="every network and 15° turn",
    )
    turn = records[0]["turn_deg"]
    mirror = next(k for k, t in enumerate(turn) if t not in STEP_TURNS)  # `turns`
    for name, k, color in (("as applied", turn.index(0), "tab:green"), ("mirrored", mirror, "tab:purple")):
        damping, out = [along_axis(r)[k] for r in records], [100 * r["out"][k] for r in records]
        ax.scatter(damping, out, s=9, color=color, label=name)
    ax.axvline(field_value, color="tab:blue", ls="--", lw=0.8)
    ax.legend(fontsize=6)
    ax.set_xlim(0, None)
    ax.set_xlabel("damping along the pushing axis [N s/m]", fontsize=7)
    ax.set_ylabel("out [%]", fontsize=7)
    ax.tick_params(labelsize=6)
    fig.suptitle(
        "No-field networks: hand damping in every direction (black; grey: passive), the field's +15.9 N s/m (dashed),"
        " out share when the field's pushing axis lies at each dot (white 0 – red 100%); green: the pushing axis as"
        " applied (113°), purple: mirrored (67°)",
        fontsize=8,
    )
    fig.tight_layout()
    return fig


def main(argv=None) -> int:
    """Test, measure, write."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", type=Path)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--replot", action="store_true", help="only draw OUT.png again from OUT.json")
    args = p.parse_args(argv)
    if args.replot:
        done = json.loads(args.out.with_suffix(".json").read_text())
        fig = figure(done["records"], done["summary"]["field_eigenvalue"], done["axes_deg"])
        fig.savefig(args.out.with_suffix(".png"), dpi=110)
        return 0
    distribute.setup_backend(1)
    records = [r for run in args.runs for r in run_records(run)]
    cfg = run_dir_io.read_config(args.runs[0])
    b, mirrored = (np.asarray(condition(cfg, n).viscous) for n in ("viscous", "viscous_mirror"))
    field_value = float(np.linalg.eigvalsh(0.5 * (b + b.T))[-1])
    axes = {"as applied": pushing_axis(b), "mirrored": pushing_axis(mirrored)}
    result = {"records": records, "summary": summary(records, axes["mirrored"], field_value), "axes_deg": axes}
    command = " ".join([f"python {SCRIPT}", *map(str, args.runs), "--out", str(args.out)])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(result, indent=1) + "\n")
    args.out.with_suffix(".md").write_text(markdown(result, command))
    figure(records, field_value, axes).savefig(args.out.with_suffix(".png"), dpi=110)
    print(markdown(result, command))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
