"""The paper's plausibility as a two-network draw from our networks: made-up networks where the answer is known, the
committed runs' numbers, and where it is written (table2.md, claims.md, the evaluate command's closing screen)."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from reach_jax.config import Config, paper
from reach_jax.evaluate import claims, lattice, plausibility, report

ROOT = Path(__file__).resolve().parent.parent
PAIRS = 1040
LEVEL = 0.95


def cells_from(rates: dict) -> list[dict]:
    """claims.json cells from {(learning, test): ((n,) success rates, (n,) out rates)}, the paper's where it has one."""
    rows = []
    for (learning, test), (success, out) in rates.items():
        for seed, (s, o) in enumerate(zip(success, out, strict=True)):
            s, o = round(s * PAIRS), round(o * PAIRS)
            rows.append(
                {"learning": learning, "test": test, "seed": seed, "success": s, "out": o, "fail": PAIRS - s - o}
                | {"mean_time_s": 1.0}
            )
    return claims.table_cells(claims.Cells(rows, PAIRS), Config().claims)


def spread(centre: float, n: int, width: float = 0.04) -> np.ndarray:
    """n rates evenly spread over centre +- width / 2."""
    return centre + np.linspace(-width / 2, width / 2, n)


def paper_centred(n: int) -> dict:
    """Every paper cell with n networks spread around the paper's own rates."""
    out = {}
    for key in paper.PAPER_TABLE2:
        cell = paper.paper_cell(*key)
        out[key] = (spread(cell["success"], n), np.clip(spread(cell["out"], n), 0, None))
    return out


def test_distance_is_the_old_studies_definition_on_a_committed_claims_file():
    # studies/search/objective.py's own D before it moved into the library, against every recipe of two runs.
    def old(cells):
        judged = [c for c in cells if c["paper"] is not None]
        terms = [abs(c[k]["mean"] - c["paper"][k]) * 100 for c in judged for k in ("success", "out")]
        return sum(terms) / len(judged)

    for run in ("frame_constant", "screen2"):
        data = json.loads((ROOT / "runs" / run / "eval" / "claims.json").read_text())
        for recipe in [r for decided in (data, *data.get("frames", {}).values()) for r in decided["recipes"]]:
            assert plausibility.distance(recipe["cells"]) == pytest.approx(old(recipe["cells"]), abs=1e-12)
    assert plausibility.distance([{**c, "paper": None} for c in cells_from(paper_centred(3))]) is None


def test_pairs_are_every_two_networks_measured_against_the_others():
    inside, rest = plausibility.pair_means([0.1, 0.2, 0.6, 0.9])
    # (0,1) (0,2) (0,3) (1,2) (1,3) (2,3), each against the mean of the two left out.
    np.testing.assert_allclose(inside, [0.15, 0.35, 0.5, 0.4, 0.55, 0.75])
    np.testing.assert_allclose(rest, [0.75, 0.55, 0.4, 0.5, 0.35, 0.15])


def test_the_range_is_every_pair_below_40_pairs_and_the_percentiles_from_there():
    eight = np.arange(28.0)  # 8 networks: 28 pairs, no tail would hold a whole pair
    assert plausibility.pair_range(eight, LEVEL) == (0.0, 27.0, "all pairs")
    ten = np.arange(45.0)  # 10 networks: 45 pairs, the 2.5 and 97.5 percentiles
    low, high, how = plausibility.pair_range(ten, LEVEL)
    assert how == "percentiles" and low == pytest.approx(1.1) and high == pytest.approx(42.9)


def test_a_paper_among_our_networks_is_plausible_and_one_far_from_them_is_not():
    rates = paper_centred(8)
    record = plausibility.judge(cells_from(rates), LEVEL)
    assert record["plausible_cells"] == 8 and record["range"] == "all pairs" and record["plausible"]
    assert record["networks"] == dict.fromkeys(("none", "viscous", "random", "random_nopast"), 8)
    assert record["pairs_D"]["tables"] == 28**4 and not record["pairs_D"]["sampled"]
    # Our none -> viscous networks succeed 20 points more than the paper's: that cell falls out, and so does the
    # table as a whole, whose D the one cell raises far above our pairs'.
    success, out = rates[("none", "viscous")]
    rates[("none", "viscous")] = (success + 0.2, out - 0.2)
    far = plausibility.judge(cells_from(rates), LEVEL)
    cell = next(c for c in far["cells"] if (c["learning"], c["test"]) == ("none", "viscous"))
    assert not cell["plausible"] and not cell["success"]["inside"] and not cell["out"]["inside"]
    assert cell["success"]["low"] > cell["success"]["paper"] + 0.15
    assert far["plausible_cells"] == 7 and far["D"] == pytest.approx(record["D"] + 40 / 8, abs=0.1)
    assert far["paper_D_above"] == 1.0 and not far["plausible"]
    # The paper's success inside and its out outside is not a plausible cell either.
    rates[("none", "viscous")] = (success, out - 0.2)
    assert plausibility.judge(cells_from(rates), LEVEL)["plausible_cells"] == 7


