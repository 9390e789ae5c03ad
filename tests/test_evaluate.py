"""The Table-2 evaluator: the 1040-pair lattice, outcome classes with scripted controllers, counting and the
mean-time rule, the after-effect and quality measures, the command line and an end-to-end run."""

from __future__ import annotations

import dataclasses
import json
import shutil

import chex
import jax
import jax.numpy as jnp
import matplotlib.image
import numpy as np
import pytest

from reach_jax import env, errors, evaluate, train
from reach_jax.agent import network
from reach_jax.config import TRAINED_CONDITIONS, Config, TrainConfig, paper, to_json
from reach_jax.engine import batch
from reach_jax.env import task, trial_log
from reach_jax.evaluate import anatomy, anatomy_report, episodes, frames, paper_figures
from reach_jax.evaluate import cli as evaluate_cli
from reach_jax.evaluate.episodes import Episode
from reach_jax.physics import arm, sensor
from reach_jax.store import checkpoint
from reach_jax.store import run_dir as run_dir_io

TEST_CONDITIONS = frames.test_columns(Config())  # the null field, the field as applied, the field mirrored
CELLS = [(c, t) for c in TRAINED_CONDITIONS for t in TEST_CONDITIONS]  # a default run's (learning, test) pairs
OTHER_FRAME = Config().eval.frames[1]  # the frame that the main files do not judge (fig4_OTHER.png)

CFG = Config()
N_STEPS = episodes.n_steps(CFG)
PAST = slice(CFG.sensor.n_cells**2 + 40, None)  # the 60 one-step-before inputs (encoding layout)


def pd_policy(params, obs):
    """Hand-space PD: F = kp (target - hand) - kd v, applied as J^T F; params = (kp, kd)."""
    force = params[0] * (obs.target - obs.hand) - params[1] * obs.hand_vel
    return arm.jacobian(obs.arm[:2], CFG.arm).T @ force


def limit_policy(params, obs):
    """Full clockwise shoulder torque: theta1 falls below 0."""
    return jnp.array([-CFG.arm.tau_max[0], 0.0])


def zero_policy(params, obs):
    """No torque: the arm stays at rest."""
    return jnp.zeros(2)


def left_pd_policy(params, obs):
    """PD only towards targets left of the field centre; params = (kp, kd)."""
    left = obs.target[0] < CFG.sensor.centre[0]
    return jnp.where(left, pd_policy(params, obs), 0.0)


def past_policy(params, obs):
    """Torque from the past inputs alone: zero whenever they are masked."""
    return jnp.array([0.0, -jnp.sum(obs.x[PAST])])


PD_GAINS = (100.0, 20.0)  # [N/m], [N s/m]


def run_policy(policy, params, masks=None, starts=None, targets=None):
    if starts is None:
        starts, targets = evaluate.test_pairs(CFG)
    params = jnp.asarray(params)
    masks = jnp.ones((params.shape[0], 125)) if masks is None else masks
    return episodes.Episode(
        *jax.device_get(
            episodes.run_episodes(policy, params, masks, evaluate.test_fields(CFG), starts, targets, CFG)[0]
        )
    )


# ---- the lattice ----


def test_lattice_gives_exactly_1040_pairs_none_touching():
    starts, targets = evaluate.test_pairs(CFG)
    assert starts.shape == targets.shape == (1040, 2)
    assert not np.any(np.asarray(task.touching(jnp.asarray(starts), jnp.asarray(targets), task.goal_half_width(CFG))))
    assert len({(*s, *t) for s, t in zip(starts.tolist(), targets.tolist(), strict=True)}) == 1040

    pts = evaluate.lattice_points(CFG)
    assert pts.shape == (36, 2)
    (x0, y0), (x1, y1) = sensor.field_bounds(CFG.sensor)
    half = CFG.sensor.cell_size / 2
    assert np.all(pts - half >= np.array([x0, y0]) - 1e-12) and np.all(pts + half <= np.array([x1, y1]) + 1e-12)
    # Every pair of kept points that is left out touches.
    all_s, all_t = np.repeat(pts, 36, axis=0), np.tile(pts, (36, 1))
    kept = {(*s, *t) for s, t in zip(starts.tolist(), targets.tolist(), strict=True)}
    dropped = [i for i in range(len(all_s)) if (*all_s[i], *all_t[i]) not in kept]
    assert len(dropped) == 36**2 - 1040
    half = task.goal_half_width(CFG)
    assert np.all(np.asarray(task.touching(jnp.asarray(all_s[dropped]), jnp.asarray(all_t[dropped]), half)))
    # The kept points are the 8 x 8 edge-to-edge lattice minus its border, whose squares stick out.
    k = np.arange(CFG.eval.lattice) / (CFG.eval.lattice - 1)
    xs = x0 + k * (x1 - x0)
    np.testing.assert_allclose(np.unique(pts[:, 0]), xs[1:-1])
    assert xs[0] - half < x0 and xs[-1] + half > x1


