"""Claims as computed verdicts: the t-intervals, and each claim's verdict on synthetic Table-2 numbers."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from reach_jax.config import ClaimsConfig, Config, paper
from reach_jax.evaluate import claims, lattice, report, stats
from reach_jax.evaluate.verdicts import curriculum_stability

CFG = Config()
PAIRS = 1040
SEEDS = 6


def rows_from(cells: dict) -> list[dict]:
    """Per-network rows from {(learning, test): (success %, out %, mean time s)}, with a small spread over seeds."""
    rows = []
    for k, ((learning, test), (success, out, time)) in enumerate(sorted(cells.items())):
        # Independent spread per cell (fixed seed), so paired differences have a spread too.
        noise = np.random.default_rng(k).normal(size=(2, SEEDS))
        for seed in range(SEEDS):
            s = round(min(100.0, success + 0.5 * noise[0, seed]) / 100 * PAIRS)
            o = min(round(out / 100 * PAIRS), PAIRS - s)
            rows.append(
                {
                    "learning": learning,
                    "test": test,
                    "seed": seed,
                    "success": s,
                    "out": o,
                    "fail": PAIRS - s - o,
                    "mean_time_s": time * (1 + 0.02 * noise[1, seed]),
                }
            )
    return rows


def paper_like() -> dict:
    """Every cell at the paper's per-network values."""
    out = {}
    for key in paper.PAPER_TABLE2:
        cell = paper.paper_cell(*key)
        out[key] = (100 * cell["success"], 100 * cell["out"], cell["mean_time_s"])
    return out


AFTER_PAPER = {
    "fraction_b_with_force": 1.0,
    "fraction_c_against_force": 0.9,
    "mean_pull_b_to_force_deg": 30.0,
    "angle_deg": {"mean": 90.0, "low": 80.0, "high": 100.0, "n": SEEDS},
}


def verdicts(cells: dict, after=AFTER_PAPER) -> dict:
    result = claims.recipe_claims(claims.Cells(rows_from(cells), PAIRS), after, CFG)
    return {c["claim"]: c for c in result}


def coverage(interval, draw, truth: float, rounds: int = 2000) -> float:
    """The share of `rounds` intervals, each from a sample `draw(rng)`, that contain `truth`."""
    rng = np.random.default_rng(0)
    inside = 0
    for _ in range(rounds):
        ci = interval(draw(rng))
        inside += ci["low"] <= truth <= ci["high"]
    return inside / rounds


def test_t_quantiles_and_intervals():
    # The half-width over sd / sqrt(n) is Student's t of n - 1 degrees of freedom: textbook two-sided values at 95%
    # and 90%, and none at level 0.
    rng = np.random.default_rng(1)
    for n, level, value in [(2, 0.95, 12.706), (3, 0.95, 4.303), (8, 0.95, 2.365), (31, 0.95, 2.042), (4, 0.9, 2.353)]:
        x = rng.normal(size=n)
        ci = stats.mean_ci(x, level)
        assert (ci["high"] - ci["low"]) / 2 / (x.std(ddof=1) / np.sqrt(n)) == pytest.approx(value, abs=1e-3)
    assert stats.mean_ci([1.0, 2.0, 4.0], 0.0)["low"] == pytest.approx(stats.mean_ci([1.0, 2.0, 4.0])["mean"])
    # To full precision: with 1 degree of freedom t is Cauchy's tan(pi (p - 1/2)); with 3, the root of its
    # closed-form CDF, found to 30 digits (mpmath).
    for x, t in [([1.0, 2.0], math.tan(math.pi * 0.475)), ([1.0, 2.0, 3.0, 4.0], 3.1824463052837096)]:
        x = np.array(x)
        ci, half = stats.mean_ci(x), t * x.std(ddof=1) / math.sqrt(len(x))
        assert (ci["low"], ci["high"]) == pytest.approx((x.mean() - half, x.mean() + half), rel=1e-14)
    assert stats.mean_ci([3.0])["low"] is None and not stats.above(stats.mean_ci([3.0]), 0.0)
    assert stats.paired_ci([3, 4, 5], [1, 1, 1])["mean"] == pytest.approx(3.0)
    assert stats.ratio_ci([2, 2, 2], [1, 1, 1])["mean"] == pytest.approx(2.0)
    assert stats.ratio_ci([2, 4, 8], [1, 1, 1])["mean"] == pytest.approx(4.0)  # geometric mean
    # Coverage: about 95% of intervals from normal samples of 8 contain the true mean.
    assert 0.93 < coverage(stats.mean_ci, lambda rng: rng.normal(1.0, 2.0, 8), 1.0) < 0.97


