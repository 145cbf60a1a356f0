"""A stalled speed log's zero readings, censored: one rule for the graph (:mod:`graphnav.graph.water`) and the filters.

A paddle wheel stops turning below its stall speed ``s`` and the log reads exactly zero (psaros33 never reads
between 0 and 1.0 kn; 22-40 % of its readings are zero, drifting or moored in a current included). A zero
reading says only that the water passes the hull slower than ``s``: it is taken as the velocity through the
water ``R(yaw)^T (V - W) = (0, 0)`` (along and across the bow) with ``s / sqrt(3)`` (a uniform on ``(-s, s)``)
added in quadrature to both sigmas, the along-bow one the record's and the across-bow one the leeway at rest,
and without the speed log's scale (a reading of nothing has no scale) or the heading (the bow only orients the
sigmas). ``s`` is the option ``stall_speed`` (the graph's ``water.stall_speed``), else the smallest non-zero
reading so far (:class:`Stall`); before one, a zero reading says nothing and is not used. A log that reads fine
speeds (plaka: 0.005 m/s) gets nearly the plain measurement back. docs/smoother.md *Speed through water online*,
docs/ekf.md *Zero readings of a stalled log*. No gtsam here: the filters import it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray


class Stall:
    """A speed log's stall speed [m/s]: ``given`` (the option), else the smallest non-zero reading so far (``None``
    before one)."""

    def __init__(self, given: float | None) -> None:
        self.given, self.seen = given, math.inf

    def see(self, v: float) -> None:
        if v != 0.0:
            self.seen = min(self.seen, abs(v))

    @property
    def speed(self) -> float | None:
        if self.given is not None:
            return self.given
        return self.seen if math.isfinite(self.seen) else None


class ZeroReadings:
    """A speed log's readings as the graph and the filters take them (module docstring): :meth:`see` each reading
    in time order; ``stall_speed`` the option (``None``: the smallest non-zero reading so far)."""

    def __init__(self, stall_speed: float | None) -> None:
        if stall_speed is not None and not (math.isfinite(stall_speed) and stall_speed > 0.0):
            raise ValueError(f"stall_speed must be positive and finite or null, not {stall_speed!r}")
        self.stall = Stall(None if stall_speed is None else float(stall_speed))
        self.censored = self.unused = 0

    def see(self, v: float) -> str:
        """The reading ``v`` [m/s] taken: ``"plain"`` (non-zero: the filter's measurement as before), ``"censored"``
        (zero: the velocity through the water within :attr:`spread`) or ``"unused"`` (zero before any stall
        speed is known)."""
        self.stall.see(v)
        if v != 0.0:
            return "plain"
        if self.stall.speed is None:
            self.unused += 1
            return "unused"
        self.censored += 1
        return "censored"

    @property
    def spread(self) -> float:
        """[m/s] the stall's sigma ``s / sqrt(3)`` (0 before a stall speed is known)."""
        s = self.stall.speed
        return 0.0 if s is None else s / math.sqrt(3.0)

    def sigmas(self, sigma: float, leeway: float) -> tuple[float, float]:
        """[m/s] a censored reading's sigmas along and across the bow: the record's ``sigma`` and the ``leeway``
        at rest, each with :attr:`spread` in quadrature."""
        u = self.spread
        return math.hypot(sigma, u), math.hypot(leeway, u)

    def info(self) -> dict[str, Any]:
        """The run info's ``water_speed_censored`` when the log had a zero reading, else empty."""
        if not (self.censored or self.unused):
            return {}
        return {"water_speed_censored": {"stall_m_s": self.stall.speed, "censored": self.censored,
                                         "unused": self.unused}}


def through_water_rows(n: int, yaw: float, iv: int, ic: int) -> NDArray[np.float64]:
    """The ``2 x n`` Jacobian of the velocity through the water along and across the bow, ``R(yaw)^T (v - c)``, in a
    filter's ``n`` states with the velocity at ``iv:iv+2`` and the current at ``ic:ic+2``: a censored reading's
    measurement (linear in ``v`` and ``c``; the heading only orients it)."""
    c, s = math.cos(yaw), math.sin(yaw)
    H = np.zeros((2, n))
    H[0, iv], H[0, iv + 1], H[1, iv], H[1, iv + 1] = c, s, -s, c
    H[:, ic:ic + 2] = -H[:, iv:iv + 2]
    return H
