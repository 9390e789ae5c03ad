"""The paper's field in each reading of its coordinates (model §6): an evaluation seen from one frame at a time.

A frame is a condition of cfg.eval.frames that stands for the paper's viscous field. Its view of an evaluation keeps
the other learners and tests as they are, names its own field's learners and test "viscous" (the paper's Table 2
and the claims are written in that name), and leaves out the learners and tests of every other frame: a network
trained in one frame is not the paper's viscous row in another. Without frames the one view is the evaluation itself.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from reach_jax.config import Config
from reach_jax.env import task

PAPER_FIELD = "viscous"  # the field's name in the paper's Table 2 and in the claims


def frame_list(cfg: Config) -> tuple[str | None, ...]:
    """The frames to judge, the main one first; (None,) for a run without frames (`view` leaves it as it is)."""
    return cfg.eval.frames or (None,)


def test_columns(cfg: Config) -> tuple[str, ...]:
    """The conditions every network is tested in: cfg.eval.test_conditions, then the frames not among them."""
    tests = cfg.eval.test_conditions
    return tests + tuple(f for f in cfg.eval.frames if f not in tests)


def rename(name: str, frame: str | None, cfg: Config) -> str | None:
    """A learning or test condition's name in `frame`'s view: the frame's field as "viscous", None for a condition
    the view leaves out (another frame, or a "viscous" that is not this frame)."""
    if frame is None:
        return name
    if name == frame:
        return PAPER_FIELD
    return None if name in cfg.eval.frames or name == PAPER_FIELD else name


def rows_view(rows: list[dict], frame: str | None, cfg: Config) -> list[dict]:
    """Records with "learning" and "test" names in `frame`'s view, those it leaves out dropped."""
    out = []
    for r in rows:
        learning, test = rename(r["learning"], frame, cfg), rename(r["test"], frame, cfg)
        if learning is not None and test is not None:
            out.append({**r, "learning": learning, "test": test})
    return out


@dataclasses.dataclass(frozen=True)
class View:
    """One frame's view of a run's networks and test columns."""

    frame: str | None  # the condition that is the paper's field here; None: the run as it is
    learners: list  # (learning condition in the view, or None if left out, seed) per network
    recipe_of: list[int]  # recipe per network, -1 for one left out, so no recipe pools it
    tests: list  # each test column's name in the view, None if left out
    cfg: Config  # the run's config with the view's test columns as eval.test_conditions
    field: np.ndarray  # (2, 2) the frame's viscous matrix [N s/m] as the arm felt it (float32)


def view(frame: str | None, learners: list, recipe_of: list[int], cfg: Config) -> View:
    """`frame`'s view of a run whose networks are `learners` ((condition, seed) each) with recipes `recipe_of`."""
    names = [rename(name, frame, cfg) for name, _ in learners]
    tests = [rename(t, frame, cfg) for t in test_columns(cfg)]
    shown = dataclasses.replace(cfg.eval, test_conditions=tuple(t for t in tests if t is not None))
    field = task.make_condition(frame or PAPER_FIELD, cfg).field.viscous
    return View(
        frame=frame,
        learners=[(n, seed) for n, (_, seed) in zip(names, learners, strict=True)],
        recipe_of=[k if n is not None else -1 for n, k in zip(names, recipe_of, strict=True)],
        tests=tests,
        cfg=dataclasses.replace(cfg, eval=shown),
        field=np.asarray(field),
    )


def table_view(table: dict, frame: str | None, cfg: Config) -> dict:
    """A `lattice.table2` record in `frame`'s view."""
    return {**table, **{k: rows_view(table[k], frame, cfg) for k in ("rows", "first_two", "per_network")}}


# How the tables and claims of several frames say what a frame is (model §6).
FRAMES_WORDS = (
    "Each frame is a reading of the paper's viscous field: its networks trained in that field stand for the paper's"
    ' "viscous" row and its test for the "viscous" column; networks trained in another frame\'s field are left out.'
)


def heading(frame: str | None) -> str:
    """The start of a section heading for `frame`: "Frame viscous_mirror, ", or nothing for a run without frames."""
    return "" if frame is None else f"Frame {frame}, "


def shown(name: str, frame: str | None) -> str:
    """A condition as the run names it: in `frame`'s view the paper's "viscous" is the frame's field."""
    return frame if frame is not None and name == PAPER_FIELD else name
