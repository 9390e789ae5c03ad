"""The paper's five claims and its Table 2 as verdicts computed over networks, with confidence intervals.

Units: success and out are fractions of a network's 1040 test pairs (percentage points in the Markdown), times
are seconds, angles degrees, damping N s/m. Every interval is a Student-t interval over networks (`stats`), on the
logit scale for success and out rates (`stats.rate_ci`) and on the log scale for times (`stats.positive_ci`).

Networks are grouped into recipes (one per sweep point of a run, a single one otherwise); within a recipe the
networks of different learning conditions are paired by seed index, since seed s starts from the same initial
weights in every condition. The criteria (cfg.claims) are stored with each run and documented, claim by claim,
in docs/claims.md. Verdicts are "holds", "holds in part" and "does not hold".
"""

from __future__ import annotations

import math

import numpy as np

from reach_jax.config import ClaimsConfig, Config
from reach_jax.config.paper import PAPER_TABLE2, paper_cell
from reach_jax.evaluate import stats

HOLDS, PARTLY, FAILS = "holds", "holds in part", "does not hold"


class Cells:
    """Per-network Table-2 values of one recipe: success, out and mean time per (learning, test), seed-ordered."""

    def __init__(self, per_network: list[dict], pairs: int):
        self.rows = sorted(per_network, key=lambda r: r["seed"])
        self.pairs = pairs

    def get(self, learning: str, test: str, name: str) -> np.ndarray:
        """(seeds,) values of `name` ("success", "out" as fractions, "mean_time_s") for one cell."""
        rows = [r for r in self.rows if r["learning"] == learning and r["test"] == test]
        scale = self.pairs if name in ("success", "out", "fail") else 1.0
        return np.array([r[name] / scale for r in rows], dtype=np.float64)

    def has(self, *learnings: str) -> bool:
        """Every given learning condition has networks in this recipe."""
        return all(any(r["learning"] == c for r in self.rows) for c in learnings)

    def drop(self, learning: str) -> np.ndarray:
        """(seeds,) success under the field minus success without it, per network."""
        return self.get(learning, "viscous", "success") - self.get(learning, "none", "success")


def _paper_drop(learning: str) -> float:
    return paper_cell(learning, "viscous")["success"] - paper_cell(learning, "none")["success"]


def _large_enough(mean: float | None, paper: float, c: ClaimsConfig, log: bool = False) -> bool:
    """Our mean effect reaches c.size_fraction of the paper's (in log units for ratios), in its direction."""
    if mean is None:
        return False
    ours, theirs = (math.log(mean), math.log(paper)) if log else (mean, paper)
    return ours / theirs >= c.size_fraction if theirs else False


def _claim(number: int, claim: str, test: str, numbers: dict, verdict: str, why: str, learnings: tuple) -> dict:
    """A claim's record; `learnings` are the learning conditions whose networks it reads."""
    return {
        "claim": number,
        "statement": claim,
        "test": test,
        "numbers": numbers,
        "verdict": verdict,
        "why": why,
        "learnings": list(learnings),
    }


def claim_matched(cells: Cells, c: ClaimsConfig) -> dict:
    """Claim 1: when learning and test conditions match, success is high."""
    numbers = {
        f"{k}->{k}": {
            "success": stats.rate_ci(cells.get(k, k, "success"), c.level),
            "paper": paper_cell(k, k)["success"],
        }
        for k in ("none", "viscous")
    }
    ok = [stats.above(v["success"], c.matched_min_success) for v in numbers.values()]
    verdict = HOLDS if all(ok) else PARTLY if any(ok) else FAILS
    return _claim(
        1,
        "When learning and test conditions match, success is high.",
        f"mean success of none->none and viscous->viscous, interval above {c.matched_min_success:.0%}",
        numbers,
        verdict,
        f"{sum(ok)} of 2 intervals above the bound",
        ("none", "viscous"),
    )