def test_corner_pairs_join_the_four_corner_cell_centres():
    starts, targets, corner = paper_figures.corner_pairs(CFG)
    assert starts.shape == targets.shape == (12, 2)
    assert np.all(np.any(starts != targets, axis=1))
    (x0, y0), _ = sensor.field_bounds(CFG.sensor)
    half = CFG.sensor.cell_size / 2
    assert [x0 + half, y0 + half] in starts.tolist()
    np.testing.assert_allclose(starts, paper_figures.corner_centres(CFG)[corner])


# ---- outcome classes with scripted controllers ----


def test_pd_controller_succeeds_on_every_pair_in_both_tests():
    assert TEST_CONDITIONS == ("none", "viscous", "viscous_mirror")
    ep = run_policy(pd_policy, [PD_GAINS])
    ep = Episode(*(a[:, :2] for a in ep))  # mirrored, the field throws this controller out of 207 of the movements
    assert np.all(ep.outcome == env.SUCCESS)
    assert np.all(ep.steps < N_STEPS)
    starts, targets = evaluate.test_pairs(CFG)
    idx = ep.steps[..., None, None]
    final_hand = np.take_along_axis(ep.hand, idx, axis=-2)[..., 0, :]
    final_speed = np.take_along_axis(ep.speed, ep.steps[..., None], axis=-1)[..., 0]
    assert np.all(np.abs(final_hand - targets) < task.goal_half_width(CFG))
    assert np.all(final_speed < CFG.task.goal_speed)
    table = evaluate.count(ep.outcome, ep.steps, CFG)
    np.testing.assert_allclose(table["mean_time_s"], np.mean(ep.steps) * CFG.arm.dt, rtol=1e-6)
    # The viscous field is applied in the second test: the same controller moves differently.
    assert not np.allclose(ep.hand[0, 0], ep.hand[0, 1])


def test_controller_driving_a_joint_past_its_limit_is_out():
    ep = run_policy(limit_policy, [0.0])
    assert np.all(ep.outcome == env.OUT)
    assert np.all(ep.steps < N_STEPS)
    table = evaluate.count(ep.outcome, ep.steps, CFG)
    assert (table["success"], table["out"], table["fail"]) == (0, ep.outcome.size, 0)
    assert table["mean_time_s"] == CFG.eval.max_time


def test_zero_torque_fails_at_exactly_4_s():
    ep = run_policy(zero_policy, [0.0])
    assert np.all(ep.outcome == env.FAIL)
    assert np.all(ep.steps == N_STEPS)
    assert np.all(evaluate.trial_times(ep.outcome, ep.steps, CFG) == 4.0)
    assert evaluate.count(ep.outcome, ep.steps, CFG)["mean_time_s"] == 4.0
    starts, _ = evaluate.test_pairs(CFG)
    np.testing.assert_allclose(ep.hand, np.broadcast_to(starts[None, None, :, None], ep.hand.shape), atol=1e-5)


def test_counts_are_per_pair_and_summed_over_a_conditions_networks():
    starts, targets = evaluate.test_pairs(CFG)
    n_left = int(np.sum(targets[:, 0] < CFG.sensor.centre[0]))
    assert 0 < n_left < 1040
    # Network 0 reaches only left targets; network 1 has zero gains and never moves.
    ep = run_policy(left_pd_policy, [PD_GAINS, (0.0, 0.0)])
    learners = [("none", 0), ("none", 1)]
    table = evaluate.table2(ep.outcome, ep.steps, learners, [0, 0], CFG)
    assert table["pairs_per_network"] == 1040
    rows = {(r["learning"], r["test"]): r for r in table["rows"]}
    assert set(rows) == {("none", t) for t in TEST_CONDITIONS}
    for test in ("none", "viscous"):  # mirrored, the field throws some of these movements out
        r = rows[("none", test)]
        assert (r["networks"], r["success"], r["out"], r["fail"]) == (2, n_left, 0, 2080 - n_left)
    per = {(r["learner"], r["test"]): r for r in table["per_network"]}
    assert (per[(0, "none")]["success"], per[(0, "none")]["fail"]) == (n_left, 1040 - n_left)
    assert (per[(1, "none")]["success"], per[(1, "none")]["fail"]) == (0, 1040)
    assert per[(1, "none")]["mean_time_s"] == 4.0


