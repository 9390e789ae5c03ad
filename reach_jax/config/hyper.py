"""Per-learner hyperparameters: one table entry each (model §5, §11).

An entry of `TABLE` is the whole of a hyperparameter. From it come the field of `config.LearnerConfig` that holds
its default, the `config.TrainConfig` grid that sweeps it (`<name>_grid`), its range check, the field of the
per-learner `Hyper` arrays the compiled step reads, how the command line's `--sweep NAME=V[,V...]` reads it, its
place in a recipe's label and its words in a recipe's description (`describe`).
"""

from __future__ import annotations

import dataclasses
import difflib
from typing import Any, NamedTuple

import numpy as np

from reach_jax.config import compat
from reach_jax.config.hyperparameter import Hyperparameter

TABLE = (
    Hyperparameter(
        "lr",
        1.0,
        "SGD learning rate on squared error (model §11 choice; issue 56's held-out pick)",
        low_open=True,
        words="learning rate {v:g}",
    ),
    Hyperparameter(
        "noise",
        0.2,
        "exploration bound b of rnd ~ U(-b, b) in actor units (model §11 choice; issue 56's held-out pick)",
        words="bound {v:g}",
    ),
    Hyperparameter(
        "lam", 0.999, "lambda of eq. 3 (model §11 choice; issue 56's held-out pick)", low_open=True, words="λ {v:g}"
    ),
    Hyperparameter(
        "noise_final_ratio",
        1.0,
        "bound after the anneal as a fraction of noise; 1 = no anneal (model §5 choice)",
        words="annealed to ×{v:g}",
    ),
    Hyperparameter(
        "noise_anneal_delay",
        0,
        "trials from the first full-field trial to the start of the anneal",
        integer=True,
        words="the anneal {v:,.0f} trials after the whole field",
        part_of="noise_final_ratio",
    ),
    Hyperparameter(
        "noise_anneal_trials",
        300_000,
        "length of the linear anneal [trials]",
        integer=True,
        words="the anneal over {v:,.0f} trials",
        part_of="noise_final_ratio",
    ),
    Hyperparameter(
        "noise_value_ratio",
        1.0,
        "smallest bound, where the critic expects the goal, as a fraction of the bound; 1 = off (model §5 choice)",
        high=1.0,
        neutral=1.0,
        words="×{v:g} near the goal",
    ),
    Hyperparameter(
        "noise_value_hi",
        0.3,
        "critic value p at or above which the bound is smallest (model §5 choice)",
        neutral=0.3,
        words="smallest from p {v:g}",
        part_of="noise_value_ratio",
    ),
    Hyperparameter(
        "noise_value_lo",
        0.0,
        "critic value p at or below which the bound is whole (model §5 choice)",
        neutral=0.0,
        words="whole up to p {v:g}",
        part_of="noise_value_ratio",
    ),
    Hyperparameter(
        "noise_value_after_full",
        0.0,
        "true: the value scaling starts once the curriculum has first reached the whole field (model §5 choice)",
        high=1.0,
        switch=True,
        neutral=0.0,
        words="the value scaling once full",
        part_of="noise_value_ratio",
    ),
    Hyperparameter(
        "noise_value_gate",
        0.0,
        "curriculum shortfall from the whole field (fraction of it) at which the value scaling is fully relaxed; "
        "0 = off (model §5 choice)",
        high=1.0,
        neutral=0.0,
        words="the value scaling relaxed {v:.0%} short of the whole field",
        part_of="noise_value_ratio",
    ),
    Hyperparameter(
        "noise_value_steps",
        0,
        "steps into a trial from which the value scaling is off, the whole bound back; 0 = never (model §5 choice)",
        integer=True,
        neutral=0,
        words="the whole bound from step {v:.0f} of a trial",
        part_of="noise_value_ratio",
    ),
    Hyperparameter(
        "noise_corr",
        0.0,
        "step-to-step correlation of rnd, AR(1) with the spread kept; 0 = white (model §5 choice)",
        high=1.0,
        high_open=True,
        neutral=0.0,
        words="AR ρ {v:g}",
    ),
    Hyperparameter(
        "actor_baseline",
        0.0,
        "share of P_range/N_max taken from dp in eq. 2's actor signal; 1 = the TD error (departs from eq. 2, model §5)",
        high=1.0,
        neutral=0.0,
        words="actor baseline {v:g}",
    ),
    Hyperparameter(
        "actor_gain_power",
        0.0,
        "the actor's signal divided by the value scaling's factor to this power; 2 keeps eq. 2's expected step "
        "(departs from eq. 2, model §5)",
        high=2.0,
        neutral=0.0,
        words="actor gain ×s^-{v:g}",
    ),
    Hyperparameter(
        "actor_signal_gain",
        1.0,
        "g: eq. 2's actor signal multiplied by it, the critic's left as it is; 1 = eq. 2, others depart (model §5)",
        neutral=1.0,
        words="actor-only gain {v:g}",
    ),
    Hyperparameter(
        "actor_target_bound",
        0.0,
        "a: eq. 2's actor targets clipped to [-a, a], so that no target drives an actor output into saturation, where "
        "its gradient and the noise's effect on the torque vanish; 0 = off, eq. 2, others depart (model §5)",
        high=0.5,
        neutral=0.0,
        words="actor targets within ±{v:g}",
    ),
    Hyperparameter(
        "drift_neutral_early",
        0.0,
        "true: a drift-aided success leaves the curriculum unchanged before the first full field too (model §5 choice)",
        high=1.0,
        switch=True,
        neutral=0.0,
        words="drift neutral from the start",
    ),
    Hyperparameter(
        "drift_gate",
        0.0,
        "a trial's target drifts only while the learner's recent failure share exceeds it; 0 = off, every trial "
        "drifts (the paper's 'often fails', model §5)",
        high=1.0,
        neutral=0.0,
        words="drift only above {v:g} recent failure",
    ),
    Hyperparameter(
        "drift_gate_trials",
        300,
        "time constant of the recent failure share, an exponential mean over trials (model §5 choice)",
        low_open=True,
        integer=True,
        neutral=300,
        words="the failure share over {v:.0f} trials",
        part_of="drift_gate",
    ),
    Hyperparameter(
        "n_max_clean",
        0.0,
        "true: eq. 3 takes only successes without drift into N_max (departs from eq. 3's every success, model §5)",
        high=1.0,
        switch=True,
        neutral=0.0,
        words="N_max from clean successes",
    ),
    Hyperparameter(
        "quiet_every",
        0,
        "every n-th trial runs without exploration; 0 = never (model §5 choice)",
        integer=True,
        neutral=0,
        words="quiet 1/{v:.0f}",
    ),
)

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
