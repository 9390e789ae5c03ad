"""Reading files that older code wrote: every migration of a config or a checkpoint, keyed by its format version.

A run must resume under the rules it was trained with, so each change of a stored format bumps its version, and
the reading of each older version is written here once, with a test (tests/test_compat.py).
"""

from __future__ import annotations

CHECKPOINT_VERSION = 3  # 3: the trial, its condition and block, the curriculum and the trial count under `env`
READABLE_CHECKPOINTS = (2, 3)
READABLE_CONFIGS = (1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16)  # `config.CONFIG_VERSION` is the last
FIRST_COMPLETE_CONFIG = 2  # from version 2 on a stored config holds every field of its version

# Fields added with a config version, each at the value that keeps the runs of the versions before it unchanged.
ADDED_CONFIG_FIELDS = {
    3: {"learner": {"noise_value_gate": 0.0}, "train": {"noise_value_gate_grid": []}},
    4: {"learner": {"noise_value_steps": 0}, "train": {"noise_value_steps_grid": []}},
    5: {"learner": {"actor_gain_power": 0.0}, "train": {"actor_gain_power_grid": []}},
    6: {
        "learner": {"actor_signal_gain": 1.0, "drift_gate": 0.0, "drift_gate_trials": 300, "n_max_clean": 0.0},
        "task": {"drift_gate_start": 1.0},
        "train": {
            "saturated_output": 0.45,
            **{f"{name}_grid": [] for name in ("actor_signal_gain", "drift_gate", "drift_gate_trials", "n_max_clean")},
        },
    },
    7: {"train": {"zip_grids": False}},
    8: {"claims": {"informative_networks": 4}},
    11: {
        "learner": {"actor_target_bound": 0.0},
        "claims": {"collapse_success": 0.5, "collapse_trials": 10_000},
        "train": {"actor_target_bound_grid": []},
    },
    # The elbow stop trained as the clamp before version 13; every run is tested in both frames of the field.
    13: {"arm": {"one_link_stop": False}, "eval": {"frames": ["viscous", "viscous_mirror"]}},
    # Version 15: the task's geometry as per-learner data (every learner of an older run sees the visual field of its
    # sensor), and the failure anatomy's thresholds (they describe the fails of a test and change no outcome, so an
    # older run takes today's).
    15: {
        "learner": {"sensor_dx": 0.0, "sensor_dy": 0.0, "sensor_scale": 1.0},
        "train": {"sensor_dx_grid": [], "sensor_dy_grid": [], "sensor_scale_grid": []},
        "eval": {
            "anatomy_window": 1.0,
            "anatomy_fold_margin_deg": 1.0,
            "anatomy_fold_share": 0.5,
            "anatomy_flip_torque": 0.5,
            "anatomy_chatter_share": 0.5,
            "anatomy_hover_share": 0.5,
            "anatomy_rest_speed": 0.05,
            "anatomy_near_cells": 2.0,
        },
    },
}

# The constant-exploration recipe (versions 1-8 and 10-11) in the fields that versions 9 and 12 changed.
_CONSTANT_EXPLORATION = {
    "learner": {
        "lr": 1.0,
        "noise": 0.2,
        "lam": 0.999,
        "noise_final_ratio": 1.0,
        "noise_anneal_delay": 0,
        "noise_value_ratio": 1.0,
        "noise_corr": 0.0,
        "actor_signal_gain": 1.0,
        "drift_gate": 0.0,
    },
    "task": {"max_trial_time": 10.0},
}

# Round 4's pick (the default of version 9), and the same with eq. 2's actor targets clipped (versions 12-13).
_ROUND4_PICK = {
    "learner": {
        "lr": 1.6,
        "noise": 0.213,
        "lam": 0.99728,
        "noise_final_ratio": 0.758,
        "noise_anneal_delay": 298_000,
        "noise_value_ratio": 0.716,
        "noise_corr": 0.311,
        "actor_signal_gain": 0.703,
        "drift_gate": 0.401,
    },
    "task": {"max_trial_time": 4.0},
}
_CLIPPED_PICK = {**_ROUND4_PICK, "learner": {**_ROUND4_PICK["learner"], "actor_target_bound": 0.45}}

