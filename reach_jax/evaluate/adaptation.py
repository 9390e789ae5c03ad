"""Adaptation curves and the human pattern of Shadmehr & Mussa-Ivaldi 1994 from a run's per-trial log (model §12).

Units: errors in the JSON are [cm] and [deg]; trials are counted over each learner's life.
A trial's error is aligned with the perturbing field: positive where the field pushes the hand, for that trial's
direction of movement, so that errors of different directions add up instead of cancelling.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from reach_jax.config import ConditionConfig, Config, blocks_of, condition
from reach_jax.env.environment import SUCCESS
from reach_jax.evaluate import stats

M_TO_CM = 100.0

WINDOWS = ("baseline", "early_field", "late_field", "late_catch", "early_washout", "late_washout")

# The pattern: (key, claim, window, window it is taken relative to, side of zero its whole interval must lie on).
# A claim is the paired difference over networks between the protocol's effect in one window and in another,
# where the effect in a window is the protocol's mean error there minus the reference's: the same window of the
# control (`control_of`) when the run has one, else the protocol's own baseline.
PATTERN = (
    ("deflected", "the field pushes the hand off the line", "early_field", None, "above"),
    ("adapts", "the error falls with practice in the field", "early_field", "late_field", "above"),
    ("after_effect", "removing the field gives a mirror-image error", "early_washout", None, "below"),
    ("washes_out", "the after-effect decays in the washout block", "late_washout", "early_washout", "above"),
    ("catch", "catch trials late in the field show the mirror-image error", "late_catch", None, "below"),
)


def perturbation(cfg: Config, name: str) -> tuple[int, ConditionConfig] | None:
    """(block index, condition) of the first block of protocol `name` whose condition differs from its first's."""
    blocks = blocks_of(cfg, name)
    for i, b in enumerate(blocks):
        if b.condition != blocks[0].condition:
            return i, condition(cfg, b.condition)
    return None


def field_sign(aim_rad: np.ndarray, field: ConditionConfig) -> np.ndarray:
    """(n,) +1 or -1: the side (left of the aim is +) to which the field pushes a hand moving along the aim.

    The velocity- and state-independent terms count: B u + F_c for a unit velocity u along the aim.
    """
    u = np.stack([np.cos(aim_rad), np.sin(aim_rad)], axis=-1)
    normal = np.stack([-u[:, 1], u[:, 0]], axis=-1)
    push = u @ np.asarray(field.viscous).T + np.asarray(field.constant)
    side = np.sign(np.sum(normal * push, axis=-1))
    return np.where(side == 0, 1.0, side)


def block_starts(cfg: Config, name: str) -> np.ndarray:
    """(B + 1,) trial index at which each block of protocol `name` starts, then the protocol's end."""
    return np.concatenate([[0], np.cumsum([b.trials for b in blocks_of(cfg, name)])])


def _mean(values: np.ndarray, trials: dict, lo: float, hi: float, catch: bool) -> float | None:
    """Mean of values over the logged trials with index in [lo, hi), catch trials or the others."""
    index = trials["trial"]
    keep = (index >= lo) & (index < hi) & ((trials["catch"] > 0) == catch)
    return float(np.mean(values[keep])) if keep.any() else None


def control_of(cfg: Config, name: str) -> str | None:
    """A protocol of the run that can serve as `name`'s control: as many blocks of the same lengths and catch rates,
    all in the first condition of `name`, so that it differs only by the field (None if the run has none)."""
    mine = blocks_of(cfg, name)
    for other in cfg.train.protocols:
        theirs = blocks_of(cfg, other)
        if (
            other != name
            and len(theirs) == len(mine)
            and all(
                (a.trials, a.catch, a.learning) == (b.trials, b.catch, b.learning) and b.condition == mine[0].condition
                for a, b in zip(mine, theirs, strict=True)
            )
        ):
            return other
    return None