def test_our_own_pair_as_the_paper_is_plausible_in_every_cell():
    rng = np.random.default_rng(1)
    rates = {key: (rng.uniform(0.5, 0.9, 6), rng.uniform(0.0, 0.1, 6)) for key in paper.PAPER_TABLE2}
    cells = cells_from(rates)
    for c in cells:  # the paper is our networks 2 and 5 summed, counts over 2080 as the paper's
        c["paper"] = {k: (c[k]["values"][2] + c[k]["values"][5]) / 2 for k in plausibility.RATES}
    record = plausibility.judge(cells, LEVEL)
    assert record["plausible_cells"] == 8
    assert record["D"] <= record["pairs_D"]["high"] and record["plausible"]


def test_the_pairs_d_are_every_combination_of_one_pair_per_condition():
    # Two learning conditions of 3 networks, one cell each: 3 x 3 tables, checked by brute force.
    rates = {("none", "none"): ([0.9, 0.8, 0.5], [0.0, 0.1, 0.3]), ("viscous", "none"): ([0.7, 0.6, 0.2], [0.1] * 3)}
    record = plausibility.judge(cells_from(rates), LEVEL)
    values = {key: [np.round(np.array(v) * PAIRS) / PAIRS for v in vs] for key, vs in rates.items()}
    want = []
    for a, b in itertools.product(itertools.combinations(range(3), 2), repeat=2):
        terms = 0.0
        for pair, (s, o) in zip((a, b), values.values(), strict=True):
            left = [i for i in range(3) if i not in pair][0]
            terms += sum(abs(x[list(pair)].mean() - x[left]) for x in (s, o)) * 100
        want.append(terms / 2)
    assert record["pairs_D"]["tables"] == 9
    assert record["pairs_D"]["median"] == pytest.approx(np.median(want))
    assert record["paper_D_above"] == pytest.approx(np.mean(np.array(want) < record["D"]))


def test_beyond_max_tables_a_seeded_sample_stands_for_every_combination(monkeypatch):
    cells = cells_from(paper_centred(8))
    full = plausibility.judge(cells, LEVEL)["pairs_D"]
    monkeypatch.setattr(plausibility, "MAX_TABLES", 20_000)
    sampled = plausibility.judge(cells, LEVEL)["pairs_D"]
    assert sampled["sampled"] and sampled["tables"] == 20_000
    assert sampled == plausibility.judge(cells, LEVEL)["pairs_D"]  # the same sample every time
    assert sampled["median"] == pytest.approx(full["median"], rel=0.02)


def test_fewer_than_three_networks_a_condition_leave_it_undecided():
    assert plausibility.judge(cells_from(paper_centred(2)), LEVEL) is None
    assert "needs 3 networks" in plausibility.words(None, 12.3) and "D 12.3 points" in plausibility.words(None, 12.3)


def test_the_committed_mirrored_table_is_plausible_in_two_cells_and_not_as_a_whole():
    # The committed record is the judgement of the committed cells, and it says what the README and claims.md say.
    data = json.loads((ROOT / "runs" / "frame_constant" / "eval" / "claims.json").read_text())
    recipe = data["frames"]["viscous_mirror"]["recipes"][0]
    record = plausibility.judge(recipe["cells"], LEVEL)
    assert record == recipe["plausibility"]
    plausible = [(c["learning"], c["test"]) for c in record["cells"] if c["plausible"]]
    assert plausible == [("random", "viscous"), ("random_nopast", "none")]
    assert record["D"] == pytest.approx(20.78, abs=0.01) and record["pairs_D"]["high"] == pytest.approx(20.38, abs=0.01)
    assert 0.95 < record["paper_D_above"] < 0.99 and not record["plausible"]


