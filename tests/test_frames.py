"""Frames of the paper's field (model §6): each frame's view of an evaluation names its own field "viscous" and
leaves out the networks and tests of the other frames."""

from __future__ import annotations

import numpy as np
import pytest

from reach_jax.config import Config, condition, from_partial
from reach_jax.evaluate import frames

CFG = Config()
LEARNERS = [("none", 0), ("viscous", 0), ("viscous_mirror", 0), ("random", 0), ("random_nopast", 0)]
TESTS = ("none", "viscous", "viscous_mirror")


def cells() -> list[dict]:
    return [{"learning": n, "test": t, "learner": i} for i, (n, _) in enumerate(LEARNERS) for t in TESTS]


def pairs(rows: list[dict]) -> set[tuple[str, str]]:
    return {(r["learning"], r["test"]) for r in rows}


def test_every_network_is_tested_in_every_frame():
    assert frames.test_columns(CFG) == TESTS
    no_frames = from_partial({"eval": {"frames": []}})  # a config may judge its run without frames
    assert frames.test_columns(no_frames) == ("none", "viscous") and frames.frame_list(no_frames) == (None,)


def test_the_frame_as_applied_leaves_the_mirrored_networks_and_test_out():
    seen = frames.rows_view(cells(), "viscous", CFG)
    assert pairs(seen) == {(n, t) for n in ("none", "viscous", "random", "random_nopast") for t in ("none", "viscous")}
    assert {r["learner"] for r in seen if r["learning"] == "viscous"} == {1}


def test_the_mirrored_frame_names_its_field_viscous_and_leaves_the_other_out():
    seen = frames.rows_view(cells(), "viscous_mirror", CFG)
    assert pairs(seen) == {(n, t) for n in ("none", "viscous", "random", "random_nopast") for t in ("none", "viscous")}
    assert {r["learner"] for r in seen if r["learning"] == "viscous"} == {2}  # the network trained mirrored
    v = frames.view("viscous_mirror", LEARNERS, [0] * 5, CFG)
    assert v.learners[1] == (None, 0) and v.learners[2] == ("viscous", 0)
    assert v.recipe_of == [0, -1, 0, 0, 0]  # no recipe pools the network of the other frame
    assert v.tests == ["none", None, "viscous"] and v.cfg.eval.test_conditions == ("none", "viscous")
    np.testing.assert_array_equal(v.field, np.asarray(condition(CFG, "viscous_mirror").viscous, np.float32))
    assert frames.shown("viscous", "viscous_mirror") == "viscous_mirror" and frames.shown("none", "x") == "none"


def test_without_frames_the_view_is_the_run_itself():
    assert frames.rows_view(cells(), None, CFG) == cells()
    v = frames.view(None, LEARNERS, [0] * 5, CFG)
    assert v.learners == LEARNERS and v.recipe_of == [0] * 5


@pytest.mark.parametrize("frame", ["viscous", "viscous_mirror"])
def test_a_table_view_keeps_its_counts(frame):
    table = {"rows": cells(), "first_two": cells(), "per_network": cells(), "pairs_per_network": 1040}
    seen = frames.table_view(table, frame, CFG)
    assert seen["pairs_per_network"] == 1040 and len(seen["rows"]) == len(seen["per_network"]) == 4 * 2
