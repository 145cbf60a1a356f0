"""A minimal online factor graph: the GTSAM fixed-lag / iSAM2 adapter that live mode
(:mod:`graphnav.online.live`) runs by default, registered as ``fixed-lag`` and ``isam2`` in
:data:`graphnav.online.runner.ONLINE_ESTIMATORS`; it implements
:class:`graphnav.result.OnlineEstimator` (``add(record) -> Estimate | None``).

:class:`GraphOnline` is deliberately small: one ``Pose2`` per distinct record time, native GTSAM
factors built by the :mod:`factors` package, the same constructors as the batch smoother's
(``odometry_between`` from the SOG/ROT increment -- the beacon paper's motion model, eq. 3,
integrated exactly with its eq. 4-5 noise propagated (:func:`factors.odometry_increment`) -- or a
weak constant-position model without odometry; Huber-robust ``gnss_factor`` fixes;
``compass_factor`` headings; ``pose_prior`` anchors), solved by
``gtsam.IncrementalFixedLagSmoother`` (bounded memory; ``lag`` seconds) or plain ``gtsam.ISAM2``
(``lag=None``, grows without bound). Scans are registered to the previous scan with small_gicp's
GICP (fixed sigmas, not the weighted-ICP covariance model -- the paper's weighted-ICP factors come
with the full smoother through the same interface) and join the graph as ``icp_between`` factors.
"""

from __future__ import annotations

import math
import time
from collections import deque
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

import factors as F

from ..geometry import wrap_angle
from ..log import Gnss, Heading, Odometry, Record, Scan
from ..result import Estimate


