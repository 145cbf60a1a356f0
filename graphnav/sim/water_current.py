"""A tidal current for the simulated vessels: uniform in space, slowly varying in time.

Speed ``c(t) = speed + speed_amp sin(2 pi t / speed_period)`` and direction (where the water flows
to, CCW from east) ``d(t) = direction + dir_amp sin(2 pi t / dir_period)``, ``t`` from the start of
the run; the velocity is ``c(t) (cos d(t), sin d(t))``. A vessel's motion over ground is its motion
through the water plus this velocity. :meth:`TidalCurrent.to_meta` stores the model and a sampled
series in a log's ``meta["current"]``; :func:`current_from_meta` reads it back (linear interpolation
of the series: the error is below 1e-4 m/s at the 10 s spacing used).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray


@dataclass(frozen=True)
class TidalCurrent:
    """The current's model (SI units, radians; periods in seconds)."""

    speed: float = 0.4
    speed_amp: float = 0.1
    speed_period: float = 1200.0
    direction: float = math.radians(30.0)
    dir_amp: float = math.radians(25.0)
    dir_period: float = 1800.0

    def __post_init__(self) -> None:
        vals = asdict(self).values()
        if not all(math.isfinite(v) for v in vals):
            raise ValueError(f"the current's parameters must be finite: {self}")
        if self.speed < 0 or self.speed_amp < 0 or self.speed_amp > self.speed:
            raise ValueError(f"the current needs 0 <= speed_amp <= speed, got {self.speed}, {self.speed_amp}")
        if self.speed_period <= 0 or self.dir_period <= 0:
            raise ValueError("the current's periods must be > 0")

    @property
    def still(self) -> bool:
        """Still water (no current at all)."""
        return self.speed == 0.0

    def _phases(self, t: NDArray[np.float64]) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        ws, wd = 2 * math.pi / self.speed_period, 2 * math.pi / self.dir_period
        c = self.speed + self.speed_amp * np.sin(ws * t)
        d = self.direction + self.dir_amp * np.sin(wd * t)
        return c, d, self.speed_amp * ws * np.cos(ws * t), self.dir_amp * wd * np.cos(wd * t)

    def at(self, t: float) -> tuple[float, float]:
        """Current velocity (vx, vy) [m/s] at one time ``t`` [s from the start] (scalar, for loops)."""
        c = self.speed + self.speed_amp * math.sin(2 * math.pi * t / self.speed_period)
        d = self.direction + self.dir_amp * math.sin(2 * math.pi * t / self.dir_period)
        return c * math.cos(d), c * math.sin(d)

    def velocity(self, t: ArrayLike) -> NDArray[np.float64]:
        """Current velocity (N, 2) [m/s] at times ``t`` [s from the start]."""
        c, d, _, _ = self._phases(np.atleast_1d(np.asarray(t, dtype=float)))
        return np.column_stack([c * np.cos(d), c * np.sin(d)])

    def acceleration(self, t: ArrayLike) -> NDArray[np.float64]:
        """Its time derivative (N, 2) [m/s^2]: what an IMU on a vessel carried by it senses."""
        c, d, dc, dd = self._phases(np.atleast_1d(np.asarray(t, dtype=float)))
        return np.column_stack([dc * np.cos(d) - c * dd * np.sin(d), dc * np.sin(d) + c * dd * np.cos(d)])

    def to_meta(self, t_start: float, t_end: float, t0: float = 0.0, every: float = 10.0) -> dict[str, Any]:
        """``meta["current"]``: the model and the velocity every ``every`` s over [t_start, t_end]
        (run time), stamped in record time (``t0 +``)."""
        ts = np.arange(t_start, t_end, every)
        ts = np.append(ts, t_end) if len(ts) == 0 or ts[-1] < t_end else ts
        v = self.velocity(ts)
        mean = v.mean(axis=0) if len(v) else np.zeros(2)
        return {"model": "uniform in space; speed + speed_amp sin(2 pi t/speed_period), direction (flowing "
                         "to, CCW from east) + dir_amp sin(2 pi t/dir_period), t from the start",
                **asdict(self), "vx_mean": float(mean[0]), "vy_mean": float(mean[1]),
                "t": (ts + t0).tolist(), "vx": v[:, 0].tolist(), "vy": v[:, 1].tolist()}


def current_from_meta(meta: dict[str, Any], t: ArrayLike) -> NDArray[np.float64]:
    """The true current (N, 2) [m/s] at record times ``t`` from a log's ``meta["current"]`` (zero
    when the log has none)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    cur = meta.get("current") if isinstance(meta, dict) else None
    if not cur:
        return np.zeros((len(t), 2))
    ts = np.asarray(cur["t"], dtype=float)
    return np.column_stack([np.interp(t, ts, cur["vx"]), np.interp(t, ts, cur["vy"])])
