"""When the learned damping and the late-setback rate settle: from kept checkpoints and metrics (issue 31, item 6).

    python studies/hover/settle.py runs/dev_value_half runs/dev_gain_half runs/dev_gain_mid runs/dev_value \
        runs/heldout_round2 runs/dev_gain runs/dev_anneal runs/dev_delayed runs/dev_gradual --out studies/hover/settle

Writes OUT.md (the tables), OUT.json (every number) and OUT.png (the figure).

Damping: at every kept checkpoint of a run (`RUN_DIR/checkpoints`), every network's learned hand damping along
the viscous field's unstable axis (+15.9 N s/m), tested without a field, as `reach_jax.evaluate.run` measures it
(`impedance.measure`, `impedance.summarize`): each network's median over the states of its own test movements,
then the mean over the networks of a learning condition with its t-interval (`stats.mean_ci`).
Setbacks: from metrics.jsonl, the share of chunks whose curriculum distance lies below
cfg.claims.curriculum_min_fraction of the whole field (the rule of `verdicts.curriculum_stability`), counted
per window of trials, only after each learner first reached the whole field.

Both series are then judged by the settle rules below (`settle_point`), and the recommended screen length is
the smallest trial count by which both have settled in most full-length runs, rounded up to 100,000 trials.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path

import matplotlib
import numpy as np

from reach_jax.engine import distribute
from reach_jax.env import task
from reach_jax.evaluate import episodes, impedance, lattice, stats, verdicts
from reach_jax.store import checkpoint
from reach_jax.store import run_dir as run_dir_io

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

SCRIPT = "studies/hover/settle.py"  # how its outputs name the command that made them

FULL_TRIALS = 2_000_000  # a full-length run (the paper's trials per network)
WINDOW = 200_000  # setback windows [trials]
ROUND = 100_000  # the recommended screen length is rounded up to this [trials]

# The damping rule: settled at the first checkpoint from which the no-field mean stays within
# max(DAMPING_REL x |final|, DAMPING_ABS) of its value at the run's last checkpoint.
DAMPING_REL = 0.2
DAMPING_ABS = 3.0  # [N s/m]
# The setback rule: the late value is the pooled fraction over LATE_FROM..FULL_TRIALS; settled by the end of the
# first window from which every window with counted chunks stays within max(SETBACK_REL x late, SETBACK_ABS) of it.
LATE_FROM = 1_600_000  # the late part of training, where late instability shows (issue 31)
SETBACK_REL = 0.25
SETBACK_ABS = 0.02
# Reported beside the rule, not deciding: a looser band, and whether the mean stays on the final value's side of
# the field's +15.9 N s/m (what the screening rule of round 2 read: a recipe is compliant below it).
DAMPING_LOOSE = (0.3, 5.0)
FIELD_UNSTABLE = 15.9  # the viscous field's eigenvalue along its unstable axis [N s/m] (docs/model.md §6)
# A settle point counts only when the series then stays in its band over at least this many trials: a series that
# is in band only at its last point (or its last two, which the trainer keeps one chunk apart) has not settled.
MIN_SPAN = 200_000


def stays_from(x, inside, min_span: float = MIN_SPAN) -> float | None:
    """First x from which `inside` holds at every later point, or None when that stretch spans under min_span."""
    x, inside = np.asarray(x, float), np.asarray(inside, bool)
    if not inside[-1]:
        return None
    outside = np.flatnonzero(~inside)
    first = 0 if outside.size == 0 else int(outside[-1]) + 1
    return float(x[first]) if x[-1] - x[first] >= min_span else None


def settle_point(x, y, final: float, band: float, min_span: float = MIN_SPAN) -> float | None:
    """First x from which every y stays within `band` of `final`, or None when that stretch spans under min_span."""
    return stays_from(x, np.abs(np.asarray(y, float) - final) <= band, min_span)


def damping_band(final: float, rel: float = DAMPING_REL, floor: float = DAMPING_ABS) -> float:
    """The damping rule's half-width around the final value [N s/m]."""
    return max(rel * abs(final), floor)


def setback_band(late: float) -> float:
    """The setback rule's half-width around the late fraction."""
    return max(SETBACK_REL * late, SETBACK_ABS)


