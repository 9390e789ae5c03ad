"""A config from the command line: a --config file, the --set values and the training flags over the defaults.

`build_config` is what `python -m reach_jax.train` runs; a resume checks the same overlay against the stored config.
"""

from __future__ import annotations

import json
from pathlib import Path

from reach_jax.config import compat, hyper
from reach_jax.config.loading import from_dict, protocol_trials, to_dict, with_defaults
from reach_jax.config.schema import CONFIG_VERSION, Config
from reach_jax.errors import UsageError

# Training flag -> the TrainConfig field it sets; a hyperparameter's flag sets its sweep grid.
TRAIN_FLAGS = {
    **{name: name for name in ("trials", "seeds", "conditions", "seed", "chunk_steps", "keep_every")},
    **{name: name for name in ("protocols", "init_from", "trial_log_every")},
    **{h.name: h.grid for h in hyper.TABLE},
}


def read_config_file(path: Path) -> dict:
    """The JSON object of a --config file; raises UsageError naming the file."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise UsageError(f"--config {path}: unreadable ({exc})") from None
    if not isinstance(data, dict):
        raise UsageError(f"--config {path}: expected a JSON object")
    return data


def checked_config(data: dict) -> Config:
    """Config of --config data with the settings applied: without a version (or of the current one) the fields
    given over the defaults, of an older version migrated as a stored config is."""
    if data.get("version", CONFIG_VERSION) == CONFIG_VERSION:
        data = with_defaults(data)
    return from_dict(data)


def with_settings(data: dict, args) -> dict:
    """Config data with the --set values and the training flags written over it, in that order."""
    data = json.loads(json.dumps(data))  # a deep copy that the caller's dict never sees
    for section, field, value in args.set:
        if compat.retired(section, field):
            raise UsageError(f"--set {section}.{field}: no longer a config field (a speed setting: see --help)")
        part = data.setdefault(section, {})
        if section == "conditions":  # conditions.NAME.FIELD: a field of one condition, added if it is new
            name, _, field = field.partition(".")
            part = part.setdefault(name, {}) if isinstance(part, dict) else None
        if not isinstance(part, dict):
            raise UsageError(f"--set {section}.{field}: {section} is not a section")
        part[field] = value
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


def build_config(args) -> Config:
    """Config from --config (else the defaults), the --set values and the training flags, checked by from_dict."""
    data = read_config_file(args.config) if args.config is not None else to_dict(Config())
    try:
        return checked_config(with_settings(data, args))
    except (TypeError, ValueError) as exc:
        raise UsageError(str(exc)) from None
