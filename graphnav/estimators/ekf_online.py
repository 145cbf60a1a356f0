"""The ``ekf`` estimator (:class:`Ekf`: the batch :func:`~graphnav.estimators.ekf.run_ekf` and its live
form) and that live form, :class:`EkfOnline`: the :class:`graphnav.result.OnlineEstimator` adapter that
``graphnav live --estimator ekf`` runs.

It is the batch ``ekf`` (:func:`graphnav.estimators.ekf.run_ekf`) step for step: the same
:class:`~graphnav.estimators.ekf.EkfStepper`, initialised by the same rule
(:func:`~graphnav.estimators.ekf.initial_state`) from the records seen so far. Records are held
until an epoch (a record time) is complete and that rule has its inputs (a ``pose_prior``, or a
GNSS fix and a heading -- and an odometry speed with ``speed=True``), or for ``init_wait`` seconds
after the first fix, then replayed; the first estimate is that of the record that completed the
epoch. So on a log whose first epoch has those inputs, every later estimate is bit-identical to
the batch filter's (``tests/online/test_ekf_online.py``).
"""

from __future__ import annotations

import math
from collections import Counter, deque
from typing import Any

import numpy as np

from ..geometry import wrap_angle
from ..log import Gnss, GnssVelocity, Heading, Odometry, PosePrior, Record
from ..result import Estimate
from .base import BatchEstimator
from .ekf import IMU_DEFAULTS, EkfConfig, EkfStepper, _inputs, _unmet, initial_state, run_ekf


