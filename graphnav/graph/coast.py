"""Coasting: the online output through a gap without records.

A navigation system keeps publishing at its output rate when its sensors fall silent: the newest
state propagated by the motion model, its covariance grown by the model's process noise, flagged as
a prediction. :class:`Coaster` keeps the output grid (the median interval of the estimates so far,
or ``coast_hz``) and the newest estimate the predictions start from; :func:`predict_planar` and
:func:`predict_nav` are the two graphs' motion models (the Pose2 graph's constant velocity or random
walk, :meth:`~graphnav.graph.motion.Motion.coast`; the Pose3 graph's IMU preintegration, or the
vessel model's white-noise acceleration without an IMU). The predictions are outputs only: no
variable or factor joins the graph, and the graph's state is untouched.

Offline the grid points of a gap are known once the next keyframe comes (they are filled up to half
a period before it); live, the runner's clock tick asks for them while the stream is silent
(:meth:`graphnav.graph.navigator.Navigator.coast`).
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Iterable
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

from ..geometry import cov_to_world
from ..log import KnownBeacon, Record
from ..result import Estimate, OnEstimate
from .imu_chain import relative_prediction
from .motion import Motion, NavPrev
from .online_track import OnlineTrack
from .order_stats import median, quantile
from .solver import Solver, SolverError
from .space import V, as_pose2

OUTPUT_INTERVALS = 64  # the output period: the median of the newest this many intervals between estimates ...
MIN_INTERVALS = 3  # ... once there are this many
MAX_POINTS = 100_000  # coasted estimates per call at most (a clock jump of days is not walked at the output rate)
EPS = 1e-9  # [s]
log_ = logging.getLogger("graphnav.coast")

#: a prediction: pose (x, y, yaw), world covariance, speed over ground, course, yaw rate
Prediction = tuple[NDArray[np.float64], NDArray[np.float64], float | None, float | None, float | None]


def grid_times(t0: float, period: float, after: float, until: float) -> list[float]:
    """The output grid ``t0 + i period`` (i >= 1) strictly after ``after`` and up to ``until`` (inclusive, to
    1e-9 of a period), at most :data:`MAX_POINTS` of them."""
    n = max(1, math.floor((after - t0) / period + 1e-9) + 1)
    last = math.floor((until - t0) / period + 1e-9)
    return [t0 + i * period for i in range(n, min(last, n + MAX_POINTS - 1) + 1)]


class Coaster:
    """The output grid through gaps. ``hz``: the output rate (``None``: the median rate of the
    estimates so far, from the :data:`MIN_INTERVALS`-th on; 0: off). :meth:`estimated` records each
    real estimate (the newest is the seed of the predictions); :meth:`gap` says whether the next one
    leaves a gap; :meth:`grid` gives the times due."""

    def __init__(self, hz: float | None, max_s: float | None = None) -> None:
        if hz is not None and not (hz >= 0 and math.isfinite(hz)):
            raise ValueError(f"coast_hz must be >= 0 (0: off) or None (the estimates' rate), got {hz}")
        if max_s is not None and not max_s > 0:
            raise ValueError(f"coast_max_s must be > 0 or None (no limit), got {max_s}")
        self.hz = hz
        self.max_s = max_s  # [s] no prediction further than this from the newest real estimate (None: no limit)
        self.stopped = 0  # gaps in which coasting stopped at max_s
        self._stopped_seed: tuple[int, float] | None = None
        self.t_silent: float | None = None  # the newest time said to have no solution (:meth:`silent`)
        self.silent_count = 0  # such times so far
        self.dts: deque[float] = deque(maxlen=OUTPUT_INTERVALS)
        self.seed: tuple[int, float] | None = None  # the newest real estimate: keyframe, time
        self.t_out: float | None = None  # the newest output (real or coasted)
        self.count = 0  # coasted estimates so far
        self.vel_cov: NDArray[np.float64] | None = None  # the seed's velocity marginal, when asked once
        self.t_rec: float | None = None  # the newest record's time
        self.out: list[Estimate] = []  # the coasted estimates put out since the newest record came
        self.rec_dts: deque[float] = deque(maxlen=OUTPUT_INTERVALS)  # intervals between distinct record times

    def period(self) -> float | None:
        """[s] the output period; ``None``: off, or not known yet."""
        if self.hz is not None:
            return 1.0 / self.hz if self.hz > 0 else None
        if len(self.dts) < MIN_INTERVALS:
            return None
        return median(self.dts)

    def gap(self, t: float) -> bool:
        """Whether an estimate at ``t`` after the newest one leaves a gap in the output: longer than 1.5
        periods of an asked ``hz``; else (the log's own rate) longer than twice the 90th percentile of
        the recent intervals -- the keyframe policy's own spread (one keyframe per 1 m, at least every
        second: 0.1-1 s apart under way) is the normal output, not a gap."""
        period = self.period()
        if period is None or self.seed is None:
            return False
        limit = 1.5 * period if self.hz is not None else 2.0 * quantile(self.dts, 0.9)
        return t - self.seed[1] > limit

    def estimated(self, k: int, t: float) -> None:
        """A real estimate of keyframe ``k`` at ``t``."""
        if self.seed is not None and t > self.seed[1] + EPS:
            self.dts.append(t - self.seed[1])
        if self.seed is None or t >= self.seed[1]:
            self.seed = (k, t)
            self.vel_cov = None
        self.t_out = t if self.t_out is None else max(self.t_out, t)

    def record(self, rec: Record | KnownBeacon) -> Record | None:
        """A record came in (its time: the input's rate, live mode's silence rule); returns it (``None``
        for a charted beacon, which has no time)."""
        self.out = []
        if isinstance(rec, KnownBeacon):
            return None
        if rec.kind == "truth":  # a reference, not an input
            return rec
        self.record_times((rec.t,))
        return rec

    def record_times(self, times: Iterable[float]) -> None:
        """Records at ``times`` came in, in this order (:meth:`record` of each, a run of IMU samples at once)."""
        self.out = []
        t_rec, dts = self.t_rec, self.rec_dts
        for t in times:
            t = float(t)
            if t_rec is not None and t > t_rec + EPS:
                dts.append(t - t_rec)
            t_rec = t if t_rec is None else max(t_rec, t)
        self.t_rec = t_rec

    def live_horizon(self, now: float) -> float | None:
        """Live mode at stream time ``now``: coast up to the returned time once the input has been
        silent for two periods (``lag``: the larger of the output period and the median interval
        between record times -- an estimate comes out only once a later record has come, so one
        period of silence is normal); up to ``now - lag`` (``None``: not due)."""
        period = self.period()
        if period is None or self.t_rec is None:
            return None
        lag = max(period, median(self.rec_dts) if self.rec_dts else 0.0)
        return now - lag if now - self.t_rec > 2 * lag else None

    def grid(self, until: float) -> list[float]:
        """The output times due up to ``until`` (inclusive): the seed's time + n periods, after the
        newest output, and at most ``max_s`` after the seed (coasting stops there: counted in
        :attr:`stopped` once per gap, logged)."""
        period = self.period()
        if period is None or self.seed is None or self.t_out is None or not period > 0:
            return []
        t0 = self.seed[1]
        if self.max_s is not None and until > t0 + self.max_s:
            until = t0 + self.max_s
            if self._stopped_seed != self.seed:
                self._stopped_seed = self.seed
                self.stopped += 1
                log_.warning("coasting stopped %.1f s after the last estimate (coast_max_s): 'no fix' until a "
                             "record comes", self.max_s)
        return grid_times(t0, period, self.t_out, until)

    def silent(self, until: float) -> list[float]:
        """Once coasting has stopped (``max_s`` after the newest real estimate), the output times up to
        ``until`` on which live mode says it has no solution (GGA quality 0, RMC status V, Signal K
        ``methodQuality`` "no GPS": :meth:`graphnav.online.sink.Sink.no_fix`) rather than falling silent,
        which a chart plotter cannot tell from a broken cable; each time once, on the coasting grid."""
        period = self.period()
        if self.max_s is None or period is None or self.seed is None or not period > 0:
            return []
        t0 = self.seed[1]
        start = t0 + self.max_s if self.t_silent is None else max(t0 + self.max_s, self.t_silent)
        if not start < until:  # (also a limit too large to count periods in: inf, 1e308)
            return []
        out = grid_times(t0, period, start, until)
        if out:
            self.t_silent = out[-1]
            self.silent_count += len(out)
        return out

    def info(self) -> dict[str, Any]:
        """The summary's coasting entries: how many estimates were coasted, at which period, and (with
        ``max_s``) the limit, how many gaps it cut short and how many times were said to have no solution."""
        out: dict[str, Any] = {"coasted_estimates": self.count, "coast_period_s": self.period()}
        if self.max_s is not None:
            out.update(coast_max_s=self.max_s, coast_stopped=self.stopped, no_fix_outputs=self.silent_count)
        return out

    def coasted(self, t: float) -> None:
        """A coasted estimate at ``t`` was put out."""
        self.count += 1
        self.t_out = t if self.t_out is None else max(self.t_out, t)


def predict_planar(motion: Motion, pose: gtsam.Pose2, cov: NDArray[np.float64], t0: float, dt: float
                   ) -> Prediction:
    """The Pose2 graph: ``pose`` (at ``t0``, world covariance ``cov``) moved ``dt`` seconds by the
    motion model (:meth:`Motion.coast <graphnav.graph.motion.Motion.coast>`): the covariance carried
    through the composition (``Ad(rel^-1) P Ad(rel^-1)^T`` in the body tangent) plus the model's."""
    rel, q, twist = motion.coast(t0, dt)
    new = pose.compose(rel)
    body = cov_to_world(-pose.theta(), cov)  # world -> the body tangent of GTSAM's Pose2
    a = np.asarray(rel.inverse().AdjointMap())
    grown = a @ body @ a.T + q
    vec = np.array([new.x(), new.y(), new.theta()])
    if twist is None:
        return vec, cov_to_world(new.theta(), grown), 0.0, None, 0.0
    sog = math.hypot(twist[0], twist[1])
    return vec, cov_to_world(new.theta(), grown), sog, new.theta() + math.atan2(twist[1], twist[0]), float(twist[2])


