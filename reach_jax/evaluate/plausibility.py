"""Whether the paper's Table 2 is a plausible two-network draw from our model: per cell, and as a whole by its D.

Units: rates are fractions of a network's test pairs (a pair of networks' rate is the mean of the two, its summed
counts over twice the pairs, as the paper's cells); D and its distribution are in percentage points.

The paper sums 2 networks per learning condition (`config.paper.PAPER_NETWORKS`), so a cell of ours is set beside
it as the sums of every pair of our networks of that condition. A cell is plausible when the paper's success and
out both lie inside the range of our pairs' values: their 2.5-97.5 percentiles (the `level`), or every pair's value
from lowest to highest where there are too few pairs for a tail to hold one (fewer than 40 at level 0.95).
The table as a whole: D is the mean over the paper's cells of |success - paper| + |out - paper| against our mean
over every network (`distance`). Each pair of our networks has its own D against the mean of the networks that are
not in it, as the paper's two are not in ours; a table of our pairs takes one pair per learning condition, every
combination of them (a seeded sample of MAX_TABLES where there are more). The paper's D is plausible when at least
1 - level of our pair tables lie as far from the rest as the paper lies from our mean, or farther.
docs/claims.md says why; `verdicts.decide` writes the record beside the claims in claims.json.
"""

from __future__ import annotations

import itertools

import numpy as np

from reach_jax.config.paper import PAPER_NETWORKS

RATES = ("success", "out")  # the rates D and the cells' plausibility compare
MIN_NETWORKS = PAPER_NETWORKS + 1  # a pair needs at least one network left out to be measured against
MAX_TABLES = 1 << 20  # pair tables enumerated before a seeded sample of this many is drawn instead
SAMPLE_SEED = 0  # the sample's seed, so that a verdict is the same on every machine
EDGE = 1e-12  # a paper rate equal to a range's end (both counts over 2080) lies inside it, whatever the rounding


def distance(cells: list[dict]) -> float | None:
    """D [points] of a recipe's claims.json `cells` against the paper's, over the cells the paper has.

    Args:
      cells: a recipe's `cells` in claims.json; success and out carry our mean ("mean", a fraction), `paper` the
        paper's per-network fractions (None for a cell the paper lacks).

    Returns:
      the mean over those cells of |success - paper| + |out - paper| in percentage points; None without one.
    """
    judged = [c for c in cells if c["paper"] is not None]
    if not judged:
        return None
    return sum(abs(c[k]["mean"] - c["paper"][k]) * 100 for c in judged for k in RATES) / len(judged)


def pair_means(values) -> tuple[np.ndarray, np.ndarray]:
    """Every pair's mean rate of a cell's networks, and the mean of the networks outside each pair.

    Args:
      values: (n,) one rate per network (fractions), n >= MIN_NETWORKS.

    Returns:
      ((P,), (P,)) with P = n (n - 1) / 2, pairs in `itertools.combinations` order.
    """
    x = np.asarray(values, dtype=np.float64)
    pairs = np.array(list(itertools.combinations(range(len(x)), PAPER_NETWORKS)))
    inside = x[pairs].mean(axis=1)
    rest = (x.sum() - x[pairs].sum(axis=1)) / (len(x) - PAPER_NETWORKS)
    return inside, rest


def pair_range(pairs: np.ndarray, level: float) -> tuple[float, float, str]:
    """The range of a cell's pair values at `level`: (low, high, how it was taken).

    Args:
      pairs: (P,) rates of the pairs (fractions).
      level: coverage of the range; its tails are (1 - level) / 2 each.
    """
    tail = (1.0 - level) / 2
    if len(pairs) * tail < 1.0:  # no tail would hold a whole pair: every pair's value is the range
        return float(pairs.min()), float(pairs.max()), "all pairs"
    low, high = np.percentile(pairs, [100 * tail, 100 * (1 - tail)])
    return float(low), float(high), "percentiles"


def table_distances(terms: list[np.ndarray], cells: int) -> tuple[np.ndarray, bool]:
    """D of every table made of one pair per learning condition (or of a seeded sample of MAX_TABLES of them).

    Args:
      terms: per learning condition, (P_c,) each pair's summed |pair - rest| over the condition's cells [points].
      cells: the cells D is a mean over.

    Returns:
      ((T,) D per table [points], whether the tables are a sample).
    """
    if np.prod([len(t) for t in terms], dtype=np.float64) <= MAX_TABLES:
        total = np.zeros(1)
        for t in terms:  # every combination: the outer sum, flattened
            total = np.add.outer(total, t).ravel()
        return total / cells, False
    rng = np.random.default_rng(SAMPLE_SEED)
    total = sum(t[rng.integers(len(t), size=MAX_TABLES)] for t in terms)
    return total / cells, True


