"""The paper's numbers and the criteria that compare a run with them (our choices, docs/claims.md).

Units: counts of test movements, times [s]; the criteria's success and out as fractions, cell_points in
percentage points.
"""

from __future__ import annotations

from dataclasses import dataclass

# The paper's Table 2: (learning, test) -> (success, out, fail, mean time [s]), summed over 2 networks.
PAPER_TABLE2 = {
    ("none", "none"): (2071, 5, 4, 0.324),
    ("none", "viscous"): (1139, 926, 15, 2.03),
    ("viscous", "none"): (1869, 193, 18, 0.793),
    ("viscous", "viscous"): (2035, 38, 7, 0.467),
    ("random", "none"): (2038, 5, 37, 0.546),
    ("random", "viscous"): (1833, 227, 20, 0.909),
    ("random_nopast", "none"): (1887, 0, 193, 0.896),
    ("random_nopast", "viscous"): (1165, 853, 62, 2.12),
}
PAPER_NETWORKS = 2  # networks summed in each cell of the paper's Table 2
PAPER_PAIRS = 1040  # test pairs per network in the paper


@dataclass(frozen=True)
class ClaimsConfig:
    """How `claims` decides the paper's five claims and the Table-2 targets (our choices, docs/claims.md).

    Stored with each run, so a run trained on held-out seeds carries the criteria fixed before it was trained.
    """

    level: float = 0.95  # two-sided coverage of every confidence interval over networks
    informative_networks: int = 4  # below this many networks a condition, tables show each network's value instead
    # of an interval (with 2, t = 12.7 makes any interval uninformative; docs/claims.md)
    matched_min_success: float = 0.90  # claim 1: the interval of mean success stays above this
    robust_min_success_none: float = 0.85  # claim 4: random -> none success interval above this
    robust_min_success_field: float = 0.80  # claim 4: random -> viscous success interval above this
    size_fraction: float = 0.5  # an effect "as large as the paper's" reaches this fraction of it (log for time)
    cell_points: float = 5.0  # Table-2 target: success and out within this many percentage points of the paper
    cell_time: float = 0.25  # Table-2 target: mean time within this fraction of the paper's
    curriculum_tail: float = 0.2  # stability is judged over the last 20% of each learner's trials
    curriculum_min_fraction: float = 0.9  # a chunk below 90% of the whole field counts as a setback
    curriculum_max_setbacks: float = 0.01  # a learner is stable with at most 1% of its tail chunks set back
    collapse_success: float = 0.5  # a network collapsed: success below this in its home test (docs/claims.md)
    collapse_trials: int = 10_000  # in training: collapsed while success over its last this many trials (whole
    # chunks) is below collapse_success, after the curriculum first reached the whole field (our choice)


def paper_cell(learning: str, test: str) -> dict:
    """The paper's cell as per-network success and out fractions and its mean time [s]."""
    s, o, _, t = PAPER_TABLE2[(learning, test)]
    n = PAPER_NETWORKS * PAPER_PAIRS
    return {"success": s / n, "out": o / n, "mean_time_s": t}
