"""Per-learner hyperparameters: one table entry each (model §5, §11).

An entry of `TABLE` (`hyper_table`) is the whole of a hyperparameter. From it come the field of
`config.LearnerConfig` that holds its default, the `config.TrainConfig` grid that sweeps it (`<name>_grid`), its range
check, the field of the per-learner `Hyper` arrays the compiled step reads, how the command line's
`--sweep NAME=V[,V...]` reads it, its place in a recipe's label and its words in a recipe's description (`describe`).
"""

from __future__ import annotations

import dataclasses
import difflib
from typing import Any, NamedTuple

import numpy as np

from reach_jax.config import compat
from reach_jax.config.hyper_table import TABLE
from reach_jax.config.hyperparameter import Hyperparameter

NAMES = tuple(h.name for h in TABLE)
BY_NAME = {h.name: h for h in TABLE}

# A NamedTuple is a JAX pytree without importing JAX here: config and the NumPy oracle import this table.
Hyper = NamedTuple("Hyper", [(h.name, Any) for h in TABLE])
Hyper.__doc__ = "Per-learner learning constants, one () array each (a sweep is just a batch of learners)."


def defaults(version: int | None = None) -> dict[str, float]:
    """Every hyperparameter's default, as at config `version` when given (`compat.CHANGED_DEFAULTS`)."""
    today = {h.name: h.default for h in TABLE}
    return today if version is None else compat.defaults_of(version, "learner", today)


def lookup(name: str) -> Hyperparameter:
    """The entry called `name`; raises ValueError naming the closest name when there is none."""
    if name in BY_NAME:
        return BY_NAME[name]
    close = difflib.get_close_matches(name, NAMES, n=1)
    hint = f"; closest: {close[0]}" if close else ""
    raise ValueError(f"no hyperparameter {name!r}{hint} (--list-hyper lists them)")


def table_text() -> str:
    """The table as aligned text, one line an entry: name, default, allowed values, help (what --list-hyper prints)."""
    rows = [("name", "default", "range", "help")]
    rows += [(h.name, _default_text(h), h.bounds, h.help) for h in TABLE]
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    return "".join("  ".join([*(c.ljust(w) for c, w in zip(r[:3], widths, strict=True)), r[3]]) + "\n" for r in rows)


def _default_text(h: Hyperparameter) -> str:
    if h.switch:
        return "true" if h.default else "false"
    return f"{h.default:g}" if not h.integer else str(h.default)


def config_fields() -> list[tuple]:
    """The LearnerConfig fields of the table: (name, type, default)."""
    return [(h.name, int if h.integer else float, dataclasses.field(default=h.default)) for h in TABLE]


def grid_fields() -> list[tuple]:
    """The TrainConfig sweep grids of the table: (name, type, default ()); () takes the learner's default."""
    return [(h.grid, tuple[float, ...], dataclasses.field(default=())) for h in TABLE]


def check(where: str, name: str, values) -> None:
    """Raise ValueError "where: why" if any of `values` is out of the hyperparameter `name`'s range."""
    for value in values:
        why = BY_NAME[name].check(value)
        if why:
            raise ValueError(f"{where}: {why}")


def label(values: dict[str, float]) -> dict[str, float]:
    """The hyperparameters that name a recipe: every one without a neutral value, the others where they are on.

    Values read from a batch are float32, so they are compared with the neutral value at that precision.
    """
    return {
        k: v for k, v in values.items() if BY_NAME[k].neutral is None or np.float32(v) != np.float32(BY_NAME[k].neutral)
    }


def describe(values: dict[str, float], baseline: dict[str, float] | None = None) -> str:
    """A recipe in words: its bound, then each hyperparameter set away from the baseline (one that shapes another's
    form only while that one is on), in table order.

    Args:
        values: hyperparameter name -> value, such as a recipe's label (`label`) in `eval/claims.json`.
        baseline: name -> value that goes unsaid; today's defaults when None (`defaults(version)` for a study's).
    """
    baseline = defaults() if baseline is None else baseline
    words = [BY_NAME["noise"].words.format(v=values.get("noise", baseline["noise"]))]
    for h in TABLE:
        part_of = h.part_of and BY_NAME[h.part_of]
        if h.name == "noise" or not _set(values, h, baseline) or (part_of and not _set(values, part_of, baseline)):
            continue
        words.append(h.words.format(v=values[h.name]))
    return "; ".join(words)


def changed(values: dict[str, float], baseline: dict[str, float] | None = None) -> list[str]:
    """The names in `values` set away from the baseline (today's defaults when None), in their order, compared at
    float32 precision as a batch stores them."""
    baseline = defaults() if baseline is None else baseline
    return [name for name in values if _set(values, BY_NAME[name], baseline)]


def _set(values: dict[str, float], h: Hyperparameter, baseline: dict[str, float]) -> bool:
    """Whether `values` sets h away from the baseline (at float32 precision, as a batch stores it)."""
    return h.name in values and np.float32(values[h.name]) != np.float32(baseline[h.name])
