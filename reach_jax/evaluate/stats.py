"""Statistics over networks: Student-t confidence intervals of means, of rates and of paired differences.

Units: whatever the sample carries (fractions, seconds); interval levels are probabilities in (0, 1). Every
interval also carries the networks' own values (`values`), which a table shows instead where there are too few
networks for an interval to say much (2 networks: t = 12.7).
NumPy in float64 on the CPU, with SciPy's Student-t quantile (`scipy.stats.t.ppf`), so a verdict does not depend on
the accelerator.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.stats


def _t(level: float, n: int) -> float:
    """Student's t of a two-sided interval of coverage `level` over n values (n - 1 degrees of freedom)."""
    return float(scipy.stats.t.ppf(0.5 + 0.5 * level, n - 1))


def mean_ci(sample, level: float = 0.95) -> dict:
    """Mean of a sample with its two-sided Student-t confidence interval, JSON-ready.

    Args:
      sample: (n,) values, one per network.
      level: coverage of the interval.

    Returns:
      {"mean", "low", "high", "n", "values"}; low and high are None for fewer than 2 values.
    """
    x = np.asarray(sample, dtype=np.float64)
    n = int(x.size)
    values = [float(v) for v in x]
    if n == 0:
        return {"mean": None, "low": None, "high": None, "n": 0, "values": values}
    mean = float(x.mean())
    if n < 2:
        return {"mean": mean, "low": None, "high": None, "n": n, "values": values}
    half = _t(level, n) * float(x.std(ddof=1)) / math.sqrt(n)
    return {"mean": mean, "low": mean - half, "high": mean + half, "n": n, "values": values}


def rate_ci(sample, level: float = 0.95) -> dict:
    """Mean of rates in [0, 1] with a Student-t interval on the logit scale, so that it stays inside [0, 1].

    The interval is logit(mean) +- t * se / (mean (1 - mean)) mapped back (the delta method): near a bound it is
    asymmetric and never crosses it. When every network has the same rate (0 or 1 included) it is that rate.

    Args:
      sample: (n,) rates, one per network (success or out fractions).
      level: coverage of the interval.

    Returns:
      {"mean", "low", "high", "n", "values"} as `mean_ci`.
    """
    plain = mean_ci(sample, level)
    mean, n = plain["mean"], plain["n"]
    if n < 2:
        return plain
    sd = float(np.std(np.asarray(sample, dtype=np.float64), ddof=1))
    if sd == 0.0 or not 0.0 < mean < 1.0:
        return {**plain, "low": mean, "high": mean}
    centre = math.log(mean / (1.0 - mean))
    half = _t(level, n) * sd / math.sqrt(n) / (mean * (1.0 - mean))
    low, high = (1.0 / (1.0 + math.exp(-(centre + sign * half))) for sign in (-1.0, 1.0))
    return {**plain, "low": low, "high": high}


def positive_ci(sample, level: float = 0.95) -> dict:
    """Mean of a positive quantity with a Student-t interval on the log scale, so that it stays above zero.

    The interval is mean exp(+-t se / mean) (the delta method, as `rate_ci` on the logit scale). A quantity that can
    be negative (a learned damping or stiffness) gets the plain interval of `mean_ci` where a network's value is not
    positive, and says so with "signed": true.

    Args:
      sample: (n,) values, one per network (times [s], gains [N/m], [N s/m]).
      level: coverage of the interval.

    Returns:
      {"mean", "low", "high", "n", "values"} as `mean_ci`, with "signed" where the plain interval was taken.
    """
    plain = mean_ci(sample, level)
    if plain["n"] < 2:
        return plain
    x = np.asarray(sample, dtype=np.float64)
    if np.any(x <= 0.0):
        return {**plain, "signed": True}
    mean, sd = plain["mean"], float(x.std(ddof=1))
    half = _t(level, plain["n"]) * sd / math.sqrt(plain["n"]) / mean
    return {**plain, "low": mean * math.exp(-half), "high": mean * math.exp(half)}


def paired_ci(a, b, level: float = 0.95) -> dict:
    """Mean of the paired differences a - b with its Student-t confidence interval (see `mean_ci`)."""
    return mean_ci(np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64), level)


def ratio_ci(a, b, level: float = 0.95) -> dict:
    """Geometric mean of the paired ratios a / b with its interval, from the t-interval of log(a / b)."""
    log = mean_ci(np.log(np.asarray(a, dtype=np.float64) / np.asarray(b, dtype=np.float64)), level)
    ratios = [math.exp(v) for v in log.pop("values")]
    return {**{k: (math.exp(v) if v is not None and k != "n" else v) for k, v in log.items()}, "values": ratios}


def above(ci: dict, value: float) -> bool:
    """The whole interval lies above `value` (False without an interval)."""
    return ci["low"] is not None and ci["low"] > value


def below(ci: dict, value: float) -> bool:
    """The whole interval lies below `value` (False without an interval)."""
    return ci["high"] is not None and ci["high"] < value