def windows(trials: dict, starts: np.ndarray, block: int, field: ConditionConfig, size: int) -> dict:
    """Window means of one learner's field-aligned perpendicular errors [cm] around a protocol's field block.

    Args:
      trials: that learner's per-trial log (`run_dir.read_trials`, one learner's rows).
      starts: the protocol's `block_starts`.
      block: index of the field block; the blocks before and after it are the baseline and the washout.
      field: the field whose push sets each trial's sign.
      size: trials per window (of which every train.trial_log_every-th is logged).

    Returns:
      {name: mean or None (no logged trial there)} for each of WINDOWS. The windows hold the trials without catch,
      except late_catch: the catch trials of the field block's second half.
    """
    error = trials["perp_error_m"] * field_sign(trials["aim_rad"], field) * M_TO_CM
    lo, hi = starts[block], starts[block + 1]
    before = starts[block - 1] if block > 0 else lo
    after = starts[block + 2] if block + 2 < len(starts) else hi
    return {
        "baseline": _mean(error, trials, max(lo - size, before), lo, False),
        "early_field": _mean(error, trials, lo, lo + size, False),
        "late_field": _mean(error, trials, hi - size, hi, False),
        "late_catch": _mean(error, trials, (lo + hi) / 2, hi, True),
        "early_washout": _mean(error, trials, hi, min(hi + size, after), False),
        "late_washout": _mean(error, trials, max(after - size, hi), after, False),
    }


CATCH_BIN = 5  # catch trials are rarer: their curve's bins are this many windows wide


def curves(trials: dict, starts: np.ndarray, field: ConditionConfig, size: int) -> dict:
    """One learner's binned curves: aligned perpendicular [cm] and direction [deg] errors and success.

    Bins of `size` trials (CATCH_BIN times that for catch trials) start at each block's start and never straddle
    blocks; each point sits at its bin's middle.
    """
    sign = field_sign(trials["aim_rad"], field)
    measures = {
        "perp_cm": trials["perp_error_m"] * sign * M_TO_CM,
        "direction_deg": np.degrees(trials["direction_error_rad"]) * sign,
        "success": (trials["outcome"] == SUCCESS).astype(float),
    }
    out = {}
    for kind, catch, width in (("normal", False, size), ("catch", True, CATCH_BIN * size)):
        points = {"trial": [], **{k: [] for k in measures}}
        for lo, hi in zip(starts[:-1], starts[1:], strict=True):
            for edge in range(int(lo), int(hi), width):
                values = {k: _mean(v, trials, edge, min(edge + width, hi), catch) for k, v in measures.items()}
                if values["perp_cm"] is not None:
                    points["trial"].append(0.5 * (edge + min(edge + width, hi)))
                    for k, v in values.items():
                        points[k].append(v)
        out[kind] = points
    return out


def _effects(own: dict, reference: dict | None) -> dict:
    """Each window's mean minus the reference's: the control's same window, or else the own baseline."""
    out = {}
    for name in WINDOWS:
        ref = own["baseline"] if reference is None else reference[name]
        out[name] = None if own[name] is None or ref is None else own[name] - ref
    return out


def _verdict(key: str, text: str, first: str, second: str | None, side: str, effects: list[dict], level: float):
    a = [e[first] for e in effects]
    b = [0.0 if second is None else e[second] for e in effects]
    verdict = {"key": key, "claim": text, "windows": [first, second], "side": side}
    if len(a) < 2 or any(v is None for v in a + b):
        return {**verdict, "difference_cm": None, "holds": None}
    ci = stats.paired_ci(a, b, level=level)
    return {**verdict, "difference_cm": ci, "holds": stats.above(ci, 0.0) if side == "above" else stats.below(ci, 0.0)}


def _per_learner(
    trials: dict,
    learners: list[tuple[str, int]],
    name: str,
    starts: np.ndarray,
    block: int,
    field: ConditionConfig,
    size: int,
) -> dict:
    """{seed: windows and curves} of each learner of protocol `name`, from its rows of the run's per-trial log.

    Args:
      trials: the run's per-trial log (`run_dir.read_trials`).
      learners: (condition or protocol, seed) per learner (`batch.learner_table`).
      name: the protocol.
      starts: its `block_starts`.
      block: index of its field block.
      field: the field whose push sets each trial's sign.
      size: trials per window and per bin.
    """
    found = {}
    for i, (learner_name, seed) in enumerate(learners):
        if learner_name == name:
            mine = {k: v[trials["learner"] == i] for k, v in trials.items()}
            found[seed] = {
                "learner": i,
                "seed": seed,
                "windows": windows(mine, starts, block, field, size),
                "curves": curves(mine, starts, field, size),
            }
    return found


