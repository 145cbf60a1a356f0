"""The odometry between keyframes: samples buffered as they arrive (a little late ones in their
place), composed over any interval (beacon paper eq. 3-5, :func:`graphnav.geometry.increment`)."""

from __future__ import annotations

import bisect
import math

import gtsam
import numpy as np
from numpy.typing import NDArray

from ..geometry import increment
from ..log import Odometry
from .smoother_config import OdometryConfig


class OdometryBuffer:
    """Odometry samples ``t, v, w, sigma_v, sigma_w, density`` (``density`` 1: the sigmas are the
    configuration's noise densities, the record gave none)."""

    def __init__(self, cfg: OdometryConfig) -> None:
        self.cfg = cfg
        self.t: list[float] = []
        self.rows: list[tuple[float, float, float, float, float, float]] = []

    def __bool__(self) -> bool:
        return bool(self.t)

    def add(self, r: Odometry) -> bool:
        """Take one sample; whether its sigmas came from the configuration."""
        cfg = self.cfg
        sv, sw = r.sigma_v, r.sigma_w
        defaulted = not (math.isfinite(sv) and math.isfinite(sw))
        if not defaulted:
            row = (r.t, r.v, r.w, sv, sw, 0.0)
        else:  # the defaults: noise densities, relative to the speed and turn rate plus a floor
            w_floor = math.radians(cfg.sigma_w_deg)
            row = (r.t, r.v, r.w,
                   sv if math.isfinite(sv) else math.hypot(cfg.sigma_v, cfg.sigma_v_rel * r.v),
                   sw if math.isfinite(sw) else math.hypot(w_floor, cfg.sigma_w_rel * r.w), 1.0)
        if self.t and r.t == self.t[-1]:
            self.rows[-1] = row  # the newest sample at a time holds (as searchsorted right does)
        elif self.t and r.t < self.t[-1]:  # a little late: in its place
            i = bisect.bisect_left(self.t, r.t)
            if self.t[i] == r.t:
                self.rows[i] = row
            else:
                self.t.insert(i, r.t)
                self.rows.insert(i, row)
        else:
            self.t.append(r.t)
            self.rows.append(row)
        return defaulted

    def prune(self, t: float) -> None:
        """Drop samples no later interval can need (all before the last one at or before ``t``)."""
        i = bisect.bisect_right(self.t, t) - 1
        if i > 256:
            del self.t[:i]
            del self.rows[:i]

    def between(self, t0: float, t1: float) -> tuple[gtsam.Pose2, NDArray[np.float64]] | None:
        """The odometry (zero-order hold of the latest sample) composed over ``[t0, t1]``; ``None``
        before the first sample."""
        if not self.t or (self.t[0] > t0 + 1e-9 and self.t[0] >= t1):
            return None
        lo = max(bisect.bisect_right(self.t, max(t0, self.t[0])) - 1, 0)
        hi = bisect.bisect_right(self.t, t1)
        samples = np.array(self.rows[lo:max(hi, lo + 1)], dtype=float)
        inc = increment(samples, max(t0, self.t[0]), t1, lateral=self.cfg.lateral)
        if inc is None:
            return None
        return gtsam.Pose2(*inc[0]), inc[1]
