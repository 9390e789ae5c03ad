"""Replay one learner of a run from a snapshot, step by step, recording the signals of its TS learning (issue 49).

`python studies/postmortem/trace.py RUN --learner L --from-chunk C --chunks N --out DIR`

Starts learner L of RUN at its snapshot `checkpoints/chunk_C.npz` (written with `--keep-every`) and runs the steps
of chunks C+1 ... C+N through the training step itself (`rollout.budgeted_step`, batched as a chunk batches it),
with read-only probes beside it: at every step the critic's output and its eq.-1 target, the actor's outputs,
eq.-2 targets and pre-activations, each hidden layer's saturation, the TS loss gradient per layer, the weight
norms, N_max, the curriculum, the drift gate and the outcome. Each chunk's steps are folded into one record per
trial (`trials.npz`). Where RUN holds a snapshot at the replay's last chunk, every leaf of the replayed learner is
compared with it (`replay.json`, "identical"): the probes must not change what they watch.
Units: network outputs in (-0.5, 0.5); distances [m]; N_max and lengths in steps.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from reach_jax.agent import exploration, learner, network
from reach_jax.config.schema import DEFAULT_SPEED
from reach_jax.engine import chunk, rollout
from reach_jax.env import curriculum, task
from reach_jax.store import checkpoint, run_dir

SATURATED = 0.45  # |f(u)| beyond it is a saturated unit: f'(u) below 0.0475, under a fifth of its peak 0.25


def parse(argv=None) -> argparse.Namespace:
    """Command line."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", type=Path, help="a run directory with --keep-every snapshots")
    p.add_argument("--learner", type=int, required=True, help="the learner's index in the batch")
    p.add_argument("--from-chunk", type=int, required=True, help="the snapshot to start from")
    p.add_argument("--chunks", type=int, required=True, help="chunks to replay")
    p.add_argument("--out", type=Path, required=True, help="folder for trials.npz and replay.json")
    return p.parse_args(argv)


def _forward(layers, x):
    """(activations per layer from the input on, pre-activations per layer) of one input."""
    acts, pre = [x], []
    for w, b in layers:
        pre.append(jnp.sum(acts[-1][:, None] * w, axis=0) + b)
        acts.append(network.squash(pre[-1]))
    return acts, pre


def probe(s, info, hyper, cfg) -> dict:
    """Measures of one learner's step: its state before it (`s`), what it did (`info`), its hyperparameters."""
    pending, width = s.agent.pending, cfg.network.hidden[0]
    layers = network.dense_layers(s.agent.params)  # W(t), padded: the extra hidden units are exactly 0
    acts, pre = _forward(layers, info.x)
    prev_acts, _ = _forward(layers, pending.x)
    target = learner.ts_targets(pending, acts[-1][0], s.agent.n_max, cfg.learner, hyper.actor_baseline)

    def ts_loss(lay):
        return 0.5 * jnp.sum((target - _forward(lay, pending.x)[0][-1]) ** 2)

    valid = pending.valid.astype(float)
    grads = jax.grad(ts_loss)(layers)
    cur = s.env.curriculum
    short = curriculum.shortfall(cur, task.geometry(cfg))  # the traced runs see the config's own sensor
    return {
        "p": acts[-1][0],
        "p_target": target[0],
        "p_prev": prev_acts[-1][0],
        "m": acts[-1][1:],
        "actor_error": (target[1:] - prev_acts[-1][1:]) * valid,  # eq. 2's error on the previous input
        "actor_signal": (target[1:] - pending.out[1:]) * valid,  # rnd * gain * dp: what eq. 2 adds to m
        # > 0: eq. 2 pushes the output further from 0, into saturation; < 0: back toward the middle
        "actor_push": (target[1:] - prev_acts[-1][1:]) * jnp.sign(prev_acts[-1][1:]) * valid,
        "target_beyond": jnp.mean(jnp.abs(target[1:]) > SATURATED) * valid,
        "critic_error": (target[0] - prev_acts[-1][0]) * valid,
        "rnd": info.rnd,
        "u_out": pre[-1],
        "sat_h1": jnp.mean(jnp.abs(acts[1][:width]) > SATURATED),
        "sat_h2": jnp.mean(jnp.abs(acts[2]) > SATURATED),
        "sat_m": jnp.mean(jnp.abs(acts[-1][1:]) > SATURATED),
        "tau_clipped": jnp.mean(jnp.abs(info.tau) >= jnp.asarray(cfg.arm.tau_max)),
        "grad": jnp.stack([jnp.sqrt(jnp.sum(g[0] ** 2)) for g in grads]) * valid,
        "w_norm": jnp.stack(
            [jnp.sqrt(jnp.sum(w[..., :width] ** 2 if i == 0 else w**2)) for i, (w, _) in enumerate(layers)]
        ),
        "n_max": s.agent.n_max,
        "distance": cur.distance,
        "failure": cur.failure,
        "gate_open": curriculum.drift_open(cur, hyper.drift_gate),
        "value_scale": exploration.value_scale(hyper, acts[-1][0], cur.full_at, short),
        "drifted": s.env.trial.drifted,
        "goal": info.goal,
        "out": info.out_of_range,
        "cap": info.cap,
        "ended": info.ended,
    }


