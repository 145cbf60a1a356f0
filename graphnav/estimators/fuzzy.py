"""The fuzzy adjustment coefficient of Liu, Liu & Bucknall (IEEE Access 2019), section IV.

Input: the degree of matching ``DoM = C_A / C_T`` (eq. 20) of one measurement channel. Three rules
(Table 1): DoM large -> alpha large, DoM ~ 1 -> alpha equal, DoM small -> alpha small. Input
membership functions eq. 22-24, output membership functions eq. 25-27 over the universe
``alpha in [0, al_max]``, Mamdani inference (rule strength clips its output set, the clipped sets are
combined by max) and centroid defuzzification (eq. 28). Pure numeric; no I/O.

:class:`FuzzyAlpha` tabulates ``alpha(DoM)`` once (it is a fixed scalar function) and interpolates,
so the per-step cost is one ``np.interp``; :func:`alpha_direct` is the reference evaluation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray


@dataclass(frozen=True)
class Thresholds:
    """Table 2: input (ep1, ep2, max) and output (al_ep1, al_ep2, al_max) thresholds."""

    ep1: float = 0.25
    ep2: float = 0.15
    max: float = 7.0
    al_ep1: float = 0.2
    al_ep2: float = 0.08
    al_max: float = 5.0


def _large(x: NDArray, e2: float, top: float) -> NDArray:
    """Eq. 22 / 25: 0 up to 1 + e2, a ramp ``(1 + e2 - x)/(e2 + 1 - top)`` to 1 at ``top``, then 1."""
    return np.where(x > top, 1.0, np.where(x > 1.0 + e2, (1.0 + e2 - x) / (e2 + 1.0 - top), 0.0))


def _equal(x: NDArray, e1: float, e2: float) -> NDArray:
    """Eq. 23 / 26: a trapezoid, 1 on (1 - e2, 1 + e2], zero outside [1 - e1, 1 + e1]."""
    up = (1.0 + e1 - x) / (e1 - e2)
    lo = (x + e1 - 1.0) / (e1 - e2)
    return np.where((x > 1.0 + e2) & (x <= 1.0 + e1), up,
                    np.where((x > 1.0 - e2) & (x <= 1.0 + e2), 1.0,
                             np.where((x >= 1.0 - e1) & (x <= 1.0 - e2), lo, 0.0)))


def _small(x: NDArray, e2: float) -> NDArray:
    """Eq. 24 / 27: ``x/(e2 - 1) + 1`` below ``1 - e2`` (1 at zero), else 0."""
    return np.where(x < 1.0 - e2, np.clip(x / (e2 - 1.0) + 1.0, 0.0, 1.0), 0.0)


def input_memberships(dom: ArrayLike, th: Thresholds = Thresholds()) -> NDArray:
    """``(..., 3)`` memberships (large, equal, small) of DoM, eq. 22-24."""
    d = np.asarray(dom, dtype=float)
    return np.stack([_large(d, th.ep2, th.max), _equal(d, th.ep1, th.ep2), _small(d, th.ep2)], axis=-1)


def output_memberships(alpha: ArrayLike, th: Thresholds = Thresholds()) -> NDArray:
    """``(..., 3)`` memberships (large, equal, small) of alpha, eq. 25-27."""
    a = np.asarray(alpha, dtype=float)
    return np.stack([_large(a, th.al_ep2, th.al_max), _equal(a, th.al_ep1, th.al_ep2), _small(a, th.al_ep2)],
                    axis=-1)


def universe(th: Thresholds = Thresholds(), n: int = 5001) -> NDArray:
    """The output universe ``[0, al_max]`` sampled for the centroid integral."""
    return np.linspace(0.0, th.al_max, n)


def alpha_direct(dom: ArrayLike, th: Thresholds = Thresholds(), n: int = 5001) -> NDArray:
    """Mamdani inference of Table 1 + centroid defuzzification (eq. 28), evaluated on a grid."""
    d = np.atleast_1d(np.asarray(dom, dtype=float))
    a = universe(th, n)
    out = output_memberships(a, th)  # (n, 3)
    w = input_memberships(d, th)  # (m, 3) rule strengths
    agg = np.max(np.minimum(w[:, None, :], out[None, :, :]), axis=2)  # (m, n)
    num = np.trapezoid(agg * a, a, axis=1)
    den = np.trapezoid(agg, a, axis=1)
    res = np.where(den > 0, num / np.where(den > 0, den, 1.0), 1.0)
    return res if np.ndim(dom) else res[:1].reshape(())


class FuzzyAlpha:
    """``alpha(DoM)`` tabulated on ``[0, max + 1]`` (constant beyond: only rule 1 fires there),
    densely around 1 where the rules overlap (interpolation error ~1e-4, see the tests)."""

    _cache: dict[Thresholds, tuple[NDArray, NDArray]] = {}

    def __init__(self, th: Thresholds = Thresholds()) -> None:
        self.th = th
        if th not in self._cache:
            lo, hi = 1.0 - th.ep1 - 0.05, 1.0 + th.ep1 + 0.05
            dom = np.unique(np.concatenate([np.linspace(0.0, lo, 71), np.linspace(lo, hi, 601),
                                            np.linspace(hi, th.max + 1.0, 135)]))
            self._cache[th] = (dom, alpha_direct(dom, th, n=2001))
        self.dom, self.alpha = self._cache[th]

    def __call__(self, dom: ArrayLike) -> NDArray:
        return np.interp(dom, self.dom, self.alpha)
