"""The failure anatomy: a made-up trajectory of each fail class and each out gets its label, the classes' precedence,
the goal square per network, the shares per cell over networks, and scripted arms' episodes labelled end to end."""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from reach_jax.config import Config, EvalConfig
from reach_jax.env.environment import FAIL, OUT, SUCCESS
from reach_jax.evaluate import anatomy, anatomy_report, episodes, lattice
from reach_jax.evaluate.episodes import Episode, Trajectory

CFG = Config()
TH = anatomy.thresholds(CFG, np.array([CFG.sensor.cell_size]))
W = TH.window
T = episodes.n_steps(CFG)
TARGET = np.array([-0.05, 0.37])  # [m]
CELL = CFG.sensor.cell_size
LABEL = {name: k for k, name in enumerate(anatomy.LABELS)}


def window(theta2=1.5, tau=(1.0, 1.0), offset=(0.15, 0.0), speed=0.5, wobble=0.0):
    """A fail's last states: the elbow at `theta2` [rad], torques `tau` [N m] ((W, 2) or held), the hand at
    `offset` [m] from the target, moving `wobble` [m] back and forth, at `speed` [m/s]."""
    state = np.zeros((W, 4))
    state[:, 0], state[:, 1] = 0.8, theta2
    torques = np.broadcast_to(np.asarray(tau, dtype=np.float64), (W, 2))
    swing = wobble * np.sin(np.arange(W) * 0.3)
    hand = TARGET + np.asarray(offset) + np.stack([swing, np.zeros(W)], axis=1)
    return state, torques, hand, np.full(W, speed)


def classify(state, torques, hand, speed, half_width=None):
    half = TH.half_width[0] if half_width is None else half_width
    kind = anatomy.fail_class(state, torques, hand, speed, TARGET, half, TH.near[0], TH)
    return anatomy.FAIL_CLASSES[int(kind)]


CHATTER = np.stack([4.7 * (-1.0) ** np.arange(W), 2.7 * (-1.0) ** (np.arange(W) + 1)], axis=1)  # every step


@pytest.mark.parametrize(
    ("name", "kwargs"),
    [
        # on the stop throughout, chattering and in the goal square too: folded comes first
        ("folded", {"theta2": math.pi, "tau": CHATTER, "offset": (0.0, 0.0), "speed": 0.0}),
        # chatter inside the goal square with its speed above the goal's (no-past -> none, SPEC 17): chatter first
        ("chatter", {"tau": CHATTER, "offset": (0.01, 0.0), "speed": 0.13}),
        ("hover", {"offset": (0.02, -0.02), "speed": 0.3, "wobble": 0.01}),
        ("rest_near", {"offset": (1.5 * CELL, 0.0), "speed": 0.01}),
        ("rest_far", {"offset": (0.0, -3 * CELL), "speed": 0.01}),
        ("swinging", {"offset": (0.1, 0.05), "speed": 0.5, "wobble": 0.03}),
    ],
)
def test_a_made_up_fail_of_each_class_gets_its_label(name, kwargs):
    assert classify(*window(**kwargs)) == name


