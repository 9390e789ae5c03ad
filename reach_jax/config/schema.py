"""The config's schema: one frozen dataclass per section, every constant of the model at the paper's value.

Units: lengths [m], masses [kg], times [s], angles [rad], torques [N m], forces [N].
Each field names the paper's equation or table, or `model §n`, a section of docs/model.md, for a choice the
paper leaves open; §11 there gives the evidence behind each value.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from reach_jax.config import hyper
from reach_jax.config.paper import ClaimsConfig
from reach_jax.config.tables import (
    PAPER_CONDITIONS,
    PROTOCOLS,
    TRAINED_CONDITIONS,
    BlockConfig,
    ConditionConfig,
    ProtocolConfig,
)

# A stored config holds every field; versions 3-8, 11, 13 and 15 added fields, 9-10, 12-14 and 16 changed defaults
# (`compat`).
CONFIG_VERSION = 16


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
    # On the stop the arm moves "as one link" (the paper's words): held there while pressed, the shoulder with the
    # one-link inertia, the impact keeping the momentum about the shoulder (model §1). False: the clamp of config
    # versions 1-12, which zeroes an outward elbow speed and lets the shoulder move as if the elbow were free.
    one_link_stop: bool = True


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
    max_trial_time: float = 10.0  # safety cap on a learning trial [s] (model §5 choice; issue 56's held-out pick)
    drift_neutral_when_full: bool = True  # once the field was first full, a drift-aided success leaves the
    # curriculum unchanged instead of shrinking it (model §11 choice, "drift-aided success")
    drift_gate_start: float = 1.0  # recent failure share a fresh learner starts with: it fails (model §5 choice)


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
    # The conditions that each stand for the paper's viscous field in one reading of its coordinates (model §6):
    # every network is tested in each too, and Table 2 and the claims are made once per frame, its field's learners
    # as the paper's viscous row; the first frame is the one the run's main files judge (docs/claims.md).
    frames: tuple[str, ...] = ("viscous_mirror", "viscous")
    adaptation_window: int = 1000  # adaptation windows and curve bins span this many trials (choice)
    # The failure anatomy (`evaluate.anatomy`, docs/claims.md): a fail's class is read from its last
    # anatomy_window seconds, the first class that fits in the order folded, chatter, hover, rest near, rest far,
    # swinging. They change no outcome, only how the fails are described (choices).
    anatomy_window: float = 1.0  # the last second of the 4 s decides a fail's class [s]
    anatomy_fold_margin_deg: float = 1.0  # the elbow this close to its stop (theta2_stop) is on it [deg]
    anatomy_fold_share: float = 0.5  # folded: the elbow on its stop in at least this share of the window's states
    anatomy_flip_torque: float = 0.5  # a sign flip counts when the torque exceeds this before and after it [N m]
    anatomy_chatter_share: float = 0.5  # chatter: a joint's torque flips sign in at least this share of the steps
    anatomy_hover_share: float = 0.5  # hover: the hand inside the goal square in at least this share of the states
    anatomy_rest_speed: float = 0.05  # at rest: the hand's mean speed over the window below this [m/s]
    anatomy_near_cells: float = 2.0  # rest near: the hand ends within this L-inf distance of the target [cells]


@dataclass(frozen=True)
class TrainSettings:
    """One training run: which learners, how long, how it is chunked."""

    trials: int = 2_000_000  # trials per learner, section 4.4
    seeds: int = 2  # networks per condition, section 4.4
    conditions: tuple[str, ...] = TRAINED_CONDITIONS  # learning conditions (names in Config.conditions), Table 2 rows
    seed: int = 0  # master PRNG seed
    chunk_steps: int = 50_000  # learner steps per compiled chunk; checkpoint and log between chunks
    keep_every: int = 0  # also keep the checkpoint of every keep_every-th chunk (snapshots); 0 = newest two only
    protocols: tuple[str, ...] = ()  # learners that run protocols (names in Config.protocols), after the conditions
    init_from: str = ""  # a run directory whose final networks start the learners (model §12); "" = fresh weights
    trial_log_every: int = 0  # log every n-th trial's movement to trials/ (model §12); 0 = no per-trial log
    direction_time: float = 0.1  # the logged initial direction is the hand's at this time into the trial [s] (choice)
    saturated_output: float = 0.45  # metrics count an actor output |m| above it as saturated (model §5 choice)
    zip_grids: bool = False  # the sweep grids pair up point by point (a design's draws, studies/search) instead of
    # crossing; every grid given then has the same length


# The settings, then one sweep grid per entry of hyper.TABLE (<name>_grid): the values crossed with the other
# grids (or paired with them, `zip_grids`), () = the learner's default.
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


# How the compiled loops run: not part of Config, since results do not depend on it (but for sparse_layer1).
ENGINES = ("auto", "jax", "native")  # Speed.engine's values
MAX_HIDDEN_PAD = 128  # largest Speed.hidden_pad: a TPU vector row of float32; wider only wastes memory


@dataclass(frozen=True)
class Speed:
    """How the compiled loops run. Results do not depend on it bit for bit, except for `sparse_layer1`, which
    only the lever benchmark turns off: a run stores that one (`SPEED_RESULT_FIELDS`) and resumes only under it.

    `benchmarks/levers.py` measures what each one gives by switching it off.
    """

    hidden_pad: int = 8  # pad the first hidden layer to a multiple of this with inert units; 1 = off
    draw_block: int = 64  # steps whose uniforms are drawn in one call; the stream does not depend on it
    donate: bool = True  # a chunk reuses its input states' buffers for its output
    # Layer 1 and its update over the inputs that can be non-zero (about 1/3 of them), not all 125. Off, the
    # same terms are summed in another order: equal to float32 rounding, not bit for bit.
    sparse_layer1: bool = True
    # The step loop's engine: "jax" (the compiled JAX step, the reference and the GPU/TPU path), "native" (the C++
    # kernel of `engine.native`, bit-identical on CPU under "cpu-exact") or "auto" (native where it can run).
    engine: str = "auto"

    def __post_init__(self):
        if self.engine not in ENGINES:
            raise ValueError(f"engine: must be one of {', '.join(ENGINES)}")
        for name, top in (("hidden_pad", MAX_HIDDEN_PAD), ("draw_block", None)):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1 or (top is not None and value > top):
                raise ValueError(f"{name}: must be a whole number in [1, {top or 'inf'}]")


DEFAULT_SPEED = Speed()
SPEED_RESULT_FIELDS = ("sparse_layer1",)  # the Speed fields that change results (float32 rounding)


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
