"""Chi-square quantiles without importing scipy.stats (~1 s and 40 MB at start-up): the same
expression scipy.stats' ``chi2.ppf`` evaluates, ``2 gammaincinv(dof / 2, p)``, cached per (p, dof)."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import gammaincinv, gammaln, ndtri


@lru_cache(maxsize=256)
def chi2_ppf(p: float, dof: int) -> float:
    """``scipy.stats.chi2.ppf(p, dof)``: the ``p`` quantile of a chi-square with ``dof`` degrees of freedom."""
    return float(2.0 * gammaincinv(dof / 2.0, p))


def chi2_median(dof: ArrayLike) -> NDArray[np.float64]:
    """``scipy.stats.chi2.median(dof)``, elementwise."""
    return 2.0 * gammaincinv(np.asarray(dof, dtype=float) / 2.0, 0.5)


#: [samples] the neighbourhood of a measurement's noise scale (``gnc.factor_scales``, the online GNSS
#: scale): 50 s of 1 Hz fixes, as the filters' innovation scale (docs/ekf.md)
SCALE_WINDOW = 50


@lru_cache(maxsize=256)
def significant_scale(dim: int, prob: float, window: int = SCALE_WINDOW) -> float:
    """The variance scale a window's median exceeds by chance with probability ``1 - prob`` on
    consistent data (``gnc.factor_scales``, the online GNSS scale): ``1 + z_prob sd``, ``sd`` the
    relative standard deviation of the median of ``window`` samples of ``chi2_dim`` (asymptotically
    ``1 / (2 f(m) sqrt(n))``, ``f`` the chi-square density at its median ``m``): 1.47 for 2-D fixes,
    50 of them and ``prob`` 0.99."""
    m = float(chi2_median(np.array([dim]))[0])
    f = math.exp((dim / 2 - 1) * math.log(m) - m / 2 - (dim / 2) * math.log(2.0) - float(gammaln(dim / 2)))
    return 1.0 + float(ndtri(prob)) / (2.0 * f * math.sqrt(window)) / m