def predict_nav(motion: Motion, state: NavPrev, cov: NDArray[np.float64], vel_cov: NDArray[np.float64] | None,
                t0: float, dt: float) -> Prediction:
    """The Pose3 graph: the state at ``t0`` (pose, velocity, IMU bias; world pose covariance ``cov``,
    velocity covariance ``vel_cov``) preintegrated ``dt`` seconds as the graph's next factor would
    (the IMU's samples, or the vessel model's white noise without an IMU): the pose's covariance plus
    the preintegration's and the velocity's carried over ``dt`` (their correlation with the pose is
    left out)."""
    assert motion.imu is not None
    pose, vel, bias, _ = state
    pim = motion.imu.preintegrate(bias, t0, t0 + dt, speed=float(np.hypot(vel[0], vel[1])))
    pred, _, rel_cov = relative_prediction(pim, pose, vel, bias, vel_cov)
    rel_cov = rel_cov + np.diag(np.square(motion.floor()))
    p2 = as_pose2(pred.pose())
    yaw0 = as_pose2(pose).theta()
    grown = np.asarray(cov) + cov_to_world(yaw0, rel_cov)
    v = np.asarray(pred.velocity())
    vec = np.array([p2.x(), p2.y(), p2.theta()])
    return vec, grown, math.hypot(v[0], v[1]), math.atan2(v[1], v[0]), None


