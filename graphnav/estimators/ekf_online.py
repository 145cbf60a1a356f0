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

``motion="auto"`` (the default) chooses the motion as the batch filter does
(:func:`~graphnav.estimators.ekf.auto_motion`) and ``meta`` (a marine stream's odometry is a rate of turn
with the SOG: ``{"odometry": ODOMETRY_FROM_ROT}``, which ``graphnav live`` passes): provisionally from the
first epoch's records, finally from every record up to ``init_wait`` seconds after the first fix (the kinds
the stream carries by then); if the two differ, the filter is rebuilt from those records as if the final
choice had been made at the start, and goes on.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from typing import Any

import numpy as np

from ..geometry import wrap_angle
from ..graph.coast import Coaster
from ..graph.position_walk import WalkTracker
from ..log import Gnss, GnssVelocity, Heading, NavLog, Odometry, PosePrior, Record, odometry_is_rot
from ..result import Estimate
from .base import BatchEstimator
from .ekf import (
    IMU_DEFAULTS,
    EkfConfig,
    EkfStepper,
    _inputs,
    _unmet,
    auto_motion,
    compass_yaw,
    initial_state,
    run_ekf,
    vessel_model,
)
from .pose_ekf import PoseEkf


class EkfOnline:
    """EKF behind ``add(record) -> Estimate | None``. ``emit``: ``"fix"`` (default) yields an
    estimate per GNSS fix, and per used record while no fix came for ``outage_s`` [s];
    ``"all"`` one per used record. The other options are :func:`run_ekf`'s (``motion`` is
    ``"auto"``, ``"odometry"``, ``"imu"``, ``"icp"`` or ``"vessel"``; ``"auto"`` decides at the start, from the
    records held by then and ``meta``: module docstring); with
    ``"imu"`` or ``"vessel"`` the IMU (vessel) motion's options, :data:`graphnav.estimators.ekf.IMU_DEFAULTS`,
    the initial velocity the first held GNSS velocity when ``v0`` is not given)."""

    def __init__(self, *, motion: str = "auto", speed: bool = False, emit: str = "fix", outage_s: float = 1.5,
                 init_wait: float = 2.0, meta: dict[str, Any] | None = None, coast_hz: float | None = None,
                 coast_max_s: float | None = None, **ekf_options: Any) -> None:
        if emit not in ("fix", "all"):
            raise ValueError(f"emit must be 'fix' or 'all', not {emit!r}")
        #: the output grid through gaps without records (the navigator's rule, :class:`~graphnav.graph.coast.Coaster`)
        self.coaster = Coaster(None if coast_hz is None else float(coast_hz),
                               None if coast_max_s is None else float(coast_max_s))
        self.motion, self.speed, self.emit = motion, speed, emit
        self.outage_s, self.init_wait = outage_s, init_wait
        self.meta = dict(meta or {})
        self.heard: list[Record] | None = None  # motion "auto": the records since the start, until the choice
        self.t_decide: float | None = None
        imu = {k: ekf_options.pop(k) for k in list(ekf_options) if k in IMU_DEFAULTS}
        self.options: dict[str, Any] = {"keep": 10_000, **ekf_options}
        if imu:
            if motion not in ("imu", "vessel", "auto"):
                raise ValueError(f"ekf option(s) {sorted(imu)} need motion='imu' or 'vessel'")
            self.options["imu"] = imu
        #: the vessel motion's position walk estimated from the stream (unless given), as live mode's graph
        self.walker = None if self.options.get("imu", {}).get("vessel_position_walk") is not None else WalkTracker()
        for m in (("vessel", "odometry") if motion == "auto" else (motion,)):  # validate the options now
            EkfStepper(np.zeros(3), np.eye(3), motion=m, **self._options_for(m))
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

    def _options_for(self, motion: str) -> dict[str, Any]:
        """The stepper's options for ``motion``: the IMU (vessel) motion's only where it has them."""
        if motion == "vessel" and self.options.get("imu", {}).get("vessel_rot") is None:  # the ROT: from meta
            rot = odometry_is_rot(self.meta)
            return {**self.options, "imu": {**self.options.get("imu", {}), "vessel_rot": rot}}
        return self.options if motion in ("imu", "vessel") else {k: v for k, v in self.options.items() if k != "imu"}

    def _choose(self, records: list[Record], least: int) -> str:
        return auto_motion(NavLog.from_unsorted(records, meta=self.meta), least=least)

    def _start(self) -> None:
        recs = list(self.pending)
        if self.motion == "auto":  # provisional, from the first epoch; final init_wait after the first fix
            self.motion = self._choose(recs, least=1)
            self.heard = recs
            self.t_decide = (self.t_first_fix if self.t_first_fix is not None else recs[0].t) + self.init_wait
        self._build(recs)
        self.pending.clear()
        self.held.clear()
        self.t_first_fix = None

    def _build(self, recs: list[Record]) -> None:
        """The stepper from ``recs``' initial state (:func:`initial_state`), ``recs`` replayed into it."""
        x0, P0, self.anchor = initial_state(recs, self.speed)
        options = self._options_for(self.motion)
        if self.motion in ("imu", "vessel") and "v0" not in options.get("imu", {}):
            gv = next((r for r in recs if isinstance(r, GnssVelocity)), None)
            if gv is not None and gv.t - recs[0].t <= 1.0:  # as run_ekf's rule
                sv = gv.sigma if math.isfinite(gv.sigma) else IMU_DEFAULTS["sigma_gnss_velocity"]
                options = {**options, "imu": {**options.get("imu", {}), "v0": (gv.vx, gv.vy, 3.0 * sv)}}
        self.stepper = st = EkfStepper(x0, P0, motion=self.motion, compass_yaw=compass_yaw(self.anchor, P0),
                                       **options)
        for r in recs:
            if st.step(r) and isinstance(r, Gnss) and st.use_gnss:  # as in add: an unused fix is none
                self.last_fix_t = r.t

    # -- the interface
    def add(self, record: Record) -> Estimate | None:
        self.coaster.out = []
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
        if st.uses(record):  # (a record the filter does not take is silence to it)
            silent = self.coaster.live_horizon(record.t) is not None  # (before this record counts)
            self.coaster.record(record)
            if silent:
                self._coast_before(record.t)
        if self.walker is not None and st.vessel is not None:
            walk = self.walker.add(record)
            if walk is not None:
                st.vessel["vessel_position_walk"] = max(walk["walk"], vessel_model({})["vessel_position_walk"])
        if self.heard is not None and self._decided(record):  # the motion changed: rebuilt, this record replayed
            st = self.stepper
            assert st is not None
            if not st.uses(record):
                return None
        elif not st.step(record):
            return None
        if isinstance(record, Gnss) and st.use_gnss:
            self.last_fix_t = record.t
            return self._estimate()
        if self.emit == "all" or (record.t - self.last_fix_t > self.outage_s and record.t > self.last_emit_t):
            return self._estimate()
        return None

    def _decided(self, record: Record) -> bool:
        """``motion="auto"``: hear ``record``; at ``t_decide`` (or a full buffer) the final choice from every
        record heard. True when it differs from the provisional one: the stepper is rebuilt from the heard
        records (``record`` among them) as if it had been chosen at the start."""
        assert self.heard is not None and self.t_decide is not None
        self.heard.append(record)
        if record.t < self.t_decide and len(self.heard) < (self.pending.maxlen or 10_000):
            return False
        heard, self.heard = self.heard, None
        final = self._choose(heard, least=2)
        if final == self.motion:
            return False
        self.motion = final
        self._build(heard)
        return True

    def _estimate(self) -> Estimate:
        st = self.stepper
        assert st is not None and st.t is not None
        self.last_emit_t = st.t
        self.coaster.estimated(0, st.t)
        return self._of(st.f, st.t)

    def _of(self, f: PoseEkf, t: float, coasted: bool = False) -> Estimate:
        """The estimate of filter ``f`` (the stepper's, or a predicted copy) at ``t``."""
        st = self.stepper
        assert st is not None
        if self.motion in ("imu", "vessel"):  # velocity over ground from the state, rate of turn from the IMU
            vx, vy = float(f.x[3]), float(f.x[4])
            m = st.imu_u
            ib = getattr(f, "ib", None)
            w = None if m is None else m.wz - (float(f.x[ib + 2]) if ib is not None else 0.0)
            return Estimate(t, f.x[:3].copy(), f.P[:3, :3].copy(), math.hypot(vx, vy),
                            float(wrap_angle(math.atan2(vy, vx))), w, coasted=coasted)
        u = st.u
        v = float(f.x[3]) if f.has_speed else (u.v if u is not None else None)
        w = u.w if u is not None else None
        cog = None if v is None else float(f.x[2] if v >= 0 else math.remainder(f.x[2] + math.pi, 2 * math.pi))
        return Estimate(t, f.x[:3].copy(), f.P[:3, :3].copy(), None if v is None else abs(v), cog, w,
                        coasted=coasted)

    # -- coasting (graphnav.graph.coast: the same output grid and silence rule as the navigator's)
    @property
    def coasted_out(self) -> list[Estimate]:
        """The coasted estimates the last ``add()`` put out, before its own (live mode's sink publishes them)."""
        return self.coaster.out

    def coast(self, t: float) -> list[Estimate]:
        """Live mode's clock tick at stream time ``t``: once no record the filter takes came for two output (or
        record) periods, the predictions due on the output grid up to a period before ``t``
        (:meth:`~graphnav.graph.coast.Coaster.live_horizon`); offline the gaps are filled as the next record comes."""
        until = self._horizon(t)
        return [] if until is None else self._coast_to(until)

    def no_fix(self, t: float) -> list[float]:
        """Live mode's clock tick at stream time ``t``, after :meth:`coast`: the output times past
        ``coast_max_s`` that have no solution (:meth:`~graphnav.graph.coast.Coaster.silent`)."""
        until = self._horizon(t)
        return [] if until is None else self.coaster.silent(until)

    def _horizon(self, t: float) -> float | None:
        """Live mode at stream time ``t``: how far the output is due (:meth:`Coaster.live_horizon`) once the
        filter has started; ``None``: nothing due."""
        return self.coaster.live_horizon(t) if self.stepper is not None else None

    def _coast_before(self, t: float) -> None:
        """A record at ``t`` after a silence live mode would have coasted through (the live rule at ``t``, checked
        by the caller) and a gap in the output (:meth:`~graphnav.graph.coast.Coaster.gap`): the grid up to half a
        period before it."""
        period = self.coaster.period()
        if period is not None and self.coaster.gap(t):
            self._coast_to(t - 0.5 * period)

    def _coast_to(self, until: float) -> list[Estimate]:
        """Predictions on the output grid up to ``until``, each from a copy of the filter
        (:meth:`~graphnav.estimators.ekf.EkfStepper.coast`: the filter's own motion model, its process noise),
        flagged ``coasted``; kept in :attr:`coasted_out`. The filter is untouched."""
        st = self.stepper
        if st is None or st.t is None:
            return []
        out = []
        for tau in self.coaster.grid(until):
            if tau <= st.t + 1e-9:  # records came up to st.t: no silence there
                continue
            g = st.coast(tau)
            if g is None:  # nothing to move with (no control, IMU record or scan increment yet)
                break
            out.append(self._of(g, tau, coasted=True))
            self.coaster.coasted(tau)
        self.coaster.out.extend(out)
        return out

    def info(self) -> dict[str, Any]:
        st = self.stepper
        s = np.asarray(st.step_ms if st is not None else [])
        out: dict[str, Any] = {"estimator": "ekf-online", "motion": self.motion, "anchor": self.anchor,
                               **self.counts, "step_ms_median": float(np.median(s)) if s.size else None,
                               "step_ms_p99": float(np.percentile(s, 99)) if s.size else None,
                               **self.coaster.info()}
        if st is not None:
            out.update(st.f.counts, icp_failed=st.icp_failed, **st.zeros.info())
            if st.vessel is not None:
                out["position_walk_live"] = self.walker.last if self.walker is not None else None
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