def _test_cfg(cfg):
    """The run's config narrowed to what the damping needs: the no-field test only, and the first
    impedance_max_steps steps of the movements that `impedance.measure` reads (every impedance_pair_stride-th
    pair). The states it measures at are those of the full evaluation, step for step: an episode is
    deterministic, and the policy never sees the time (`_check_against_eval` compares the two)."""
    ev = cfg.eval
    short = dataclasses.replace(
        ev, test_conditions=("none",), frames=(), max_time=ev.impedance_max_steps * cfg.arm.dt, impedance_pair_stride=1
    )
    # The training section does not reach the test episodes; a common one lets runs share their compiled tests.
    return dataclasses.replace(cfg, eval=short, train=type(cfg.train)()), ev.impedance_pair_stride


def damping_at(run_dir: Path, path: Path) -> dict:
    """Every network's damping along the unstable axis without a field, at one checkpoint, and its trial count."""
    data = run_dir_io.load(run_dir, path)
    cfg, stride = _test_cfg(data.cfg)
    starts, targets = (a[::stride] for a in lattice.test_pairs(data.cfg))
    params, masks = data.batch.states.agent.params, data.batch.conds.input_mask
    policy = episodes.network_policy(cfg)
    ep, traj = episodes.run_episodes(policy, params, masks, lattice.test_fields(cfg), starts, targets, cfg)
    gains = impedance.measure(policy, params, masks, ep, traj, starts, targets, cfg)
    viscous = np.asarray(task.make_condition("viscous", cfg).field.viscous)  # the float32 matrix the arm felt
    rows = impedance.summarize(gains, data.learners, cfg.eval.test_conditions, viscous)["per_network"]
    recipes, recipe_of = lattice.recipe_index(data.batch.hypers)
    return {
        "recipes": recipes,
        "chunk": data.chunk,
        "trials": [int(t) for t in np.asarray(data.batch.states.env.trials)],
        "damping": [r["damping_unstable"]["median"] if r["states"] else None for r in rows],
        "learning": [name for name, _ in data.learners],
        "recipe": list(recipe_of),
    }


def damping_series(snapshots: list[dict], recipe: int, level: float) -> list[dict]:
    """Per checkpoint: the mean trial count of a recipe's no-field networks and each learning condition's mean
    damping with its interval over networks."""
    series = []
    for snap in snapshots:
        nets = [i for i, k in enumerate(snap["recipe"]) if k == recipe]
        none = [i for i in nets if snap["learning"][i] == "none"] or nets
        cells = {}
        for learning in dict.fromkeys(snap["learning"][i] for i in nets):
            values = [snap["damping"][i] for i in nets if snap["learning"][i] == learning]
            cells[learning] = stats.mean_ci([v for v in values if v is not None], level)
        series.append(
            {
                "chunk": snap["chunk"],
                "trials": float(np.mean([snap["trials"][i] for i in none])),
                "none_per_network": [snap["damping"][i] for i in none],
                "damping": cells,
            }
        )
    return series


def setback_windows(metrics: list[dict], learners: list[int], cfg, edges: np.ndarray) -> dict:
    """Counted and set-back chunks per window of trials, per learning condition and pooled ("all").

    A learner's chunk counts when it ended a trial in it (as in `verdicts.curriculum_stability`) and comes after
    the chunk in which the learner first reached the whole field; it falls in the window that holds its trial
    count at the chunk's end.
    """
    full = cfg.sensor.n_cells * cfg.sensor.cell_size
    low = cfg.claims.curriculum_min_fraction * full
    counted, setback = {}, {}
    for i in learners:
        rows = sorted((r for r in metrics if r["learner"] == i), key=lambda r: r["chunk"])
        reached = next((k for k, r in enumerate(rows) if r["distance_m"] >= full - 1e-6), None)  # float32 distance
        if reached is None:
            continue
        for r in rows[reached + 1 :]:
            if r["chunk_trials"] <= 0:
                continue
            w = int(np.searchsorted(edges, r["trials"], side="left")) - 1  # window (edges[w], edges[w + 1]]
            if not 0 <= w < len(edges) - 1:
                continue
            for key in (r["condition"], "all"):
                counted.setdefault(key, np.zeros(len(edges) - 1, int))[w] += 1
                setback.setdefault(key, np.zeros(len(edges) - 1, int))[w] += r["distance_m"] < low
    return {
        key: {
            "counted": counted[key].tolist(),
            "setback": setback[key].tolist(),
            "fraction": [s / c if c else None for s, c in zip(setback[key], counted[key], strict=True)],
        }
        for key in counted
    }


