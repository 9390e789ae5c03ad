"""Reading and writing configs as JSON: the type-checked merge over the defaults, migration by version, validation.

`to_dict`/`to_json` write a config with its version; `from_dict` reads one back (an older version migrated by
`compat`), `from_partial` builds one from a few fields over the defaults.
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import math

from reach_jax.config import compat, hyper, workspace
from reach_jax.config.schema import CONFIG_VERSION, Config, blocks_of
from reach_jax.config.tables import PAPER_CONDITIONS, PROTOCOLS, BlockConfig, ConditionConfig, ProtocolConfig
from reach_jax.errors import printable


def to_dict(config: Config) -> dict:
    """Config as a JSON-ready dict, with the config version; conditions as an object keyed by name."""
    data = dataclasses.asdict(config)
    data["conditions"] = {c.pop("name"): c for c in data["conditions"]}
    data["protocols"] = {p["name"]: p["blocks"] for p in data["protocols"]}
    return {"version": CONFIG_VERSION, **data}


def tuplify(value):
    """Lists (from JSON) to tuples, recursively, to match the frozen config fields."""
    if isinstance(value, list):
        return tuple(tuplify(v) for v in value)
    return value


def _check_type(name: str, value, default):
    if isinstance(default, bool) or isinstance(value, bool):
        ok = type(value) is type(default)
    elif isinstance(default, float):
        ok = isinstance(value, (int, float)) and math.isfinite(value)
    elif isinstance(default, tuple):
        # Grids and the condition list have free length and a fixed element type; other tuples match the default.
        named = name.endswith(("conditions", "protocols", "frames"))  # lists of names, e.g. eval.test_conditions
        free_length = named or name.endswith("grid")
        ok = isinstance(value, tuple) and (free_length or len(value) == len(default))
        if ok and free_length:
            ok = all(isinstance(v, str if named else (int, float)) for v in value)
        elif ok:
            for i, (v, d) in enumerate(zip(value, default, strict=True)):
                _check_type(f"{name}[{i}]", v, d)
    else:
        ok = type(value) is type(default)
    if not ok:
        raise ValueError(
            f"{name}: {json.dumps(value) if not isinstance(value, tuple) else list(value)} "
            f"does not match the type of {default!r}"
        )


def _coerce(value, default):
    """value (type-checked against default) with ints made floats wherever the default holds a float."""
    if isinstance(default, tuple) and len(default) == len(value):  # free-length tuples (grids, names) stay
        return tuple(_coerce(v, d) for v, d in zip(value, default, strict=True))
    return float(value) if isinstance(default, float) else value


def _build(cls, raw, where: str, base=None, complete: bool = False):
    """cls with the fields of the JSON object `raw` written over `base` (default cls()), each checked by type.

    With `complete`, a field that `raw` lacks is an error: a stored config of the current version holds them all.
    """
    if not isinstance(raw, dict):
        raise ValueError(f"{where}: expected an object")
    base = cls() if base is None else base
    names = {g.name for g in dataclasses.fields(cls)}
    missing = sorted(names - set(raw) - {"name"}) if complete else []
    if missing:
        raise ValueError(f"{where}.{missing[0]}: missing (a version-{CONFIG_VERSION} config stores every field)")
    values = {}
    for key, value in raw.items():
        if key not in names or key == "name":
            close = difflib.get_close_matches(str(key), sorted(names - {"name"}), n=1)
            raise ValueError(f"{where}.{printable(key)}: unknown field" + (f"; closest: {close[0]}" if close else ""))
        value = tuplify(value)
        _check_type(f"{where}.{key}", value, getattr(base, key))
        values[key] = _coerce(value, getattr(base, key))
    return dataclasses.replace(base, **values)


def _conditions(raw, table: dict, complete: bool) -> tuple[ConditionConfig, ...]:
    """The conditions table: the paper's four, with the entries of `raw` ({name: fields}) added or changed."""
    if not isinstance(raw, dict):
        raise ValueError("conditions: expected an object of name: fields")
    for name, fields in raw.items():
        _check_name(f"conditions.{printable(name)}", name)
        base = table.get(name, ConditionConfig(name))
        table[name] = _build(ConditionConfig, fields, f"conditions.{name}", base, complete)
    return tuple(table.values())