def test_each_class_needs_its_share_of_the_window():
    """Just under each share the next class in order takes the movement."""
    fold = int(math.ceil(TH.fold_share * W))
    state, tau, hand, speed = window(theta2=math.pi, offset=(0.0, -3 * CELL), speed=0.01)
    state[: W - fold, 1] = 1.5  # on the stop in the last `fold` states: exactly the share
    assert classify(state, tau, hand, speed) == "folded"
    state[W - fold, 1] = 1.5
    assert classify(state, tau, hand, speed) == "rest_far"
    # Flips in a share of the steps just under the bound, or with a torque under the flip size, are no chatter.
    flips = int(math.ceil(TH.chatter_share * (W - 1)))
    tau, start = CHATTER.copy(), W - 1 - flips
    tau[:start] = tau[start]  # held, then flipping in each of the last `flips` steps: exactly the share
    assert classify(*window(tau=tau)) == "chatter"
    tau[start + 1] = tau[start]
    assert classify(*window(tau=tau)) == "swinging"
    assert classify(*window(tau=CHATTER * TH.flip_torque / 5.0)) == "swinging"
    # A hand moving just above the rest speed is not at rest.
    assert classify(*window(offset=(0.0, -3 * CELL), speed=TH.rest_speed * 1.01)) == "swinging"
    assert classify(*window(offset=(0.0, -3 * CELL), speed=TH.rest_speed * 0.99)) == "rest_far"
    assert classify(*window(offset=(TH.near[0] - 1e-6, 0.0), speed=0.0)) == "rest_near"
    assert classify(*window(offset=(TH.near[0] + 1e-4, 0.0), speed=0.0)) == "rest_far"


def test_the_goal_square_is_each_networks_own():
    """The same hovering hand hovers in a network's wider goal square and swings past a narrower one."""
    moving = window(offset=(0.03, 0.0), speed=0.3, wobble=0.005)
    assert classify(*moving, half_width=0.04) == "hover"
    assert classify(*moving, half_width=0.02) == "swinging"


def test_an_out_is_named_by_the_limit_it_crossed_first_in_order():
    lo, hi = CFG.arm.theta1_range
    last = np.array(
        [
            [lo - 0.01, 1.0, 0, 0],
            [hi + 0.01, 1.0, 0, 0],
            [0.5, CFG.arm.theta2_min - 0.01, 0, 0],
            [lo - 0.01, CFG.arm.theta2_min - 0.01, 0, 0],  # both: theta1's comes first
        ]
    )
    assert anatomy.out_limit(last, TH).tolist() == [0, 1, 2, 0]


def _batch(movements):
    """An Episode and Trajectory, axes (N=1, C=1, P), from (outcome, steps, arm states (T+1, 4), torques (T+1, 2),
    hand (T+1, 2), speed (T+1,)) per movement."""
    outcome, steps, states, tau, hand, speed = (np.stack(a)[None, None] for a in zip(*movements, strict=True))
    return Episode(outcome, steps, hand, speed), Trajectory(states, tau)


def _movement(outcome, steps, last_window, out_state=None):
    """A whole movement of T steps whose last W states are `last_window` (`window`'s output); an out's state at
    its step is `out_state`, and the states after it differ, so that reading them would name another limit."""
    state, tau, hand, speed = (np.zeros((T + 1, *a.shape[1:])) for a in last_window)
    for whole, part in zip((state, tau, hand, speed), last_window, strict=True):
        whole[:] = part[0]
        whole[-W:] = part
    if out_state is not None:
        state[steps] = out_state
        state[steps + 1 :] = [0.5, 1.0, 0.0, 0.0]
    return outcome, np.int32(steps), state, tau, hand, speed


def test_label_movements_reads_outs_at_their_step_and_fails_from_their_window():
    hi = CFG.arm.theta1_range[1]
    rest = window(offset=(0.0, -3 * CELL), speed=0.0)
    there = window(tau=CHATTER, offset=(0.01, 0.0), speed=0.13)
    ep, traj = _batch(
        [
            _movement(SUCCESS, 30, rest),
            _movement(OUT, 40, rest, out_state=[hi + 0.05, 1.0, 0.0, 0.0]),
            _movement(OUT, 12, rest, out_state=[0.5, -0.05, 0.0, 0.0]),
            _movement(FAIL, T, window(theta2=math.pi)),
            _movement(FAIL, T, rest),
            _movement(FAIL, T, there),
            _movement(SUCCESS, 30, there),  # in the goal square, but no fail
        ]
    )
    m = anatomy.label_movements(ep, traj, np.tile(TARGET, (7, 1)), TH)
    names = [anatomy.LABELS[k] for k in m.label[0, 0]]
    assert names == ["success", "theta1_high", "theta2_low", "folded", "rest_far", "chatter", "success"]
    assert m.steps[0, 0].tolist() == [30, 40, 12, T, T, T, 30]
    assert m.in_goal[0, 0].tolist() == [False] * 5 + [True, False]


