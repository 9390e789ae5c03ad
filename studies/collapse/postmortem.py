"""The post-mortem of two collapses, from `trace.py`'s per-trial records: phases, their signals, a figure (issue 49).

    python studies/collapse/postmortem.py studies/collapse/trace_viscous0 studies/collapse/trace_none1 \
        --out studies/collapse/postmortem

Each trace's phases are found by code: the *collapse* begins at the first trial from which at least ONSET_OUT of
the next ONSET_TRIALS end out; *healthy* is the trace's first HEALTHY trials, the *run-up* the RUN_UP trials before
the collapse, *absorbing* the trace's last ABSORBING. A *setback* that recovered before the collapse (the curriculum
below SETBACK of the whole field, then at the whole field again RECOVERED trials or more before the collapse) is
measured over the HEALTHY trials before it and the RECOVERED trials after its recovery. Writes OUT.json (each
phase's mean signals), OUT.md and OUT.png. Units: network outputs and their targets in (-0.5, 0.5); pre-activations
u; gradient norms of the TS loss.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

ONSET_OUT, ONSET_TRIALS = 0.95, 500
HEALTHY, RUN_UP, ABSORBING, RECOVERED = 1500, 5000, 5000, 3000
SETBACK, FULL = 0.9, 0.2  # a setback: the curriculum below 90% of the whole field, 0.2 m (the claims' rule)
SMOOTH = 250  # trials in the figure's running means
SIGNALS = {  # name in the table -> (record, column or None, scale)
    "out %": ("out", None, 100),
    "cap %": ("cap", None, 100),
    "steps a trial": ("length", None, 1),
    "critic at the start": ("p_first", None, 1),
    "critic, mean": ("p_mean", None, 1),
    "hidden 1 saturated %": ("sat_h1_mean", None, 100),
    "hidden 2 saturated %": ("sat_h2_mean", None, 100),
    "actor saturated %": ("sat_m_mean", None, 100),
    "eq. 2 targets past ±0.45 %": ("target_beyond_mean", None, 100),
    "torque at its limit %": ("tau_clipped_mean", None, 100),
    "shoulder actor, abs. pre-activation": ("u_out_abs", 1, 1),
    "elbow actor, abs. pre-activation": ("u_out_abs", 2, 1),
    "eq. 2 push, shoulder (1e-4)": ("actor_push_mean", 0, 1e4),
    "eq. 2 push, elbow (1e-4)": ("actor_push_mean", 1, 1e4),
    "actor signal, abs. (1e-4)": ("actor_signal_abs", 0, 1e4),
    "gradient, layer 1 (1e-3)": ("grad_mean", 0, 1e3),
    "gradient, layer 3 (1e-3)": ("grad_mean", 2, 1e3),
    "‖W1‖": ("w_norm", 0, 1),
    "N_max": ("n_max", None, 1),
}


def column(t: dict, record: str, index: int | None) -> np.ndarray:
    """One signal per trial, as float64."""
    a = np.asarray(t[record], dtype=np.float64)
    return a if index is None else a[:, index]


def phases(t: dict) -> dict[str, tuple[int, int]]:
    """The trace's phases as trial ranges [start, end)."""
    out, n = np.asarray(t["out"], dtype=np.float64), len(t["length"])
    ahead = np.convolve(out, np.ones(ONSET_TRIALS), "valid") / ONSET_TRIALS  # ahead[i]: trials i .. i + 499
    onset = int(np.argmax(ahead >= ONSET_OUT))
    found = {"healthy": (0, HEALTHY), "run-up": (max(0, onset - RUN_UP), onset), "absorbing": (n - ABSORBING, n)}
    low = np.flatnonzero(np.asarray(t["distance"][:onset]) < SETBACK * FULL)
    back = low[0] + int(np.argmax(np.asarray(t["distance"][low[0] : onset]) >= FULL * (1 - 1e-6))) if len(low) else 0
    if len(low) and low[0] > HEALTHY and low[0] < back <= onset - RECOVERED:  # it recovered, and held, before it
        found.update({"before the setback": (low[0] - HEALTHY, low[0]), "after its recovery": (back, back + RECOVERED)})
    return {"onset": (onset, onset), **found}


