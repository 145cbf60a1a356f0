"""The median and a linear-interpolation quantile of a few numbers, as ``np.median`` / ``np.quantile``
compute them, to the last bit, without numpy's per-call overhead (~25 and ~100 us; these take 1-3 us).

The online graph asks for them per record or per keyframe over windows of at most a few hundred
values (the scan period, the output period, the IMU's rate): thousands of calls per log
(docs/performance.md). Both assume finite values (numpy propagates a NaN; a window of intervals
holds none).
"""

from __future__ import annotations

import math
from collections.abc import Iterable


def median(values: Iterable[float]) -> float:
    """``float(np.median(values))`` of finite values: the middle one, or the two middle ones' mean
    ``(a + b) / 2`` (numpy's ``mean`` of the two: their sum halved, the same rounding)."""
    s = sorted(values)
    n = len(s)
    if not n:
        raise ValueError("median of no values")
    m = n // 2
    return float(s[m]) if n % 2 else (s[m - 1] + s[m]) / 2.0


def quantile(values: Iterable[float], q: float) -> float:
    """``float(np.quantile(values, q))`` (method ``"linear"``) of finite values: the sorted values at the
    virtual index ``(n - 1) q`` interpolated as numpy's ``_lerp`` does (from the lower neighbour below a
    fraction of 0.5, from the upper one at or above it)."""
    s = sorted(values)
    n = len(s)
    if not n:
        raise ValueError("quantile of no values")
    v = (n - 1) * q
    lo = math.floor(v)
    if lo >= n - 1:
        return float(s[-1])
    if lo < 0:
        return float(s[0])
    g = v - lo
    a, b = s[lo], s[lo + 1]
    d = b - a
    return float(b - d * (1.0 - g)) if g >= 0.5 else float(a + d * g)