def _labels_of(names):
    return np.array([LABEL[n] for n in names], dtype=np.int8)


def test_a_cells_shares_are_means_over_networks_and_its_composition_is_pooled():
    labels = np.stack(
        [
            _labels_of(["success", "success", "folded", "theta1_high"]),
            _labels_of(["folded", "chatter", "chatter", "theta2_low"]),
        ]
    )
    steps = np.array([[10, 20, T, 30], [T, T, T, 50]])
    goal = np.array([[False, False, False, False], [False, True, True, False]])
    c = anatomy.cell(anatomy.Labelled(labels, steps, goal), "none", "viscous", CFG.arm.dt, 0.95)
    assert c["networks"] == 2 and c["movements"] == 8
    assert c["counts"]["folded"] == 2 and c["counts"]["chatter"] == 2 and c["counts"]["success"] == 2
    assert c["shares"]["success"]["values"] == [0.5, 0.0]
    assert c["shares"]["folded"]["mean"] == pytest.approx(0.25) and c["shares"]["folded"]["low"] == 0.25  # equal
    assert c["shares"]["chatter"]["mean"] == pytest.approx(0.25)
    assert c["shares"]["chatter"]["low"] < 0.25 < c["shares"]["chatter"]["high"]
    assert c["of_fails"] == {"folded": 0.5, "chatter": 0.5, "hover": 0.0, "rest_near": 0.0, "rest_far": 0.0,
                             "swinging": 0.0}  # fmt: skip
    assert c["of_outs"] == {"theta1_low": 0.0, "theta1_high": 0.5, "theta2_low": 0.5}
    assert c["fails_in_goal"] == 0.5
    assert c["out_time_s"]["median"] == pytest.approx(40 * CFG.arm.dt) and c["out_time_s"]["n"] == 2
    assert sum(v["mean"] for v in c["shares"].values()) == pytest.approx(1.0)