def test_mean_time_counts_out_and_fail_as_max_time():
    dt, cap = CFG.arm.dt, CFG.eval.max_time
    outcome = np.array([env.SUCCESS, env.OUT, env.FAIL, env.SUCCESS])
    steps = np.array([10, 5, N_STEPS, 50])
    np.testing.assert_allclose(evaluate.trial_times(outcome, steps, CFG), [10 * dt, cap, cap, 50 * dt])
    got = evaluate.count(outcome, steps, CFG)
    assert (got["success"], got["out"], got["fail"]) == (2, 1, 1)
    np.testing.assert_allclose(got["mean_time_s"], (10 * dt + cap + cap + 50 * dt) / 4)

    # Three networks, two learning conditions: rows sum the networks of a condition.
    out3 = np.broadcast_to(outcome, (3, len(TEST_CONDITIONS), 4)).copy()
    out3[2] = env.SUCCESS
    steps3 = np.broadcast_to(steps, out3.shape)
    table = evaluate.table2(out3, steps3, [("none", 0), ("none", 1), ("viscous", 0)], [0, 0, 0], CFG)
    rows = {(r["learning"], r["test"]): r for r in table["rows"]}
    assert [(r["learning"], r["test"]) for r in table["rows"]] == [
        (c, t) for c in ("none", "viscous") for t in TEST_CONDITIONS
    ]
    assert (rows[("none", "none")]["success"], rows[("none", "none")]["out"], rows[("none", "none")]["fail"]) == (
        4,
        2,
        2,
    )
    np.testing.assert_allclose(rows[("viscous", "viscous")]["mean_time_s"], np.mean(steps) * dt)
    assert len(table["per_network"]) == 3 * len(TEST_CONDITIONS)


# ---- what the network policy sees ----


def test_network_policy_is_the_noise_free_actor():
    params = network.init_params(
        jax.random.PRNGKey(3), dataclasses.replace(CFG, network=dataclasses.replace(CFG.network, output_init=1.0))
    )
    x = jax.random.uniform(jax.random.PRNGKey(4), (125,))
    obs = episodes.Obs(
        x=x,
        arm=jnp.zeros(4),
        hand=jnp.zeros(2),
        hand_vel=jnp.zeros(2),
        start=jnp.zeros(2),
        target=jnp.zeros(2),
        t=jnp.array(0),
    )
    got = episodes.network_policy(CFG)(params, obs)
    want = network.torque(network.apply(params, x, CFG)[1:], jnp.zeros(2), CFG)
    np.testing.assert_allclose(got, want, rtol=1e-6)
    assert not np.allclose(got, 0.0)


def test_learning_condition_mask_reaches_the_policy():
    masks = jnp.stack(
        [task.make_condition("random", CFG).input_mask, task.make_condition("random_nopast", CFG).input_mask]
    )
    ep = run_policy(past_policy, [0.0, 0.0], masks=masks)
    assert np.all(ep.outcome[1] == env.FAIL)  # no past inputs: no torque, no movement
    assert np.ptp(ep.hand[1], axis=-2).max() < 1e-6
    assert np.ptp(ep.hand[0], axis=-2).max() > 1e-3  # the same policy moves the arm when it sees them


# ---- after-effect and quality measures ----