def make_replay(cfg, n_steps: int):
    """Compiled `(states, plans, hypers, budget) -> (states, probes per step)` of a batch, as `chunk.chunk_body`
    steps it: the same batched `rollout.budgeted_step`, with its stats reset, and the probes beside it."""
    step = jax.vmap(lambda s, u, p, h, b: rollout.budgeted_step(s, u, p, h, b, cfg), in_axes=(0, 0, 0, 0, None))
    measure = jax.vmap(lambda s, i, h: probe(s, i, h, cfg))

    def replay(states, plans, hypers, budget):
        stats = jax.tree.map(jnp.zeros_like, states.counters.stats)
        states = states.replace(counters=states.counters.replace(stats=stats))

        def body(states, u):
            new, info = step(states, u, plans, hypers, budget)
            return new, measure(states, info, hypers)

        return chunk.scan_steps(body, states, n_steps, cfg, batched=True, speed=DEFAULT_SPEED)

    return jax.jit(replay)


def fold_trials(steps: dict) -> dict[str, np.ndarray]:
    """One record per trial that ended among the steps (each array (n_steps, ...)): means over its steps, and its
    outcome, length and the state at its end. Steps after the last ended trial are left out."""
    ended = np.flatnonzero(steps["ended"])
    steps = {k: v[: ended[-1] + 1] for k, v in steps.items()}  # reduceat's last sum would run to the end
    starts = np.concatenate([[0], ended[:-1] + 1])
    counts = ended - starts + 1
    out = {"length": counts, "goal": steps["goal"][ended], "out": steps["out"][ended], "cap": steps["cap"][ended]}
    for name in ("drifted", "gate_open", "n_max", "distance", "failure", "w_norm"):
        out[name] = steps[name][ended]
    means = ("p", "p_target", "p_prev", "sat_h1", "sat_h2", "sat_m", "tau_clipped", "value_scale", "grad")
    for name in (*means, "actor_push", "target_beyond", "critic_error"):
        out[f"{name}_mean"] = np.add.reduceat(steps[name], starts, axis=0) / counts.reshape(
            -1, *[1] * (steps[name].ndim - 1)
        )
    for name in ("m", "actor_error", "actor_signal", "u_out", "rnd"):
        out[f"{name}_abs"] = np.add.reduceat(np.abs(steps[name]), starts, axis=0) / counts[:, None]
    out["p_first"] = steps["p"][starts]
    return out


def main(argv=None) -> int:
    """Replay, fold and compare; write DIR/trials.npz and DIR/replay.json."""
    args = parse(argv)
    snap = args.run / "checkpoints" / f"chunk_{args.from_chunk:07d}.npz"
    run = run_dir.load(args.run, snap)
    cfg, pick = run.cfg, jnp.asarray([args.learner])
    states, plans, hypers = (
        jax.tree.map(lambda a: a[pick], t) for t in (run.batch.states, run.batch.plans, run.batch.hypers)
    )
    replay = make_replay(cfg, cfg.train.chunk_steps)
    budget = jnp.asarray(cfg.train.trials)
    folded = []
    for _ in range(args.chunks):
        states, probes = replay(states, plans, hypers, budget)
        steps = jax.tree.map(lambda a: np.asarray(a)[:, 0], probes)
        folded.append(fold_trials(steps))
    trials = {k: np.concatenate([f[k] for f in folded]) for k in folded[0]}
    trials["chunk"] = np.concatenate([np.full(len(f["length"]), args.from_chunk + i + 1) for i, f in enumerate(folded)])
    args.out.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        args.out / "trials.npz", **{k: v.astype(np.float32) if v.dtype == np.float64 else v for k, v in trials.items()}
    )
    report = {
        "run": str(args.run),
        "learner": args.learner,
        "learner_name": list(run.learners[args.learner]),
        "from_chunk": args.from_chunk,
        "chunks": args.chunks,
        "trials": int(len(trials["length"])),
    }
    end = args.run / "checkpoints" / f"chunk_{args.from_chunk + args.chunks:07d}.npz"
    if end.is_file():
        stored = run_dir.load(args.run, end).batch.states
        mine = checkpoint.flatten({"s": states})
        theirs = checkpoint.flatten({"s": jax.tree.map(lambda a: a[pick], stored)})
        differ = [k for k in mine if not np.array_equal(np.asarray(mine[k]), np.asarray(theirs[k]))]
        report.update(compared_with=end.name, leaves=len(mine), differing=differ, identical=not differ)
    (args.out / "replay.json").write_text(json.dumps(report, indent=1) + "\n")
    print(json.dumps(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