# Defaults changed with a config version, at their values before it: a version-1 config, which left out the
# fields added during its life, trained with these where it lacks them. Version 9 made round 4's held-out pick the
# default recipe; version 10 put the recipe of version 8 back, since the pick collapsed learners in both runs of the
# main command (model §11). Version 12 made the pick with eq. 2's actor targets clipped to ±0.45 the default, by
# issue 49's adoption rule (no collapse on held-out seeds, studies/collapse/verdict.md). The pick without the clip is
# `recipes/round4_pick.json`; the recipe of versions 10-11 is `recipes/constant_exploration.json`. Version 13 made
# the elbow stop the paper's one link (model §1); a version-1 config trained with the clamp. Version 14 trains and
# judges the paper's field mirrored by default, with the constant-exploration recipe, by issue 56's adoption rule
# (studies/frame/verdict.md): before it, the field's learners and the adaptation protocol's field block trained in the
# frame as applied, which the first frame judged, with the clipped pick (`recipes/clipped_pick.json`). Version 16
# raised the exploration bound from 0.2 to 0.25, by issue 62's adoption rule (studies/geometry/verdict.md); the
# recipe of versions 14-15 is `recipes/constant_exploration.json`.
CHANGED_DEFAULTS = {
    9: _CONSTANT_EXPLORATION,
    10: _ROUND4_PICK,
    12: {**_CONSTANT_EXPLORATION, "learner": {**_CONSTANT_EXPLORATION["learner"], "actor_target_bound": 0.0}},
    13: {"arm": {"one_link_stop": False}},
    14: {
        **_CLIPPED_PICK,
        "train": {"conditions": ["none", "viscous", "random", "random_nopast"]},
        "eval": {"frames": ["viscous", "viscous_mirror"]},
        "protocols": {
            "adaptation": [
                {"trials": 5_000, "condition": "none"},
                {"trials": 20_000, "condition": "viscous", "catch": 0.1},
                {"trials": 20_000, "condition": "none"},
            ]
        },
    },
    16: {"learner": {"noise": 0.2}},
}

# Config fields that older runs stored and that no longer belong to the config: speed knobs, which do not change
# results (`reach_jax.config.Speed`). Reading drops them, so those runs still load and resume.
RETIRED_FIELDS = {"train": ("hidden_pad",)}

# Checkpoint format 2 kept these fields of today's state elsewhere (path under ['states'], today -> then).
_V2_MOVED = (("env.trial.", "env."), ("env.cond.", "cond."), ("env.block.", "block."))
_V2_MOVED += (("env.curriculum.", "curriculum."), ("env.trials", "counters.trials"))
# Format-2 files of the first layout stored the state flat, without the groups' names, and the block by its parts.
_V2_GROUPS = ("agent", "env", "curriculum", "counters")
_V2_FLAT_RENAMED = {"block.index": "block", "block.learning": "learning", "block.catch": "catch"}
# State fields that older checkpoints lack: a fresh batch fills them with what those runs trained with. Format-2
# files of the first layout lack the run's own condition, block 0 and learning on (made before protocols); every
# file before the actor's gain lacks its value 1 (`exploration.actor_gain`); every file before the drift gate lacks
# the recent failure share (its start value: those runs drifted in every trial) and the chunk counters added with it
# (reset at each chunk).
ADDED_STATE_FIELDS = ("agent.pending_learning", "env.cond", "env.block", "agent.pending.gain", "env.curriculum.failure")
_ADDED_STATS = ("clean_goals", "gate_open", "steps", "saturated", "starts", "start_value")
ADDED_STATE_FIELDS += tuple(f"counters.stats.{name}" for name in _ADDED_STATS)

# The result-changing speed settings (`schema.SPEED_RESULT_FIELDS`) and engine of checkpoints written before they
# were stored: until the step loop became one kernel, XLA:CPU contracted multiply-adds as each kernel's shape let it.
SPEED_BEFORE_STORED = {"sparse_layer1": True, "engine": "cpu-fma-kernels"}
# Where the code that trained an engine no longer made here lives, for the error that refuses to resume its runs.
ENGINE_CODE = {"cpu-fma-kernels": " (that engine is reach_jax's up to commit c0a0a95: resume the run with that code)"}

_STATES = "['states']."


