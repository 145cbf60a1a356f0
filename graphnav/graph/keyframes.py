"""Keyframe policy: which times get a pose variable, and which keyframe each measurement joins.

* Keyframes are the scan times when the log has scans (one pose per scan, ICP between
  consecutive scans; ``scan_stride`` N keeps every N-th scan, to bound the matching cost),
  otherwise a fixed ``period`` [s] (default 0.5 s) from the first record.
* In the IMU graph a scan becomes a keyframe by the motion since the newest one; an IMU slower than
  the scans (or the grid) makes it wait for the scan nearest one of its records (:meth:`Keyframes.at_imu_record`).
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

import bisect
import math
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..log import NavLog, Record
from .order_stats import median
from .smoother_config import KeyframeConfig

DEFAULT_PERIOD = 0.5
EPS = 1e-9  # [s] times closer than this are equal


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


class Keyframes:
    """The keyframes placed online and the measurements waiting for theirs (the builder's policy,
    as :func:`keyframe_times` and :func:`schedule` on a whole log).

    One keyframe per scan (every ``scan_stride``-th; with the IMU's keyframe rule, see
    :meth:`scan_is_keyframe`) once scans arrive, else a ``period`` grid from the first record, whose
    slots inside a gap of more than ``grid_gap`` seconds without records are skipped. A measurement
    between two keyframes waits for the later one, joins the nearer of the two (ties: the earlier)
    and is added with the later keyframe's batch; a keyframe is ready once a later record arrived.
    """

    def __init__(self, cfg: KeyframeConfig, scans: bool | None) -> None:
        self.cfg = cfg
        # keyframe policy: "grid" (fixed period) or "scan"; with keyframe_period set always the grid
        self.grid_only = cfg.period is not None
        self.period = cfg.period if cfg.period is not None else DEFAULT_PERIOD
        self.mode = "scan" if (scans and not self.grid_only) else "grid"
        self.t: list[float] = []  # the keyframes' times
        self.stepped = 0  # keyframes [0, stepped) have their batch
        self.grid_t0: float | None = None
        self.grid_i = 0  # the next grid slot
        self.scans: dict[int, Record] = {}  # keyframe -> its scan or cloud (until the next has its batch)
        self.n_scans = 0
        self.imu: Any = None  # the IMU chain (graphnav.graph.imu_chain.ImuChain) of the IMU graph: set by the builder
        self._last_scan_t: float | None = None
        self._scan_gaps: deque[float] = deque(maxlen=16)
        self.lidar_kind: str | None = None  # "scan" or "cloud": the first LiDAR record's kind drives the keyframes
        self.pending: list[Record] = []  # measurements after the newest keyframe
        self.due: dict[int, list[tuple[int, Record]]] = {}  # step -> (attach, record)
        self.late: list[tuple[int, Record]] = []  # after the last keyframe's batch (finish)
        self.t_last: float | None = None
        self.t_data: float | None = None
        self.finished = False

    def __len__(self) -> int:
        return len(self.t)

    def start(self, t0: float) -> None:
        """The grid starts at the first record, whatever it is (as :func:`keyframe_times`)."""
        self.grid_t0 = t0

    def behind(self, rec: Record) -> bool:
        """Whether ``rec`` is late: its keyframe's batch is out already (a scan: it is older than the
        newest keyframe)."""
        t = rec.t
        behind_batch = self.stepped > 0 and t < self.t[self.stepped - 1] - EPS
        behind_scan = rec.kind == "scan" and self.mode == "scan" and bool(self.t) and t < self.t[-1] - EPS
        return behind_batch or behind_scan

    def quiet(self, t_lo: float, t_hi: float, t_data: float | None) -> bool:
        """Whether IMU and truth records from ``t_lo`` to ``t_hi`` (the newest with data at ``t_data``; truth is a
        reference) can neither make, complete nor miss a keyframe: the keyframes at the scans, none waiting for
        its batch, none of them late. If so their times are clocked (as :meth:`clock` of each); ``False``:
        nothing done."""
        if self.mode != "scan" or self.finished or self.stepped < len(self.t) or (
                self.stepped > 0 and t_lo < self.t[self.stepped - 1] - EPS):
            return False
        if t_data is not None:
            self.t_data = t_data if self.t_data is None else max(self.t_data, t_data)
        self.t_last = t_hi if self.t_last is None else max(self.t_last, t_hi)
        return True

    def clock(self, rec: Record) -> None:
        """The newest record's time; on the grid, the keyframes it completes."""
        t, kind = rec.t, rec.kind
        prev_t = self.t_data  # the last record with data (truth is a reference, not an input)
        if kind != "truth":
            self.t_data = t if self.t_data is None else max(self.t_data, t)
        self.t_last = t if self.t_last is None else max(self.t_last, t)
        if self.mode != "grid":
            return
        if self.grid_t0 is None:
            self.grid_t0 = t
        gap = prev_t is not None and kind != "truth" and t - prev_t > self.cfg.grid_gap
        while (kind != "truth" or prev_t is None or t - prev_t <= self.cfg.grid_gap) and (
                ts := self.grid_t0 + self.period * self.grid_i) <= t + EPS * self.period:
            # no record for grid_gap seconds: the slots more than a period from both sides are skipped,
            # by index arithmetic (a jump of days must not walk its slots one by one)
            if gap and prev_t + self.period + EPS < ts < t - self.period - EPS:
                self.grid_i = max(self.grid_i + 1, math.ceil((t - self.period - EPS - self.grid_t0) / self.period))
                continue
            self.grid_i += 1
            if self.imu is not None and self.t and not self.at_imu_record(_rates(self.imu), ts, self.period):
                continue  # a slow IMU: the slots between its records are skipped
            self.add(ts, None)

    def is_lidar(self, kind: str) -> bool:
        """Whether a LiDAR record of ``kind`` drives the keyframes: the first LiDAR record's kind does (a
        log with 2D scans and 3D clouds)."""
        if self.lidar_kind is None:
            self.lidar_kind = kind
        return kind == self.lidar_kind

    def to_scans(self) -> bool:
        """The first scan: one keyframe per scan from now on (unless the grid is asked for); whether the
        policy changed."""
        if self.mode == "grid" and not self.grid_only:
            self.mode = "scan"
            return True
        return False

    def scan_is_keyframe(self, t: float, speed: Callable[[], float], imu: Any) -> bool:
        """Every ``scan_stride``-th scan; with an IMU (``keyframe_motion``), only once the vessel has
        moved ``keyframe_distance`` (at the newest interval's ``speed``) or turned ``keyframe_angle_deg``
        (the gyro) since the newest keyframe, or ``keyframe_max_dt`` has passed."""
        cfg = self.cfg
        self._scan_gap(t)
        if self.n_scans % cfg.scan_stride:
            return False
        use = cfg.motion if cfg.motion is not None else bool(imu)
        if not use or not self.t or not imu:
            return True
        dt = t - self.t[-1]
        due = (dt >= cfg.max_dt - EPS or speed() * dt >= cfg.distance
               or imu.rotation(self.t[-1], t) >= math.radians(cfg.angle_deg))
        if not due:
            return False
        scan_dt = self._scan_period()
        # an IMU slower than the LiDAR: the keyframe waits (at most one IMU period) for the scan nearest a
        # record's time
        if scan_dt is None or dt >= cfg.max_dt + self._imu_period(imu) - EPS:
            return True
        return self.at_imu_record(imu, t, scan_dt * cfg.scan_stride)

    @staticmethod
    def _imu_period(imu: Any) -> float:
        return imu.period() if imu and len(imu.t) >= 2 else 0.0

    def at_imu_record(self, imu: Any, t: float, spacing: float) -> bool:
        """Whether a keyframe at ``t`` (candidates ``spacing`` seconds apart) keeps the IMU's records whole:
        always, unless the IMU is slower than the candidates (1.5x), when ``t`` must be the candidate nearest
        a record's time (the newest record's, or a period on from it). Each record is the mean over its
        interval: its preintegration is exact over whole records, and over a share of one only to the
        rate's variation within it (:meth:`~graphnav.graph.imu_chain.ImuChain.hold_variance`)."""
        period = self._imu_period(imu)
        if period <= 1.5 * spacing:
            return True
        tn = imu.t[-1]
        return abs(t - (tn + round((t - tn) / period) * period)) <= 0.5 * spacing + EPS

    def _scan_gap(self, t: float) -> None:
        """A scan at ``t``: the interval since the previous one (:meth:`_scan_period`)."""
        if self._last_scan_t is not None and t > self._last_scan_t:
            self._scan_gaps.append(t - self._last_scan_t)
        self._last_scan_t = t

    def _scan_period(self) -> float | None:
        """The median interval of the last scans, ``None`` before two (asked only where a keyframe is due)."""
        return median(self._scan_gaps) if self._scan_gaps else None

    def add(self, t: float, scan: Record | None) -> None:
        """A new keyframe at ``t`` (with its scan); the pending measurements join it or the previous one."""
        k = len(self.t)
        self.t.append(t)
        if scan is not None:
            self.scans[k] = scan
        for r in self.pending:  # they all lie in (t_{k-1}, t_k]: join the nearer keyframe, added now
            a = k - 1 if k > 0 and r.t - self.t[k - 1] <= t - r.t else k
            self.due.setdefault(k, []).append((a, r))
        self.pending = []

    def attach(self, rec: Record) -> bool:
        """A measurement: due with the first keyframe at or after it (joining the nearer), or pending
        until the next keyframe; ``False`` when that keyframe's batch is out already (late)."""
        t = rec.t
        if self.t and t <= self.t[-1] + EPS:  # at (or, late, before) the newest keyframe
            j = bisect.bisect_left(self.t, t - EPS)  # the first keyframe at or after it: added there
            if j < self.stepped:
                return False
            a = j - 1 if j > 0 and t - self.t[j - 1] <= self.t[j] - t else j
            self.due.setdefault(j, []).append((a, rec))
        else:
            self.pending.append(rec)
        return True

    def finish(self) -> None:
        """End of the records: measurements after the last keyframe join it (in a batch of their own,
        :meth:`take_late`, when its batch is already out)."""
        self.finished = True
        if not self.t:
            return
        last = len(self.t) - 1
        for r in self.pending:
            if self.stepped > last:
                self.late.append((last, r))
            else:
                self.due.setdefault(last, []).append((last, r))
        self.pending = []

    def ready(self, imu_until: float | None) -> list[int]:
        """Keyframes whose batch can be built now (in order): every one after :meth:`finish`, else
        those before the newest record (and, ``imu_until``, the newest IMU sample: the one closing a
        keyframe's interval is awaited)."""
        if self.finished:
            return list(range(self.stepped, len(self.t)))
        if self.t_last is None:
            return []
        t_ready = self.t_last - EPS
        if imu_until is not None:
            t_ready = min(t_ready, imu_until + EPS)
        return [k for k in range(self.stepped, len(self.t)) if self.t[k] < t_ready]

    def take(self, k: int) -> list[tuple[int, Record]]:
        """Keyframe ``k``'s measurements (``(attach, record)``); it must be the next one in order."""
        if k != self.stepped:
            raise ValueError(f"keyframe {k} stepped out of order (next is {self.stepped})")
        return self.due.pop(k, [])

    def done(self, k: int) -> None:
        """Keyframe ``k`` has its batch: ``k-1``'s scan is no longer needed."""
        self.stepped = k + 1
        self.scans.pop(k - 1, None)

    def first_after(self, t: float) -> int:
        """The first keyframe at or after ``t``."""
        return bisect.bisect_left(self.t, t)

    def take_late(self) -> list[tuple[int, Record]]:
        late, self.late = self.late, []
        return late


def _rates(imu: Any) -> Any:
    """The records whose intervals the grid keeps whole: the IMU's, else (the vessel model) its ROT's."""
    return imu if imu or getattr(imu, "rot", None) is None else imu.rot
