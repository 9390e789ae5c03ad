"""Judging an evaluated run: the claims of each frame decided from the measured tables, and the files that say so
(claims.json, table2.md, claims.md); `redecide` decides them again from a run's written eval/ files.

Units as in `claims`: success and out in percentage points, times [s], damping [N s/m].
"""

from __future__ import annotations

import json
from pathlib import Path

from reach_jax.config import Config
from reach_jax.evaluate import anatomy_report, frames, lattice, report, verdicts
from reach_jax.store import files
from reach_jax.store import run_dir as run_dir_io
from reach_jax.store.checkpoint import CheckpointError

EVAL_DIR = "eval"


def aftereffect_result(per_seed: list[dict], cfg: Config) -> dict:
    """aftereffect.json: recipe 0's figure seed, with every (recipe, seed) beside it."""
    main = [a for a in per_seed if a["recipe"] == 0 and a["seed"] == cfg.eval.figure_seed]
    if main:
        return {**main[0], "per_seed": per_seed}
    return {"error": "needs the none and viscous learning conditions at seed cfg.eval.figure_seed"}


def judge(v: frames.View, table: dict, per_seed: list[dict], imp: dict, recipes: list[dict], metrics) -> dict:
    """One frame's judgement: {"aftereffect", "impedance", "claims"} as the files hold them, from the whole run's
    `table`, its impedance summary `imp` along this frame's axes and the frame's `per_seed` after-effects; the
    claims are decided on the frame's view of the table and of the impedance."""
    seen = {**imp, "per_network": frames.rows_view(imp["per_network"], v.frame, v.cfg)}
    table = frames.table_view(table, v.frame, v.cfg)
    decided = verdicts.decide(table, per_seed, seen, recipes, v.recipe_of, metrics, v.cfg)
    return {"aftereffect": aftereffect_result(per_seed, v.cfg), "impedance": imp, "claims": {"recipes": decided}}


def by_frame(judged: dict, key: str) -> dict:
    """A file's record of every frame (`judge`): the first frame's at the top, the others' under "frames"."""
    first, *others = judged
    return {"frame": first, **judged[first][key], "frames": {f: judged[f][key] for f in others}}


def redecide(run_dir: Path) -> dict:
    """Decide the claims again from a run's committed eval/ files, without running the test episodes again.

    For a change in how claims are decided (the statistics, the criteria's presentation): the test episodes
    round differently in float32 on another CPU, where a few of a network's 2080 movements can change outcome.
    Rewrites eval/claims.json, claims.md and table2.md; returns the new claims results. claims.md carries the
    failure anatomy's line where eval/anatomy.json exists (evaluations before it have none).
    """
    run_dir = Path(run_dir)
    out = run_dir / EVAL_DIR
    if (out / "geometries.json").is_file():
        raise CheckpointError(f"{out}: a run of several visual fields; evaluate it in full to decide its claims again")
    paths = [out / f"{n}.json" for n in ("table2", "aftereffect", "impedance")]
    for path in paths:
        if not path.is_file():
            raise CheckpointError(f"{path}: missing; evaluate the run in full first")
    table, after, imp = (json.loads(path.read_text()) for path in paths)
    cfg = run_dir_io.read_config(run_dir)
    afters, imps = ({r.get("frame"): r, **r.get("frames", {})} for r in (after, imp))
    missing = [f for f in frames.frame_list(cfg) if f not in afters or f not in imps]
    if missing:
        raise CheckpointError(f"{paths[1]}: no frame {missing[0]} (written before frames); evaluate the run in full")
    networks = {r["learner"]: r for r in table["per_network"]}
    learners = [(networks[i]["learning"], networks[i]["seed"]) for i in sorted(networks)]
    recipe_of = [networks[i]["recipe"] for i in sorted(networks)]
    metrics = run_dir_io.read_metrics(run_dir, table["chunk"])
    judged = {}
    for frame in frames.frame_list(cfg):
        v = frames.view(frame, learners, recipe_of, cfg)
        per_seed = afters[frame].get("per_seed", [])
        judged[frame] = judge(v, table, per_seed, imps[frame], imp["recipes"], metrics)
    result = {"chunk": table["chunk"], "trials_per_network": cfg.train.trials, **by_frame(judged, "claims")}
    anatomy_path = out / "anatomy.json"
    anat = json.loads(anatomy_path.read_text()) if anatomy_path.is_file() else None
    write_judgements(out, table, result, cfg, f"{run_dir} (chunk {table['chunk']})", anat)
    return result


def write_judgements(out: Path, table: dict, claims: dict, cfg: Config, source: str, anat: dict | None) -> None:
    """Write claims.json, and table2.md and claims.md with a section for each frame (with the failure anatomy's
    line per recipe from `anat`, anatomy.json's record, where there is one)."""
    decided = {claims["frame"]: claims, **claims["frames"]}
    files.atomic_write_bytes(out / "claims.json", json.dumps(claims, indent=2).encode())
    seen = {f: (frames.table_view(table, f, cfg), decided[f]["recipes"]) for f in decided}
    files.atomic_write_bytes(out / "table2.md", lattice.frames_markdown(seen, source).encode())
    lines = anatomy_report.headlines(anat) if anat is not None else {}
    files.atomic_write_bytes(out / "claims.md", report.claims_markdown(claims, source, lines).encode())