class GraphOnline:
    """Minimal online factor graph (see the module docstring). Options (all have defaults):

    ``lag`` [s] fixed-lag window (None: full iSAM2); ``outage_s``: without GNSS for this long,
    heading records also yield estimates (otherwise a heading joins the graph at the next fix's
    solve: one solve per epoch); ``odo_sigma_v`` [m/s], ``odo_sigma_w_deg`` [deg/s]: odometry noise
    when the log gives none; ``lateral_sigma`` [m/s]: sway/current, a lateral random walk added to
    the motion model (``lateral_sigma * dt`` per step);
    ``gnss_huber`` Huber threshold in sigmas; ``covariance``: compute the marginal covariance of
    every ``cov_every``-th estimate (0.2-5 ms each; the others carry ``cov=None``);
    ``rebase_every``: re-anchor the fixed-lag smoother every so many nodes (bounded memory, see
    :meth:`_rebase`); ``use_scans`` and ``icp_*``: scan registration (see :meth:`_scan`); a scan
    older than the newest node joins the node within ``scan_attach_dt`` [s] of it, if any;
    ``relinearize_threshold``/``relinearize_skip``:
    iSAM2's (GTSAM defaults; 0.01/1 is ~4 % more accurate on the synthetic trial and 3x slower).
    """

    def __init__(self, *, lag: float | None = 5.0, outage_s: float = 1.5, odo_sigma_v: float = 0.1,
                 odo_sigma_w_deg: float = 0.5, lateral_sigma: float = 0.2, free_speed: float = 3.0,
                 free_rate_deg: float = 10.0, odo_max_age: float = 2.0, gnss_huber: float = 1.5,
                 covariance: bool = True, cov_every: int = 10, rebase_every: int | None = 6_000,
                 relinearize_threshold: float = 0.1, relinearize_skip: int = 10, use_scans: bool = True,
                 icp_sigma_xy: float = 0.2, icp_sigma_yaw_deg: float = 1.0, icp_max_dist: float = 2.0,
                 icp_min_inliers: float = 0.5, icp_max_step: float = 3.0,
                 scan_attach_dt: float = 0.06) -> None:
        self.lag = lag
        self.outage_s = outage_s
        self.sv, self.sw = odo_sigma_v, math.radians(odo_sigma_w_deg)
        self.lateral = lateral_sigma
        self.free_speed, self.free_rate = free_speed, math.radians(free_rate_deg)
        self.odo_max_age = odo_max_age
        self.gnss_huber = gnss_huber
        self.covariance = covariance
        self.cov_every = max(1, cov_every)
        self.n_solves = 0
        self.rebase_every = rebase_every
        self.use_scans = use_scans
        self.icp_sigmas = np.array([icp_sigma_xy, icp_sigma_xy, math.radians(icp_sigma_yaw_deg)])
        self.icp_max_dist, self.icp_min_inliers = icp_max_dist, icp_min_inliers
        self.icp_max_step = icp_max_step
        self.last_scan: tuple[int, NDArray[np.float64]] | None = None
        self.scan_attach_dt = scan_attach_dt
        self.node_times: deque[tuple[int, float]] = deque(maxlen=256)
        self.icp_ms: deque[float] = deque(maxlen=10_000)
        self.params = None
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(relinearize_threshold)
        params.relinearizeSkip = relinearize_skip
        self.params = params
        self.solver = gtsam.IncrementalFixedLagSmoother(lag, params) if lag else gtsam.ISAM2(params)
        self.k_base = 0
        self.k = -1  # current node
        self.t: float | None = None  # its time
        self.t_origin: float | None = None
        self.pose: NDArray[np.float64] | None = None  # current estimate of node k
        self.prev: tuple[float, NDArray[np.float64]] | None = None
        self.odo: Odometry | None = None
        self.yaw0: tuple[float, float] | None = None  # (yaw, sigma) seen before the first fix
        self.last_gnss_t = -math.inf
        self.graph = gtsam.NonlinearFactorGraph()
        self.values = gtsam.Values()
        self.stamps: dict[int, float] = {}
        self.counts = {"nodes": 0, "gnss": 0, "heading": 0, "odometry": 0, "scan": 0, "late": 0, "other": 0}
        self.step_ms: deque[float] = deque(maxlen=10_000)  # the last 10 000 solves

    # -- graph building
    def _motion(self, dt: float) -> tuple[gtsam.Pose2, NDArray[np.float64]]:
        """Increment and tangent covariance from the last node to one ``dt`` later."""
        o = self.odo
        if o is not None and self.t is not None and self.t - o.t <= self.odo_max_age:
            sv = o.sigma_v if math.isfinite(o.sigma_v) else self.sv
            sw = o.sigma_w if math.isfinite(o.sigma_w) else self.sw
            inc, cov = F.odometry_increment(o.v, o.w, dt, sv, sw, lateral=0.0)
            cov[1, 1] += (self.lateral * dt) ** 2
            return inc, cov
        # no (recent) odometry: constant position with a generous random walk
        sig = np.maximum([self.free_speed * dt, self.free_speed * dt, self.free_rate * dt], 1e-4)
        return gtsam.Pose2(), np.diag(np.square(sig))

    def _new_node(self, t: float, xy: tuple[float, float] | None) -> None:
        k = self.k + 1
        if self.k < 0:
            yaw, syaw = self.yaw0 if self.yaw0 else (0.0, math.pi)
            assert xy is not None
            guess = np.array([xy[0], xy[1], yaw])
            self.graph.add(F.pose_prior(k, guess, np.array([100.0, 100.0, syaw])))
            self.t_origin = t
        else:
            inc, cov = self._motion(t - self.t)
            self.graph.add(F.odometry_between(self.k, k, inc, cov))
            g = gtsam.Pose2(*self.pose).compose(inc)
            guess = np.array([g.x(), g.y(), g.theta()])
        self.values.insert(k, gtsam.Pose2(*guess))
        self.stamps[k] = t - self.t_origin
        if self.pose is not None and self.t is not None:
            self.prev = (self.t, self.pose)
        self.k, self.t, self.pose = k, t, guess
        self.counts["nodes"] += 1
        self.node_times.append((k, t))

    def _solve(self) -> Estimate:
        t0 = time.perf_counter()
        if self.lag:
            self.solver.update(self.graph, self.values, self.stamps)
        else:
            self.solver.update(self.graph, self.values)
        self.graph, self.values, self.stamps = gtsam.NonlinearFactorGraph(), gtsam.Values(), {}
        p = self.solver.calculateEstimatePose2(self.k)
        self.pose = np.array([p.x(), p.y(), p.theta()])
        self.n_solves += 1
        want_cov = self.covariance and (self.n_solves - 1) % self.cov_every == 0
        cov = np.asarray(self.solver.marginalCovariance(self.k)) if want_cov else None
        if cov is not None:  # body-frame (GTSAM) -> world-frame covariance
            R = np.eye(3)
            c, s = math.cos(p.theta()), math.sin(p.theta())
            R[:2, :2] = [[c, -s], [s, c]]
            cov = R @ cov @ R.T
        sog = cog = w = None
        if self.k >= 1 and self.prev is not None and self.t > self.prev[0]:
            try:
                q = self.solver.calculateEstimatePose2(self.k - 1)
            except (RuntimeError, IndexError, ValueError):  # marginalized (a gap longer than the lag)
                q = gtsam.Pose2(*self.prev[1])
            dt = self.t - self.prev[0]
            dx, dy = p.x() - q.x(), p.y() - q.y()
            sog, cog = math.hypot(dx, dy) / dt, math.atan2(dy, dx)
            w = float(wrap_angle(p.theta() - q.theta())) / dt
        if self.odo is not None and self.t - self.odo.t <= self.odo_max_age:
            sog, w = abs(self.odo.v), self.odo.w  # measured rates are less noisy than differenced poses
        if self.lag and self.rebase_every and self.k - self.k_base >= self.rebase_every:
            self._rebase(p)
        self.step_ms.append((time.perf_counter() - t0) * 1e3)
        return Estimate(self.t, self.pose.copy(), cov, sog, cog, w)

    def _rebase(self, p: gtsam.Pose2) -> None:
        """Start a fresh fixed-lag smoother anchored at the current node with its marginal covariance.

        GTSAM's smoothers keep an empty slot for every factor ever removed, so their memory grows
        ~220 bytes per epoch (measured); re-anchoring every ``rebase_every`` nodes (10 min at 10 Hz) keeps it
        flat at the cost of dropping the correlation with the older nodes of the window.
        """
        cov = np.asarray(self.solver.marginalCovariance(self.k))
        self.solver = gtsam.IncrementalFixedLagSmoother(self.lag, self.params)
        g = gtsam.NonlinearFactorGraph()
        g.add(F.pose_prior(self.k, [p.x(), p.y(), p.theta()], cov))
        v = gtsam.Values()
        v.insert(self.k, p)
        self.solver.update(g, v, {self.k: self.t - self.t_origin})
        self.k_base = self.k
        self.counts["rebases"] = self.counts.get("rebases", 0) + 1

    # -- the interface
    def add(self, record: Record) -> Estimate | None:
        t = record.t
        if self.t is not None and t < self.t - 1e-9:
            k = self._node_near(t) if isinstance(record, Scan) and self.use_scans else None
            if k is None:
                self.counts["late"] += 1
                return None
            self.counts["scan"] += 1  # a scan that came in after later sentences (another socket)
            self._scan(record, k)
            return None
        if isinstance(record, Odometry):
            self.counts["odometry"] += 1
            self.odo = record
            return None
        if isinstance(record, Heading):
            self.counts["heading"] += 1
            if self.k < 0:
                self.yaw0 = (record.yaw, record.sigma)
                return None
            if t > self.t + 1e-9:
                self._new_node(t, None)
            self.graph.add(F.compass_factor(self.k, record.yaw, record.sigma))
            if t - self.last_gnss_t > self.outage_s:  # GNSS outage: headings drive the output
                return self._solve()
            return None  # solved with the next fix (one solve per epoch)
        if isinstance(record, Gnss):
            self.counts["gnss"] += 1
            if self.k < 0 or t > self.t + 1e-9:
                self._new_node(t, (record.x, record.y))
            self.graph.add(F.gnss_factor(self.k, record.x, record.y, record.sigma, robust="huber", k=self.gnss_huber))
            self.last_gnss_t = t
            return self._solve()
        if isinstance(record, Scan):
            self.counts["scan"] += 1
            if self.use_scans and self.k >= 0:
                if t > self.t + 1e-9:
                    self._new_node(t, None)
                self._scan(record, self.k)
            return None
        self.counts["other"] += 1
        return None

    def _node_near(self, t: float) -> int | None:
        """The node within ``scan_attach_dt`` of ``t`` (None if there is none)."""
        best = min(self.node_times, key=lambda kt: abs(kt[1] - t), default=None)
        return best[0] if best is not None and abs(best[1] - t) <= self.scan_attach_dt else None

    def _node_pose(self, k: int) -> gtsam.Pose2:
        """Node ``k``'s current estimate: its initial guess while it waits for the next solve (nodes
        made by scans between fixes), else the solver's."""
        if self.values.exists(k):
            return self.values.atPose2(k)
        if k == self.k:
            return gtsam.Pose2(*self.pose)
        return self.solver.calculateEstimatePose2(k)

    def _scan(self, scan: Scan, k: int) -> None:
        """Scan-to-previous-scan registration (small_gicp GICP) -> ``BetweenFactorPose2``, solved
        with the next fix. Rejected when it does not converge, has too few inliers, or moves more
        than ``icp_max_step`` from the motion-model prediction."""
        import small_gicp

        ok = scan.valid()
        r, a = scan.ranges[ok], scan.angles[ok]
        pts = np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros(r.size)])
        prev, self.last_scan = self.last_scan, (k, pts)
        if prev is None or len(pts) < 20 or len(prev[1]) < 20 or prev[0] == k:
            return
        try:
            p0, pk = self._node_pose(prev[0]), self._node_pose(k)
        except (RuntimeError, IndexError, ValueError):  # the node left the window
            self.counts["icp_skipped"] = self.counts.get("icp_skipped", 0) + 1
            return
        guess = p0.between(pk)
        init = np.eye(4)
        init[:2, :2] = [[math.cos(guess.theta()), -math.sin(guess.theta())],
                        [math.sin(guess.theta()), math.cos(guess.theta())]]
        init[:2, 3] = [guess.x(), guess.y()]
        t0 = time.perf_counter()
        res = small_gicp.align(prev[1], pts, init, registration_type="GICP", downsampling_resolution=0.1,
                               max_correspondence_distance=self.icp_max_dist, max_iterations=30)
        self.icp_ms.append((time.perf_counter() - t0) * 1e3)
        T = np.asarray(res.T_target_source)
        rel = gtsam.Pose2(T[0, 3], T[1, 3], math.atan2(T[1, 0], T[0, 0]))
        step = math.hypot(rel.x() - guess.x(), rel.y() - guess.y())
        if not res.converged or res.num_inliers < self.icp_min_inliers * len(pts) or step > self.icp_max_step:
            self.counts["icp_rejected"] = self.counts.get("icp_rejected", 0) + 1
            return
        self.graph.add(F.icp_between(prev[0], k, [rel.x(), rel.y(), rel.theta()], np.diag(self.icp_sigmas**2)))
        self.counts["icp"] = self.counts.get("icp", 0) + 1

    def info(self) -> dict[str, Any]:
        s = np.asarray(self.step_ms)
        icp = np.asarray(self.icp_ms)
        return {"estimator": "graph-online", "lag_s": self.lag, **self.counts,
                "icp_ms_median": float(np.median(icp)) if icp.size else None,
                "step_ms_median": float(np.median(s)) if s.size else None,
                "step_ms_p99": float(np.percentile(s, 99)) if s.size else None}
