"""Why low exploration destabilises learning: evidence from committed runs (issue 20 §1, docs/model.md §5).

    python studies/exploration/exploration_mechanism.py --out studies/exploration/mechanism

Two measurements, written to OUT/mechanism.json and OUT/mechanism.md:
1. Training metrics by exploration bound. Over every chunk after a learner's curriculum first reached the whole
   field, grouped by the chunk's bound b: how often the curriculum fell back below 90% of the field (a crisis),
   and the out rate, trial length, drift-aided share and N_max around it, in the annealed development runs and in
   the constant-0.2 held-out run. For each crisis, which of these indicators had already left the learner's
   typical range in the chunks before it.
2. The actor's signal at logged states. At states visited by trained networks (weights frozen), the actor's
   target moves by A = rnd (dp - beta P_range/N_max) (eq. 2 at beta = 0; the TD error at beta = 1). For each state
   `--samples` noise draws at each bound give E[A | state] (the useful part: the noise's correlation with the
   value it brings) and sd[A | state]; their ratio is the signal-to-noise ratio of one step's actor update.
"""

from __future__ import annotations

import argparse
import collections
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from reach_jax import env
from reach_jax.agent import exploration, network
from reach_jax.engine import random_stream, rollout
from reach_jax.env import protocol
from reach_jax.store import run_dir as run_dir_io

SCRIPT = "studies/exploration/exploration_mechanism.py"  # how its outputs name the command that made them

SETBACK = 0.9  # a chunk whose curriculum distance is below this fraction of the whole field is a crisis
BINS = (0.19, 0.15, 0.12, 0.0)  # bound bins, upper edges implied: [0.19, inf), [0.15, 0.19), ...
INDICATORS = ("out_rate", "mean_trial_steps", "drift_rate", "n_max")


def bound_bin(b: float) -> str:
    """The label of the bin that holds bound b."""
    for lo, hi in zip(BINS, (np.inf, *BINS[:-1]), strict=True):
        if lo <= b < hi:
            return f"[{lo:g}, {hi:g})"
    raise ValueError(b)


def metrics_by_bound(run: Path) -> dict:
    """Per condition group and bound bin: chunks, crisis share and indicator medians after the first full field."""
    rows = run_dir_io.read_metrics(run)
    full = max(r["distance_m"] for r in rows)
    by_learner = collections.defaultdict(list)
    for r in rows:
        if r["chunk_trials"]:
            by_learner[r["learner"]].append(r)
    table = collections.defaultdict(lambda: collections.defaultdict(lambda: collections.defaultdict(list)))
    precursors = collections.Counter()
    crises = 0
    for chunks in by_learner.values():
        first = next((i for i, r in enumerate(chunks) if r["distance_m"] >= full - 1e-6), None)
        if first is None:
            continue
        group = "no-force" if chunks[0]["condition"] in ("none", "viscous") else "random-force"
        calm = [r for r in chunks[first:] if r["distance_m"] >= full - 1e-6]
        typical = {k: np.percentile([r[k] for r in calm], 90) for k in INDICATORS}
        for i in range(first, len(chunks)):
            r = chunks[i]
            down = r["distance_m"] < SETBACK * full
            cell = table[group][bound_bin(r["exploration"])]
            cell["crisis"].append(down)
            for k in INDICATORS:
                cell[k].append(r[k])
            if down and chunks[i - 1]["distance_m"] >= SETBACK * full:  # the first chunk of a crisis
                crises += 1
                before = chunks[max(i - 2, first) : i]
                for k in INDICATORS:
                    precursors[k] += any(b[k] > typical[k] for b in before)
    out = {
        group: {
            b: {
                "chunks": len(cell["crisis"]),
                "crisis_share": float(np.mean(cell["crisis"])),
                **{f"median_{k}": float(np.median(cell[k])) for k in INDICATORS},
            }
            for b, cell in sorted(bins.items(), reverse=True)
        }
        for group, bins in sorted(table.items())
    }
    return {"by_bound": out, "crises": crises, "precursors_above_p90_in_2_chunks_before": dict(precursors)}


