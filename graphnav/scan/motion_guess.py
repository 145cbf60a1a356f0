"""Initial guesses (and bridging priors) for consecutive scan matches.

``MotionGuess`` keeps the last GOOD match only — a flagged one (``ok`` False) is never fed
forward, so a bad match cannot become the next pair's guess and run away. Modes:

* ``cv``: constant velocity, the last good increment scaled to this pair's time step, when that
  match was the previous pair's; otherwise (after a flagged match) the odometry increment when
  the log has odometry, else the last good increment however old, else zero;
* ``odometry``: the odometry increment (:func:`graphnav.geometry.increment`), else the IMU's
  prediction when the log has an IMU, else as ``cv``;
* ``imu``: the IMU's prediction (:class:`graphnav.scan.imu_guess.ImuGuess`: gyro yaw, strapdown
  velocity corrected by every match) with its covariance, else as ``odometry``;
* ``zero``: identity.

:meth:`MotionGuess.bridge` gives what to chain instead of a flagged match: the odometry increment
with its covariance, else the IMU's prediction with its covariance, else the constant-velocity
guess with a wide covariance.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..geometry import increment
from .imu_guess import ImuGuess
from .weighted_icp import GUESS_SIGMA, MatchResult

INITS = ("cv", "zero", "odometry", "imu")
# 1-sigma of a constant-velocity bridge (no odometry): x, y [m], yaw [rad]; the matcher's guess
# without a covariance has the same (graphnav.scan.weighted_icp.GUESS_SIGMA)
CV_BRIDGE_SIGMA = GUESS_SIGMA


class MotionGuess:
    """Initial guess of the motion between scans at ``t0`` and ``t1`` (``guess``), fed with each
    match (``update``); ``odometry`` is an (N, 5) array from
    :func:`graphnav.log.odometry_samples` (or ``None``)."""

    def __init__(self, mode: str = "cv", odometry: NDArray[np.float64] | None = None,
                 imu: ImuGuess | None = None) -> None:
        if mode not in INITS:
            raise ValueError(f"unknown init {mode!r}; known: {', '.join(INITS)}")
        self.mode = mode
        self.odometry = odometry if odometry is not None and len(odometry) else None
        self.imu = imu if imu else None
        self._last: tuple[NDArray[np.float64], float, float] | None = None  # increment, dt, end time
        self.source = "none"  # where the last guess came from: cv, odometry, stale-cv, none
        self.cov: NDArray[np.float64] | None = None  # the last guess's covariance (odometry, IMU; else None)

    def _cv(self, t0: float, t1: float, fresh_only: bool) -> NDArray[np.float64] | None:
        if self._last is None or self._last[1] <= 0:
            return None
        inc, dt, t_end = self._last
        if fresh_only and abs(t_end - t0) > 1e-6:
            return None
        return inc * ((t1 - t0) / dt)

    def _odo(self, t0: float, t1: float) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
        return None if self.odometry is None else increment(self.odometry, t0, t1)

    def _odo_guess(self, t0: float, t1: float) -> NDArray[np.float64] | None:
        odo = self._odo(t0, t1)
        if odo is None:
            return None
        self.cov = odo[1]
        return odo[0]

    def guess(self, t0: float, t1: float) -> NDArray[np.float64] | None:
        """Initial ``(dx, dy, dyaw)`` for the match of the scan at ``t1`` to the scan at ``t0``
        (``None``: identity); :attr:`cov` is then its covariance when it came from the odometry."""
        self.source = "none"
        self.cov = None
        if self.mode == "zero":
            return None
        fresh = ("cv", lambda: self._cv(t0, t1, fresh_only=True))
        odo = ("odometry", lambda: self._odo_guess(t0, t1))
        imu = ("imu", lambda: self._imu_guess(t0, t1))
        stale = ("stale-cv", lambda: self._cv(t0, t1, fresh_only=False))
        order = {"odometry": (odo, imu, fresh, stale), "imu": (imu, odo, fresh, stale)}.get(self.mode,
                                                                                           (fresh, odo, stale))
        for source, make in order:
            g = make()
            if g is not None:
                self.source = source
                return g
        return None

    def _imu_guess(self, t0: float, t1: float) -> NDArray[np.float64] | None:
        if self.imu is None:
            return None
        inc, self.cov = self.imu.guess(t0, t1)
        return inc

    def update(self, result: MatchResult, t0: float, t1: float, *, imu: bool = True) -> None:
        """Feed the match of the pair ``(t0, t1)``; only a good one (``ok``) is remembered. The IMU's
        velocity is corrected by a good match, and by a degenerate one across its weak directions
        (its covariance inflated along them), and carried to ``t1`` in any case: by the match's own
        estimate and covariance (:meth:`~graphnav.scan.weighted_icp.MatchResult.own`), not where the guess
        replaced it; ``imu`` False: the caller updates the IMU's state itself)."""
        if self.imu is not None and imu:
            usable = result.ok or bool(result.quality.get("inflated"))
            if usable:  # the match's own information, where its geometry sees
                self.imu.update(t0, t1, *result.own())
            else:
                self.imu.update(t0, t1, None, None)
        if result.ok:
            self._last = (np.asarray(result.pose, dtype=float).copy(), t1 - t0, t1)

    def bridge(self, t0: float, t1: float) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
        """Increment, covariance and source (``odometry``, ``imu`` or ``cv``) to chain instead of a
        flagged match: the odometry increment when the log has odometry, else the IMU's prediction,
        else the constant-velocity guess with the wide covariance :data:`CV_BRIDGE_SIGMA`."""
        odo = self._odo(t0, t1)
        if odo is not None:
            return odo[0], odo[1], "odometry"
        if self.imu is not None:  # the prediction made before the match (update has moved on to t1)
            last = self.imu.last
            inc, cov = (last[2], last[3]) if last is not None and last[:2] == (t0, t1) else self.imu.guess(t0, t1)
            return inc, cov, "imu"
        g = self._cv(t0, t1, fresh_only=False)
        return (np.zeros(3) if g is None else g), np.diag(np.square(CV_BRIDGE_SIGMA)), "cv"