def state_aliases(name: str, version: int) -> tuple[str, ...]:
    """Names under which a checkpoint of format `version` may hold today's leaf `name`, most recent layout first."""
    if version == CHECKPOINT_VERSION or not name.startswith(_STATES):
        return ()
    rest = name.removeprefix(_STATES)
    for new, old in _V2_MOVED:
        if rest.startswith(new):
            rest = old + rest.removeprefix(new)
            break
    return (_STATES + rest, _STATES + _v2_flat(rest))


def _v2_flat(rest: str) -> str:
    if rest in _V2_FLAT_RENAMED:
        return _V2_FLAT_RENAMED[rest]
    group, _, field = rest.partition(".")
    return field if group in _V2_GROUPS and field else rest


def is_added_state_field(name: str) -> bool:
    """True for a leaf of a state field that old checkpoints may lack and a fresh batch fills."""
    return name.removeprefix(_STATES).startswith(ADDED_STATE_FIELDS)


def retired(section: str, field: str) -> bool:
    """True for a config field that older runs stored and that reading drops."""
    return field in RETIRED_FIELDS.get(section, ())


def drop_retired(section: str, raw):
    """A config section's stored fields without the retired ones."""
    if not isinstance(raw, dict):
        return raw
    return {k: v for k, v in raw.items() if not retired(section, k)}


def migrate_config(data: dict, version: int) -> dict:
    """A stored config dict (without its version) in the layout of the current version.

    Version 1 configs left out the fields added during that version's life; each was added with the value that
    keeps the earlier behaviour, and `config.from_dict` fills it so, except `task.drift_neutral_when_full`, which
    came in switched on: a config without it trained under the old staircase, so it reads as False. Version 1 also
    covers the speed fields dropped since (RETIRED_FIELDS) and the `force` section of the time before conditions
    were data. A complete config of an older version gains the fields of each later one (ADDED_CONFIG_FIELDS), and
    a version-1 config reads a field whose default changed since, where it lacks it, as before (CHANGED_DEFAULTS).
    """
    if version == 1:
        data = _migrate_version_1(data)
    for since, sections in ADDED_CONFIG_FIELDS.items():
        if FIRST_COMPLETE_CONFIG <= version < since:
            data = _fill(data, sections)
    if version < FIRST_COMPLETE_CONFIG:  # later versions store every field; a missing one stays an error
        for sections in CHANGED_DEFAULTS.values():  # oldest first: the first fill of a field stands
            data = _fill(data, sections)
    return data


def defaults_of(version: int, section: str, defaults: dict) -> dict:
    """`defaults` ({field: today's default}) of a config section as they were at config version `version`."""
    values = dict(defaults)
    for since in sorted(CHANGED_DEFAULTS, reverse=True):  # newest first: the value before the first change stands
        if version < since:
            values.update((k, v) for k, v in CHANGED_DEFAULTS[since].get(section, {}).items() if k in values)
    return values


def _fill(data: dict, sections: dict) -> dict:
    """data with each field of `sections` ({section: {field: value}}) that it lacks added at the value given."""
    for name, fields in sections.items():
        section = data.get(name, {})
        if isinstance(section, dict):
            data = {**data, name: {**fields, **section}}
    return data


def _migrate_version_1(data: dict) -> dict:
    data = {k: drop_retired(k, v) for k, v in data.items()}
    task = data.get("task", {})
    if isinstance(task, dict) and "drift_neutral_when_full" not in task:
        data["task"] = {**task, "drift_neutral_when_full": False}
    return _force_as_conditions(data)


def _force_as_conditions(data: dict) -> dict:
    if "force" not in data:
        return data
    force = data.pop("force")
    if not isinstance(force, dict):
        raise ValueError("force: expected an object")
    unknown = sorted(set(force) - {"viscous", "random_amplitude"})
    if unknown:
        raise ValueError(f"force.{unknown[0]}: unknown field")
    conditions = dict(data.get("conditions", {}))
    if "viscous" in force:
        conditions["viscous"] = {"viscous": force["viscous"], **conditions.get("viscous", {})}
    if "random_amplitude" in force:
        for name in ("random", "random_nopast"):
            amplitude = force["random_amplitude"]
            conditions[name] = {"random": [amplitude, amplitude], **conditions.get(name, {})}
    return {**data, "conditions": conditions}
