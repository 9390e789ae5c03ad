"""A config from the command line: a --config file, the --set values, the hyperparameters and the training flags
over the defaults.

`build_config` is what `python -m reach_jax.train` runs; a resume checks the same overlay against the stored config.
One intent is one config: a hyperparameter given one value, by `--sweep NAME=V`, `--lr V` or `--set learner.NAME=V`,
is the learner's default with its grid empty, and `folded` stores a one-value grid that way too (`same_learners`).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from reach_jax.config import compat, hyper
from reach_jax.config.hyperparameter import SWITCH_WORDS
from reach_jax.config.loading import first_difference, from_dict, protocol_trials, to_dict, with_defaults
from reach_jax.config.schema import CONFIG_VERSION, Config
from reach_jax.errors import UsageError

# Training flag -> the TrainConfig field it sets.
TRAIN_FLAGS = {
    **{name: name for name in ("trials", "seeds", "conditions", "seed", "chunk_steps", "keep_every")},
    **{name: name for name in ("protocols", "init_from", "trial_log_every")},
}
PAPER_HYPER = ("lr", "noise", "lam")  # the hyperparameters with a flag of their own; the rest take --sweep


def read_config_file(path: Path) -> dict:
    """The JSON object of a --config file, without its top-level "comment" (a string or a list of lines, for the
    reader: JSON has no comments); raises UsageError naming the file."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise UsageError(f"--config {path}: unreadable ({exc})") from None
    if not isinstance(data, dict):
        raise UsageError(f"--config {path}: expected a JSON object")
    comment = data.pop("comment", "")
    if not (isinstance(comment, str) or (isinstance(comment, list) and all(isinstance(c, str) for c in comment))):
        raise UsageError(f"--config {path}: comment: expected a string or a list of strings")
    return data


def checked_config(data: dict) -> Config:
    """Config of --config data with the settings applied: without a version (or of the current one) the fields
    given over the defaults, of an older version migrated as a stored config is."""
    if data.get("version", CONFIG_VERSION) == CONFIG_VERSION:
        data = with_defaults(data)
    return from_dict(data)


def folded(cfg: Config) -> Config:
    """cfg with every one-value sweep grid stored as the learner's default instead: the same learners, one spelling."""
    ones = {h: getattr(cfg.train, h.grid) for h in hyper.TABLE if len(getattr(cfg.train, h.grid)) == 1}
    if not ones:
        return cfg
    learner = {h.name: int(v[0]) if h.integer else float(v[0]) for h, v in ones.items()}
    return dataclasses.replace(
        cfg,
        learner=dataclasses.replace(cfg.learner, **learner),
        train=dataclasses.replace(cfg.train, **{h.grid: () for h in ones}),
    )


def hyper_values(args) -> dict[str, tuple]:
    """{name: values} of --lr, --noise, --lam and every --sweep; raises UsageError for a name given twice."""
    given = [(name, getattr(args, name)) for name in PAPER_HYPER if getattr(args, name) is not None]
    found = {}
    for name, values in [*given, *args.sweep]:
        if name in found:
            raise UsageError(f"hyperparameter {name} given twice (one --sweep {name}=V[,V...] takes every value)")
        found[name] = values
    return found


def _set_hyper(data: dict, name: str, values: tuple) -> None:
    """One value: the learner's default, its grid empty; several: its sweep grid."""
    h = hyper.BY_NAME[name]
    if len(values) == 1:
        data.setdefault("learner", {})[name] = values[0]
        data.setdefault("train", {})[h.grid] = []
    else:
        data.setdefault("train", {})[h.grid] = list(values)


def with_settings(data: dict, args) -> dict:
    """Config data with the --set values, the hyperparameters and the training flags written over it, in that order."""
    data = json.loads(json.dumps(data))  # a deep copy that the caller's dict never sees
    for section, field, value in args.set:
        if compat.retired(section, field):
            raise UsageError(f"--set {section}.{field}: no longer a config field (a speed setting: see --help)")
        if section == "learner" and field in hyper.BY_NAME:
            if hyper.BY_NAME[field].switch and isinstance(value, bool):
                value = SWITCH_WORDS[str(value).lower()]
            _set_hyper(data, field, (value,))  # as --sweep NAME=V: one intent, one config
            continue
        part = data.setdefault(section, {})
        if section == "conditions":  # conditions.NAME.FIELD: a field of one condition, added if it is new
            name, _, field = field.partition(".")
            part = part.setdefault(name, {}) if isinstance(part, dict) else None
        if not isinstance(part, dict):
            raise UsageError(f"--set {section}.{field}: {section} is not a section")
        part[field] = value
    for name, values in hyper_values(args).items():
        _set_hyper(data, name, values)
    for flag, field in TRAIN_FLAGS.items():
        if getattr(args, flag) is not None:
            data.setdefault("train", {})[field] = getattr(args, flag)
    if args.protocols is not None:
        # A protocol run trains only the protocol's learners, for as long as the protocol lasts, unless told otherwise.
        if args.conditions is None:
            data["train"]["conditions"] = ()
        if args.trials is None and ("train", "trials") not in {(section, field) for section, field, _ in args.set}:
            try:
                lengths = {n: protocol_trials(data.get("protocols", {}), n) for n in args.protocols}
            except ValueError as exc:
                raise UsageError(str(exc)) from None
            data["train"]["trials"] = max(lengths.values())
    return data


def same_learners(a: Config, b: Config) -> str | None:
    """Dotted name of the first field where two configs differ once folded (None: they train the same learners)."""
    return first_difference(folded(a), folded(b))


def build_config(args) -> Config:
    """Config from --config (else the defaults), the --set values, the hyperparameters and the training flags,
    checked by from_dict and folded."""
    data = read_config_file(args.config) if args.config is not None else to_dict(Config())
    try:
        return folded(checked_config(with_settings(data, args)))
    except (TypeError, ValueError) as exc:
        raise UsageError(str(exc)) from None
