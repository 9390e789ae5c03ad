"""The task's geometry as per-learner data: a sweep of visual fields in one batch, checked against the oracle and
the config's own sensor, and a field the arm cannot serve refused in one line."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from reach_jax import evaluate
from reach_jax.config import from_partial, hyper, workspace
from reach_jax.engine import batch, random_stream
from reach_jax.engine.chunk import make_trace
from reach_jax.engine.learner_state import init_learner
from reach_jax.env import protocol, task
from reach_jax.evaluate import geometry
from reach_jax.physics import arm, sensor
from reach_jax.store import run_dir as run_dir_io
from reach_jax.testing import reference
from reach_jax.train import cli as train_cli

MOVED = {"sensor_dx": 0.15, "sensor_dy": 0.08, "sensor_scale": 0.75}  # the field at (0.10, 0.45) m, 30 mm cells
STEPS = 200
# A short cap and a fast, early drift, so that 200 steps end trials at the goal, at a limit and at the cap.
TASK = {"max_trial_time": 1.2, "drift_after": 0.4, "drift_per_step": 0.004}


def _learner(plans, i):
    return jax.tree.map(lambda a: a[i], plans)


def test_the_config_sensor_as_data_is_the_configs_numbers():
    cfg = from_partial({})
    geom = task.geometry(cfg)
    (x0, y0), (x1, y1) = sensor.field_bounds(cfg.sensor)
    np.testing.assert_array_equal(np.asarray(geom.sensor.lo), np.float32([x0, y0]))
    np.testing.assert_array_equal(np.asarray(geom.sensor.hi), np.float32([x1, y1]))
    assert float(geom.goal_half) == np.float32(task.goal_half_width(cfg))
    assert float(geom.full_distance) == np.float32(cfg.sensor.n_cells * cfg.sensor.cell_size)
    assert float(geom.start_distance) == np.float32(cfg.task.curriculum_init_cells * cfg.sensor.cell_size)


@pytest.mark.parametrize(("dx", "dy", "scale"), [(0.0, 0.0, 1.0), (0.15, 0.08, 0.75), (-0.05, 0.02, 1.25)])
def test_a_hand_centred_on_a_cell_lights_that_cell_alone(dx, dy, scale):
    cfg = from_partial({})
    s = workspace.moved_sensor(cfg.sensor, dx, dy, scale)
    where = sensor.placement(s)
    (x0, y0), _ = sensor.field_bounds(s)
    for row, col in ((0, 0), (2, 3), (4, 4)):
        centre = jnp.asarray([x0 + (col + 0.5) * s.cell_size, y0 + (row + 0.5) * s.cell_size])
        image = np.asarray(sensor.render(centre, centre, where, s.n_cells)).reshape(s.n_cells, s.n_cells)
        assert image[row, col] == pytest.approx(1.0, abs=1e-5)
        assert image.sum() == pytest.approx(1.0, abs=1e-5)  # the union of two equal squares is one cell's area


def test_a_geometry_sweep_gives_each_learner_its_own_field_and_the_configs_sensor_bit_for_bit():
    grids = {f"{k}_grid": [0.0, v] if k != "sensor_scale" else [1.0, v] for k, v in MOVED.items()}
    cfg = from_partial(
        {
            "task": TASK,
            "train": {"trials": 50, "seeds": 1, "conditions": ["viscous_mirror"], "zip_grids": True, **grids},
        }
    )
    plans = batch.plans(cfg)
    states = batch.fresh_states(cfg, plans)
    hypers = batch.hyper_columns(cfg)
    trace = make_trace(cfg, STEPS)
    for i, values in enumerate(batch.learner_hypers(cfg)):
        moved = dataclasses.replace(cfg, sensor=task.learner_sensor(cfg, values))
        alone = protocol.make_plan("viscous_mirror", moved)  # the config's own sensor, moved: the static reading
        same = jax.tree.map(np.array_equal, _learner(plans, i).geometry, alone.geometry)
        assert all(jax.tree.leaves(same)), i
        state = _learner(states, i)
        lo, hi = np.asarray(alone.geometry.sensor.lo), np.asarray(alone.geometry.sensor.hi)
        hand = np.asarray(arm.hand_position(state.env.trial.arm[:2], cfg.arm))
        assert np.all((lo - 1e-6 <= hand) & (hand <= hi + 1e-6)), (i, hand, lo, hi)
        got = trace(state, _learner(plans, i), _learner(hypers, i))
        want = make_trace(moved, STEPS)(state, alone, _learner(hypers, i))
        for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    # The two learners saw different fields: their first inputs differ.
    first = [np.asarray(trace(_learner(states, i), _learner(plans, i), _learner(hypers, i))[1].x[0]) for i in (0, 1)]
    assert not np.array_equal(*first)


def test_a_moved_and_scaled_learner_replays_in_the_oracle_of_its_sensor():
    cfg = from_partial({"task": TASK, "learner": MOVED, "train": {"trials": 50, "conditions": ["viscous"]}})
    moved = dataclasses.replace(cfg, sensor=workspace.moved_sensor(cfg.sensor, *MOVED.values()))
    with jax.enable_x64(True):
        plan = _learner(batch.plans(cfg), 0)
        hyper_values = {name: jnp.asarray(float(getattr(cfg.learner, name))) for name in hyper.NAMES}
        h = hyper.Hyper(**hyper_values)
        state = init_learner(jax.random.PRNGKey(5), plan, cfg)
        state = state.replace(agent=state.agent.replace(params=jax.tree.map(jnp.float64, state.agent.params)))
        final, infos = make_trace(cfg, STEPS)(state, plan, h)
        infos = jax.tree.map(np.asarray, infos)
        units = 2.0 * np.asarray(random_stream.step_uniforms(state.key, 0, STEPS, cfg))[:, :2] - 1.0
    ref_plan = reference.make_plan("viscous", moved)
    lrn = reference.learner_from_jax(state, ref_plan[0].cond)
    values = {name: float(v) for name, v in hyper_values.items()}
    recs = []
    for i in range(STEPS):
        draws = reference.Draws(*(a[i] for a in infos.draws))
        lrn, rec = reference.learner_step(lrn, ref_plan, values, cfg.learner.noise, units[i], draws, moved)
        recs.append(rec)
    for name, field in (("goal", "goal"), ("out", "out_of_range"), ("cap", "cap")):
        np.testing.assert_array_equal(getattr(infos, field), [getattr(r, field) for r in recs], err_msg=name)
    assert sum(r.goal or r.out_of_range or r.cap for r in recs) > 0  # trials ended and new ones were placed
    np.testing.assert_allclose(infos.x, np.array([r.x for r in recs]), rtol=0, atol=1e-9)
    np.testing.assert_allclose(infos.arm, np.array([r.arm for r in recs]), rtol=0, atol=1e-9)
    assert float(final.env.curriculum.distance) == pytest.approx(lrn.distance, abs=1e-12)
    # And the oracle of the config's own sensor sees another image: the geometry reached the inputs.
    plain = reference.make_plan("viscous", cfg)
    other = reference.learner_step(reference.learner_from_jax(state, plain[0].cond), plain, values, 0.2, units[0],
                                   reference.Draws(*(a[0] for a in infos.draws)), cfg)[1]  # fmt: skip
    assert not np.allclose(other.x, recs[0].x)


@pytest.mark.parametrize(
    ("flags", "words"),
    [
        (["--sweep", "sensor_dy=0,0.5"], "out of the arm's reach"),
        (["--sweep", "sensor_scale=1.5"], "shoulder angle"),
        (["--set", "learner.sensor_dx=-0.25"], "shoulder angle"),
    ],
)
def test_a_geometry_the_arm_cannot_serve_is_a_one_line_error_with_nothing_written(tmp_path, capsys, flags, words):
    out = tmp_path / "run"
    assert train_cli.main(["--trials", "10", "--out", str(out), *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and "visual field centred at" in err[0], err
    # It names what sets the field: a grid given, by its own name (a fuzzed config file found one unnamed).
    swept = [f"train.{f.split('=')[0]}_grid" for f in flags if f.startswith("sensor_") and "," in f]
    assert all(name in err[0] for name in ["learner.sensor_dx", "learner.sensor_dy", *swept]), err
    assert ("_grid" in err[0]) == bool(swept), err
    assert not out.exists()


@pytest.mark.slow
def test_a_run_of_two_visual_fields_evaluates_each_in_its_own(tmp_path, load_tool):
    spec = {
        "train": {"trials": 20, "seeds": 1, "conditions": ["none", "viscous_mirror"], "chunk_steps": 300},
        "eval": {"lattice": 4},  # 12 pairs a network instead of 1,040: enough to see where they lie
    }
    (tmp_path / "two.json").write_text(json.dumps(spec))
    run = tmp_path / "run"
    train = ["train", "--config", str(tmp_path / "two.json"), "--sweep", "sensor_dx=0,0.1", "--out", str(run)]
    for argv in ([*train, "--quiet"], ["evaluate", str(run)]):
        done = subprocess.run(
            [sys.executable, "-m", f"reach_jax.{argv[0]}", *argv[1:]], capture_output=True, text=True, timeout=600
        )
        assert done.returncode == 0, done.stderr[-3000:]
    assert "geometries.md lists them" in done.stderr
    out = run / evaluate.EVAL_DIR
    index = json.loads((out / "geometries.json").read_text())
    cfg = run_dir_io.read_config(run)
    for k, dx in enumerate((0.0, 0.1)):
        field = index["fields"][k]
        moved = workspace.moved_sensor(cfg.sensor, dx, 0.0, 1.0)
        assert field["centre_m"] == pytest.approx(list(moved.centre)) and field["learners"] == [k, k + 2]
        sub = out / geometry.subdir(k)
        rows = json.loads((sub / "table2.json").read_text())["per_network"]
        assert sorted({r["learner"] for r in rows}) == [0, 1]  # its two networks, numbered anew
        # The Fig. 4 movements start from the corner cells of this field, not of the config's sensor.
        (x0, y0), (x1, y1) = sensor.field_bounds(moved)
        moves = json.loads((sub / "aftereffect.json").read_text())["movements"]
        starts = np.array([m["start_m"] for m in moves])
        assert np.all((starts[:, 0] > x0) & (starts[:, 0] < x1) & (starts[:, 1] > y0) & (starts[:, 1] < y1))
        assert (sub / "claims.md").is_file() and (sub / "anatomy.png").is_file()
    assert "geometry_1/claims.md" in (out / "geometries.md").read_text()
    # The study's map reads each field's files: one point each, at its centre, with its networks' damping and outs.
    study = load_tool("studies/geometry/map")
    study.main([str(run), "--out", str(tmp_path / "map")])
    found = json.loads((tmp_path / "map.json").read_text())
    assert [p["centre_m"] for p in found["points"]] == [f["centre_m"] for f in index["fields"]]
    assert all(len(p["damping_per_network"]) == len(p["none_field_out_per_network"]) == 1 for p in found["points"])
    assert found["networks"] == 2 and (tmp_path / "map.png").is_file()