def setback_settle(windows: dict, edges: np.ndarray) -> dict:
    """The pooled late setback fraction, its band and the trial count by which the rate settled (`settle_point`
    over the windows with counted chunks, x at each window's end)."""
    late = [w for w in range(len(edges) - 1) if edges[w] >= LATE_FROM]
    c = sum(windows["counted"][w] for w in late)
    if not c:
        return {"late": None, "band": None, "settled_at": None}
    value = sum(windows["setback"][w] for w in late) / c
    seen = [w for w in range(len(edges) - 1) if windows["counted"][w]]
    at = settle_point(edges[seen], [windows["fraction"][w] for w in seen], value, setback_band(value))
    # Settled from the start of that window on: a screen sees the settled rate once it has run through it.
    return {"late": value, "band": setback_band(value), "settled_at": None if at is None else at + WINDOW}


def verdict_by_length(metrics: list[dict], learners: list[int], cfg, lengths) -> list[dict]:
    """The claims' stability verdict (`verdicts.curriculum_stability`) of each learner as a screen of each length
    would give it, from the metrics rows up to that trial count, and how many match the verdict at full length."""
    final = verdicts.curriculum_stability(metrics, learners, FULL_TRIALS, cfg)["learners"]
    unstable_at_end = {p["learner"] for p in final if p["tail_chunks"] and not p["stable"]}
    out = []
    for t in lengths:
        seen = [r for r in metrics if r["trials"] <= t]
        per = verdicts.curriculum_stability(seen, learners, t, cfg)["learners"]
        unstable = {p["learner"] for p in per if p["tail_chunks"] and not p["stable"]}
        out.append(
            {
                "trials": float(t),
                "unstable": sorted(unstable),
                "matching": len(learners) - len(unstable ^ unstable_at_end),
                "found": len(unstable & unstable_at_end),
            }
        )
    return out


def analyse(run_dir: Path, edges: np.ndarray) -> list[dict]:
    """One record per recipe of a run: its damping series, setback windows and stability verdicts by screen length,
    with the settle points."""
    cfg = run_dir_io.read_config(run_dir)
    snapshots = [damping_at(run_dir, p) for p in checkpoint.list_checkpoints(run_dir)]
    metrics = run_dir_io.read_metrics(run_dir, snapshots[-1]["chunk"])
    recipes = snapshots[-1]["recipes"]
    check = _check_against_eval(run_dir, snapshots)
    records = []
    for k, hypers in enumerate(recipes):
        series = damping_series(snapshots, k, cfg.claims.level)
        # The untrained networks of chunk 0 have learned nothing: the rules read the trained checkpoints only.
        means = [s["damping"]["none"]["mean"] for s in series if s["chunk"] > 0]
        trials = [s["trials"] for s in series if s["chunk"] > 0]
        final = means[-1]
        settled = settle_point(trials, means, final, damping_band(final))
        loose = settle_point(trials, means, final, damping_band(final, *DAMPING_LOOSE))
        side = stays_from(trials, (np.asarray(means) < FIELD_UNSTABLE) == (final < FIELD_UNSTABLE))
        learners = [i for i, r in enumerate(snapshots[-1]["recipe"]) if r == k]
        windows = setback_windows(metrics, learners, cfg, edges)
        back = setback_settle(windows["all"], edges) if "all" in windows else setback_settle({}, edges)
        full_length = trials[-1] >= FULL_TRIALS
        by_length = verdict_by_length(metrics, learners, cfg, edges[1:])
        agree = [b["matching"] == len(learners) for b in by_length]
        records.append(
            {
                "run": str(run_dir),
                "recipe": k,
                "hypers": hypers,
                "full_length": bool(full_length),
                "learners": len(learners),
                "damping": series,
                "damping_final": final,
                "damping_band": damping_band(final),
                "damping_settled_at": settled,
                "damping_settled_at_loose": loose,
                "damping_side_from": side,
                "setbacks": windows,
                "setback_late": back["late"],
                "setback_band": back["band"],
                "setback_settled_at": back["settled_at"],
                "verdict_by_length": by_length,
                "unstable_at_full_length": by_length[-1]["unstable"] if full_length else None,
                "verdict_agrees_from": stays_from(edges[1:], agree) if full_length else None,
                "both_settled_at": _later(settled, back["settled_at"]),
                "both_settled_at_loose": _later(loose, back["settled_at"]),
                "check_against_eval": check,
            }
        )
    return records