def test_aftereffect_pulls_are_displacements_from_the_matched_path():
    m, t = 3, 11
    starts = np.zeros((m, 2))
    targets = np.tile([0.1, 0.0], (m, 1))
    line = np.linspace(0, 1, t)[None, :, None] * targets[:, None]
    bump = np.sin(np.linspace(0, np.pi, t))[None, :, None]
    paths = {"a": line, "b": line + 0.02 * bump * [0.0, 1.0], "d": line, "c": line + 0.03 * bump * [1.0, -1.0]}
    curl = np.array([[0.0, -10.0], [10.0, 0.0]])  # pushes a +x movement toward +y
    got = evaluate.aftereffect(paths, starts, targets, np.zeros(m, int), curl)
    assert len(got["movements"]) == m
    mv = got["movements"][0]
    np.testing.assert_allclose([mv["pull_b_deg"], mv["pull_c_deg"], mv["angle_deg"]], [90.0, -45.0, 135.0], atol=1e-6)
    np.testing.assert_allclose([mv["pull_b_m"], mv["pull_c_m"]], [0.02, 0.03 * np.sqrt(2)], rtol=1e-6)
    np.testing.assert_allclose([mv["line_deviation_b_m"], mv["line_deviation_c_m"]], [0.02, -0.03], rtol=1e-6)
    np.testing.assert_allclose(got["mean_angle_deg"], 135.0, atol=1e-6)
    assert got["fraction_opposite_line_deviation"] == 1.0
    np.testing.assert_allclose(
        [mv["field_force_deg"], mv["pull_b_to_force_deg"], mv["pull_c_to_force_deg"]], [90, 0, 135]
    )
    assert got["fraction_b_with_force"] == 1.0 and got["fraction_c_against_force"] == 1.0
    against = evaluate.aftereffect(paths, starts, targets, np.zeros(m, int), -curl)
    assert against["fraction_b_with_force"] == 0.0 and against["fraction_c_against_force"] == 0.0


def test_perpendicular_is_left_positive_on_numpy_and_in_jitted_jax():
    rng = np.random.default_rng(0)
    aim = trial_log.unit(rng.normal(size=(50, 2))).astype(np.float32)
    rel = rng.normal(size=(50, 2)).astype(np.float32)
    want = trial_log.perpendicular(aim, rel)
    # One pair at a time, as in the training step; XLA may fuse the multiply-subtract, so only float32-close.
    got = jax.jit(jax.vmap(trial_log.perpendicular))(jnp.asarray(aim), jnp.asarray(rel))
    np.testing.assert_allclose(np.asarray(got), want, rtol=1e-5, atol=1e-6)
    assert trial_log.perpendicular(np.array([1.0, 0.0]), np.array([0.3, 0.2])) == 0.2  # left of +x is +y


def test_quality_measures_on_known_profiles():
    u = np.linspace(0, 1, 41)
    bell = evaluate.minimum_jerk_speed(u)
    np.testing.assert_allclose(evaluate.bell_correlation(bell[None], np.array([40])), [1.0], atol=1e-9)
    assert evaluate.bell_correlation((1 - bell)[None], np.array([40]))[0] < 0
    assert evaluate.count_peaks(bell, 0.1) == 1
    two = np.concatenate([bell, bell[1:]])
    assert evaluate.count_peaks(two, 0.1) == 2
    spiky = bell.copy()
    spiky[38] += 0.05 * bell.max()  # a small bump on the tail, far below the prominence threshold
    assert evaluate.count_peaks(spiky, 0.1) == 1
    assert evaluate.count_peaks(spiky, 0.0) == 2
    assert evaluate.count_peaks(np.linspace(0, 1, 20), 0.1) == 0  # still rising at the end

    # A path that bulges 0.02 m sideways over a 0.1 m movement has straightness 0.2.
    t = np.linspace(0, 1, 21)
    hand = np.stack([0.1 * t, 0.02 * np.sin(np.pi * t)], axis=-1)[None]
    s = evaluate.straightness(hand, np.array([20]), np.zeros((1, 2)), np.array([[0.1, 0.0]]))
    np.testing.assert_allclose(s, [0.2], rtol=1e-6)


def test_minimum_jerk_yardstick_is_straight_single_peaked_and_reaches_every_target():
    starts, targets = evaluate.test_pairs(CFG)
    ep = evaluate.minimum_jerk_episodes(starts, targets, CFG)
    assert np.all(ep.outcome == env.SUCCESS)
    q = evaluate.movement_quality(ep, starts, targets, CFG)
    assert q["successful"] == 1040
    assert q["straightness"]["mean"] < 1e-9
    assert q["speed_peaks"]["single_peak_fraction"] == 1.0
    assert 0.5 < q["bell_correlation"]["mean"] < 1.0  # the goal test ends the bell before it comes to rest