def claim_unexpected_field(cells: Cells, after: dict, c: ClaimsConfig) -> dict:
    """Claim 2: an unexpected viscous field lowers success, lengthens movements and pulls the paths with it."""
    d_s = stats.paired_ci(cells.get("none", "viscous", "success"), cells.get("none", "none", "success"), c.level)
    r_t = stats.ratio_ci(cells.get("none", "viscous", "mean_time_s"), cells.get("none", "none", "mean_time_s"), c.level)
    paper_d, paper_r = _paper_drop("none"), PAPER_TABLE2[("none", "viscous")][3] / PAPER_TABLE2[("none", "none")][3]
    with_force = after.get("fraction_b_with_force")
    numbers = {
        "success_change": {**d_s, "paper": paper_d},
        "time_ratio": {**r_t, "paper": paper_r},
        "paths_pulled_with_force": with_force,
        "pull_to_force_deg": after.get("mean_pull_b_to_force_deg"),
    }
    significant = stats.below(d_s, 0.0) and stats.above(r_t, 1.0)
    direction = with_force is not None and with_force > 0.5
    large = _large_enough(d_s["mean"], paper_d, c) and _large_enough(r_t["mean"], paper_r, c, log=True)
    if significant and direction and large:
        verdict, why = HOLDS, "success falls, time grows, paths follow the force, at least half the paper's size"
    elif (stats.below(d_s, 0.0) or stats.above(r_t, 1.0)) and direction:
        verdict, why = PARTLY, "the field hurts and pulls the paths with it, but less than half as much as the paper's"
        if not significant:
            why = "the paths follow the force, but success and time do not both change significantly"
    else:
        verdict, why = FAILS, "no significant harm with paths pulled along the force"
    return _claim(
        2,
        "An unexpected viscous field hurts a network trained without it and pulls its paths along the force.",
        "paired over seeds: success(none->viscous) - success(none->none) < 0 and time ratio > 1; "
        "Fig. 4 (b) pulls within 90 deg of the field force in most movements; size >= "
        f"{c.size_fraction:.0%} of the paper's",
        numbers,
        verdict,
        why,
        ("none",),
    )


def claim_aftereffect(cells: Cells, after: dict, c: ClaimsConfig) -> dict:
    """Claim 3: removing the field after learning in it hurts, and the paths curve the other way."""
    d_s = stats.paired_ci(cells.get("viscous", "none", "success"), cells.get("viscous", "viscous", "success"), c.level)
    r_t = stats.ratio_ci(
        cells.get("viscous", "none", "mean_time_s"), cells.get("viscous", "viscous", "mean_time_s"), c.level
    )
    paper_d = paper_cell("viscous", "none")["success"] - paper_cell("viscous", "viscous")["success"]
    paper_r = PAPER_TABLE2[("viscous", "none")][3] / PAPER_TABLE2[("viscous", "viscous")][3]
    against = after.get("fraction_c_against_force")
    numbers = {
        "success_change": {**d_s, "paper": paper_d},
        "time_ratio": {**r_t, "paper": paper_r},
        "paths_pulled_against_force": against,
        "angle_between_pulls_deg": after.get("angle_deg"),
        "paper_angle_deg": 90.0,
    }
    direction = against is not None and against > 0.5
    s_ok, t_ok = stats.below(d_s, 0.0), stats.above(r_t, 1.0)
    large = _large_enough(d_s["mean"], paper_d, c) and _large_enough(r_t["mean"], paper_r, c, log=True)
    if s_ok and t_ok and direction and large:
        verdict, why = HOLDS, "success falls, time grows and paths curve against the force, at least half the size"
    elif (s_ok or t_ok) and direction:
        parts = [name for name, ok in (("success", s_ok), ("time", t_ok)) if ok]
        verdict, why = PARTLY, f"paths curve against the force; significant in {' and '.join(parts)} only"
        if s_ok and t_ok:
            why = "paths curve against the force and both change, but less than half as much as the paper's"
    else:
        verdict, why = FAILS, "no significant after-effect with paths curved against the force"
    return _claim(
        3,
        "After learning in the field, removing it hurts and the paths curve the other way (after-effect).",
        "paired over seeds: success(viscous->none) - success(viscous->viscous) < 0 and time ratio > 1; "
        "Fig. 4 (c) pulls more than 90 deg from the field force in most movements",
        numbers,
        verdict,
        why,
        ("viscous",),
    )