def _protocols(raw, complete: bool) -> tuple[ProtocolConfig, ...]:
    """The protocols table: the shipped ones, with the entries of `raw` ({name: [blocks]}) added or replaced."""
    if not isinstance(raw, dict):
        raise ValueError("protocols: expected an object of name: [blocks]")
    table = {p.name: p for p in PROTOCOLS}
    for name, blocks in raw.items():
        where = f"protocols.{printable(name)}"
        _check_name(where, name)
        if not isinstance(blocks, (list, tuple)) or not blocks:
            raise ValueError(f"{where}: expected a list of blocks")
        built = tuple(_build(BlockConfig, b, f"{where}[{i}]", complete=complete) for i, b in enumerate(blocks))
        table[name] = ProtocolConfig(name, built)
    return tuple(table.values())


def _check_name(where: str, name: str) -> None:
    if not name or any(c in name for c in ", ") or not name.isprintable():
        raise ValueError(f"{where}: a name needs letters, without commas or spaces")


def with_defaults(fields: dict) -> dict:
    """A complete config dict of the current version: the given fields (a hand-written file, say) over the defaults.

    Sections merge field by field, conditions entry by entry and field by field, and a protocol given replaces
    one, its blocks' missing fields at their defaults. A "version" among the fields is ignored.
    """
    data = to_dict(Config())
    condition_defaults = {k: v for k, v in dataclasses.asdict(ConditionConfig()).items() if k != "name"}
    block_defaults = dataclasses.asdict(BlockConfig())
    for key, value in fields.items():
        if key == "version":
            continue
        if not isinstance(value, dict) or not isinstance(data.get(key), dict):
            data[key] = value
        elif key == "conditions":
            for name, entry in value.items():
                old = data["conditions"].get(name, condition_defaults)
                data["conditions"][name] = {**old, **entry} if isinstance(entry, dict) else entry
        elif key == "protocols":
            for name, blocks in value.items():
                whole = isinstance(blocks, (list, tuple)) and all(isinstance(b, dict) for b in blocks)
                data["protocols"][name] = [{**block_defaults, **b} for b in blocks] if whole else blocks
        else:
            data[key] = {**data[key], **value}
    return data


def from_partial(fields: dict) -> Config:
    """Config from a few fields, the rest at today's defaults (`with_defaults`); raises ValueError like from_dict."""
    return from_dict(with_defaults(fields))


def from_dict(data: dict) -> Config:
    """Rebuild a Config from `to_dict` output; raises ValueError naming a bad, unknown or missing field.

    A config of the current version holds every field; one of an older version is migrated first
    (`compat.migrate_config`), its fields added since taking the values that reproduce what it trained with. A
    condition given in `conditions` is added to the paper's four, or changes one of them; `from_partial` builds a
    config from a few fields.
    """
    data = dict(data)
    version = data.pop("version", None)
    if version not in compat.READABLE_CONFIGS:
        *earlier, last = map(str, compat.READABLE_CONFIGS)
        raise ValueError(f"version: expected {', '.join(earlier)} or {last}, found {printable(str(version))}")
    data = compat.migrate_config(data, version)
    complete = version >= compat.FIRST_COMPLETE_CONFIG
    table = {c.name: c for c in PAPER_CONDITIONS}
    sections = {}
    for f in dataclasses.fields(Config):
        if f.name in ("conditions", "protocols"):
            continue
        if complete and f.name not in data:
            raise ValueError(f"{f.name}: missing (a version-{CONFIG_VERSION} config stores every field)")
        sections[f.name] = _build(f.default_factory, data.pop(f.name, {}), f.name, complete=complete)
    conditions = _conditions(data.pop("conditions", {}), table, complete)
    protocols = _protocols(data.pop("protocols", {}), complete)
    if data:
        raise ValueError(f"{printable(sorted(data)[0])}: unknown field")
    _check_learner(sections["learner"])
    _check_names("eval.test_conditions", sections["eval"].test_conditions, conditions)
    if sections["eval"].frames:  # none: the run is judged as it is, by eval.test_conditions alone
        _check_names("eval.frames", sections["eval"].frames, conditions)
    cfg = Config(**sections, conditions=conditions, protocols=protocols)
    _check_protocols(cfg)
    _check_train(cfg)
    _check_workspace(cfg)
    return cfg


def _check_names(where: str, names: tuple[str, ...], table: tuple) -> None:
    known = [c.name for c in table]
    if not names or len(set(names)) != len(names) or any(n not in known for n in names):
        raise ValueError(f"{where}: must be distinct names from {', '.join(known)}")


def _check_learner(learner) -> None:
    for name in hyper.NAMES:
        hyper.check(f"learner.{name}", name, [getattr(learner, name)])