class Coasting:
    """The :class:`~graphnav.graph.navigator.Navigator`'s output through gaps without records (the
    module docstring): the navigator holds a :class:`Coaster`, the newest estimate's state and its graph."""

    coaster: Coaster
    solver: Solver
    builder: Any  # GraphBuilder
    track: OnlineTrack
    on_estimate: OnEstimate | None
    last_pose: gtsam.Pose2 | None
    last_cov: NDArray[np.float64] | None
    last_state: NavPrev | None
    nav: bool
    _result: Any

    @property
    def coasted_out(self) -> list[Estimate]:
        """The coasted estimates the last ``add()`` put out, before its own (live mode's sink publishes them)."""
        return self.coaster.out

    def coast(self, t: float) -> list[Estimate]:
        """Live mode's clock tick at stream time ``t``: once no record came for two output (or record)
        periods, the predicted estimates due on the output grid (:class:`~graphnav.graph.coast.Coaster`)
        up to a period before ``t``; offline the gaps are filled as the next keyframe comes."""
        until = self._horizon(t)
        return [] if until is None else self._coast_to(until)

    def no_fix(self, t: float) -> list[float]:
        """Live mode's clock tick at stream time ``t``, after :meth:`coast`: the output times past
        ``coast_max_s`` that have no solution (:meth:`Coaster.silent`)."""
        until = self._horizon(t)
        return [] if until is None else self.coaster.silent(until)

    def _horizon(self, t: float) -> float | None:
        """Live mode at stream time ``t``: how far the output is due (:meth:`Coaster.live_horizon`), while an
        online solver runs and the run has not ended; ``None``: nothing due."""
        return self.coaster.live_horizon(t) if self.solver.online and self._result is None else None

    def _coast_to(self, until: float) -> list[Estimate]:
        """Predicted estimates on the output grid after the newest output, up to ``until``: the newest
        estimate's state moved by the graph's motion model (:mod:`graphnav.graph.coast`), flagged
        ``coasted``; in the online track, passed to ``on_estimate`` and kept in :attr:`coasted_out`."""
        seed = self.coaster.seed
        times = self.coaster.grid(until)
        if seed is None or not times or self.last_pose is None or self.last_cov is None:
            return []
        k, t0 = seed
        out = []
        for tau in times:
            if self.nav and self.last_state is not None:
                vec, cov, sog, cog, w = predict_nav(self.builder.motion, self.last_state, self.last_cov,
                                                    self._seed_vel_cov(k), t0, tau - t0)
            else:
                vec, cov, sog, cog, w = predict_planar(self.builder.motion, self.last_pose, self.last_cov, t0,
                                                       tau - t0)
            self.track.add(tau, vec, cov, coasted=True)
            self.coaster.coasted(tau)
            if self.on_estimate is not None:
                self.on_estimate(tau, vec, cov)
            out.append(Estimate(tau, vec, cov, sog, cog, w, coasted=True))
        self.coaster.out.extend(out)
        return out

    def _seed_vel_cov(self, k: int) -> NDArray[np.float64] | None:
        """The velocity marginal of keyframe ``k`` (the Pose3 graph's coasting; asked once per gap)."""
        state = self.last_state
        if state is not None and state[3] is not None:
            return state[3]
        if self.coaster.vel_cov is None:
            try:
                self.coaster.vel_cov = np.asarray(self.solver.marginal(V(k)))
            except SolverError:
                return None
        return self.coaster.vel_cov

    def _coast_info(self) -> dict[str, Any]:
        """How many online estimates were coasted (predictions through gaps) and at which period."""
        if not self.solver.online:
            return {}
        return self.coaster.info()


    def _coast_before(self, k: int) -> None:
        """Offline (and live) at keyframe ``k``: the output grid through the gap before it (:meth:`Coaster.gap`),
        up to half a period before it (online solvers only)."""
        t = self.builder.kf_t[k]
        period = self.coaster.period()
        if self.solver.online and period is not None and self.coaster.gap(t):
            self._coast_to(t - 0.5 * period)