# ---- command line and end to end ----


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("run") / "tiny"
    cfg = dataclasses.replace(CFG, train=dataclasses.replace(TrainConfig(), trials=20, seeds=1, chunk_steps=300))
    train.run(cfg, run_dir, progress=False)
    return run_dir


def _cli_error(run_dir, capsys, must_name):
    status = evaluate_cli.main([str(run_dir)])
    err = capsys.readouterr().err
    assert status == errors.EXIT_USAGE
    assert err.count("\n") == 1 and err.startswith("python -m reach_jax.evaluate: error: ")
    assert str(must_name) in err
    assert not (run_dir / evaluate.EVAL_DIR).exists()


def test_cli_missing_run_dir(tmp_path, capsys):
    _cli_error(tmp_path / "nope", capsys, tmp_path / "nope")


def test_cli_run_dir_without_checkpoints(tmp_path, capsys):
    (tmp_path / run_dir_io.CONFIG_FILE).write_text(to_json(CFG))
    _cli_error(tmp_path, capsys, tmp_path / checkpoint.CHECKPOINT_DIR)


def test_cli_corrupt_checkpoint_and_metrics(tiny_run, tmp_path, capsys):
    bad = tmp_path / "bad"
    shutil.copytree(tiny_run, bad)
    newest = checkpoint.list_checkpoints(bad)[-1]
    newest.write_bytes(b"not a zip file")
    _cli_error(bad, capsys, newest)
    shutil.rmtree(bad)
    shutil.copytree(tiny_run, bad)
    (bad / run_dir_io.METRICS_FILE).write_bytes(b"not gzip")
    _cli_error(bad, capsys, bad / run_dir_io.METRICS_FILE)
    (bad / run_dir_io.LEGACY_METRICS_FILE).write_text('{"chunk": 1}\n{torn\n')  # a run from before the gzip form
    _cli_error(bad, capsys, bad / run_dir_io.LEGACY_METRICS_FILE)


def test_quality_markdown_marks_a_cell_without_successes():
    nothing = {"mean": None, "median": None}
    empty = {"learning": "none", "test": "viscous", "networks": 1, "movements": 1040, "successful": 0}
    empty |= {"straightness": nothing, "bell_correlation": nothing}
    empty["speed_peaks"] = {**nothing, "single_peak_fraction": None}
    ref = {"duration_s": 0.5, "movements": 1040, "successful": 1040, "straightness": {"median": 0.0}}
    ref |= {"bell_correlation": {"median": 0.91}, "speed_peaks": {"median": 1.0, "single_peak_fraction": 1.0}}
    md = evaluate.quality_markdown({"cells": [empty], "minimum_jerk_reference": ref, "peak_prominence": 0.1}, "x")
    assert "| none → viscous | 1 | 0/1040 | – | – | – | – |" in md
    assert "| minimum jerk, 0.5 s | – | 1040/1040 | 0.000 | 0.91 | 1 | 100.0% |" in md


