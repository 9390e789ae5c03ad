"""Networks that collapsed, read from the test: success below `claims.collapse_success` in their home test.

A network's home test is the test in its own learning condition where the tests have it (none -> none,
viscous -> viscous), else the first test condition, the null field (random -> none, random_nopast -> none). A claim
that reads a collapsed network's learning condition says so (`claims.recipe_claims`). Training names a collapse
from the metrics instead (`train.health`). Units: success as a fraction of a network's test pairs.
"""

from __future__ import annotations

from reach_jax.config import Config


def home_test(learning: str, tests: tuple[str, ...]) -> str:
    """The test condition that a network learned in `learning` is judged in: its own where tested, else tests[0]."""
    return learning if learning in tests else tests[0]


def collapsed_networks(per_network: list[dict], pairs: int, tests: tuple[str, ...], threshold: float) -> list[dict]:
    """The networks below `threshold` success in their home test: learner, learning, seed, recipe, test, success.

    Args:
      per_network: `lattice.table2`'s per-network rows (learner, learning, seed, recipe, test, success count).
      pairs: test pairs per network.
      tests: the evaluation's test conditions, the null field first (cfg.eval.test_conditions).
      threshold: cfg.claims.collapse_success.
    """
    keys = ("learner", "learning", "seed", "recipe", "test")
    return [
        {**{k: r[k] for k in keys}, "success": r["success"] / pairs}
        for r in per_network
        if r["test"] == home_test(r["learning"], tests) and r["success"] < threshold * pairs
    ]


def of_table(table: dict, cfg: Config, recipe: int | None = None) -> list[dict]:
    """The collapsed networks of a `lattice.table2` record under cfg's criteria, of one recipe or of all of them."""
    rows = [r for r in table["per_network"] if recipe is None or r["recipe"] == recipe]
    tests, rate = cfg.eval.test_conditions, cfg.claims.collapse_success
    return collapsed_networks(rows, table["pairs_per_network"], tests, rate)


def with_collapsed(claim: dict, collapsed: list[dict]) -> dict:
    """A claim's record with the collapsed networks (`collapsed_networks`) of the learning conditions it reads."""
    return {**claim, "collapsed": [n for n in collapsed if n["learning"] in claim["learnings"]]}


def names(networks: list[dict]) -> str:
    """Collapsed networks in words: "none seed 1 (0.0%), viscous seed 0 (12.5%)"."""
    return ", ".join(f"{n['learning']} seed {n['seed']} ({100 * n['success']:.1f}%)" for n in networks)
