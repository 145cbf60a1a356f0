"""Chi-square quantiles without importing scipy.stats (~1 s and 40 MB at start-up): the same
expression scipy.stats' ``chi2.ppf`` evaluates, ``2 gammaincinv(dof / 2, p)``, cached per (p, dof).

The few values of ``scipy.special`` a run asks for (chi-square medians and quantiles of 1-6 degrees of
freedom at the usual probabilities, ``gammaln`` of half-integers, normal quantiles) are in :data:`KNOWN`,
exactly as ``scipy.special`` computes them (tests/graph/test_chi2.py checks each): with them a run need
not import ``scipy.special`` (~0.05 s of its functions' docstring parsing at import; and with the position
walk's own fit, no ``scipy.optimize`` either, ~0.1 s). Any other argument imports it."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: ``scipy.special.gammaincinv(a, p)`` for a = dof / 2 of 1-6 degrees of freedom (0.5, 1.0, ..., 3.0), per ``p``:
#: chi-square medians (p = 0.5) and quantiles (ppf = 2 gammaincinv), to the bit
GAMMAINCINV: dict[float, tuple[float, ...]] = {
    0.5: (0.227468211559786, 0.6931471805599455, 1.1829869421876689,
          1.6783469900166612, 2.175730095547763, 2.674060313723559),
    0.95: (1.920729410347062, 2.9957322735539895, 3.9073639516255896,
           4.743864518390577, 5.535248846758176, 6.295793621871988),
    0.99: (3.3174483005106072, 4.60517018598809, 5.6724333650721865,
           6.638352067993811, 7.543136234694495, 8.405946914885464),
    0.999: (5.413783085331366, 6.907755278982137, 8.133118098119064,
            9.233413476451585, 10.257502826216436, 11.228872242412661),
}
#: ``scipy.special.gammaln`` of half-integers 0.5-3.0 and ``ndtri`` at the usual probabilities, to the bit
GAMMALN = (0.5723649429247, 0.0, -0.12078223763524526, 0.0, 0.2846828704729192, 0.6931471805599453)
NDTRI = {0.95: 1.6448536269514722, 0.99: 2.3263478740408408, 0.999: 3.090232306167813}
#: ``scipy.special`` at these arguments, to the bit: ``(function, *arguments) -> value``
KNOWN: dict[tuple[str, float] | tuple[str, float, float], float] = {
    **{("gammaincinv", (i + 1) / 2, p): v for p, row in GAMMAINCINV.items() for i, v in enumerate(row)},
    **{("gammaln", (i + 1) / 2): v for i, v in enumerate(GAMMALN)},
    **{("ndtri", p): v for p, v in NDTRI.items()},
}


def special(name: str, *args: float) -> float:
    """``scipy.special.<name>(*args)`` of scalars: :data:`KNOWN`'s value, else scipy's (imported then)."""
    v = KNOWN.get((name, *(float(a) for a in args)))
    if v is None:
        from scipy import special as sc

        v = float(getattr(sc, name)(*args))
    return v


def ndtri(p: float) -> float:
    """``scipy.special.ndtri(p)``: the standard normal's ``p`` quantile."""
    return special("ndtri", p)


@lru_cache(maxsize=256)
def chi2_ppf(p: float, dof: int) -> float:
    """``scipy.stats.chi2.ppf(p, dof)``: the ``p`` quantile of a chi-square with ``dof`` degrees of freedom."""
    return float(2.0 * special("gammaincinv", dof / 2.0, p))


def chi2_median(dof: ArrayLike) -> NDArray[np.float64]:
    """``scipy.stats.chi2.median(dof)``, elementwise."""
    half = np.asarray(dof, dtype=float) / 2.0
    u, inv = np.unique(half, return_inverse=True)
    return 2.0 * np.array([special("gammaincinv", x, 0.5) for x in u.tolist()])[inv].reshape(half.shape)


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
    f = math.exp((dim / 2 - 1) * math.log(m) - m / 2 - (dim / 2) * math.log(2.0) - special("gammaln", dim / 2))
    return 1.0 + ndtri(prob) / (2.0 * f * math.sqrt(window)) / m