def test_summarize_names_each_frames_field_viscous_and_reads_its_own_test_column():
    """Networks trained in the mirrored field are the viscous row of the mirrored frame, tested in its column."""
    learners = [("none", 0), ("none", 1), ("viscous_mirror", 0), ("viscous_mirror", 1)]
    tests = ("none", "viscous", "viscous_mirror")
    assert tests == tuple(anatomy.frames.test_columns(CFG))
    labels = np.zeros((4, 3, 6), dtype=np.int8)  # every movement a success ...
    labels[:2, 2, :3] = LABEL["folded"]  # ... but half of the no-field networks' in the mirrored field
    labels[:2, 1, :1] = LABEL["theta2_low"]  # and one in the field as applied
    steps, goal = np.full(labels.shape, T), labels == LABEL["folded"]
    goal[0, 2, 0] = False  # one of the six folds out of the goal square
    recipes, recipe_of = [{"lr": 1.0}], [0, 0, 0, 0]
    result = anatomy.summarize(anatomy.Labelled(labels, steps, goal), learners, recipe_of, recipes, CFG)
    assert result["frame"] == "viscous_mirror" and set(result["frames"]) == {"viscous"}
    cells = {(c["learning"], c["test"]): c for c in result["recipes"][0]["cells"]}
    assert list(cells) == [("none", "none"), ("none", "viscous"), ("viscous", "none"), ("viscous", "viscous")]
    assert cells["none", "viscous"]["shares"]["folded"]["mean"] == 0.5
    assert cells["none", "viscous"]["counts"]["theta2_low"] == 0
    applied = {(c["learning"], c["test"]): c for c in result["frames"]["viscous"]["recipes"][0]["cells"]}
    assert list(applied) == [("none", "none"), ("none", "viscous")]  # no network trained in that frame's field
    assert applied["none", "viscous"]["counts"]["theta2_low"] == 2
    assert len(result["per_network"]) == 12 and result["per_network"][2]["folded"] == 3
    assert result["per_network"][2]["fails_in_goal"] == 2 and result["per_network"][5]["fails_in_goal"] == 3
    assert result["limits_deg"] == {"theta1_low": 0.0, "theta1_high": 90.0, "theta2_low": 0.0}
    lines = anatomy_report.headlines(result)
    assert list(lines) == ["viscous_mirror", "viscous"] and all(len(v) == 1 for v in lines.values())
    assert lines["viscous_mirror"][0] == (
        "**Failure anatomy** (`anatomy.md`), none → viscous_mirror: 50.0% of movements fail (100% folded;"
        " 83% in the goal square), 0.0% go out."
    )
    assert lines["viscous"][0].endswith("16.7% go out (100% θ2 < 0°; median 4.00 s).")
    md = anatomy_report.markdown(result, "test", few=2)
    rows = [line for line in md.splitlines() if line.startswith("| none → viscous_mirror | 2 | ")]
    assert rows[0] == "| none → viscous_mirror | 2 | 50.0 [50.0, 50.0] |" + " 0.0 [0.0, 0.0] |" * 3 + " – |"  # outs
    assert rows[1].startswith("| none → viscous_mirror | 2 | 50.0 [50.0, 50.0] (100%) | 0.0 [0.0, 0.0] (0%) |")
    assert rows[1].endswith(" | 83% |")
    assert "| learning → test | networks | success % | out, θ1 < 0° % | out, θ1 > 90° % | out, θ2 < 0° % |" in md
    assert "## Frame viscous, Recipe 0: lr 1" in md
    assert set(result["thresholds"]) == {f.name for f in dataclasses.fields(EvalConfig) if "anatomy_" in f.name}
    fig = anatomy_report.figure(result)
    assert len(fig.axes) == 2


def _policy_limit(params, obs):
    """Full clockwise shoulder torque: theta1 falls below its lower limit."""
    return jnp.array([-CFG.arm.tau_max[0], 0.0])


def _policy_rest(params, obs):
    """No torque: the arm stays where it starts."""
    return jnp.zeros(2)


def _policy_flip(params, obs):
    """Torques that change sign every step, as no-past networks chatter; half the first, so the arm does not drift."""
    sign = jnp.where(obs.t % 2 == 0, 1.0, -1.0) * jnp.where(obs.t == 0, 0.5, 1.0)
    return sign * jnp.array([2.0, 1.5])


@pytest.mark.parametrize(
    ("policy", "names"),
    [(_policy_limit, {"theta1_low"}), (_policy_rest, {"rest_near", "rest_far"}), (_policy_flip, {"chatter"})],
)
def test_scripted_arms_episodes_in_the_null_field_get_their_labels(policy, names):
    starts, targets = lattice.test_pairs(CFG)
    pick = np.array([0, 5, 300, 1039])  # targets a cell or more away, and far
    params = jnp.zeros((1, 1))
    ep, traj = jax.device_get(
        episodes.run_episodes(
            policy, params, jnp.ones((1, 125)), lattice.test_fields(CFG), starts[pick], targets[pick], CFG
        )
    )
    labels = anatomy.label_movements(ep, traj, targets[pick], TH).label
    seen = {anatomy.LABELS[k] for k in labels[:, 0].ravel()}  # without a field (a field drives the flips' swing)
    assert seen <= names and seen
    if policy is _policy_rest:  # near exactly where the hand ends within two cells of the target
        far = np.max(np.abs(starts[pick] - targets[pick]), axis=1) > 2 * CELL
        assert [anatomy.LABELS[k] == "rest_far" for k in labels[0, 0]] == far.tolist()