def _check_protocols(cfg: Config) -> None:
    known = {c.name for c in cfg.conditions}
    for p in cfg.protocols:
        if p.name in known:
            raise ValueError(f"protocols.{p.name}: a condition has that name")
        for i, b in enumerate(p.blocks):
            where = f"protocols.{p.name}[{i}]"
            for name in ("condition", "catch_condition"):
                if getattr(b, name) not in known:
                    raise ValueError(f"{where}.{name}: must be a name from {', '.join(sorted(known))}")
            if b.trials < 1:
                raise ValueError(f"{where}.trials: must be at least 1")
            if not 0.0 <= b.catch <= 1.0:
                raise ValueError(f"{where}.catch: must be a probability in [0, 1]")


def _check_train(cfg: Config) -> None:
    train = cfg.train
    for name in ("trials", "seeds", "chunk_steps"):
        if getattr(train, name) < 1:
            raise ValueError(f"train.{name}: must be at least 1")
    for name in ("seed", "keep_every", "trial_log_every"):
        if getattr(train, name) < 0:
            raise ValueError(f"train.{name}: must not be negative")
    if not 0.0 < train.direction_time:
        raise ValueError("train.direction_time: must be positive")
    if train.conditions or not train.protocols:
        _check_names("train.conditions", train.conditions, cfg.conditions)
    if train.protocols:
        _check_names("train.protocols", train.protocols, cfg.protocols)
    for name in train.protocols:
        total = sum(b.trials for b in blocks_of(cfg, name))
        if total != train.trials:
            raise ValueError(f"train.trials: {train.trials}, but protocol {name} lasts {total} trials")
    for h in hyper.TABLE:
        hyper.check(f"train.{h.grid}", h.name, getattr(train, h.grid))
    lows = train.noise_value_lo_grid or (cfg.learner.noise_value_lo,)
    highs = train.noise_value_hi_grid or (cfg.learner.noise_value_hi,)
    if train.zip_grids:
        _check_zipped(train)
        n = max(len(lows), len(highs))  # each is 1 long or n long
        if any(lo >= hi for lo, hi in zip(lows * (n // len(lows)), highs * (n // len(highs)), strict=True)):
            raise ValueError("learner.noise_value_lo: must lie below noise_value_hi in every sweep point")
    elif max(lows) >= min(highs):
        raise ValueError("learner.noise_value_lo: must lie below noise_value_hi in every sweep point")


def _check_workspace(cfg: Config) -> None:
    """Each sweep point's visual field lies in the arm's reach inside its joint limits, or an error names the fields."""
    names = workspace.GEOMETRY_HYPERS
    setters = ["sensor.centre", "sensor.cell_size", *(f"learner.{n}" for n in names)]
    setters += [f"train.{n}_grid" for n in names if getattr(cfg.train, f"{n}_grid")]
    for s in workspace.sweep_sensors(cfg):
        why = workspace.field_fault(s, cfg.arm)
        if why:
            raise ValueError(
                f"sensor: the visual field centred at ({s.centre[0]:.3f}, {s.centre[1]:.3f}) m with "
                f"{s.cell_size:.3f} m cells does not fit the arm: {why} (set by {', '.join(setters)})"
            )


def _check_zipped(train) -> None:
    """Zipped grids pair up point by point, so every grid given has the same length."""
    lengths = {h.grid: len(getattr(train, h.grid)) for h in hyper.TABLE if getattr(train, h.grid)}
    first = next(iter(lengths), None)
    for grid, n in lengths.items():
        if n != lengths[first]:
            raise ValueError(
                f"train.{grid}: {n} values, but train.{first} has {lengths[first]} "
                "(train.zip_grids pairs the grids point by point)"
            )


def first_difference(a: Config, b: Config) -> str | None:
    """Dotted name of the first field (in sorted order) where two configs differ, e.g. "train.trials"; None if equal."""

    def walk(x, y, prefix: str) -> str | None:
        if isinstance(x, dict) and isinstance(y, dict):
            for k in sorted(set(x) | set(y)):
                found = walk(x.get(k), y.get(k), f"{prefix}{k}.")
                if found:
                    return found
            return None
        return prefix.rstrip(".") if x != y else None

    return walk(*(json.loads(to_json(c)) for c in (a, b)), "")


def to_json(config: Config) -> str:
    """Config as indented JSON text."""
    return json.dumps(to_dict(config), indent=2)


def protocol_trials(raw_protocols: dict, name: str) -> int:
    """Trials that protocol `name` lasts, in the shipped table with the JSON entries `raw_protocols` written over it."""
    table = _protocols(raw_protocols, False)
    for p in table:
        if p.name == name:
            return sum(b.trials for b in p.blocks)
    raise ValueError(f"unknown protocol {name!r}; choose from {', '.join(p.name for p in table)}")
