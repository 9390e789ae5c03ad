"""The committed evaluations' t-intervals come out of today's `stats` again (issue 50: SciPy's t-quantile in place of
a hand-written one): every interval of every committed eval/*.json, from its own values, within 1e-12."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest
from conftest import ROOT

from reach_jax.evaluate import anatomy, stats

# An interval's kind, by its key: rates on the logit scale, ratios as the geometric mean, times and gains on the log
# scale, the rest (differences, angles) plain.
RATES = ("success", "out", *anatomy.LABELS)  # the anatomy's shares of a network's movements are rates too
RATIOS = ("time_ratio",)
POSITIVE = ("mean_time_s", "damping_", "stiffness_", "passive_")
TOLERANCE = 1e-12  # of max(1, |value|): the old bisection stopped within 1e-12 of t, so a bound [N/m] of 8e6 moved 6e-7


def committed_json(pattern: str) -> dict[str, object]:
    """{path: parsed JSON} of the files git tracks under `pattern`, as committed at HEAD (not as the work tree has
    them: a run being trained again there has deleted its own)."""
    paths = subprocess.run(
        ["git", "ls-files", "-z", "--", pattern], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.split("\0")
    paths = [p for p in paths if p]
    blobs = subprocess.run(
        ["git", "cat-file", "--batch"],
        cwd=ROOT,
        input="".join(f"HEAD:{p}\n" for p in paths).encode(),
        capture_output=True,
        check=True,
    ).stdout
    found, at = {}, 0
    for path in paths:
        header_end = blobs.index(b"\n", at)
        size = int(blobs[at:header_end].split()[2])
        found[path] = json.loads(blobs[header_end + 1 : header_end + 1 + size])
        at = header_end + 1 + size + 1  # each blob ends with a newline
    return found


def recomputed(key: str, values: list[float], level: float) -> dict:
    """The interval that `stats` gives today for a committed one stored under `key`, from its values."""
    if key in RATES:
        return stats.rate_ci(values, level)
    if key in RATIOS:
        return stats.ratio_ci(values, np.ones(len(values)), level)  # the values are the paired ratios a / b
    if key.startswith(POSITIVE):
        return stats.positive_ci(values, level)
    return stats.mean_ci(values, level)


def intervals(data, key: str = "", level: float | None = None):
    """(key, interval, level) of every interval with its values in a JSON tree; the level is the nearest one above."""
    if isinstance(data, dict):
        level = data.get("level", level)
        if {"mean", "low", "high", "n", "values"} <= set(data):
            yield key, data, level
        for k, v in data.items():
            yield from intervals(v, k, level)
    elif isinstance(data, list):
        for v in data:
            yield from intervals(v, key, level)


def pattern_intervals(protocol: dict):
    """(committed, recomputed) of each adaptation verdict's interval, stored without its values: from the
    networks' window means, each minus its seed's control's same window (or else its own baseline)."""
    controls = {c["seed"]: c["windows"] for c in protocol["controls"]}

    def effect(network: dict, window: str) -> float:
        reference = controls[network["seed"]][window] if protocol["control"] else network["windows"]["baseline"]
        return network["windows"][window] - reference

    for verdict in protocol["pattern"]:
        first, second = verdict["windows"]
        a = [effect(n, first) for n in protocol["networks"]]
        b = [0.0 if second is None else effect(n, second) for n in protocol["networks"]]
        yield verdict["difference_cm"], stats.paired_ci(a, b, protocol["level"])


def differences(committed: dict, ci: dict) -> list[float]:
    """|today - committed| over max(1, |committed|) of the mean and both bounds; inf where one has a bound and the
    other none."""
    out = []
    for name in ("mean", "low", "high"):
        old, new = committed[name], ci[name]
        if old is None or new is None:
            out.append(0.0 if old is new else np.inf)
        else:
            out.append(abs(new - old) / max(1.0, abs(old)))
    return out


@pytest.fixture(scope="module")
def evaluations() -> dict:
    return committed_json("runs/*/eval/*.json")


def test_every_committed_interval_is_unchanged(evaluations):
    compared, worst, where = {}, 0.0, None
    for path, data in evaluations.items():
        pairs = [(ci, recomputed(key, ci["values"], level)) for key, ci, level in intervals(data)]
        if path.endswith("/adaptation.json"):
            pairs += [pair for p in data["protocols"].values() for pair in pattern_intervals(p)]
        for committed, ci in pairs:
            assert committed["n"] == ci["n"], path
            for d in differences(committed, ci):
                if d > worst:
                    worst, where = d, path
        compared[path] = len(pairs)
    print(f"{sum(compared.values())} intervals in {len(compared)} files; largest difference {worst:.3g} ({where})")
    # The walk found every kind of file that holds intervals, and every committed run's claims.
    assert all(compared[p] > 0 for p in compared if p.endswith(("/claims.json", "/adaptation.json")))
    assert any(p.endswith("/adaptation.json") for p in compared)
    assert worst <= TOLERANCE, where


def test_the_comparison_sees_a_wrong_quantile(evaluations, monkeypatch):
    # The same walk with t off by one part in 1e9 fails it: the check is not blind to the quantile.
    exact = stats._t
    monkeypatch.setattr(stats, "_t", lambda level, n: exact(level, n) * (1 + 1e-9))
    data = evaluations["runs/heldout/eval/claims.json"]
    worst = max(max(differences(ci, recomputed(key, ci["values"], level))) for key, ci, level in intervals(data))
    assert worst > 100 * TOLERANCE