def analyse(trials: dict | None, learners: list[tuple[str, int]], cfg: Config) -> dict | None:
    """The adaptation results of a run, JSON-ready: per-network windows and curves, and the pattern's verdicts.

    Args:
      trials: the run's per-trial log (`run_dir.read_trials`), or None.
      learners: (condition or protocol, seed) per learner (`batch.learner_table`).
      cfg: the run's config.

    Returns:
      {"protocols": {name: results}} for each protocol with a field block; None when the run has no protocol
      learner or no per-trial log.
    """
    if trials is None or not cfg.train.protocols:
        return None
    size, level = cfg.eval.adaptation_window, cfg.claims.level
    protocols = {}
    for name in cfg.train.protocols:
        found = perturbation(cfg, name)
        if found is None:
            continue
        block, field = found
        starts = block_starts(cfg, name)
        control = control_of(cfg, name)
        networks = _per_learner(trials, learners, name, starts, block, field, size)
        controls = _per_learner(trials, learners, control, starts, block, field, size) if control else {}
        effects = [_effects(n["windows"], controls[s]["windows"] if control else None) for s, n in networks.items()]
        protocols[name] = {
            "blocks": [dataclasses.asdict(b) for b in blocks_of(cfg, name)],
            "field_block": block,
            "field": field.name,
            "control": control,
            "window": size,
            "level": level,
            "networks": list(networks.values()),
            "controls": list(controls.values()),
            "pattern": [_verdict(*p, effects, level) for p in PATTERN],
        }
    return {"protocols": protocols}


def _describe(blocks: list[dict]) -> str:
    return " → ".join(
        f"{b['condition']} × {b['trials']:,}"
        + (f" (catch {b['catch']:.0%} {b['catch_condition']})" if b["catch"] else "")
        + ("" if b["learning"] else " (frozen)")
        for b in blocks
    )


def markdown(results: dict, source: str) -> str:
    """adaptation.md: the pattern's verdicts with their intervals, and each network's window means."""
    lines = [f"# Adaptation ({source})", ""]
    for name, p in results["protocols"].items():
        reference = f"the same window of the control `{p['control']}`" if p["control"] else "the baseline"
        lines += [
            f"## Protocol `{name}`: {_describe(p['blocks'])}",
            "",
            f"Perpendicular error at peak speed, signed + where the {p['field']} field pushes the hand, in cm: means "
            f"of {p['window']:,}-trial windows. An effect is a window's mean minus {reference}. "
            f"{p['level']:.0%} t-intervals over {len(p['networks'])} networks, paired by seed.",
            "",
            "| pattern (Shadmehr & Mussa-Ivaldi 1994) | effect [cm] | interval | holds |",
            "|---|---|---|---|",
        ]
        for v in p["pattern"]:
            first, second = v["windows"]
            what = first if second is None else f"{first} − {second}"
            ci = v["difference_cm"]
            if ci is None:
                lines.append(f"| {v['claim']} ({what}) | – | – | not judged |")
                continue
            lines.append(
                f"| {v['claim']} ({what}) | {ci['mean']:+.2f} | [{ci['low']:+.2f}, {ci['high']:+.2f}] | "
                f"{'yes' if v['holds'] else 'no'} |"
            )
        lines += ["", "Window means [cm]:", "", "| learners | seed | " + " | ".join(WINDOWS) + " |"]
        lines.append("|---" * (len(WINDOWS) + 2) + "|")
        for label, group in ((name, p["networks"]), (p["control"], p["controls"])):
            for n in group:
                cells = ["–" if n["windows"][k] is None else f"{n['windows'][k]:+.2f}" for k in WINDOWS]
                lines.append(f"| {label} | {n['seed']} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)
