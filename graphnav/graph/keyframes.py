"""Keyframe policy: which times get a pose variable, and which keyframe each measurement joins.

* Keyframes are the scan times when the log has scans (one pose per scan, ICP between
  consecutive scans; ``scan_stride`` N keeps every N-th scan, to bound the matching cost),
  otherwise a fixed ``period`` [s] (default 0.5 s) from the first record.
* Every other measurement (GNSS, heading, beacon) is attached to the keyframe **nearest in time**.
  The error this introduces is bounded by the motion over half the largest keyframe gap
  ``dt_max``: position ``<= v_max * dt_max / 2`` and yaw ``<= |ROT|_max * dt_max / 2``
  (e.g. 1.5 m/s and 5 Hz scans: <= 0.15 m, far below a 3 m GNSS sigma, and zero-mean when
  fixes fall at random phases). :func:`attachment_error_bound` computes it for a log.
* Online causality: a measurement stamped after its keyframe is only added to the graph at the
  next keyframe's update (:func:`schedule`), so the online estimate at ``t_k`` never uses data
  from after ``t_k``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..log import NavLog

DEFAULT_PERIOD = 0.5


def keyframe_times(log: NavLog, period: float | None = None, scan_stride: int = 1) -> NDArray[np.float64]:
    """Times of the pose variables: every ``scan_stride``-th scan (``period=None`` and scans
    present) or a fixed grid."""
    if period is None:
        scans = log.of("scan")
        if scans:
            if scan_stride < 1:
                raise ValueError(f"scan_stride must be >= 1, got {scan_stride}")
            return np.array([s.t for s in scans[::scan_stride]])
        period = DEFAULT_PERIOD
    if period <= 0:
        raise ValueError(f"keyframe period must be > 0, got {period}")
    t0, t1 = log.t0, log.t1
    if t0 is None:
        return np.zeros(0)
    n = int(np.floor((t1 - t0) / period + 1e-9)) + 1
    return t0 + period * np.arange(n)


def nearest(kf_t: NDArray[np.float64], t: ArrayLike) -> NDArray[np.int64]:
    """Index of the keyframe nearest to each time in ``t`` (ties go to the earlier keyframe)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    j = np.clip(np.searchsorted(kf_t, t), 1, max(len(kf_t) - 1, 1))
    if len(kf_t) == 1:
        return np.zeros(len(t), dtype=np.int64)
    left = kf_t[j - 1]
    right = kf_t[j]
    return np.where(t - left <= right - t, j - 1, j).astype(np.int64)


def schedule(kf_t: NDArray[np.float64], t: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """``(attach, add)``: the keyframe each measurement joins and the update step that adds it
    (the first keyframe at or after the measurement's time, never before ``attach``)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    a = nearest(kf_t, t)
    first_after = np.minimum(np.searchsorted(kf_t, t - 1e-9), len(kf_t) - 1)
    return a, np.maximum(a, first_after)


def attachment_error_bound(
    kf_t: NDArray[np.float64], truth_xyyaw: ArrayLike | None = None, truth_t: ArrayLike | None = None
) -> dict[str, float]:
    """The policy's worst-case time offset [s] and, given a reference track, the implied bounds
    on position [m] and yaw [rad] (max speed / yaw rate times half the largest gap)."""
    gap = float(np.max(np.diff(kf_t))) if len(kf_t) > 1 else 0.0
    out = {"max_gap_s": gap, "max_offset_s": gap / 2}
    if truth_xyyaw is not None and truth_t is not None and len(truth_t) > 1:
        p = np.asarray(truth_xyyaw, dtype=float)
        dt = np.diff(np.asarray(truth_t, dtype=float))
        ok = dt > 0
        v = np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))[ok] / dt[ok]
        w = np.abs(np.diff(np.unwrap(p[:, 2])))[ok] / dt[ok]
        out["position_bound_m"] = float(v.max() * gap / 2)
        out["yaw_bound_rad"] = float(w.max() * gap / 2)
    return out