def recipe(n: int = 4) -> dict:
    """A recipe record as `verdicts.decide` writes it, with n networks a condition around the paper's rates."""
    cells = cells_from(paper_centred(n))
    return {
        "hypers": {"lr": 1.0},
        "level": LEVEL,
        "informative_networks": 4,
        "networks_per_condition": n,
        "claims": [{"claim": 1, "verdict": "holds"}, {"claim": 2, "verdict": "holds in part"}],
        "cells": cells,
        "D": plausibility.distance(cells),
        "plausibility": plausibility.judge(cells, LEVEL),
        "impedance": [],
        "curriculum": {"learners": [], "judged": 0, "all_stable": True},
    }


def test_table2_and_claims_md_say_the_plausibility_beside_each_cell_and_under_the_table():
    r = recipe()
    text = lattice.table2_markdown({"pairs_per_network": PAIRS, "first_two": []}, [r], "runs/x (chunk 1)")
    row = next(line for line in text.splitlines() if line.startswith("| none → viscous |"))
    cell = next(c for c in r["plausibility"]["cells"] if (c["learning"], c["test"]) == ("none", "viscous"))
    assert row.endswith(
        f"| {100 * cell['success']['low']:.1f}–{100 * cell['success']['high']:.1f} / "
        f"{100 * cell['out']['low']:.1f}–{100 * cell['out']['high']:.1f} | yes / yes |"
    )
    sentence = "Plausibility: " + plausibility.words(r["plausibility"], r["D"])
    assert sentence in text.splitlines() and "plausible in 8 of 8 cells" in sentence
    assert sentence in report.claims_markdown({"recipes": [{**r, "claims": []}]}, "runs/x").splitlines()
    # Below 3 networks the columns are empty and the line gives D alone.
    two = recipe(2)
    text = lattice.table2_markdown({"pairs_per_network": PAIRS, "first_two": []}, [two], "runs/x (chunk 1)")
    assert next(line for line in text.splitlines() if line.startswith("| none → none |")).endswith("| – | – |")
    assert f"Plausibility: D {two['D']:.1f} points; the paper's plausibility needs 3 networks" in text


def test_the_closing_screen_names_verdicts_d_plausibility_and_the_files_there(tmp_path):
    for name in ("table2.md", "claims.md", "fig4.png"):
        (tmp_path / name).write_text("")
    far = recipe()
    far["plausibility"] = {**far["plausibility"], "plausible": False, "plausible_cells": 3}
    results = {"claims": {"chunk": 7, "frame": "viscous_mirror", "recipes": [far], "frames": {"viscous": {}}}}
    results["claims"]["frames"]["viscous"] = {"recipes": [recipe(2)]}
    lines = report.summary_text(results, Path("runs/a b"), tmp_path).splitlines()
    assert lines[0] == "runs/a b at chunk 7:"
    assert lines[1] == "Frame viscous_mirror, recipe 0 (4 networks a condition): claims 1 holds · 2 part"
    near = len(report.paper_cells(far["cells"])[1])
    assert lines[2] == f"  Table 2: {near} of 8 cells near the paper; the paper plausible in 3 of 8"
    assert lines[3].startswith(f"  D {far['D']:.1f} points, our pairs'") and "is not a plausible draw" in lines[3]
    assert lines[4].startswith("Frame viscous, recipe 0 (2 networks a condition)")
    assert lines[6] == f"  D {recipe(2)['D']:.1f} points (plausibility needs 3 networks)"
    assert not any("Failures" in line for line in lines)
    opened = lines[lines.index("Open:") + 1 : -1]
    assert [line.split()[0] for line in opened] == [str(tmp_path / n) for n in ("table2.md", "claims.md", "fig4.png")]
    assert lines[-1].startswith("Next: python -m reach_jax.evaluate.compare 'runs/a b' ")
    assert len(lines) < 25
    # The failures' headline under its frame's recipe where the anatomy has one.
    lines = report.summary_text(results, Path("r"), tmp_path, {"viscous": ["none → viscous: 9% fail"]}).splitlines()
    assert lines[lines.index("  " + report._plausible_table(recipe(2))) + 1] == "  Failures, none → viscous: 9% fail"
    # A sweep's many recipes: the first sections, then a line that points to the rest.
    results["claims"]["recipes"] = [far] * 8 + [{**far, "collapsed": [{"learning": "none"}] * 2}]
    lines = report.summary_text(results, Path("r"), tmp_path).splitlines()
    assert sum(line.startswith("Frame ") for line in lines) == report.SUMMARY_SECTIONS == 4
    assert "… and 6 more frame and recipe sections in claims.md" in lines and len(lines) < 25