def _later(a: float | None, b: float | None) -> float | None:
    """The later of two settle points; None when either series has not settled."""
    return None if a is None or b is None else max(a, b)


def _check_against_eval(run_dir: Path, snapshots: list[dict]) -> dict | None:
    """The largest difference between this script's damping and the run's eval/impedance.json at the evaluated
    checkpoint, over the networks tested without a field [N s/m]; None when that checkpoint was not kept."""
    path = run_dir / "eval" / "impedance.json"
    if not path.is_file():
        return None
    imp = json.loads(path.read_text())
    snap = next((s for s in snapshots if s["chunk"] == imp.get("chunk")), None)
    if snap is None:
        return None
    theirs = {r["learner"]: r["damping_unstable"]["median"] for r in imp["per_network"] if r["test"] == "none"}
    diffs = [abs(snap["damping"][i] - v) for i, v in theirs.items() if v is not None and snap["damping"][i] is not None]
    return {"chunk": snap["chunk"], "networks": len(diffs), "max_abs_diff": max(diffs) if diffs else None}


def recommend(records: list[dict], key: str = "both_settled_at") -> dict:
    """The smallest trial count by which both series settled in most full-length runs, rounded up to ROUND; the
    full length when they had not settled in most."""
    full = [r for r in records if r["full_length"]]
    need = sorted(math.inf if r[key] is None else r[key] for r in full)
    most = len(need) // 2 + 1  # more than half
    settled = len(need) >= most and not math.isinf(need[most - 1])
    trials = int(math.ceil(need[most - 1] / ROUND) * ROUND) if settled else FULL_TRIALS
    return {"runs": len(need), "most": most, "settled_in_most": bool(settled), "trials": trials}


def _name(r: dict) -> str:
    return r["run"] + (f" #{r['recipe']}" if r["recipe"] else "")


def _k(x: float | None) -> str:
    return "–" if x is None else f"{x / 1e3:,.0f}k"


def _ci(c: dict | None) -> str:
    if c is None or c["mean"] is None:
        return "–"
    if c["low"] is None:
        return f"{c['mean']:.1f}"
    return f"{c['mean']:.1f} [{c['low']:.1f}, {c['high']:.1f}]"


def _frac(x: float | None) -> str:
    return "–" if x is None else f"{100 * x:.1f}"


CONDITIONS = ("none", "viscous", "random", "random_nopast")