def test_rate_intervals_stay_inside_0_1_and_cover():
    # The held-out run's viscous -> viscous success had the t-interval [95.1, 100.4]; near a bound the logit-scale
    # interval is asymmetric, inside [0, 1], and keeps the mean.
    near_one = np.array([1.0, 0.999, 0.998, 0.93, 0.99, 0.97, 0.995, 0.935])
    t, rate = stats.mean_ci(near_one), stats.rate_ci(near_one)
    assert t["high"] > 1.0 and 0.0 < rate["low"] < rate["mean"] < rate["high"] < 1.0
    assert rate["mean"] == t["mean"] and rate["high"] - rate["mean"] < rate["mean"] - rate["low"]
    # Far from the bounds it agrees with the t-interval to first order.
    middle = np.array([0.50, 0.52, 0.48, 0.51, 0.49, 0.50])
    assert (stats.rate_ci(middle)["low"], stats.rate_ci(middle)["high"]) == pytest.approx(
        (stats.mean_ci(middle)["low"], stats.mean_ci(middle)["high"]), abs=1e-4
    )
    # Every network alike, at a bound or not: the interval is that rate; one network: no interval.
    assert stats.rate_ci([0.0, 0.0, 0.0])["low"] == stats.rate_ci([0.0, 0.0, 0.0])["high"] == 0.0
    assert stats.rate_ci([1.0, 1.0])["low"] == 1.0 and stats.rate_ci([0.3])["low"] is None
    # Coverage of the mean of 8 networks' rates drawn around 0.95 (beta-distributed): close to the nominal 95%.
    assert 0.92 < coverage(stats.rate_ci, lambda rng: rng.beta(19.0, 1.0, 8), 0.95) < 0.98


def test_positive_intervals_stay_above_zero_and_cover():
    # The README command's 2-network table printed a mean time of "0.44 [-0.63, 1.50]" s with the t-interval.
    two = np.array([0.36, 0.52])
    t, pos = stats.mean_ci(two), stats.positive_ci(two)
    assert t["low"] < 0.0 < pos["low"] < pos["mean"] < pos["high"] and pos["mean"] == t["mean"]
    assert pos["values"] == [0.36, 0.52] and "signed" not in pos
    # On the log scale: symmetric about the mean in ratio, close to the t-interval where the spread is small.
    assert pos["mean"] / pos["low"] == pytest.approx(pos["high"] / pos["mean"])
    tight = np.array([10.0, 10.2, 9.9, 10.1, 9.8, 10.0])
    assert (stats.positive_ci(tight)["low"], stats.positive_ci(tight)["high"]) == pytest.approx(
        (stats.mean_ci(tight)["low"], stats.mean_ci(tight)["high"]), rel=1e-3
    )
    # A damping can be negative: where a network's is, the plain interval, marked signed.
    signed = stats.positive_ci([-3.0, 5.0, 12.0])
    assert signed["signed"] and (signed["low"], signed["high"]) == pytest.approx(
        (stats.mean_ci([-3.0, 5.0, 12.0])["low"], stats.mean_ci([-3.0, 5.0, 12.0])["high"])
    )
    # Coverage of the mean of 8 log-normal times: close to the nominal 95%.
    assert 0.92 < coverage(stats.positive_ci, lambda rng: rng.lognormal(0.0, 0.3, 8), math.exp(0.045)) < 0.98


