"""Reading what older code wrote: each migration of `reach_jax.compat` against the names and values it stored."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from reach_jax.config import (
    CONDITIONS,
    CONFIG_VERSION,
    Config,
    LearnerConfig,
    TaskConfig,
    blocks_of,
    checked_config,
    compat,
    from_dict,
    from_partial,
    hyper,
    read_config_file,
    to_dict,
    with_defaults,
)


@pytest.mark.parametrize(
    ("name", "grouped", "flat"),
    [
        ("env.trial.arm", "env.arm", "arm"),
        ("env.trial.drifted", "env.drifted", "drifted"),
        ("env.trials", "counters.trials", "trials"),
        ("env.curriculum.full_at", "curriculum.full_at", "full_at"),
        ("env.block.index", "block.index", "block"),
        ("env.block.learning", "block.learning", "learning"),
        ("env.cond.input_mask", "cond.input_mask", "cond.input_mask"),
        ("counters.stats.goals", "counters.stats.goals", "stats.goals"),
        ("agent.n_max", "agent.n_max", "n_max"),
        (
            "agent.params['params']['Dense_0']['bias']",
            "agent.params['params']['Dense_0']['bias']",
            "params['params']['Dense_0']['bias']",
        ),
        ("key", "key", "key"),
    ],
)
def test_format_2_names_of_each_state_field_in_both_of_its_layouts(name, grouped, flat):
    """Format 2 kept the environment's fields beside the agent's (grouped), or, first, without groups (flat)."""
    states = "['states']."
    assert compat.state_aliases(states + name, 2) == (states + grouped, states + flat)
    assert compat.state_aliases(states + name, compat.CHECKPOINT_VERSION) == ()
    assert compat.state_aliases("['hypers'].lr", 2) == ()


def test_fields_that_the_first_layout_lacks_are_the_ones_a_fresh_batch_fills():
    assert compat.is_added_state_field("['states'].env.cond.field.viscous")
    assert compat.is_added_state_field("['states'].env.block.index")
    assert compat.is_added_state_field("['states'].agent.pending_learning")
    assert compat.is_added_state_field("['states'].agent.pending.gain")
    assert compat.is_added_state_field("['states'].env.curriculum.failure")
    assert compat.is_added_state_field("['states'].counters.stats.start_value")
    assert not compat.is_added_state_field("['states'].counters.stats.goals")
    assert not compat.is_added_state_field("['states'].env.trial.arm")
    assert not compat.is_added_state_field("['states'].agent.params['params']['Dense_0']['bias']")


def test_version_1_a_retired_speed_field_is_dropped_and_a_force_section_becomes_the_conditions():
    stored = {**to_dict(Config()), "version": 1}
    del stored["conditions"]  # configs of that time had none
    stored["train"]["hidden_pad"] = 32
    stored["force"] = {"viscous": [[-1.0, -2.0], [-2.0, 3.0]], "random_amplitude": 4.0}
    cfg = from_dict(stored)
    by_name = {c.name: c for c in cfg.conditions}
    assert by_name["viscous"].viscous == ((-1.0, -2.0), (-2.0, 3.0))
    assert by_name["random"].random == by_name["random_nopast"].random == (4.0, 4.0)
    assert compat.retired("train", "hidden_pad") and not compat.retired("train", "trials")
    with pytest.raises(ValueError, match="force.spring: unknown field"):
        from_dict({"version": 1, "force": {"spring": 1.0}})


def test_version_1_fields_added_since_read_as_what_those_runs_trained_with():
    stored = {**to_dict(Config()), "version": 1}
    del stored["task"]["drift_neutral_when_full"]  # came in switched on: before it, the old staircase
    del stored["learner"]["noise_corr"]  # came in neutral
    cfg = from_dict(stored)
    assert cfg.task.drift_neutral_when_full is False
    assert cfg.learner.noise_corr == 0.0  # white, as every default but those of versions 9 and 12 on
    stored["task"]["drift_neutral_when_full"] = True
    assert from_dict(stored) == Config(learner=LearnerConfig(noise_corr=0.0))


def test_before_version_9_a_missing_field_whose_default_changed_reads_as_it_was_before():
    """Version 9 made round 4's pick the default, version 10 put the old recipe back, version 12 made the pick with
    its actor targets clipped the default and version 14 the old recipe again; a version-1 config without those
    fields trained the old recipe."""
    old, pick, before_12, before_14 = (compat.CHANGED_DEFAULTS[v] for v in (9, 10, 12, 14))
    assert old.keys() == pick.keys() == before_12.keys() and all(old[s].keys() == pick[s].keys() for s in old)
    assert {**pick["learner"], "actor_target_bound": 0.45} == before_14["learner"] and pick["task"] == before_14["task"]
    old_config = Config(learner=LearnerConfig(**before_14["learner"]), task=TaskConfig(**before_14["task"]))
    stored = {**to_dict(old_config), "version": 1}
    for section in ("learner", "task"):
        for name in before_12[section]:
            del stored[section][name]
    cfg = from_dict(stored)
    for section, fields in before_12.items():
        for name, value in fields.items():
            assert getattr(getattr(cfg, section), name) == value != getattr(getattr(old_config, section), name), name
    today, constant = hyper.defaults(), hyper.defaults(15)  # version 16 raised the bound alone
    assert constant == {**today, "noise": 0.2} != today
    assert (
        hyper.defaults(8) == hyper.defaults(10) == hyper.defaults(11) == {**today, **before_12["learner"]} == constant
    )
    assert hyper.defaults(9) == {**today, **pick["learner"], "actor_target_bound": 0.0}
    assert hyper.defaults(12) == hyper.defaults(13) == {**hyper.defaults(9), "actor_target_bound": 0.45}
    assert hyper.defaults(13) != constant and hyper.defaults(14) == constant
    stored = {**to_dict(Config(learner=LearnerConfig(**pick["learner"]))), "version": 9}  # complete: its values stand
    assert from_dict(stored).learner == LearnerConfig(**pick["learner"])
    del stored["learner"]["lr"]
    with pytest.raises(ValueError, match="^learner.lr: missing"):
        from_dict(stored)


@pytest.mark.parametrize(
    ("recipe", "version"),
    [("round4_pick", 9), ("constant_exploration", 10), ("constant_exploration", 11), ("clipped_pick", 13)],
)
def test_a_named_recipe_is_an_earlier_default_one_config_away(recipe, version):
    """recipes/round4_pick.json spells config version 9's default recipe, recipes/constant_exploration.json that of
    versions 10-11 (and 1-8, and 14-15) and recipes/clipped_pick.json that of versions 12-13: the values
    `CHANGED_DEFAULTS` holds."""
    data = read_config_file(Path(__file__).resolve().parents[1] / "recipes" / f"{recipe}.json")
    assert "comment" not in data  # read and dropped
    cfg = checked_config(data)
    assert {n: getattr(cfg.learner, n) for n in hyper.NAMES} == hyper.defaults(version)
    assert cfg.task.max_trial_time == compat.defaults_of(version, "task", {"max_trial_time": None})["max_trial_time"]
    assert dataclasses.replace(cfg, learner=Config().learner, task=Config().task) == Config()


@pytest.mark.parametrize(
    ("section", "field"), [("task", "drift_neutral_when_full"), ("learner", "noise_corr"), ("train", "seeds")]
)
def test_a_current_config_that_lacks_a_field_is_an_error_naming_it(section, field):
    stored = to_dict(Config())
    assert stored["version"] == CONFIG_VERSION
    del stored[section][field]
    with pytest.raises(ValueError, match=f"^{section}.{field}: missing"):
        from_dict(stored)
    blocks = {**to_dict(Config()), "protocols": {"p": [{"trials": 5, "condition": "none"}]}}
    with pytest.raises(ValueError, match=r"^protocols.p\[0\].catch: missing"):
        from_dict(blocks)
    expected = "1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15 or 16"
    with pytest.raises(ValueError, match=f"^version: expected {expected}, found 0"):
        from_dict({**to_dict(Config()), "version": 0})


def test_before_version_13_the_elbow_stop_is_the_clamp_and_the_evaluation_judges_both_frames():
    stored = {**to_dict(Config()), "version": 12}
    del stored["arm"]["one_link_stop"], stored["eval"]["frames"]
    cfg = from_dict(stored)
    assert cfg.arm.one_link_stop is False and Config().arm.one_link_stop is True
    assert cfg.eval.frames == ("viscous", "viscous_mirror")  # both frames, the one as applied first
    then = dataclasses.replace(Config().eval, frames=("viscous", "viscous_mirror"))
    assert cfg == dataclasses.replace(Config(), arm=dataclasses.replace(Config().arm, one_link_stop=False), eval=then)
    partial = {**to_dict(Config()), "version": 1}
    del partial["arm"]["one_link_stop"]  # a version-1 config that left it out trained with the clamp
    assert from_dict(partial).arm.one_link_stop is False
    stored = to_dict(Config())
    del stored["arm"]["one_link_stop"]  # version 13 stores it
    with pytest.raises(ValueError, match="^arm.one_link_stop: missing"):
        from_dict(stored)


def test_before_version_14_the_field_trains_and_is_judged_in_the_frame_as_applied():
    """Version 14 trains the paper's field mirrored and judges that frame first; a config that stored its
    conditions, frames and protocols reads them as stored, and a version-1 config that left them out reads those
    of the frame as applied."""
    today = Config()
    assert today.train.conditions == ("none", "viscous_mirror", "random", "random_nopast")
    assert today.eval.frames == ("viscous_mirror", "viscous")
    assert [b.condition for b in blocks_of(today, "adaptation")] == ["none", "viscous_mirror", "none"]
    then = compat.CHANGED_DEFAULTS[14]
    partial = {**to_dict(today), "version": 1}
    del partial["train"]["conditions"], partial["eval"]["frames"], partial["protocols"]
    old = from_dict(partial)
    assert old.train.conditions == CONDITIONS == tuple(then["train"]["conditions"])
    assert old.eval.frames == ("viscous", "viscous_mirror")
    assert [b.condition for b in blocks_of(old, "adaptation")] == ["none", "viscous", "none"]
    assert [b.catch for b in blocks_of(old, "adaptation")] == [b.catch for b in blocks_of(today, "adaptation")]
    as_applied = dataclasses.replace(today, train=dataclasses.replace(today.train, conditions=CONDITIONS))
    stored = {**to_dict(as_applied), "version": 13}
    assert from_dict(stored) == as_applied


def test_before_version_16_the_exploration_bound_is_0_2():
    """Version 16 raised the exploration bound to 0.25 (issue 62's held-out pick); a version-1 config that left the
    bound out trained with 0.2, and a stored config of version 15, which holds it, reads as stored."""
    assert Config().learner.noise == 0.25 and compat.CHANGED_DEFAULTS[16] == {"learner": {"noise": 0.2}}
    partial = {**to_dict(Config()), "version": 1}
    del partial["learner"]["noise"]
    assert from_dict(partial).learner.noise == 0.2
    assert from_dict({**to_dict(Config()), "version": 15}) == Config()
    assert from_partial({"learner": {"lr": 1.0}}).learner.noise == 0.25  # a partial file takes today's defaults
    recipe = checked_config(
        read_config_file(Path(__file__).resolve().parents[1] / "recipes" / "constant_exploration.json")
    )
    assert {n: getattr(recipe.learner, n) for n in hyper.NAMES} == hyper.defaults(15)  # versions 14-15's recipe


LEVERS_6 = ("actor_signal_gain", "drift_gate", "drift_gate_trials", "n_max_clean")  # hyperparameters of version 6
OFF_6 = {"actor_signal_gain": 1.0, "drift_gate": 0.0}  # what a config of version 5 or earlier trained with


def _as_version_5(stored: dict) -> dict:
    """A version-6 config dict without the fields that version 6 added."""
    for name in LEVERS_6:
        del stored["learner"][name], stored["train"][f"{name}_grid"]
    del stored["task"]["drift_gate_start"], stored["train"]["saturated_output"]
    return stored


def test_versions_2_and_3_gain_the_fields_added_since_at_the_values_that_keep_their_runs():
    stored = _as_version_5({**to_dict(Config(learner=LearnerConfig(noise_value_ratio=0.5))), "version": 2})
    for name in ("noise_value_gate", "noise_value_steps", "actor_gain_power"):
        del stored["learner"][name], stored["train"][f"{name}_grid"]
    cfg = from_dict(stored)
    assert cfg.learner.noise_value_gate == 0.0 and cfg.train.noise_value_gate_grid == ()
    assert cfg.learner.noise_value_steps == 0 and cfg.train.noise_value_steps_grid == ()
    assert cfg.learner.actor_gain_power == 0.0 and cfg.train.actor_gain_power_grid == ()
    assert cfg == Config(learner=LearnerConfig(noise_value_ratio=0.5, **OFF_6))
    stored = _as_version_5({**to_dict(Config(learner=LearnerConfig(noise_value_gate=0.1))), "version": 3})
    for name in ("noise_value_steps", "actor_gain_power"):
        del stored["learner"][name], stored["train"][f"{name}_grid"]
    assert from_dict(stored) == Config(learner=LearnerConfig(noise_value_gate=0.1, **OFF_6))
    del stored["learner"]["noise_corr"]  # version 3 stored every field of its own
    with pytest.raises(ValueError, match="^learner.noise_corr: missing"):
        from_dict(stored)


def test_version_5_gains_the_drift_gate_n_max_rule_and_actor_gain_switched_off():
    stored = _as_version_5({**to_dict(Config(learner=LearnerConfig(actor_gain_power=2.0))), "version": 5})
    cfg = from_dict(stored)
    assert (cfg.learner.drift_gate, cfg.learner.n_max_clean, cfg.learner.actor_signal_gain) == (0.0, 0.0, 1.0)
    assert cfg.learner.drift_gate_trials == 300 and cfg.task.drift_gate_start == 1.0
    assert cfg.train.saturated_output == 0.45 and all(getattr(cfg.train, f"{n}_grid") == () for n in LEVERS_6)
    assert cfg == Config(learner=LearnerConfig(actor_gain_power=2.0, **OFF_6))
    stored = {**to_dict(Config()), "version": 6}
    del stored["learner"]["drift_gate"]  # version 6 stores them
    with pytest.raises(ValueError, match="^learner.drift_gate: missing"):
        from_dict(stored)


def test_a_partial_config_takes_the_current_defaults_for_what_it_leaves_out():
    cfg = from_partial({"task": {"goal_speed": 0.2}, "protocols": {"p": [{"trials": 5, "condition": "viscous"}]}})
    assert cfg.task.goal_speed == 0.2 and cfg.task.drift_neutral_when_full is True
    assert cfg.learner == Config().learner
    assert [b.catch for b in next(p for p in cfg.protocols if p.name == "p").blocks] == [0.0]
    assert with_defaults({"version": 1})["version"] == CONFIG_VERSION


def test_before_version_15_a_config_reads_with_the_failure_anatomys_thresholds_of_today():
    """The anatomy's thresholds describe the fails of a test and change no outcome: an older run takes today's."""
    stored = {**to_dict(Config()), "version": 14}
    names = [n for n in stored["eval"] if n.startswith("anatomy_")]
    assert names and set(names) == set(compat.ADDED_CONFIG_FIELDS[15]["eval"])
    for name in names:
        del stored["eval"][name]
    assert from_dict(stored) == Config()