def markdown(records: list[dict], rec: dict, loose: dict, edges: np.ndarray, command: str) -> str:
    """The study as Markdown: the settle points first, then per run its damping and its setbacks."""
    lines = [
        "# When damping and the late-setback rate settle (issue 31, item 6)",
        "",
        f"Generated by `{command}` from each run's kept checkpoints and metrics.jsonl.",
        "",
        "**Rules.** Damping: each network's median learned hand damping along the viscous field's unstable axis"
        " (+15.9 N s/m), tested without a field, as the evaluation measures it (`impedance.measure`); the mean"
        " over a recipe's no-field networks settles at the first checkpoint from which it stays within"
        f" max({DAMPING_REL:.0%} of its final value, {DAMPING_ABS:g} N s/m) of the value at the run's last"
        " checkpoint. Setbacks: a chunk is set back when its curriculum distance is below"
        " `curriculum_min_fraction` (90%) of the whole field, counted only after the learner first reached the"
        f" whole field, per {WINDOW / 1e3:.0f}k-trial window (by the learner's trial count at the chunk's end);"
        f" the late value is the pooled fraction from {LATE_FROM / 1e6:g}M trials on, and the rate has settled"
        " by the end of the first window from which every window stays within"
        f" max({SETBACK_REL:.0%} of the late value, {100 * SETBACK_ABS:g} points) of it. A series counts as"
        f" settled only if it then stays in its band for at least {MIN_SPAN / 1e3:.0f}k trials. A run needs the"
        " later of the two; the recommended screen length is the smallest trial count by which both have settled"
        f" in most ({rec['most']} of {rec['runs']}) full-length runs, rounded up to {ROUND / 1e3:.0f}k.",
        "",
        f"**Recommended screen length: {_k(rec['trials'])} trials**"
        + (
            f" (both settled in {rec['most']} of {rec['runs']} full-length runs by then)."
            if rec["settled_in_most"]
            else f": damping and setbacks had not both settled in {rec['most']} of the {rec['runs']} full-length"
            " runs before the end of training, so a screen needs the full length."
        ),
        "",
        "Beside the rule, not deciding: the damping settle point under a looser band (max(30%, 5 N s/m)), with"
        f" which the screen length would be {_k(loose['trials'])}"
        + ("" if loose["settled_in_most"] else " (not settled in most runs either)")
        + "; the trial count from which the mean stays on its final side of the field's +15.9 N s/m (the"
        " round-2 screening rule's line between compliant and stiff); and the screen length from which the"
        " claims' own stability verdict (`verdicts.curriculum_stability`, over the last 20% of a screen's trials)"
        " names the same unstable learners as at 2M.",
        "",
        "## Settle points",
        "",
        "| run | full length | no-field damping, final [N s/m] | damping settled at | looser band |"
        " side of +15.9 from | late setback % (band) | setbacks settled by | both by |"
        " stability verdict as at 2M from (unstable there) | check vs eval [N s/m] |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in records:
        chk = r["check_against_eval"]
        chk_text = "–" if chk is None or chk["max_abs_diff"] is None else f"{chk['max_abs_diff']:.2g}"
        late = "–" if r["setback_late"] is None else f"{_frac(r['setback_late'])} (±{_frac(r['setback_band'])})"
        unstable = r["unstable_at_full_length"]
        verdict = "–" if unstable is None else f"{_k(r['verdict_agrees_from'])} ({len(unstable)})"
        lines.append(
            f"| `{_name(r)}` | {'yes' if r['full_length'] else 'no'} | {r['damping_final']:.1f}"
            f" (±{r['damping_band']:.1f}) | {_k(r['damping_settled_at'])} | {_k(r['damping_settled_at_loose'])}"
            f" | {_k(r['damping_side_from'])} | {late} | {_k(r['setback_settled_at'])}"
            f" | {_k(r['both_settled_at'])} | {verdict} | {chk_text} |"
        )
    lines += [
        "",
        "Check vs eval: the largest difference, over the networks tested without a field, between this script's"
        " damping and the run's `eval/impedance.json` at the evaluated checkpoint.",
        "",
        "## Damping against trials",
        "",
        "Mean over networks of each network's median [N s/m], with the 95% t-interval; trials: the mean over the"
        " no-field networks at the checkpoint.",
    ]
    for r in records:
        present = [c for c in CONDITIONS if c in r["damping"][0]["damping"]]
        lines += [
            "",
            f"### `{_name(r)}`",
            "",
            "| chunk | trials | " + " | ".join(present) + " | no-field networks |",
            "|---|---|" + "---|" * len(present) + "---|",
        ]
        for s in r["damping"]:
            nets = ", ".join("–" if v is None else f"{v:.1f}" for v in s["none_per_network"])
            cells = " | ".join(_ci(s["damping"].get(c)) for c in present)
            lines.append(f"| {s['chunk']} | {_k(s['trials'])} | {cells} | {nets} |")
    heads = [f"{_k(a)}–{_k(b)}" for a, b in zip(edges[:-1], edges[1:], strict=True)]
    lines += [
        "",
        "## Setback fraction per window",
        "",
        "Percent of counted chunks set back, per learning condition and pooled; counted chunks pooled in the last"
        " row of each run.",
    ]
    for r in records:
        lines += ["", f"### `{_name(r)}`", "", "| condition | " + " | ".join(heads) + " |"]
        lines.append("|---|" + "---|" * len(heads))
        for key in (*CONDITIONS, "all"):
            if key in r["setbacks"]:
                lines.append(f"| {key} | " + " | ".join(_frac(f) for f in r["setbacks"][key]["fraction"]) + " |")
        if "all" in r["setbacks"]:
            lines.append("| chunks | " + " | ".join(str(c) for c in r["setbacks"]["all"]["counted"]) + " |")
    lines += [
        "",
        "## The stability verdict by screen length",
        "",
        "Learners whose verdict (`verdicts.curriculum_stability` on the metrics up to that trial count, over its"
        " last 20%) matches the verdict at 2M, of all; in brackets, how many of the learners unstable at 2M it"
        " already finds. A learner's first T trials are those of a screen of length T, as nothing in training"
        " reads the run's length but the stop.",
        "",
        "| run | unstable at 2M | " + " | ".join(_k(b) for b in edges[1:]) + " |",
        "|---|---|" + "---|" * (len(edges) - 1),
    ]
    for r in records:
        if r["unstable_at_full_length"] is None:
            continue
        n = len(r["verdict_by_length"][-1]["unstable"])
        cells = " | ".join(f"{b['matching']}/{r['learners']} ({b['found']}/{n})" for b in r["verdict_by_length"])
        lines.append(f"| `{_name(r)}` | {', '.join(map(str, r['unstable_at_full_length'])) or '–'} | {cells} |")
    return "\n".join(lines) + "\n"


def figure(records: list[dict], edges: np.ndarray):
    """Two panels: the no-field networks' mean damping against trials, and the pooled setback fraction per
    window, one line per run."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 4.6))
    mids = 0.5 * (edges[:-1] + edges[1:])
    for n, r in enumerate(records):
        colour = plt.cm.tab10(n % 10)
        trained = [s for s in r["damping"] if s["chunk"] > 0]  # as the rules: chunk 0's networks are untrained
        trials = [s["trials"] / 1e6 for s in trained]
        means = [s["damping"]["none"]["mean"] for s in trained]
        left.plot(trials, means, "o-", ms=3, color=colour, label=_name(r).replace("runs/", ""))
        if r["damping_settled_at"] is not None:
            left.axvline(r["damping_settled_at"] / 1e6, color=colour, ls=":", lw=0.8)
        if "all" in r["setbacks"]:
            f = np.array([np.nan if v is None else 100 * v for v in r["setbacks"]["all"]["fraction"]])
            right.plot(mids / 1e6, f, "o-", ms=3, color=colour)
    left.axhline(15.9, color="0.5", ls="--", lw=1)
    left.text(0.01, 15.9, " field +15.9", fontsize=7, color="0.4", va="bottom", transform=left.get_yaxis_transform())
    left.set_xlabel("trials [millions]")
    left.set_ylabel("no-field networks' damping, unstable axis [N s/m]")
    left.set_title("damping (dotted: where it settled)", fontsize=9)
    left.legend(fontsize=7)
    right.set_xlabel("trials [millions] (window centres)")
    right.set_ylabel("chunks set back, all learners [%]")
    right.set_title(f"setbacks per {WINDOW / 1e3:.0f}k-trial window, after the first whole field", fontsize=9)
    for ax in (left, right):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", type=Path)
    p.add_argument("--out", type=Path, required=True, help="writes OUT.md, OUT.json and OUT.png")
    args = p.parse_args()
    distribute.setup_backend(1)  # as the evaluate CLI: one device, the same compiler options
    edges = np.arange(0, FULL_TRIALS + WINDOW, WINDOW, dtype=float)
    records = []
    for run in args.runs:
        records += analyse(run, edges)
        print(f"{run}: {len(records[-1]['damping'])} checkpoints", flush=True)
    rec = recommend(records)
    command = f"python {SCRIPT} " + " ".join(str(r) for r in args.runs) + f" --out {args.out}"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    loose = recommend(records, "both_settled_at_loose")
    text = markdown(records, rec, loose, edges, command)
    args.out.with_suffix(".md").write_text(text)
    result = {
        "rules": {
            "damping_rel": DAMPING_REL,
            "damping_abs": DAMPING_ABS,
            "setback_rel": SETBACK_REL,
            "setback_abs": SETBACK_ABS,
            "late_from": LATE_FROM,
            "window": WINDOW,
            "min_span": MIN_SPAN,
        },
        "recommended": rec,
        "recommended_loose": loose,
        "runs": records,
    }
    args.out.with_suffix(".json").write_text(json.dumps(result, indent=1) + "\n")
    figure(records, edges).savefig(args.out.with_suffix(".png"), dpi=110)
    print(text)


if __name__ == "__main__":
    main()
