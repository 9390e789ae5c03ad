"""The shipped tables: the paper's four conditions and the adaptation protocols, and the dataclasses of their entries.

A condition is a hand-force field and the inputs a learner sees (section 4.3, model §6); a protocol is a list of
blocks of trials (model §12). Both are data: a run adds or changes entries through its config.
Units: B [N s/m], K [N/m], forces [N], positions [m] in the shoulder frame.
"""

from __future__ import annotations

from dataclasses import dataclass

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


# The paper loads B of Shadmehr & Mussa-Ivaldi 1994 without saying in which (x, y) of its arm (model §6): "viscous"
# reads it in our shoulder frame, x right and y forward; "viscous_mirror" with y the other way (a sensor's rows run
# down, or a left arm mirrors x), B' = S B S with S = diag(1, -1): the same field mirrored.
PAPER_CONDITIONS = (
    ConditionConfig("none"),
    ConditionConfig("viscous", viscous=((-10.1, -11.2), (-11.2, 11.1))),  # B [N s/m], x right, y forward
    ConditionConfig("random", random=(8.0, 8.0)),  # Fx, Fy ~ U(-8, 8) N per trial, section 4.3
    ConditionConfig("random_nopast", random=(8.0, 8.0), past_inputs=False),  # section 4.3, without past inputs
    ConditionConfig("viscous_mirror", viscous=((-10.1, 11.2), (11.2, 11.1))),  # B' [N s/m], y mirrored
)


CONDITIONS = tuple(c.name for c in PAPER_CONDITIONS[:4])  # Table 2 rows: the paper's learning conditions
# The learning conditions a run trains by default: the paper's, its field in the frame that issue 56's held-out run
# adopted (studies/frame/verdict.md), y mirrored.
TRAINED_CONDITIONS = ("none", "viscous_mirror", "random", "random_nopast")


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
        (BlockConfig(5_000, "none"), BlockConfig(20_000, "viscous_mirror", catch=0.1), BlockConfig(20_000, "none")),
    ),
    ProtocolConfig(
        "adaptation_control",
        (BlockConfig(5_000, "none"), BlockConfig(20_000, "none", catch=0.1), BlockConfig(20_000, "none")),
    ),
)
