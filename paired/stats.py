"""Small statistics without scipy: Student-t quantiles and confidence intervals of a mean (shared
by the CLI's tables and the analysis package; standard library only)."""

from __future__ import annotations

import math
from collections.abc import Iterable
from statistics import NormalDist


def t_two_sided(df: int, t: float) -> float:
    """P(|T| < t) for Student's t with an integer number ``df`` of degrees of freedom, exactly
    (Abramowitz & Stegun 26.7.3-4: finite sums in theta = atan(t / sqrt(df)))."""
    if df < 1:
        raise ValueError(f"degrees of freedom must be >= 1, got {df}")
    theta = math.atan(t / math.sqrt(df))
    s, c2 = math.sin(theta), math.cos(theta) ** 2
    if df % 2 == 1:
        if df == 1:
            return 2 * theta / math.pi
        term, total = math.cos(theta), math.cos(theta)
        for k in range(3, df - 1, 2):  # cos^(df-2) is the last term
            term *= c2 * (k - 1) / k
            total += term
        return 2 / math.pi * (theta + s * total)
    term, total = 1.0, 1.0
    for k in range(2, df - 1, 2):
        term *= c2 * (k - 1) / k
        total += term
    return s * total


def t_quantile(level: float, df: int) -> float:
    """The t with P(|T| < t) = ``level`` (e.g. 2.262 for level 0.95 and df 9)."""
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    if df > 2000:  # the sums get long; the normal with one correction term is exact enough
        z = NormalDist().inv_cdf((1 + level) / 2)
        return z + (z**3 + z) / (4 * df)
    lo, hi = 0.0, 1.0
    while t_two_sided(df, hi) < level:
        hi *= 2
    for _ in range(100):
        mid = (lo + hi) / 2
        if t_two_sided(df, mid) < level:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-12 * hi:
            break
    return (lo + hi) / 2


def mean_ci(values: Iterable[float], level: float = 0.95) -> tuple[float, float, int]:
    """Mean, half-width of its ``level`` confidence interval (Student t), and the number of
    finite values used. The half-width is NaN with fewer than two values."""
    xs = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    n = len(xs)
    if n == 0:
        return math.nan, math.nan, 0
    mean = math.fsum(xs) / n
    if n < 2:
        return mean, math.nan, n
    var = math.fsum((x - mean) ** 2 for x in xs) / (n - 1)
    return mean, t_quantile(level, n - 1) * math.sqrt(var / n), n