def summary(t: dict) -> dict:
    """Each phase's trial range, chunks and mean signals."""
    out = {}
    for name, (a, b) in phases(t).items():
        chunk = [int(t["chunk"][a]), int(t["chunk"][min(b, len(t["chunk"])) - 1])]
        means = {} if a == b else {k: float(column(t, r, i)[a:b].mean() * s) for k, (r, i, s) in SIGNALS.items()}
        out[name] = {"trials": [int(a), int(b)], "chunks": chunk, **means}
    return out


def _running(x: np.ndarray) -> np.ndarray:
    return np.convolve(x, np.ones(SMOOTH) / SMOOTH, "valid")


def figure(traces: list[tuple[str, dict, dict]]) -> Figure:
    """Four rows of signals per trace (a column each), the phases' boundaries as lines."""
    fig = Figure(figsize=(12, 10), layout="constrained")
    axes = fig.subplots(4, len(traces), sharex="col", squeeze=False)
    rows = [
        ("outcomes", [("out", None, "out"), ("goal", None, "goal"), ("sat_m_mean", None, "actor saturated")]),
        ("critic p", [("p_first", None, "at a trial's start"), ("p_mean", None, "mean over its steps")]),
        ("|pre-activation|", [("u_out_abs", 1, "shoulder actor"), ("u_out_abs", 2, "elbow actor")]),
        ("TS gradient norm", [("grad_mean", 0, "layer 1"), ("grad_mean", 1, "layer 2"), ("grad_mean", 2, "layer 3")]),
    ]
    for j, (title, t, phase) in enumerate(traces):
        x = np.arange(SMOOTH - 1, len(t["length"]))
        for i, (label, series) in enumerate(rows):
            ax = axes[i, j]
            for record, index, name in series:
                ax.plot(x, _running(column(t, record, index)), label=name, lw=1)
            for name, (a, _) in phase.items():
                if name in ("onset", "before the setback", "after its recovery"):
                    ax.axvline(a + (HEALTHY if name == "before the setback" else 0), color="0.5", ls="--", lw=0.8)
            ax.set_ylabel(label)
            if label == "TS gradient norm":
                ax.set_yscale("log")
            if j == 0:
                ax.legend(fontsize=7, loc="best")
        axes[0, j].set_title(title)
        axes[-1, j].set_xlabel(f"trial of the replay (running mean over {SMOOTH})")
    return fig


def markdown(result: dict, command: str) -> str:
    """Each trace's phases side by side."""
    lines = [f"Generated by `{command}` from each trace's `trials.npz` (studies/collapse/trace.py)."]
    for name, trace in result["traces"].items():
        cols = [p for p in trace["phases"] if p != "onset"]
        lines += ["", f"### {name}: collapse from trial {trace['phases']['onset']['trials'][0]:,} of the replay", ""]
        lines += ["| signal | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
        spans = [f"chunks {trace['phases'][c]['chunks'][0]}–{trace['phases'][c]['chunks'][1]}" for c in cols]
        lines.append("| (where) | " + " | ".join(spans) + " |")
        for signal in SIGNALS:
            lines.append(f"| {signal} | " + " | ".join(f"{trace['phases'][c][signal]:.3g}" for c in cols) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    """Summarize the traces and draw them."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("traces", type=Path, nargs="+", help="folders written by trace.py")
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args(argv)
    result, drawn = {"traces": {}}, []
    for folder in args.traces:
        replay = json.loads((folder / "replay.json").read_text())
        t = dict(np.load(folder / "trials.npz"))
        name = f"{replay['learner_name'][0]} seed {replay['learner_name'][1]}"
        result["traces"][name] = {"replay": replay, "phases": summary(t)}
        drawn.append((name, t, phases(t)))
    command = f"python studies/collapse/postmortem.py {' '.join(map(str, args.traces))} --out {args.out}"
    result["command"] = command
    Path(f"{args.out}.json").write_text(json.dumps(result, indent=1) + "\n")
    Path(f"{args.out}.md").write_text(markdown(result, command))
    figure(drawn).savefig(f"{args.out}.png", dpi=110)
    print(markdown(result, command))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