def actor_signal(run: Path, condition: str, n_states: int, samples: int, bounds, seed: int) -> dict:
    """E[A|s] / sd[A|s] of the actor's signal at states of a run's trained `condition` networks (weights frozen)."""
    loaded = run_dir_io.load(run)
    cfg = loaded.cfg
    picks = [i for i, (c, _) in enumerate(loaded.learners) if c == condition]
    plan = protocol.make_plan(condition, cfg)
    stride = 5  # every 5th step of a frozen rollout, so that the states come from many trials

    def lookahead(state, params, n_max, key):
        cond = state.env.cond
        out = network.apply(params, env.observe_trial(state.env.trial, cond, plan.geometry, cfg), cfg)
        p_now, m = out[0], out[1:]
        cost = cfg.learner.p_range / n_max

        def signal(rnd):
            torque = network.torque(m + rnd, 0.0, cfg)
            cont, outcome = env.step_trial(state.env.trial, torque, cond, plan.geometry, cfg)
            p_next = network.apply(params, env.observe_trial(cont, cond, plan.geometry, cfg), cfg)[0]
            p_next = jnp.where(outcome.goal, cfg.learner.reward_goal, p_next)
            p_next = jnp.where(outcome.out_of_range, cfg.learner.reward_out, p_next)
            dp = p_next - p_now
            return jnp.stack([rnd * dp, rnd * (dp - cost)])  # (beta 0 / 1, joint)

        unit = jax.random.uniform(key, (samples, 2), minval=-1.0, maxval=1.0)
        res = []
        for b in bounds:
            a = jax.vmap(signal)(b * unit)  # (samples, 2, 2)
            res.append(jnp.abs(a.mean(0)) / a.std(0))
        return jnp.stack(res), p_now  # (bounds, beta, joint)

    @jax.jit
    def measure(state, params, hyper, key):
        def body(carry, k):
            s = carry
            for _ in range(stride):
                u = jax.random.uniform(k, (random_stream.n_uniforms(cfg),))
                s = rollout.learner_step(s, u, plan, hyper, cfg)[0]
                k = jax.random.fold_in(k, 1)
            return s, lookahead(s, params, s.agent.n_max, jax.random.fold_in(k, 2))

        return jax.lax.scan(body, state, jax.random.split(key, n_states))[1]

    ratios, values = [], []
    for i in picks:
        state = jax.tree.map(lambda a, i=i: jnp.asarray(a)[i], loaded.batch.states)
        hyper = jax.tree.map(lambda a, i=i: jnp.asarray(a)[i], loaded.batch.hypers)
        hyper = hyper._replace(lr=jnp.zeros_like(hyper.lr))  # frozen: the states of the trained network
        r, p = measure(state, state.agent.params, hyper, jax.random.PRNGKey(seed + i))
        ratios.append(np.asarray(r))
        values.append(np.asarray(p))
    ratios = np.concatenate(ratios)  # (states, bounds, beta, joint)
    trained_bound = float(exploration.schedule(hyper, state.env.trials, state.env.curriculum.full_at))
    return {
        "run": str(run),
        "condition": condition,
        "networks": len(picks),
        "states": int(ratios.shape[0]),
        "samples_per_state": samples,
        "noise_floor": 1.0 / np.sqrt(samples),
        "trained_bound": trained_bound,
        "critic_value_percentiles_10_50_90": [float(v) for v in np.percentile(np.concatenate(values), [10, 50, 90])],
        "median_snr": {
            f"{b:g}": {"eq2": float(np.median(ratios[:, k, 0])), "td_error": float(np.median(ratios[:, k, 1]))}
            for k, b in enumerate(bounds)
        },
    }


def markdown(result: dict) -> str:
    """mechanism.json as Markdown tables."""
    lines = [f"**Why low exploration destabilises learning** (generated by `{SCRIPT}`)", ""]
    for run, data in result["metrics"].items():
        lines += [
            f"`{run}`: {data['crises']} crises (the curriculum fell below {SETBACK:.0%} of the whole field after "
            "reaching it). Chunks after the first full field, by exploration bound:",
            "",
            "| learners | bound | chunks | in crisis | out rate | trial length [steps] | drift-aided | N_max |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for group, bins in data["by_bound"].items():
            for b, c in bins.items():
                lines.append(
                    f"| {group} | {b} | {c['chunks']} | {c['crisis_share']:.1%} | {c['median_out_rate']:.3f} | "
                    f"{c['median_mean_trial_steps']:.0f} | {c['median_drift_rate']:.2f} | {c['median_n_max']:.0f} |"
                )
        pre = data["precursors_above_p90_in_2_chunks_before"]
        if data["crises"]:
            shares = ", ".join(f"{k} {v / data['crises']:.0%}" for k, v in pre.items())
            lines += ["", f"Above the learner's 90th percentile in one of the 2 chunks before a crisis: {shares}."]
        lines.append("")
    for s in result["actor_signal"]:
        lines += [
            f"Actor's signal at {s['states']} states of {s['networks']} `{s['condition']}` networks of `{s['run']}` "
            f"(trained at bound {s['trained_bound']:g}; weights frozen; {s['samples_per_state']} draws a state, "
            f"so ratios below {s['noise_floor']:.2f} are not told from 0): median over states and joints of "
            "|E[A | state]| / sd[A | state]",
            "",
            "| bound | eq. 2 (rnd dp) | TD error (rnd (dp - P_range/N_max)) |",
            "|---|---|---|",
        ]
        for b, v in s["median_snr"].items():
            lines.append(f"| {b} | {v['eq2']:.3f} | {v['td_error']:.3f} |")
        lines.append("")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("studies/exploration/mechanism"))
    p.add_argument(
        "--runs", nargs="+", type=Path, default=[Path(f"runs/{r}") for r in ("dev_gradual", "dev_delayed", "heldout")]
    )
    p.add_argument("--signal-runs", nargs="+", type=Path, default=[Path("runs/heldout"), Path("runs/dev_delayed")])
    p.add_argument("--states", type=int, default=100, help="states per network")
    p.add_argument("--samples", type=int, default=1024, help="noise draws per state and bound")
    args = p.parse_args()
    bounds = (0.2, 0.1, 0.05)
    result = {
        "metrics": {str(r): metrics_by_bound(r) for r in args.runs},
        "actor_signal": [actor_signal(r, "none", args.states, args.samples, bounds, 0) for r in args.signal_runs],
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "mechanism.json").write_text(json.dumps(result, indent=1) + "\n")
    (args.out / "mechanism.md").write_text(markdown(result))
    print(markdown(result))


if __name__ == "__main__":
    main()