def test_with_two_networks_the_tables_show_each_networks_value_and_no_negative_number():
    # Two networks a condition, spread as in the README command's run: no interval, each value beside the mean.
    cells = paper_like()
    rows = [{**r, "seed": r["seed"] % 2} for r in rows_from(cells) if r["seed"] < 2]
    rows[0]["mean_time_s"], rows[1]["mean_time_s"] = 0.36, 0.52  # none -> none of seeds 0 and 1
    cfg = Config()
    recipe = {
        "hypers": {"lr": 1.0},
        "level": 0.95,
        "informative_networks": cfg.claims.informative_networks,
        "networks_per_condition": 2,
        "claims": claims.recipe_claims(claims.Cells(rows, PAIRS), AFTER_PAPER, cfg),
        "cells": claims.table_cells(claims.Cells(rows, PAIRS), cfg.claims),
        "impedance": [
            {
                "learning": "none",
                "test": "none",
                **{n: stats.positive_ci([22.6, 31.6]) for n in ("damping_unstable", "damping_stable")},
                "passive_damping_unstable": stats.positive_ci([6.5, 6.7]),
            }
        ],
        "curriculum": {"learners": [], "judged": 0, "all_stable": True},
    }
    table = {"pairs_per_network": PAIRS, "first_two": []}
    text = lattice.table2_markdown(table, [recipe], "runs/x (chunk 1)")
    assert "| none → none | " in text and "0.44 (networks 0.36, 0.52)" in text
    assert "[" not in text.split("| none → none |")[1].split("\n")[0]  # no interval in the row
    assert "each network's value stands beside the mean" in text
    words = report.claims_markdown({"recipes": [recipe]}, "runs/x (chunk 1)")
    assert "27.1 (networks 22.6, 31.6)" in words and "each network's value stands beside the mean" in words
    # No negative number in Table 2 or the damping table (the claims' differences may be negative: drops).
    for page in (text, words.split("Learned hand damping")[1]):
        assert not re.search(r"(?<![\w→-])-\d", page.replace("–", "")), page
    # With 4 networks the interval is back.
    four = {**recipe, "networks_per_condition": 4, "impedance": []}
    four["cells"] = claims.table_cells(claims.Cells([r for r in rows_from(cells) if r["seed"] < 4], PAIRS), cfg.claims)
    assert "each network's value" not in lattice.table2_markdown(table, [four], "runs/x (chunk 1)")
    assert re.search(r"\| none → none \| [\d.]+ \[[\d.]+, [\d.]+\]", lattice.table2_markdown(table, [four], "s"))


def test_paper_numbers_make_every_claim_hold_and_every_cell_near():
    got = verdicts(paper_like())
    assert [got[k]["verdict"] for k in range(1, 6)] == [claims.HOLDS] * 5
    cells = claims.table_cells(claims.Cells(rows_from(paper_like()), PAIRS), CFG.claims)
    assert len(cells) == 8 and all(all(c["near_paper"].values()) for c in cells)
    md = report.claims_markdown(
        {
            "recipes": [
                {
                    "hypers": {"noise": 0.2},
                    "level": 0.95,
                    "networks_per_condition": SEEDS,
                    "claims": list(got.values()),
                    "cells": cells,
                    "impedance": [],
                    "curriculum": {"learners": [], "judged": 0, "all_stable": False},
                }
            ]
        },
        "synthetic",
    )
    assert md.count("**holds**") == 5 and "8 of 8 cells" in md


def test_a_robust_no_field_network_fails_claim_2_and_4():
    cells = paper_like()
    cells[("none", "viscous")] = cells[("none", "none")]  # the field does not hurt
    got = verdicts(cells)
    assert got[2]["verdict"] == claims.FAILS
    # Random-force networks now lose more to the field than no-field networks do.
    assert got[4]["verdict"] == claims.PARTLY and "costs random-force networks less: no" in got[4]["why"]
    near = {
        (c["learning"], c["test"]): c["near_paper"]
        for c in claims.table_cells(claims.Cells(rows_from(cells), PAIRS), CFG.claims)
    }
    assert not near[("none", "viscous")]["success"] and near[("none", "none")]["success"]


def test_a_small_significant_effect_holds_only_in_part():
    cells = paper_like()
    cells[("none", "viscous")] = (92.0, 3.0, 0.55)  # significant, but a sixth of the paper's drop
    got = verdicts(cells)
    assert got[2]["verdict"] == claims.PARTLY
    assert got[2]["numbers"]["success_change"]["high"] < 0
    # The same numbers with paths pulled against the force: no claim at all.
    against = {**AFTER_PAPER, "fraction_b_with_force": 0.2}
    assert verdicts(cells, against)[2]["verdict"] == claims.FAILS


