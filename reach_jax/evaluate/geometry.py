"""Runs whose learners see more than one visual field (hyper sensor_dx, sensor_dy, sensor_scale): each field's
learners are evaluated as a run of their own, in its own geometry, into eval/geometry_<k>/, with an index.

Positions [m]; D and the cells' shares in percentage points, as in `claims`. A run of one visual field is evaluated
in that field, into eval/ itself (`evaluate.evaluate`).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import jax
import numpy as np

from reach_jax.config import SensorConfig, hyper, workspace
from reach_jax.engine import batch
from reach_jax.env import task
from reach_jax.evaluate import frames
from reach_jax.store import files
from reach_jax.store import run_dir as run_dir_io

INDEX = "geometries"  # eval/geometries.json and .md list the visual fields and each one's headline numbers


def subdir(k: int) -> str:
    """The folder of eval/ that holds the evaluation of the run's k-th visual field (in batch order)."""
    return f"geometry_{k}"


def groups(data: run_dir_io.Run) -> list[tuple[SensorConfig, list[int]]]:
    """Each distinct visual field of a run's learners, in batch order, with the indices of the learners that see it."""
    sensors = [task.learner_sensor(data.cfg, h) for h in batch.learner_hypers(data.cfg)]
    found: dict[SensorConfig, list[int]] = {}
    for i, s in enumerate(sensors):
        found.setdefault(s, []).append(i)
    return list(found.items())


def sub_run(data: run_dir_io.Run, sensor: SensorConfig, picks: list[int]) -> run_dir_io.Run:
    """The run of the learners `picks` alone, in the config of their visual field: a run as `run_dir.load` gives.

    Its learners are numbered anew in `picks` order, in its metrics rows and its per-trial log too.
    """
    rows = np.asarray(picks)
    taken = batch.Batch(*(jax.tree.map(lambda a: np.asarray(a)[rows], part) for part in data.batch))
    index = {old: new for new, old in enumerate(picks)}
    metrics = [{**r, "learner": index[r["learner"]]} for r in data.metrics if r["learner"] in index]
    trials = data.trials
    if trials is not None:
        keep = np.isin(trials["learner"], rows)
        trials = {k: np.asarray(v)[keep] for k, v in trials.items()}
        trials["learner"] = np.asarray([index[int(i)] for i in trials["learner"]], dtype=int)
    # The field becomes the config's sensor, and the sweep of fields is gone from its config (the networks' hypers
    # keep their values, which name their recipes).
    names = workspace.GEOMETRY_HYPERS
    grids = {f"{name}_grid": () for name in names}
    cfg = dataclasses.replace(
        data.cfg,
        sensor=sensor,
        learner=dataclasses.replace(data.cfg.learner, **{n: hyper.BY_NAME[n].neutral for n in names}),
        train=dataclasses.replace(data.cfg.train, **grids),
    )
    learners = [data.learners[i] for i in picks]
    return data._replace(cfg=cfg, batch=taken, learners=learners, metrics=metrics, trials=trials)


def index_record(parts: list[tuple[SensorConfig, list[int]]], claims: list[dict]) -> dict:
    """eval/geometries.json: each visual field with its learners and, per frame and recipe, D, the paper's plausible
    cells, the claims that hold and the unexpected field's cell.

    Args:
      parts: `groups`' (sensor, learner indices) per field.
      claims: each field's claims results (claims.json), in the same order.
    """
    fields = []
    for k, ((sensor, picks), decided) in enumerate(zip(parts, claims, strict=True)):
        judged = {decided.get("frame"): decided, **decided.get("frames", {})}
        recipes = []
        for frame, record in judged.items():
            for r, recipe in enumerate(record["recipes"]):
                cells = {(c["learning"], c["test"]): c for c in recipe["cells"]}
                field = cells.get(("none", frames.PAPER_FIELD))
                plaus = recipe.get("plausibility") or {}
                recipes.append(
                    {
                        "frame": frame,
                        "recipe": r,
                        "hypers": recipe["hypers"],
                        "D": recipe.get("D"),
                        "plausible_cells": plaus.get("plausible_cells"),
                        "holding": sum(c["verdict"] == "holds" for c in recipe["claims"]),
                        "none_field": None if field is None else {k: field[k]["mean"] for k in ("success", "out")},
                    }
                )
        fields.append(
            {
                "index": k,
                "folder": subdir(k),
                "centre_m": list(sensor.centre),
                "cell_m": sensor.cell_size,
                "learners": picks,
                "recipes": recipes,
            }
        )
    return {"fields": fields}


def index_markdown(record: dict, source: str) -> str:
    """eval/geometries.md: one row per visual field, frame and recipe."""
    lines = [
        f"**Visual fields — {source}**",
        "",
        "Each field's learners are evaluated as a run of their own, in the folder named; D in points from the paper's "
        "Table 2, the paper's cells plausible as a two-network draw from ours, the claims that hold, and the "
        "unexpected field's cell (none → the frame's field, success / out %).",
        "",
        "| folder | centre [m] | cell [m] | frame | recipe | D | plausible | claims holding | none → field |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for f in record["fields"]:
        for r in f["recipes"]:
            d = "–" if r["D"] is None else f"{r['D']:.1f}"
            plaus = "–" if r["plausible_cells"] is None else f"{r['plausible_cells']} of 8"
            cell = r["none_field"]
            field = "–" if cell is None else f"{100 * cell['success']:.1f} / {100 * cell['out']:.1f}"
            lines.append(
                f"| [{f['folder']}]({f['folder']}/claims.md) | ({f['centre_m'][0]:.3f}, {f['centre_m'][1]:.3f}) | "
                f"{f['cell_m']:.3f} | {r['frame']} | {r['recipe']} | {d} | {plaus} | {r['holding']} | {field} |"
            )
    return "\n".join(lines) + "\n"


def write_index(out: Path, record: dict, source: str) -> None:
    """Write eval/geometries.json and .md."""
    Path(out).mkdir(parents=True, exist_ok=True)
    files.atomic_write_bytes(Path(out) / f"{INDEX}.json", json.dumps(record, indent=2).encode())
    files.atomic_write_bytes(Path(out) / f"{INDEX}.md", index_markdown(record, source).encode())
