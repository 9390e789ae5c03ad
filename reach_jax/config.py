"""Every constant of the model, with the paper's values as defaults.

Units: lengths [m], masses [kg], times [s], angles [rad], torques [N m], forces [N].
Each field names the paper's equation or table, or `model §n`, a section of docs/model.md, for a choice the
paper leaves open; §11 there gives the evidence behind each value.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field

from reach_jax import compat, hyper
from reach_jax.errors import printable

CONFIG_VERSION = 6  # a stored config holds every field; versions 3-6 each added fields (`compat`)


@dataclass(frozen=True)
class ArmConfig:
    """Two-link arm of eq. 4-5 and Table 1."""

    mass: tuple[float, float] = (2.0, 2.0)  # M_i [kg], Table 1 (shared by both links, model §1)
    length: tuple[float, float] = (0.3, 0.3)  # l_i [m], Table 1
    com_fraction: float = 0.5  # s_i = l_i / 2, Table 1
    inertia_factor: float = 1.0 / 3.0  # I_i = M_i l_i^2 / 3 about the joint, Table 1
    joint_viscosity: tuple[float, float] = (0.4, 0.2)  # B_i [N m s/rad], Table 1
    tau_max: tuple[float, float] = (5.0, 3.0)  # [N m], Table 1
    dt: float = 0.02  # RK4 step [s], section 4.1
    theta1_range: tuple[float, float] = (0.0, math.pi / 2)  # leaving it is "out", section 4.2
    theta2_min: float = 0.0  # below it is "out", section 4.2
    theta2_stop: float = math.pi  # hard stop, not "out" (model §1 choice)


@dataclass(frozen=True)
class SensorConfig:
    """5x5 area-ratio visual sensor (section 4.2, model §2)."""

    n_cells: int = 5  # cells per side, section 4.2
    cell_size: float = 0.04  # [m], also the hand and target square side (model §2 choice)
    centre: tuple[float, float] = (-0.05, 0.37)  # field centre [m] in shoulder frame (model §2 choice)


@dataclass(frozen=True)
class EncodingConfig:
    """Localized (triangular) coding of joint signals (section 4.2, Fig. 3, model §3)."""

    theta_units: tuple[int, int] = (8, 12)  # units for theta1, theta2, section 4.2
    theta_ranges: tuple[tuple[float, float], tuple[float, float]] = (
        (0.0, math.pi / 2),
        (0.0, math.pi),
    )  # [rad], section 4.2
    omega_units: int = 10  # units per joint velocity, section 4.2
    omega_range: float = math.pi  # velocities coded over [-range, range] [rad/s], section 4.2
    tau_units: int = 10  # units per past torque over [-tau_max, tau_max] (model §3 choice)


@dataclass(frozen=True)
class NetworkConfig:
    """125-30-10-3 sigmoid network (section 4.2, model §4)."""

    hidden: tuple[int, int] = (30, 10)  # hidden layer widths, section 4.2
    n_out: int = 3  # critic + 2 actor outputs, section 4.2
    hidden_init: float = 0.5  # hidden weights ~ U(-a, a) (model §4, §11 choice)
    output_init: float = 0.0  # output weights ~ U(-a, a); 0 starts critic and actor at 0 (model §11 choice)
    use_bias: bool = True  # biases start at 0 (model §4 choice)


@dataclass(frozen=True)
class LearnerConstants:
    """TS actor-critic constants shared by every learner, eq. 1-3 (model §5)."""

    p_range: float = 0.8  # P_range of eq. 1
    reward_goal: float = 0.4  # reinforcement at the goal, section 4.2
    reward_out: float = -0.4  # reinforcement at a joint limit, section 4.2
    n_max_init: float = 100.0  # N_max[0] [steps] (choice)
    critic_floor: float = -0.3  # non-terminal critic targets never go below it, so "out" is always worse (choice)


# The constants, then the defaults of the per-learner hyperparameters (lr, noise, lam, ...): one field per entry
# of hyper.TABLE, which says what each is.
LearnerConfig = dataclasses.make_dataclass(
    "LearnerConfig",
    hyper.config_fields(),
    bases=(LearnerConstants,),
    frozen=True,
    namespace={"__doc__": "TS actor-critic, eq. 1-3 (model §5): constants and per-learner hyperparameter defaults."},
)


@dataclass(frozen=True)
class TaskConfig:
    """Goal, curriculum, target drift and trial cap (section 4.2, model §5)."""

    goal_half_width_cells: float = 1.0  # goal square side is 2 cells, section 4.2 / Fig. 4
    goal_speed: float = 0.1  # hand speed must be below it [m/s], section 4.2
    curriculum_init_cells: float = 1.6  # initial max start-target L-inf distance [cells] (model §11 choice)
    curriculum_step: float = 0.0004  # staircase step [m] (model §11 choice)
    target_candidates: int = 8  # draws to find a target not touched at the start; all fail < 0.1% (choice)
    drift_after: float = 1.0  # target starts drifting after this long in a trial [s] (model §11 choice)
    drift_per_step: float = 0.002  # drift toward the hand [m/step] (model §11 choice)
    max_trial_time: float = 10.0  # safety cap on a learning trial [s] (model §5 choice)
    drift_neutral_when_full: bool = True  # once the field was first full, a drift-aided success leaves the
    # curriculum unchanged instead of shrinking it (choice; README "The curriculum")
    drift_gate_start: float = 1.0  # recent failure share a fresh learner starts with: it fails (model §5 choice)


ZERO_MATRIX = ((0.0, 0.0), (0.0, 0.0))


@dataclass(frozen=True)
class ConditionConfig:
    """A condition (section 4.3, model §6): the hand-force field a learner trains or is tested in, and its inputs.

    The hand force is F = viscous @ xdot + stiffness @ (x - anchor) + constant + f, with f drawn uniformly in
    [-random, random] per axis at the start of each trial (`fields`). Zeros everywhere is the null field.
    """

    name: str = ""  # how --conditions and eval.test_conditions refer to it
    viscous: tuple[tuple[float, float], tuple[float, float]] = ZERO_MATRIX  # B [N s/m], F = B xdot
    stiffness: tuple[tuple[float, float], tuple[float, float]] = ZERO_MATRIX  # K [N/m], F = K (x - anchor)
    anchor: tuple[float, float] = (0.0, 0.0)  # x0 of the spring [m], shoulder frame
    constant: tuple[float, float] = (0.0, 0.0)  # a force present in every trial [N]
    random: tuple[float, float] = (0.0, 0.0)  # bound of the per-trial random force per axis [N]
    past_inputs: bool = True  # False withholds the 60 one-step-before inputs (the no-past ablation)


PAPER_CONDITIONS = (
    ConditionConfig("none"),
    ConditionConfig("viscous", viscous=((-10.1, -11.2), (-11.2, 11.1))),  # B of Shadmehr & Mussa-Ivaldi 1994
    ConditionConfig("random", random=(8.0, 8.0)),  # Fx, Fy ~ U(-8, 8) N per trial, section 4.3
    ConditionConfig("random_nopast", random=(8.0, 8.0), past_inputs=False),  # section 4.3, without past inputs
)


@dataclass(frozen=True)
class EvalConfig:
    """Table 2 test protocol (section 4.4, model §8)."""

    lattice: int = 8  # lattice points per side, section 4.4
    max_time: float = 4.0  # a test trial fails after this long [s], section 4.4
    figure_seed: int = 0  # seed index of the network per condition drawn in Fig. 4-5 (choice)
    reference_duration: float = 0.5  # minimum-jerk yardstick movement time [s], human-like (choice)
    peak_prominence: float = 0.1  # a speed peak must rise this fraction of the top speed above its bases (choice)
    impedance_pair_stride: int = 4  # impedance at every 4th lattice pair's movement: 260 of 1040 (choice, cost)
    impedance_max_steps: int = 50  # and at its first 50 acting states (1 s), where movements happen (choice)
    impedance_min_sin_elbow: float = 0.2  # states with sin(theta2) below this (J near singular) are skipped (choice)
    test_conditions: tuple[str, ...] = ("none", "viscous")  # Table 2 columns: the conditions every network is tested in
    adaptation_window: int = 1000  # adaptation windows and curve bins span this many trials (choice)


@dataclass(frozen=True)
class ClaimsConfig:
    """How `claims` decides the paper's five claims and the Table-2 targets (our choices, docs/claims.md).

    Stored with each run, so a run trained on held-out seeds carries the criteria fixed before it was trained.
    """

    level: float = 0.95  # two-sided coverage of every confidence interval over networks
    matched_min_success: float = 0.90  # claim 1: the interval of mean success stays above this
    robust_min_success_none: float = 0.85  # claim 4: random -> none success interval above this
    robust_min_success_field: float = 0.80  # claim 4: random -> viscous success interval above this
    size_fraction: float = 0.5  # an effect "as large as the paper's" reaches this fraction of it (log for time)
    cell_points: float = 5.0  # Table-2 target: success and out within this many percentage points of the paper
    cell_time: float = 0.25  # Table-2 target: mean time within this fraction of the paper's
    curriculum_tail: float = 0.2  # stability is judged over the last 20% of each learner's trials
    curriculum_min_fraction: float = 0.9  # a chunk below 90% of the whole field counts as a setback
    curriculum_max_setbacks: float = 0.01  # a learner is stable with at most 1% of its tail chunks set back


CONDITIONS = tuple(c.name for c in PAPER_CONDITIONS)  # Table 2 rows


@dataclass(frozen=True)
class BlockConfig:
    """One block of a protocol (model §12): trials in a condition, learning on or off, with catch trials."""

    trials: int = 1  # trials the block lasts
    condition: str = "none"  # name in Config.conditions
    learning: bool = True  # False freezes the weights (the curriculum and N_max still follow the trials)
    catch: float = 0.0  # probability that a trial of the block runs in catch_condition instead
    catch_condition: str = "none"  # name in Config.conditions


@dataclass(frozen=True)
class ProtocolConfig:
    """A named list of blocks; a learner running it switches blocks at trial boundaries."""

    name: str = ""  # how train.protocols and --protocol refer to it
    blocks: tuple[BlockConfig, ...] = ()


# Null -> viscous field with catch trials (in the null field) -> null again (washout): the design of Shadmehr &
# Mussa-Ivaldi 1994, for networks first trained without the field (train.init_from). The control runs the same
# blocks without the field, so that the analysis can tell the field's effects from the drift of online learning.
# Block lengths chosen on development networks (README "Adaptation").
PROTOCOLS = (
    ProtocolConfig(
        "adaptation",
        (BlockConfig(5_000, "none"), BlockConfig(20_000, "viscous", catch=0.1), BlockConfig(20_000, "none")),
    ),
    ProtocolConfig(
        "adaptation_control",
        (BlockConfig(5_000, "none"), BlockConfig(20_000, "none", catch=0.1), BlockConfig(20_000, "none")),
    ),
)


@dataclass(frozen=True)
class TrainSettings:
    """One training run: which learners, how long, how it is chunked."""

    trials: int = 2_000_000  # trials per learner, section 4.4
    seeds: int = 2  # networks per condition, section 4.4
    conditions: tuple[str, ...] = CONDITIONS  # learning conditions (names in Config.conditions), Table 2 rows
    seed: int = 0  # master PRNG seed
    chunk_steps: int = 50_000  # learner steps per compiled chunk; checkpoint and log between chunks
    keep_every: int = 0  # also keep the checkpoint of every keep_every-th chunk (snapshots); 0 = newest two only
    protocols: tuple[str, ...] = ()  # learners that run protocols (names in Config.protocols), after the conditions
    init_from: str = ""  # a run directory whose final networks start the learners (model §12); "" = fresh weights
    trial_log_every: int = 0  # log every n-th trial's movement to trials/ (model §12); 0 = no per-trial log
    direction_time: float = 0.1  # the logged initial direction is the hand's at this time into the trial [s] (choice)
    saturated_output: float = 0.45  # metrics count an actor output |m| above it as saturated (model §5 choice)


# The settings, then one sweep grid per entry of hyper.TABLE (<name>_grid): the values crossed with the other
# grids, () = the learner's default.
TrainConfig = dataclasses.make_dataclass(
    "TrainConfig",
    hyper.grid_fields(),
    bases=(TrainSettings,),
    frozen=True,
    namespace={"__doc__": "One training run: its settings and the sweep grids of the per-learner hyperparameters."},
)


@dataclass(frozen=True)
class Config:
    """The whole model and run."""

    arm: ArmConfig = field(default_factory=ArmConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    encoding: EncodingConfig = field(default_factory=EncodingConfig)
    network: NetworkConfig = field(default_factory=NetworkConfig)
    learner: LearnerConfig = field(default_factory=LearnerConfig)
    task: TaskConfig = field(default_factory=TaskConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    claims: ClaimsConfig = field(default_factory=ClaimsConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    conditions: tuple[ConditionConfig, ...] = PAPER_CONDITIONS  # the named conditions; JSON: {name: fields}
    protocols: tuple[ProtocolConfig, ...] = PROTOCOLS  # the named protocols; JSON: {name: [blocks]}


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
        named = name.endswith(("conditions", "protocols"))  # train.conditions, train.protocols, eval.test_conditions
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
            raise ValueError(f"{where}.{printable(key)}: unknown field")
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
    cfg = Config(**sections, conditions=conditions, protocols=protocols)
    _check_protocols(cfg)
    _check_train(cfg)
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
    if max(lows) >= min(highs):
        raise ValueError("learner.noise_value_lo: must lie below noise_value_hi in every sweep point")


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


def n_inputs(config: Config) -> int:
    """Number of network inputs implied by the sensor and encoding (125 for the paper)."""
    e = config.encoding
    now = sum(e.theta_units) + 2 * e.omega_units
    return config.sensor.n_cells**2 + 2 * now + 2 * e.tau_units


def n_past_inputs(config: Config) -> int:
    """Number of one-step-before inputs withheld by the no-past ablation (60 for the paper)."""
    e = config.encoding
    return sum(e.theta_units) + 2 * e.omega_units + 2 * e.tau_units


def condition(cfg: Config, name: str) -> ConditionConfig:
    """The condition called `name`; raises ValueError naming the known ones."""
    for c in cfg.conditions:
        if c.name == name:
            return c
    raise ValueError(f"unknown condition {name!r}; choose from {', '.join(c.name for c in cfg.conditions)}")


def blocks_of(cfg: Config, name: str) -> tuple[BlockConfig, ...]:
    """Blocks of the protocol called `name`, or the one block of train.trials trials of the condition `name`."""
    for p in cfg.protocols:
        if p.name == name:
            return p.blocks
    return (BlockConfig(trials=cfg.train.trials, condition=condition(cfg, name).name, catch_condition=name),)


def protocol_trials(raw_protocols: dict, name: str) -> int:
    """Trials that protocol `name` lasts, in the shipped table with the JSON entries `raw_protocols` written over it."""
    table = _protocols(raw_protocols, False)
    for p in table:
        if p.name == name:
            return sum(b.trials for b in p.blocks)
    raise ValueError(f"unknown protocol {name!r}; choose from {', '.join(p.name for p in table)}")