class EkfOnline:
    """EKF behind ``add(record) -> Estimate | None``. ``emit``: ``"fix"`` (default) yields an
    estimate per GNSS fix, and per used record while no fix came for ``outage_s`` [s];
    ``"all"`` one per used record. The other options are :func:`run_ekf`'s (``motion`` is
    ``"odometry"``, ``"imu"``, ``"icp"`` or ``"vessel"``; there is no ``"auto"`` without the whole log; with
    ``"imu"`` or ``"vessel"`` the IMU (vessel) motion's options, :data:`graphnav.estimators.ekf.IMU_DEFAULTS`,
    the initial velocity the first held GNSS velocity when ``v0`` is not given)."""

    def __init__(self, *, motion: str = "odometry", speed: bool = False, emit: str = "fix", outage_s: float = 1.5,
                 init_wait: float = 2.0, **ekf_options: Any) -> None:
        if emit not in ("fix", "all"):
            raise ValueError(f"emit must be 'fix' or 'all', not {emit!r}")
        self.motion, self.speed, self.emit = motion, speed, emit
        self.outage_s, self.init_wait = outage_s, init_wait
        imu = {k: ekf_options.pop(k) for k in list(ekf_options) if k in IMU_DEFAULTS}
        self.options: dict[str, Any] = {"keep": 10_000, **ekf_options}
        if imu:
            if motion not in ("imu", "vessel"):
                raise ValueError(f"ekf option(s) {sorted(imu)} need motion='imu' or 'vessel'")
            self.options["imu"] = imu
        EkfStepper(np.zeros(3), np.eye(3), motion=motion, **self.options)  # validate the options now
        self.stepper: EkfStepper | None = None
        self.pending: deque[Record] = deque(maxlen=10_000)
        self.held: Counter[type] = Counter()  # kinds of the held records
        self.t_first_fix: float | None = None  # time of the first held fix or pose prior
        self.anchor: str | None = None
        self.last_fix_t = -math.inf
        self.last_emit_t = -math.inf
        self.counts = {"gnss": 0, "heading": 0, "odometry": 0, "scan": 0, "imu": 0, "gnss_velocity": 0,
                       "water_speed": 0, "late": 0, "other": 0, "dropped_before_start": 0}

    # -- initialisation
    def _hold(self, record: Record) -> None:
        """Keep a record until the filter starts (the newest ``pending.maxlen``; the held kinds and
        the first held fix are kept up to date, so :meth:`_ready` is O(1))."""
        if len(self.pending) == self.pending.maxlen:  # no fix for so many records: keep the newest
            old = self.pending.popleft()
            self.counts["dropped_before_start"] += 1
            self.held[type(old)] -= 1
            if old.t == self.t_first_fix and isinstance(old, Gnss | PosePrior):
                self.t_first_fix = next((r.t for r in self.pending if isinstance(r, Gnss | PosePrior)), None)
        self.pending.append(record)
        self.held[type(record)] += 1
        if self.t_first_fix is None and isinstance(record, Gnss | PosePrior):
            self.t_first_fix = record.t

    def _ready(self, t_now: float) -> bool:
        """Whether the held records (all older than ``t_now``) are enough to start."""
        if self.t_first_fix is None:
            return False
        if t_now - self.t_first_fix >= self.init_wait:
            return True
        return (self.held[PosePrior] > 0 or self.held[Heading] > 0) and (not self.speed or self.held[Odometry] > 0)

    def _start(self) -> None:
        x0, P0, self.anchor = initial_state(self.pending, self.speed)
        options = self.options
        if self.motion in ("imu", "vessel") and "v0" not in options.get("imu", {}):
            gv = next((r for r in self.pending if isinstance(r, GnssVelocity)), None)
            if gv is not None and gv.t - self.pending[0].t <= 1.0:  # as run_ekf's rule
                sv = gv.sigma if math.isfinite(gv.sigma) else IMU_DEFAULTS["sigma_gnss_velocity"]
                options = {**options, "imu": {**options.get("imu", {}), "v0": (gv.vx, gv.vy, 3.0 * sv)}}
        self.stepper = st = EkfStepper(x0, P0, motion=self.motion, **options)
        for r in self.pending:
            if st.step(r) and isinstance(r, Gnss) and st.use_gnss:  # as in add: an unused fix is none
                self.last_fix_t = r.t
        self.pending.clear()
        self.held.clear()
        self.t_first_fix = None

    # -- the interface
    def add(self, record: Record) -> Estimate | None:
        kind = record.kind if record.kind in self.counts else "other"
        if self.stepper is None:
            if not (self.pending and record.t > self.pending[-1].t + 1e-9 and self._ready(record.t)):
                self.counts[kind] += 1
                self._hold(record)
                return None
            self._start()  # the first epoch is complete: start, then take this record
        st = self.stepper
        assert st is not None
        if st.t is not None and record.t < st.t - 1e-9:
            self.counts["late"] += 1
            return None
        self.counts[kind] += 1
        if not st.step(record):
            return None
        if isinstance(record, Gnss) and st.use_gnss:
            self.last_fix_t = record.t
            return self._estimate()
        if self.emit == "all" or (record.t - self.last_fix_t > self.outage_s and record.t > self.last_emit_t):
            return self._estimate()
        return None

    def _estimate(self) -> Estimate:
        st = self.stepper
        assert st is not None and st.t is not None
        f = st.f
        self.last_emit_t = st.t
        if self.motion in ("imu", "vessel"):  # velocity over ground from the state, rate of turn from the IMU
            vx, vy = float(f.x[3]), float(f.x[4])
            m = st.imu_u
            ib = getattr(f, "ib", None)
            w = None if m is None else m.wz - (float(f.x[ib + 2]) if ib is not None else 0.0)
            return Estimate(st.t, f.x[:3].copy(), f.P[:3, :3].copy(), math.hypot(vx, vy),
                            float(wrap_angle(math.atan2(vy, vx))), w)
        u = st.u
        v = float(f.x[3]) if f.has_speed else (u.v if u is not None else None)
        w = u.w if u is not None else None
        cog = None if v is None else float(f.x[2] if v >= 0 else math.remainder(f.x[2] + math.pi, 2 * math.pi))
        return Estimate(st.t, f.x[:3].copy(), f.P[:3, :3].copy(), None if v is None else abs(v), cog, w)

    def info(self) -> dict[str, Any]:
        st = self.stepper
        s = np.asarray(st.step_ms if st is not None else [])
        out: dict[str, Any] = {"estimator": "ekf-online", "motion": self.motion, "anchor": self.anchor,
                               **self.counts, "step_ms_median": float(np.median(s)) if s.size else None,
                               "step_ms_p99": float(np.percentile(s, 99)) if s.size else None}
        if st is not None:
            out.update(st.f.counts, icp_failed=st.icp_failed)
        return out


class Ekf(BatchEstimator):
    """The EKF (:func:`run_ekf`); live: :class:`graphnav.estimators.ekf_online.EkfOnline`."""

    description = ("EKF: odometry, IMU (INS/GNSS, bias + current states), ICP or vessel (constant velocity) motion; "
                   "gated GNSS (+velocity), compass, water speed")
    Config = EkfConfig
    live = True
    unmet = staticmethod(_unmet)
    inputs = staticmethod(_inputs)

    batch = staticmethod(run_ekf)

    @classmethod
    def online(cls, **options: Any) -> EkfOnline:
        return EkfOnline(**options)


ESTIMATORS = {"ekf": Ekf}