def test_aftereffect_in_time_only_is_partial():
    cells = paper_like()
    vv = cells[("viscous", "viscous")]
    cells[("viscous", "none")] = (vv[0] + 1.0, vv[1], 1.7 * vv[2])  # no loss of success, but slower
    got = verdicts(cells)
    assert got[3]["verdict"] == claims.PARTLY and "time only" in got[3]["why"]
    cells[("viscous", "none")] = vv  # no after-effect at all
    assert verdicts(cells)[3]["verdict"] == claims.FAILS


def test_claim_5_needs_the_field_to_cost_the_no_past_networks_more():
    cells = paper_like()
    # No-past networks worse under the field, but equally worse without it.
    r_none, r_field = cells[("random", "none")], cells[("random", "viscous")]
    cells[("random_nopast", "none")] = (r_none[0] - 20, 0.0, 1.0)
    cells[("random_nopast", "viscous")] = (r_field[0] - 20, 0.0, 1.2)
    got = verdicts(cells)
    assert got[5]["verdict"] == claims.PARTLY
    cells[("random_nopast", "viscous")] = r_field
    cells[("random_nopast", "none")] = r_none
    assert verdicts(cells)[5]["verdict"] == claims.FAILS


def test_claim_1_fails_when_a_matched_condition_is_poor():
    cells = paper_like()
    cells[("viscous", "viscous")] = (80.0, 5.0, 1.0)
    got = verdicts(cells)
    assert got[1]["verdict"] == claims.PARTLY
    cells[("none", "none")] = (70.0, 5.0, 1.0)
    assert verdicts(cells)[1]["verdict"] == claims.FAILS


def test_claims_need_their_conditions():
    only_none = {k: v for k, v in paper_like().items() if k[0] == "none"}
    assert verdicts(only_none) == {}
    two = {k: v for k, v in paper_like().items() if k[0] in ("none", "viscous")}
    assert sorted(verdicts(two)) == [1, 2, 3]


def test_size_rule_uses_logs_for_ratios():
    c = ClaimsConfig(size_fraction=0.5)
    assert claims._large_enough(math.sqrt(6.27) + 0.01, 6.27, c, log=True)
    assert not claims._large_enough(math.sqrt(6.27) - 0.01, 6.27, c, log=True)
    assert claims._large_enough(-0.25, -0.448, c) and not claims._large_enough(-0.2, -0.448, c)
    assert not claims._large_enough(0.3, -0.448, c)  # the wrong direction is never large enough


def test_curriculum_stability_counts_setbacks_in_the_tail_only():
    full = CFG.sensor.n_cells * CFG.sensor.cell_size
    trials = 1000
    metrics = []
    for chunk in range(1, 101):
        t = chunk * 10
        early_dip = 0.5 * full if chunk < 50 else full  # learner 0: setbacks only before the tail
        late_dip = 0.5 * full if chunk in (90, 91) else full  # learner 1: two setbacks of 20 tail chunks
        metrics += [
            {"learner": 0, "trials": t, "chunk_trials": 10, "distance_m": early_dip},
            {"learner": 1, "trials": t, "chunk_trials": 10, "distance_m": late_dip},
            {"learner": 2, "trials": min(t, 850), "chunk_trials": 10 if t <= 850 else 0, "distance_m": full},
        ]
    got = curriculum_stability(metrics, [0, 1, 2], trials, CFG)
    per = {p["learner"]: p for p in got["learners"]}
    assert per[0]["tail_chunks"] == 20 and per[0]["setback_chunks"] == 0 and per[0]["stable"]
    assert per[1]["setback_chunks"] == 2 and per[1]["setback_fraction"] == pytest.approx(0.1) and not per[1]["stable"]
    assert per[2]["tail_chunks"] == 5 and per[2]["stable"]  # chunks after the learner stopped do not count
    assert not got["all_stable"]
    assert curriculum_stability(metrics, [0, 2], trials, CFG)["all_stable"]
