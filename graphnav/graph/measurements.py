"""The measurement factors of the navigation graph: GNSS (gated online, compensated to its keyframe),
GNSS velocity, compass (through an estimated bias frame), beacons (charted and unknown), water speed
(:mod:`graphnav.graph.water`), and later ``pose_prior`` records -- each in the graph's state space
(:mod:`graphnav.graph.space`), each tagged with its sensor group.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

import factors as F

from ..config import OptionError
from ..log import Attitude, BeaconObs, Gnss, GnssVelocity, Heading, KnownBeacon, PosePrior, Record, WaterSpeed
from .chi2 import SCALE_WINDOW, chi2_median, significant_scale
from .fix_gate import FixGate
from .mounts import Mount
from .order_stats import median
from .smoother_config import SmootherConfig
from .space import PlanarSpace
from .step import Step
from .water import Water

MEDIAN_CHI2_2 = float(chi2_median(np.array([2.0]))[0])  # |d|^2 / sigma^2 of a 2-D fix: its median


class GnssScale:
    """The online variance scale of the GNSS fixes: ``max(1, median(x) / median(chi2_2))`` over the last
    :data:`~graphnav.graph.chi2.SCALE_WINDOW` fixes, ``x = (|d|^2 - tr P) / sigma^2`` the innovation's
    energy beyond the prediction's own variance ``P`` per stated variance of the fix (a moment
    estimate; the median shields it from fewer than half the window's fixes in a jump). Used -- on
    the factor and in the gate -- only where it exceeds chance (:func:`~graphnav.graph.chi2.significant_scale`
    at ``prob``): as the closing step's :func:`~graphnav.graph.gnc.factor_scales`, a stated sigma the
    fixes refute, never deflated (Solent s2 states 7 m for 20 m fixes)."""

    def __init__(self, prob: float) -> None:
        self.prob = prob
        self.x: deque[float] = deque(maxlen=SCALE_WINDOW)
        self.scale = 1.0
        self.max_scale = 1.0
        self._bound: dict[int, float] = {}

    def add(self, d: NDArray[np.float64], cov: NDArray[np.float64], sigma: float) -> None:
        """One innovation ``d`` of a fix of stated ``sigma`` against a prediction of covariance ``cov``."""
        if not (sigma > 0 and math.isfinite(sigma)):
            return
        self.x.append((float(d @ d) - float(np.trace(cov))) / sigma**2)
        n = len(self.x)
        if n < 10:
            return
        if n not in self._bound:
            self._bound[n] = significant_scale(2, self.prob, n)
        med = median(self.x) if all(map(math.isfinite, self.x)) else float(np.median(self.x))  # (NaN: numpy's)
        est = med / MEDIAN_CHI2_2
        self.scale = est if est > self._bound[n] else 1.0
        self.max_scale = max(self.max_scale, self.scale)


class Measurements:
    """The measurement factors and their state: the charted beacons and the beacons met so far, the
    compass-bias frame, the online GNSS gate's counters, the water-speed states (``water``).

    ``charted``, ``defaulted`` and ``counts`` are the builder's (shared); ``kf_t`` its keyframe times;
    ``mounts``: the sensors' mounts (the GNSS antennas' lever arms, the speed log's yaw).
    """

    def __init__(self, cfg: SmootherConfig, space: PlanarSpace, nav: bool, charted: dict[str, KnownBeacon],
                 kf_t: list[float], defaulted: set[str], counts: dict[str, int],
                 mounts: dict[str, Mount] | None = None) -> None:
        self.cfg, self.space, self.nav = cfg, space, nav
        self.charted, self.kf_t, self.defaulted, self.counts = charted, kf_t, defaulted, counts
        self.beacon_ids: dict[str, int] = {}
        self.beacon_init: dict[str, NDArray[np.float64]] = {}
        self.bias_key: int | None = None  # the newest compass-bias variable
        self.bias_t0: float | None = None  # when it took its first reading
        self.bias_segments = 1  # compass-bias variables so far (B(0), B(1), ...)
        self.gnss_scale = GnssScale(cfg.robust.prob)  # the fixes' online variance scale
        #: the online GNSS gate (graph.fix_gate; None: off)
        self.gate = (FixGate(cfg.gnss.gate, cfg.gnss.gate_max_rejects)
                     if cfg.gnss.gate_online and cfg.gnss.gate is not None else None)
        self.after_outage: set[int] = set()  # ids of the first fixes after a GNSS outage (not gated)
        #: the factors of the fixes the online gate rejected: the closing batch step reconsiders them
        #: (a cold start's first fixes can be the wrong ones, and the gate then rejects every good fix)
        self.rejected: list[gtsam.NonlinearFactor] = []
        #: the Pose3 graph: a keyframe key's (roll, pitch) estimate when its factors are made (the builder's)
        self.tilt_of: Callable[[int], tuple[float, float] | None] | None = None
        self.arms: dict[str, tuple[float, float, float]] = {}  # GNSS lever arms (body frame, m) by source ("": all)
        log_yaw = 0.0  # [rad] the speed log's mounting yaw (its axis from the bow)
        for name, g in (mounts or {}).items():  # the GNSS antennas: the sensor's, and each source's
            if name == "gnss" or name.startswith("gnss@"):
                self.arms[name.partition("@")[2]] = (g.x, g.y, g.z)
        if mounts and "water_speed" in mounts:
            log_yaw = mounts["water_speed"].yaw
            if abs(math.cos(log_yaw)) < 0.5:
                raise OptionError("mounts.water_speed.yaw", "mounts.water_speed.yaw: a speed log more than 60 deg "
                                  f"off the bow measures no speed along it, got {log_yaw:g} rad")
        #: speed through water, the current and the log's scale (graph.water)
        self.water = Water(cfg, kf_t, defaulted, counts, log_yaw)

    def step(self, s: Step, k: int, due: list[tuple[int, Record]], pose_k: gtsam.Pose2,
             gate_cov: NDArray[np.float64] | None, prev: gtsam.Pose2 | None,
             offset: Callable[[int, float, int], gtsam.Pose2 | None]) -> None:
        """Keyframe ``k``'s measurement factors (:meth:`add`), the water current's variables up to it,
        and the time stamps of the variables still in use (compass-bias frame, beacons, the log's scale)."""
        if self.bias_key is not None:
            s.stamps[self.bias_key] = s.t
        self.add(s, k, due, pose_k, gate_cov, prev, offset)
        self.water.step(s, k)
        for i in self.beacon_ids.values():
            s.stamps[F.L(i)] = s.t

    def step_late(self, s: Step, k: int, due: list[tuple[int, Record]],
                  offset: Callable[[int, float, int], gtsam.Pose2 | None], est: Callable[[int], gtsam.Pose2],
                  prev_cov: NDArray[np.float64] | None) -> None:
        """Measurements after the last keyframe's batch, at keyframe ``k`` (``est``: the solved poses)."""
        self.add(s, k, due, est(k), prev_cov, None, offset, est=est)
        for i in self.beacon_ids.values():
            s.stamps[F.L(i)] = s.t

    def carried_keys(self, k: int) -> list[int]:
        """The variables a re-anchored fixed-lag smoother keeps besides keyframe ``k``'s state: the
        compass-bias frame, the beacons, the water current at ``k`` and the speed log's scale."""
        keys = [self.bias_key] if self.bias_key is not None else []
        keys += [F.L(i) for i in self.beacon_ids.values()]
        return keys + self.water.keys(k)

    def report(self, values: gtsam.Values) -> dict[str, Any]:
        """The measurement states in a solution: the compass bias [deg], the beacons' first and final
        estimates."""
        out: dict[str, Any] = {}
        sp = self.space
        if self.bias_key is not None and values.exists(self.bias_key):
            out["compass_bias_deg"] = math.degrees(sp.compass_bias(sp.read_bias_frame(values, self.bias_key)))
        out["beacon_init"] = {bid: p.tolist() for bid, p in self.beacon_init.items()}
        out["beacon_estimates"] = {bid: sp.landmark_xy(values, F.L(i)).tolist()
                                   for bid, i in self.beacon_ids.items() if values.exists(F.L(i))}
        return out

    def add(self, s: Step, k: int, due: list[tuple[int, Record]], pose_k: gtsam.Pose2,
            prev_cov: NDArray[np.float64] | None, prev: gtsam.Pose2 | None,
            offset: Callable[[int, float, int], gtsam.Pose2 | None],
            est: Callable[[int], gtsam.Pose2] | None = None) -> None:
        """The factors of the records ``due`` at keyframe ``k`` (each ``(a, record)``: attached to
        keyframe ``a``, ``k`` or ``k-1``; with ``est``, any earlier one). ``prev_cov``: the online GNSS
        gate's prediction covariance (``None``: no gate); ``offset(a, t, k)``: the motion from keyframe
        ``a`` to time ``t`` (the attachment's compensation)."""
        cfg = self.cfg

        def at(a: int) -> gtsam.Pose2:
            if est is not None:
                return est(a)
            return pose_k if a == k else prev  # a is k or k-1

        for a, r in due:
            xa = F.X(a)
            delta = offset(a, r.t, k) if cfg.keyframe.compensate_attachment else None
            if isinstance(r, Gnss):
                self._gnss(s, xa, r, at(a), prev_cov, delta)
            elif isinstance(r, Heading):
                sig = r.sigma * cfg.compass.sigma_scale
                yaw = r.yaw - (delta.theta() if delta is not None else 0.0)
                if cfg.compass.bias and self.bias_key is None:  # the bias frame, with the first reading
                    self.bias_key = F.B(0)
                    s.values.insert(self.bias_key, self.space.bias_frame())
                    s.stamps[self.bias_key] = s.t
                    s.add(self.space.bias_prior(self.bias_key, math.radians(cfg.compass.bias_sigma_deg)), "bias")
                if self.bias_key is not None:
                    self._bias_segment(s)
                    s.add(self.space.biased_compass(self.bias_key, xa, yaw, sig, cfg.compass.robust), "compass")
                else:
                    s.add(self.space.compass(xa, yaw, sig, cfg.compass.robust), "compass")
            elif isinstance(r, WaterSpeed):
                if not self.nav:  # the planar graph has no velocity variable
                    self.counts["ignored"] += 1
                    continue
                self.water.reading(s, a, at(a).theta(), r)
            elif isinstance(r, GnssVelocity):
                if not self.nav:  # the planar graph has no velocity variable
                    self.counts["ignored"] += 1
                    continue
                sv = r.sigma if math.isfinite(r.sigma) else cfg.gnss.velocity_sigma
                if not math.isfinite(r.sigma):
                    self.defaulted.add("gnss_velocity")
                s.add(self.space.velocity(a, r.vx, r.vy, sv, cfg.gnss.robust), "gnss_velocity")
            elif isinstance(r, Attitude):
                if not self.nav:  # the planar graph has no roll and pitch
                    self.counts["ignored"] += 1
                    continue
                sa = r.sigma if math.isfinite(r.sigma) else math.radians(cfg.compass.attitude_sigma_deg)
                if not math.isfinite(r.sigma):
                    self.defaulted.add("attitude")
                s.add(self.space.attitude(xa, r.roll, r.pitch, sa), "attitude")
            elif isinstance(r, BeaconObs):
                self._beacon(s, xa, at(a), r, delta)
            elif isinstance(r, PosePrior):
                sig = np.array([r.sigma_xy, r.sigma_xy, r.sigma_yaw])
                s.add(self.space.prior(xa, np.array([r.x, r.y, r.yaw]), sig), "pose_prior")

    def _gnss(self, s: Step, xa: int, r: Gnss, pa: gtsam.Pose2, prev_cov: NDArray[np.float64] | None,
              delta: gtsam.Pose2 | None) -> None:
        """A GNSS fix on keyframe ``xa`` (pose ``pa``; ``delta``: the motion from it to the fix's time):
        moved back to the keyframe, its online variance scale (:class:`GnssScale`) applied, gated online
        against the prediction of covariance ``prev_cov`` (the Pose2 graph; ``None``: no gate). The closing
        step gets the fix at its stated sigma (and judges it in its own way: ``graph.solution``)."""
        cfg = self.cfg
        rx, ry = r.x, r.y
        arm3 = self.arms.get(r.source) or self.arms.get("")
        arm = (0.0, 0.0) if arm3 is None else arm3[:2]
        ant = F.antenna_position(pa, arm)  # (the keyframe's antenna: the fix's move and the gate's prediction)
        if delta is not None:  # the fix is of the antenna of X_a * delta at r.t: move it back to X_a's
            moved = F.antenna_position(pa.compose(delta), arm) - ant
            rx, ry = rx - float(moved[0]), ry - float(moved[1])
        scale = self.gnss_scale.scale
        sigma = r.sigma * math.sqrt(scale)  # the stated sigma, unless the fixes refute it
        stated = self.space.gnss(xa, rx, ry, r.sigma, cfg.gnss.robust, cfg.gnss.k, arm3)
        if prev_cov is not None and id(r) not in self.after_outage:
            d = np.array([rx - ant[0], ry - ant[1]])
            sample = (d, prev_cov[:2, :2], r.sigma)
            if self.gate is None:
                self.gnss_scale.add(*sample)
            else:  # the scale learns from accepted fixes and lone rejections, never from a jump (graph.fix_gate)
                ok = self.gate.accept(d, prev_cov[:2, :2] + sigma**2 * np.eye(2), sigma**2, sample)
                if self.gate.lone is not None:
                    self.gnss_scale.add(*self.gate.lone)
                if not ok:
                    self.rejected.append(stated)
                    return
                self.gnss_scale.add(*sample)
            if self.gate is not None and self.gate.taken_back:  # a re-acquisition: the run's fixes count again
                n, self.gate.taken_back = self.gate.taken_back, 0
                s.reacquired = True
                back, self.rejected[-n:] = self.rejected[-n:], []
                s.take_back(back, window=cfg.solver == "fixed-lag")
        elif self.gate is not None:
            self.gate.passed()
            s.restarted = True
        self.after_outage.discard(id(r))
        if scale == 1.0:
            s.add(stated, "gnss")
        else:
            s.add(self.space.gnss(xa, rx, ry, sigma, cfg.gnss.robust, cfg.gnss.k, arm3), "gnss", closing=stated)

    def _beacon(self, s: Step, xa: int, pa: gtsam.Pose2, r: BeaconObs, delta: gtsam.Pose2 | None) -> None:
        cfg = self.cfg
        charted = self.charted.get(r.id)
        if charted is None and not cfg.beacon.unknown:
            return
        rng_, brg = r.range, r.bearing
        if delta is not None:  # the sighting from X_a * delta, as seen from X_a
            ba = delta.transformFrom(np.array([rng_ * math.cos(brg), rng_ * math.sin(brg)]))
            rng_, brg = float(np.hypot(ba[0], ba[1])), math.atan2(ba[1], ba[0])
        if r.id not in self.beacon_ids:
            i = len(self.beacon_ids)
            self.beacon_ids[r.id] = i
            lk = F.L(i)
            if charted is not None:
                p0 = np.array([charted.x, charted.y])
                s.add(self.space.landmark_prior(lk, charted.x, charted.y, charted.sigma), "chart")
            else:
                p0 = F.init_from_sighting(np.array([pa.x(), pa.y(), pa.theta()]), rng_, brg)
            self.beacon_init[r.id] = p0
            s.values.insert(lk, self.space.landmark(p0))
            if charted is None and self.nav:  # an unknown mark: at the sea surface
                s.add(self.space.landmark_prior(lk, float(p0[0]), float(p0[1]), 1e4), "chart")
        if not (math.isfinite(r.sigma_range) and math.isfinite(r.sigma_bearing)):
            self.defaulted.add("beacon")
        sr = r.sigma_range if math.isfinite(r.sigma_range) else math.hypot(cfg.beacon.sigma_range,
                                                                           cfg.beacon.sigma_range_rel * r.range)
        sb = r.sigma_bearing if math.isfinite(r.sigma_bearing) else math.radians(cfg.beacon.sigma_bearing_deg)
        tilt = self.tilt_of(xa) if self.tilt_of is not None else None
        s.add(self.space.beacon(xa, F.L(self.beacon_ids[r.id]), rng_, brg, sr, sb, cfg.beacon.robust, cfg.beacon.k,
                                tilt), "beacon")

    def _bias_segment(self, s: Step) -> None:
        """A new compass-bias variable once the newest one has taken ``compass.bias_segment_s`` of readings,
        tied to it by the random walk ``compass.bias_drift_deg`` (:class:`CompassConfig`)."""
        seg = self.cfg.compass.bias_segment_s
        if self.bias_key is None or seg is None:
            return
        if self.bias_t0 is None:
            self.bias_t0 = s.t
            return
        if s.t - self.bias_t0 < seg:
            return
        new = F.B(self.bias_segments)
        s.values.insert(new, self.space.bias_frame())
        s.stamps[new] = s.t
        sigma = math.radians(self.cfg.compass.bias_drift_deg) * math.sqrt(s.t - self.bias_t0)
        s.add(self.space.bias_between(self.bias_key, new, sigma), "bias")
        self.bias_key, self.bias_t0 = new, s.t
        self.bias_segments += 1
