"""Statistics over networks: Student-t confidence intervals of means, of rates and of paired differences.

Units: whatever the sample carries (fractions, seconds); interval levels are probabilities in (0, 1). Every
interval also carries the networks' own values (`values`), which a table shows instead where there are too few
networks for an interval to say much (2 networks: t = 12.7).
Pure Python and NumPy, so a verdict does not depend on the accelerator or on a statistics package.
"""

from __future__ import annotations

import math

import numpy as np


def _betacf(a: float, b: float, x: float) -> float:
    """Continued fraction of the regularized incomplete beta function (modified Lentz)."""
    tiny, eps = 1e-300, 1e-15
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1.0)
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 500):
        for num in (
            m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)),
            -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1)),
        ):
            d = 1.0 + num * d
            d = 1.0 / (d if abs(d) > tiny else tiny)
            c = 1.0 + num / c
            c = c if abs(c) > tiny else tiny
            h *= d * c
        if abs(d * c - 1.0) < eps:
            break
    return h


def betainc(a: float, b: float, x: float) -> float:
    """Regularized incomplete beta function I_x(a, b) for a, b > 0 and x in [0, 1]."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    log_front = math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x)
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(log_front) * _betacf(a, b, x) / a
    return 1.0 - math.exp(log_front) * _betacf(b, a, 1.0 - x) / b


def t_cdf(x: float, df: float) -> float:
    """Student-t cumulative distribution function with df degrees of freedom."""
    # Of the two equal forms, take the one whose argument is not rounded to 1 near x = 0.
    if x * x < df:
        tail = 0.5 * (1.0 - betainc(0.5, 0.5 * df, x * x / (df + x * x)))
    else:
        tail = 0.5 * betainc(0.5 * df, 0.5, df / (df + x * x))
    return 1.0 - tail if x >= 0 else tail


def t_quantile(p: float, df: float) -> float:
    """The x with t_cdf(x, df) = p, by bisection (to 1e-12)."""
    if not 0.0 < p < 1.0:
        raise ValueError(f"p must lie in (0, 1), got {p}")
    lo, hi = -1.0, 1.0
    while t_cdf(lo, df) > p:
        lo *= 2.0
    while t_cdf(hi, df) < p:
        hi *= 2.0
    while hi - lo > 1e-12:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if t_cdf(mid, df) < p else (lo, mid)
    return 0.5 * (lo + hi)


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
    half = t_quantile(0.5 + 0.5 * level, n - 1) * float(x.std(ddof=1)) / math.sqrt(n)
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
    half = t_quantile(0.5 + 0.5 * level, n - 1) * sd / math.sqrt(n) / (mean * (1.0 - mean))
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
    half = t_quantile(0.5 + 0.5 * level, plain["n"] - 1) * sd / math.sqrt(plain["n"]) / mean
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