def test_end_to_end_writes_every_file_with_the_promised_shapes(tiny_run, capsys):
    assert evaluate_cli.main([str(tiny_run)]) == 0
    out = tiny_run / evaluate.EVAL_DIR
    # One closing screen: the claims of each frame, D (one network a condition: no plausibility), what to open.
    err = capsys.readouterr().err.splitlines()
    assert err[-1] == f"evaluation written to {out}"
    assert err[-2].startswith("Next: python -m reach_jax.evaluate.compare")
    assert err[0] == f"{tiny_run} at chunk {checkpoint.checkpoint_chunk(checkpoint.list_checkpoints(tiny_run)[-1])}:"
    assert [line.split(",")[0] for line in err if line.startswith("Frame ")] == [f"Frame {f}" for f in CFG.eval.frames]
    assert sum("D " in line and "(plausibility needs 3 networks)" in line for line in err) == len(CFG.eval.frames)
    assert f"  {out / 'table2.md'}" in "\n".join(err) and len(err) < 25
    networks = len(batch.learner_table(run_dir_io.read_config(tiny_run).train))

    t2 = json.loads((out / "table2.json").read_text())
    assert t2["pairs_per_network"] == 1040
    assert [(r["learning"], r["test"]) for r in t2["rows"]] == CELLS
    for r in t2["rows"]:
        assert set(r) == {"learning", "test", "networks", "success", "out", "fail", "mean_time_s"}
        assert r["success"] + r["out"] + r["fail"] == r["networks"] * 1040
        assert isinstance(r["success"], int) and isinstance(r["mean_time_s"], float)
        assert r["success"] * CFG.arm.dt <= r["mean_time_s"] * r["networks"] * 1040 + 1e-9
    assert len(t2["per_network"]) == networks * len(TEST_CONDITIONS)
    for r in t2["per_network"]:
        assert {"learner", "learning", "seed", "recipe", "test", "success", "out", "fail", "mean_time_s"} <= set(r)
        assert r["success"] + r["out"] + r["fail"] == 1040

    md = (out / "table2.md").read_text()
    for s, o, f, t in paper.PAPER_TABLE2.values():
        assert f"{s}-{o}-{f} ({t:.3g} s)" in md
    # Every cell that a frame shows; a network trained in one frame and tested in the other's field is in neither.
    # (Found by its row's label: a tiny run's networks may share their counts across cells.)
    for r in t2["first_two"]:
        rows = [line for line in md.splitlines() if line.startswith(f"| {r['learning']} → {r['test']} |")]
        crossed = r["learning"] in Config().eval.frames and r["test"] in Config().eval.frames
        assert bool(rows) == (not crossed or r["learning"] == r["test"]), r
        assert all(f"{r['success']}-{r['out']}-{r['fail']} ({r['mean_time_s']:.3g} s)" in line for line in rows), r

    after = json.loads((out / "aftereffect.json").read_text())
    assert {"movements", "mean_angle_deg", "mean_direction_deg", "angle_between_mean_directions_deg"} <= set(after)
    assert len(after["movements"]) == 12
    assert {"pull_b_deg", "pull_c_deg", "angle_deg", "line_deviation_b_m", "line_deviation_c_m"} <= set(
        after["movements"][0]
    )

    q = json.loads((out / "quality.json").read_text())
    assert [(c["learning"], c["test"]) for c in q["cells"]] == CELLS
    for cell in [*q["cells"], q["minimum_jerk_reference"]]:
        assert {"straightness", "bell_correlation", "speed_peaks", "successful", "movements"} <= set(cell)
    assert q["minimum_jerk_reference"]["successful"] == 1040
    qmd = (out / "quality.md").read_text()
    for cell in q["cells"]:
        counts = f"{cell['networks']} | {cell['successful']}/{cell['movements']}"
        straight = "–" if cell["successful"] == 0 else f"{cell['straightness']['median']:.3f}"
        assert f"| {cell['learning']} → {cell['test']} | {counts} | {straight} |" in qmd
    assert "| minimum jerk, " in qmd and "| 1040/1040 | 0.000 |" in qmd

    # The failure anatomy: every movement of a cell labelled, outs and fails as Table 2 counts them, in each frame.
    anat = json.loads((out / "anatomy.json").read_text())
    counted = {(r["learner"], r["test"]): r for r in t2["per_network"]}
    assert len(anat["per_network"]) == len(t2["per_network"])
    for r in anat["per_network"]:
        want = counted[r["learner"], r["test"]]
        assert r["success"] == want["success"]
        assert sum(r[k] for k in anatomy.OUT_LIMITS) == want["out"]
        assert sum(r[k] for k in anatomy.FAIL_CLASSES) == want["fail"]
    claims_md, anatomy_md = (out / "claims.md").read_text(), (out / "anatomy.md").read_text()
    for frame, recipes in anatomy.by_frame(anat).items():
        cells = recipes[0]["cells"]
        assert [(c["learning"], c["test"]) for c in cells] == [
            (c["learning"], c["test"]) for c in frames.table_view(t2, frame, CFG)["rows"]
        ]
        assert anatomy_report.headline(anat, frame, 0) in claims_md
        assert f"## Frame {frame}, Recipe 0" in anatomy_md
    assert claims_md.count("**Failure anatomy**") == len(Config().eval.frames)

    for name in ("fig4.png", "fig5.png", "learning_curves.png", "anatomy.png"):
        img = matplotlib.image.imread(out / name)
        assert img.ndim == 3 and min(img.shape[:2]) > 300
        assert img[..., :3].std() > 0.05  # not a blank canvas