def judge(cells: list[dict], level: float) -> dict | None:
    """The paper's plausibility as a two-network draw from our networks, per cell and for the table (module doc).

    Args:
      cells: a recipe's claims.json `cells`; success and out carry each network's rate ("values", fractions,
        seed-ordered alike in the cells of a learning condition) and `paper` the paper's (None where it has none).
      level: coverage of the ranges (cfg.claims.level).

    Returns:
      {"D", "level", "cells": per paper cell {"learning", "test", "success"/"out": {"paper", "low", "high", "inside"},
      "plausible"}, "plausible_cells", "range" ("percentiles" or "all pairs", that of the fewest pairs),
      "networks": {learning: n}, "pairs_D": {"median", "low", "high", "tables", "sampled"} [points],
      "paper_D_above" (the share of pair tables nearer the rest than the paper is to our mean), "plausible"};
      None without a paper cell or where a learning condition has fewer than MIN_NETWORKS networks.
    """
    judged = [c for c in cells if c["paper"] is not None]
    networks = {c["learning"]: len(c["success"]["values"]) for c in judged}
    if not judged or min(networks.values()) < MIN_NETWORKS:
        return None
    rows, ranges, terms = _cell_rows(judged, networks, level)
    d_pairs, sampled = table_distances(list(terms.values()), len(judged))
    d_paper = distance(judged)
    above = float(np.mean(d_pairs < d_paper))
    return {
        "D": d_paper,
        "level": level,
        "cells": rows,
        "plausible_cells": sum(r["plausible"] for r in rows),
        "range": "all pairs" if "all pairs" in ranges else "percentiles",
        "networks": networks,
        "pairs_D": _spread(d_pairs, level, sampled),
        "paper_D_above": above,
        "plausible": above <= level,
    }


def _spread(d_pairs: np.ndarray, level: float, sampled: bool) -> dict:
    """The median and `level` range of our pair tables' D [points], how many tables, and whether they were sampled."""
    tail = (1.0 - level) / 2
    low, median, high = np.percentile(d_pairs, [100 * tail, 50, 100 * (1 - tail)])
    spread = {"median": float(median), "low": float(low), "high": float(high)}
    return {**spread, "tables": int(len(d_pairs)), "sampled": sampled}


def _cell_rows(judged: list[dict], networks: dict, level: float) -> tuple[list[dict], set, dict]:
    """Per paper cell its pairs' range and the paper in it; the ranges' kinds; per learning condition the pairs' D
    terms (every pair's |pair - rest| summed over the condition's cells and rates, in points)."""
    rows, ranges, terms = [], set(), {learning: 0.0 for learning in networks}
    for c in judged:
        row = {"learning": c["learning"], "test": c["test"]}
        for k in RATES:
            inside, rest = pair_means(c[k]["values"])
            low, high, how = pair_range(inside, level)
            ranges.add(how)
            paper = c["paper"][k]
            row[k] = {"paper": paper, "low": low, "high": high, "inside": bool(low - EDGE <= paper <= high + EDGE)}
            terms[c["learning"]] = terms[c["learning"]] + np.abs(inside - rest) * 100
        row["plausible"] = all(row[k]["inside"] for k in RATES)
        rows.append(row)
    return rows, ranges, terms


def words(record: dict | None, d: float | None) -> str:
    """One sentence on a recipe's plausibility record (`judge`), or on its D alone where there is none.

    Args:
      record: `judge`'s record, or None.
      d: the recipe's D [points] (`distance`), for a record of None.
    """
    if record is None:
        d_text = "–" if d is None else f"{d:.1f}"
        return f"D {d_text} points; the paper's plausibility needs {MIN_NETWORKS} networks in each learning condition."
    pd = record["pairs_D"]
    verdict = "is" if record["plausible"] else "is not"
    return (
        f"D {record['D']:.1f} points against our pairs' median {pd['median']:.1f} ({record['level']:.0%} range"
        f" {pd['low']:.1f}–{pd['high']:.1f}), above {record['paper_D_above']:.1%} of them: the paper's table {verdict}"
        f" a plausible draw of two networks from ours; the paper plausible in {record['plausible_cells']} of"
        f" {len(record['cells'])} cells."
    )