def claim_random_robust(cells: Cells, c: ClaimsConfig) -> dict:
    """Claim 4: random-force learning makes the arm robust to the field, unlike learning without forces."""
    d = stats.paired_ci(cells.drop("random"), cells.drop("none"), c.level)
    s_none = stats.rate_ci(cells.get("random", "none", "success"), c.level)
    s_field = stats.rate_ci(cells.get("random", "viscous", "success"), c.level)
    numbers = {
        "field_cost_random_minus_none": {**d, "paper": _paper_drop("random") - _paper_drop("none")},
        "random->none": {"success": s_none, "paper": paper_cell("random", "none")["success"]},
        "random->viscous": {"success": s_field, "paper": paper_cell("random", "viscous")["success"]},
    }
    ok = [
        stats.above(d, 0.0),
        stats.above(s_none, c.robust_min_success_none),
        stats.above(s_field, c.robust_min_success_field),
    ]
    verdict = HOLDS if all(ok) else PARTLY if any(ok) else FAILS
    labels = ("the field costs random-force networks less", "random->none success high", "random->viscous success high")
    return _claim(
        4,
        "Learning with random forces gives an arm that is robust in both tests.",
        "paired over seeds: (success drop under the field of random) - (of none) > 0; random->none interval above "
        f"{c.robust_min_success_none:.0%}; random->viscous interval above {c.robust_min_success_field:.0%}",
        numbers,
        verdict,
        "; ".join(f"{label}: {'yes' if flag else 'no'}" for label, flag in zip(labels, ok, strict=True)),
        ("none", "random"),
    )


def claim_past_inputs(cells: Cells, c: ClaimsConfig) -> dict:
    """Claim 5: without the past-state inputs, random-force learning leaves the arm much worse under the field."""
    d_a = stats.paired_ci(
        cells.get("random_nopast", "viscous", "success"), cells.get("random", "viscous", "success"), c.level
    )
    d_b = stats.paired_ci(cells.drop("random_nopast"), cells.drop("random"), c.level)
    paper_a = paper_cell("random_nopast", "viscous")["success"] - paper_cell("random", "viscous")["success"]
    numbers = {
        "nopast_minus_random_under_field": {**d_a, "paper": paper_a},
        "field_cost_nopast_minus_random": {**d_b, "paper": _paper_drop("random_nopast") - _paper_drop("random")},
    }
    a_ok, b_ok = stats.below(d_a, 0.0), stats.below(d_b, 0.0)
    if a_ok and b_ok:
        verdict, why = HOLDS, "worse under the field, and the field costs the no-past networks more"
    elif a_ok:
        verdict, why = PARTLY, "worse under the field, but the field does not cost them significantly more"
    else:
        verdict, why = FAILS, "not significantly worse under the field"
    return _claim(
        5,
        "Without past-state inputs, random-force learning gives an arm much worse under the field (feedback).",
        "paired over seeds: success(random_nopast->viscous) - success(random->viscous) < 0, and the field's "
        "cost to random_nopast exceeds its cost to random",
        numbers,
        verdict,
        why,
        ("random", "random_nopast"),
    )


def table_cells(cells: Cells, c: ClaimsConfig) -> list[dict]:
    """Every Table-2 cell as mean per network with its interval, beside the paper's, and the target check."""
    rows = []
    # The paper's cells first, in its order, then those of other conditions (with no paper value to meet).
    others = [key for key in dict.fromkeys((r["learning"], r["test"]) for r in cells.rows) if key not in PAPER_TABLE2]
    for learning, test in [*PAPER_TABLE2, *others]:
        if not cells.has(learning) or not len(cells.get(learning, test, "success")):
            continue
        ours = {name: stats.rate_ci(cells.get(learning, test, name), c.level) for name in ("success", "out")}
        ours["mean_time_s"] = stats.positive_ci(cells.get(learning, test, "mean_time_s"), c.level)
        paper = paper_cell(learning, test) if (learning, test) in PAPER_TABLE2 else None
        near = None
        if paper is not None:
            near = {
                "success": abs(ours["success"]["mean"] - paper["success"]) * 100 <= c.cell_points,
                "out": abs(ours["out"]["mean"] - paper["out"]) * 100 <= c.cell_points,
                "mean_time_s": abs(ours["mean_time_s"]["mean"] / paper["mean_time_s"] - 1.0) <= c.cell_time,
            }
        rows.append({"learning": learning, "test": test, **ours, "paper": paper, "near_paper": near})
    return rows


def recipe_claims(cells: Cells, after: dict, cfg: Config) -> list[dict]:
    """The claims that the recipe's conditions allow (a claim needs every condition it compares; the path
    directions of claims 2 and 3 come from Fig. 4, which pairs a none and a viscous network of each seed)."""
    c = cfg.claims
    out = []
    if not {"none", "viscous"} <= {r["test"] for r in cells.rows}:
        return out  # every claim compares performance without and with the paper's field
    if cells.has("none", "viscous"):
        out += [claim_matched(cells, c), claim_unexpected_field(cells, after, c), claim_aftereffect(cells, after, c)]
    if cells.has("none", "random"):
        out.append(claim_random_robust(cells, c))
    if cells.has("random", "random_nopast"):
        out.append(claim_past_inputs(cells, c))
    return out