def test_python_api_evaluates_into_a_chosen_folder_and_loads_the_trained_parameters(tiny_run, tmp_path):
    results = evaluate.evaluate(tiny_run, out=tmp_path / "api")
    assert set(results) == {*evaluate.RESULT_FILES, "adaptation"}
    assert results["adaptation"] is None  # no protocol, no per-trial log
    assert not (tmp_path / "api" / "adaptation.json").exists()
    for name in evaluate.RESULT_FILES:
        assert json.loads((tmp_path / "api" / f"{name}.json").read_text()) == json.loads(json.dumps(results[name]))
    params, learners = run_dir_io.load_params(tiny_run)
    assert learners == batch.learner_table(run_dir_io.read_config(tiny_run).train)
    newest, _ = run_dir_io.load_batch(tiny_run, run_dir_io.read_config(tiny_run))
    chex.assert_trees_all_equal(params, newest.states.agent.params)
    assert all(leaf.shape[0] == len(learners) for leaf in jax.tree.leaves(params))
    # The loaded parameters drive the network as a plain function.
    one = jax.tree.map(lambda a: a[0], params)
    out = network.apply(one, jnp.zeros(125), CFG)
    assert out.shape == (3,) and bool(jnp.all(jnp.isfinite(out)))


def test_claims_only_decides_the_committed_files_again_as_the_full_evaluation_did(tiny_run, tmp_path, capsys):
    copy = tmp_path / "copy"
    shutil.copytree(tiny_run, copy)
    assert evaluate_cli.main([str(copy)]) == 0
    out = copy / evaluate.EVAL_DIR
    full = {n: (out / n).read_bytes() for n in ("claims.json", "claims.md", "table2.md")}
    for name in full:
        (out / name).unlink()
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    capsys.readouterr()
    assert evaluate_cli.main([str(copy), "--claims-only"]) == 0
    assert {n: (out / n).read_bytes() for n in full} == full  # the same verdicts, byte for byte
    err = capsys.readouterr().err.splitlines()  # the closing screen of the claims decided again
    assert err[-1] == f"claims decided again in {out}" and err[0].startswith(f"{copy} at chunk ")
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.name not in full} == before  # nothing else touched
    # Without the evaluation's files it is a one-line error, and it takes no other output folder.
    assert evaluate_cli.main([str(tiny_run), "--claims-only", "--out", str(tmp_path / "x")]) == errors.EXIT_USAGE
    fresh = tmp_path / "fresh"
    shutil.copytree(tiny_run, fresh, ignore=shutil.ignore_patterns(evaluate.EVAL_DIR))
    assert evaluate_cli.main([str(fresh), "--claims-only"]) == errors.EXIT_USAGE
    lines = [line for line in capsys.readouterr().err.splitlines() if ": error: " in line]
    assert len(lines) == 2 and "--claims-only" in lines[0] and "table2.json: missing" in lines[1]


@pytest.mark.slow
def test_a_second_evaluation_rewrites_no_figure_and_changed_data_redraw_theirs(tiny_run, tmp_path):
    out = tmp_path / "eval"
    evaluate.evaluate(tiny_run, out=out)

    def pngs():
        return {p.name: (p.read_bytes(), p.stat().st_mtime_ns, p.stat().st_ino) for p in out.glob("*.png")}

    first = pngs()
    assert set(first) == {
        "impedance.png",
        "fig4.png",
        f"fig4_{OTHER_FRAME}.png",
        "fig5.png",
        "learning_curves.png",
        "anatomy.png",
    }
    assert set(json.loads((out / evaluate.FIGURE_DIGESTS).read_text())) == set(first)
    run = run_dir_io.load(tiny_run)
    results = evaluate.evaluate_run(run)  # a second evaluation of the same run, as `evaluate` makes it
    evaluate.write_results(tiny_run, run, results, out)
    assert pngs() == first
    # Fewer metrics rows change the learning curves alone; a missing PNG is drawn again whatever its digest.
    (out / "fig5.png").unlink()
    evaluate.write_results(tiny_run, run._replace(metrics=run.metrics[: len(run.learners)]), results, out)
    now = pngs()
    assert now.keys() == first.keys() and now["fig5.png"][0] == first["fig5.png"][0]
    assert now["learning_curves.png"][0] != first["learning_curves.png"][0]
    kept = ("impedance.png", "fig4.png", f"fig4_{OTHER_FRAME}.png")
    assert {n: now[n] for n in kept} == {n: first[n] for n in kept}
