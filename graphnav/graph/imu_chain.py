"""The IMU between keyframes: samples buffered as they arrive, preintegrated over a keyframe
interval with GTSAM (``PreintegratedImuMeasurements``; Forster et al. 2017, eq. 33-38) into an
``ImuFactor`` and a prediction of the next state.

Each ``imu`` record is the mean over the interval since the previous one (docs/log-format.md), so
a sample is held over ``(t_prev, t]`` and clipped to the keyframe interval; where the stream has a
gap, or the sample closing an interval has not arrived yet, the last sample is held (zero-order hold). Planar 3-axis
records are the levelled horizontal specific force with gravity removed (gravity off,
gravity off); a log whose records carry all six axes is preintegrated
in 3D with gravity (``n_gravity``, z up).

Where an interval takes a share of a record (or holds one beyond its time) the rate's change within it
adds to the noise (:meth:`ImuChain.hold_variance`); the keyframes wait for a slow IMU's records so that
this stays rare (:meth:`graphnav.graph.keyframes.Keyframes.at_imu_record`).

The noise is the log's stated IMU model (``meta["imu"]``: ``acc_std`` [m/s^2] and ``gyro_std``
[rad/s] per sample at ``hz``) when it has one, else :class:`ImuConfig`'s; as continuous densities
``sigma^2 / hz`` the integrated error does not depend on the sample rate.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

import factors as F

from ..log import Imu, Limits, Odometry
from .order_stats import median

GRAVITY = 9.80665  # [m/s^2] standard gravity (6-axis records)
#: the record pieces covering an interval (:meth:`ImuChain._pieces`): record indices, each piece's start and end [s]
Pieces = tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]
#: the records an interval's pieces read (:func:`_window`): the first one's index, the rows as an array
Window = tuple[int, NDArray[np.float64]]
#: :meth:`ImuChain.hold_variance`: the variance per accelerometer axis, per gyro axis, of the position
Hold = tuple[NDArray[np.float64], NDArray[np.float64], float]


@dataclass
class ImuConfig:
    """The IMU's error model where the log states none (``[imu]`` section of the graph's options)."""

    acc_sigma: float = 0.02  # [m/s^2] white noise per sample at ``hz`` (a MEMS IMU's datasheet order)
    gyro_sigma_deg: float = 0.05  # [deg/s] white noise per sample
    hz: float = 100.0  # the rate those sigmas are stated at
    integration_sigma: float = 1e-3  # [m/sqrt(s)] position integration error
    bias_sigma_acc: float = 0.05  # [m/s^2] residual accelerometer bias after calibration (prior)
    bias_sigma_gyro_deg: float = 0.1  # [deg/s] residual gyro bias (prior)
    bias_rw_acc: float = 1e-4  # [m/s^2/sqrt(s)] bias random walk
    bias_rw_gyro_deg: float = 1e-3  # [deg/s/sqrt(s)]
    substeps: int = 1  # integration steps per sample (4 for slow IMUs: the acceleration turns within a sample)
    # without IMU records (motion "vessel"): the velocity is a random walk in the world frame, driven by
    # white-noise acceleration, and the heading a random walk apart from it (course != heading)
    vessel_accel: float = 0.3  # [m/s^2/sqrt(s)] a vessel's manoeuvring acceleration density
    vessel_yaw_rate_deg: float = 5.0  # [deg/s/sqrt(s)] ... and yaw-rate density under way, growing at low speed:
    vessel_steerage_speed: float = 1.0  # [m/s] below this the yaw-rate density is x (this / speed), at most x10:
    #  a hull's yaw is damped in proportion to its speed through the water; stopped or drifting, wind and
    #  waves turn it freely (and a boat going astern or drifting sideways is neither of the two)
    vessel_position_walk: float | None = None  # [m/sqrt(s)] the position's random walk apart from the velocity
    #  (the fixes wandering from the integrated SOG/COG); None: the log's (graphnav.graph.position_walk: fixes
    #  against GNSS velocity records), else integration_sigma. psaros33-20140805-0020's fixes: 0.44
    #  (docs/smoother.md, "Where the NEES came from")
    vessel_rot: bool = True  # a rate of turn (meta["odometry"] == ODOMETRY_FROM_ROT) is the vessel model's gyro z
    #  sample (:class:`RotChain`); its bias the gyro-z bias state (bias_sigma_gyro_deg, bias_rw_gyro_deg)


#: a rate-of-turn indicator's stated accuracy (IMO A.526(13), 10: within 0.5 deg/min plus 5 % of the indicated
#: rate), the 1-sigma of a ROT record that states none (NMEA 0183 ROT, NMEA 2000 127251, Signal K rateOfTurn)
ROT_ACCURACY_DEG_MIN = 0.5
ROT_ACCURACY_REL = 0.05
#: [s] a ROT record is held at most this long beyond the one before it or the newest (as the graph's
#: ODOMETRY_FRESH_S): an interval with a longer gap takes the vessel model's yaw-rate walk instead
ROT_FRESH_S = 2.0
#: [rad/s] a larger rate of turn is no measurement (the file readers' bound, Limits.max_yaw_rate: 2000 deg/s,
#: the largest MEMS gyro full scale); records handed to the API are only checked for finiteness
ROT_MAX = Limits().max_yaw_rate


def rot_sigma(rec: Odometry) -> float:
    """[rad/s] a ROT record's 1-sigma: its stated ``sigma_w``, else the indicator's accuracy
    (:data:`ROT_ACCURACY_DEG_MIN` + :data:`ROT_ACCURACY_REL` x the rate)."""
    if math.isfinite(rec.sigma_w) and rec.sigma_w > 0.0:
        return float(rec.sigma_w)
    return math.radians(ROT_ACCURACY_DEG_MIN / 60.0) + ROT_ACCURACY_REL * abs(rec.w)


def rot_bias(cfg: ImuConfig) -> tuple[float, float]:
    """The ROT gyro's bias model, the graph's gyro-z bias state: its prior 1-sigma [rad/s] and random walk
    [rad/s/sqrt(s)] (:class:`ImuConfig` ``bias_sigma_gyro_deg``, ``bias_rw_gyro_deg``; the vessel EKF's too)."""
    return math.radians(cfg.bias_sigma_gyro_deg), math.radians(cfg.bias_rw_gyro_deg)


def yaw_rate_scale(speed: float | None, steerage: float) -> float:
    """The vessel model's yaw-rate density factor at ``speed`` through the water [m/s]: 1 at or above the
    steerage speed, ``steerage / speed`` below it, at most 10 (:class:`ImuConfig`; the vessel EKF's too)."""
    if speed is None or not math.isfinite(speed) or speed >= steerage:
        return 1.0
    return min(steerage / max(speed, 1e-3), 10.0)


class ImuChain:
    """IMU samples in, per-interval preintegration out (see the module docstring)."""

    def __init__(self, cfg: ImuConfig, stated: dict[str, Any] | None = None) -> None:
        self.cfg = cfg
        self.std: tuple[float, float, float | None] = (cfg.acc_sigma, math.radians(cfg.gyro_sigma_deg), cfg.hz)
        self.source = "config"
        if isinstance(stated, dict) and all(k in stated for k in ("acc_std", "gyro_std")):
            hz = stated.get("hz")  # without it: the records' own rate
            self.std = (float(stated["acc_std"]), float(stated["gyro_std"]), float(hz) if hz else None)
            self.source = "log"
        self.t: list[float] = []
        self.rows: list[tuple[float, ...]] = []  # ax, ay, az, wx, wy, wz
        self.cum: list[float] = []  # the integrated gyro rate's norm up to each t [rad] (the keyframe rule)
        self.six: bool | None = None
        self._period: tuple[tuple[int, float] | None, float] = (None, 0.0)  # (len(t), t[-1]) -> period()
        self.params: gtsam.PreintegrationParams | None = None
        self._densities: tuple[Any, ...] = (None,)  # (:func:`_densities` of the parameters in use)
        self.body_P_sensor: gtsam.Pose3 | None = None  # the IMU's mount (graphnav.graph.mounts), when not at the origin
        walk = cfg.vessel_position_walk
        #: the log's estimate of it (graphnav.graph.position_walk), when made and used
        self.walk_estimate: dict[str, Any] | None = None
        if walk is None and isinstance(stated, dict) and stated.get("vessel_position_walk") is not None:
            walk = stated["vessel_position_walk"]
            self.walk_estimate = stated.get("position_walk")
        #: [m/sqrt(s)] the vessel model's position random walk (its integration noise)
        self.vessel_walk = max(float(walk), cfg.integration_sigma) if walk is not None else cfg.integration_sigma
        self.vessel_params = self._vessel_set(1.0)  # no IMU: zero measurements, the vessel model's noise
        self._vessel_by_scale: dict[float, gtsam.PreintegrationParams] = {1.0: self.vessel_params}
        #: the vessel model's ROT records (:meth:`add_rot`; ``None``: none)
        self.rot: RotChain | None = None

    def add_rot(self, rec: Odometry) -> None:
        """A rate of turn (``rec.w``; its speed is a SOG, not used): the vessel model's gyro z sample."""
        if self.rot is None:
            self.rot = RotChain(self.cfg)
        self.rot.add_rot(rec)

    def _vessel_set(self, scale: float) -> gtsam.PreintegrationParams:
        """The vessel model's parameters with the yaw-rate density x ``scale``."""
        c = self.cfg
        p = gtsam.PreintegrationParams.MakeSharedU(0.0)
        p.setAccelerometerCovariance(np.eye(3) * c.vessel_accel**2)
        p.setGyroscopeCovariance(np.eye(3) * (scale * math.radians(c.vessel_yaw_rate_deg)) ** 2)
        p.setIntegrationCovariance(np.eye(3) * self.vessel_walk**2)
        return p

    def set_vessel_walk(self, walk: float, estimate: dict[str, Any] | None = None) -> None:
        """A new position random walk for the vessel factors made from now on (live mode's running
        estimate, graphnav.online.warmup): fresh parameter sets, those of the factors already made untouched."""
        self.vessel_walk = max(float(walk), self.cfg.integration_sigma)
        self.walk_estimate = estimate
        self.vessel_params = self._vessel_set(1.0)
        self._vessel_by_scale = {1.0: self.vessel_params}

    def _vessel(self, speed: float | None) -> gtsam.PreintegrationParams:
        """The vessel model's parameters at ``speed``: the yaw-rate density x ``steerage / speed`` (1 to 10,
        in steps of 0.5 so that a handful of parameter sets serve a whole log)."""
        s = yaw_rate_scale(speed, self.cfg.vessel_steerage_speed)
        if s == 1.0:
            return self.vessel_params
        scale = round(s * 2) / 2
        if scale not in self._vessel_by_scale:
            self._vessel_by_scale[scale] = self._vessel_set(scale)
        return self._vessel_by_scale[scale]

    def __bool__(self) -> bool:
        return bool(self.t)

    def _make_params(self, acc_density: NDArray[np.float64] | None = None,
                     gyro_density: NDArray[np.float64] | None = None,
                     integration_density: float | None = None) -> gtsam.PreintegrationParams:
        """Preintegration parameters with the noise densities ``std^2 / rate`` [per s] (or the per-axis
        densities given)."""
        acc, gyro, hz = self.std
        rate = hz if hz else 1.0 / max(self.period(), 1e-6)
        p = gtsam.PreintegrationParams.MakeSharedU(GRAVITY if self.six else 0.0)
        p.setAccelerometerCovariance(np.diag(acc_density) if acc_density is not None else np.eye(3) * acc**2 / rate)
        p.setGyroscopeCovariance(np.diag(gyro_density) if gyro_density is not None else np.eye(3) * gyro**2 / rate)
        p.setIntegrationCovariance(np.eye(3) * (integration_density if integration_density is not None
                                                else self.cfg.integration_sigma**2))
        if self.body_P_sensor is not None:  # GTSAM rotates the samples and removes the centripetal term
            p.setBodyPSensor(self.body_P_sensor)
        return p

    def period(self) -> float:
        """The median interval of the records so far [s] (1 / ``hz`` of the config before two)."""
        if len(self.t) < 2:
            return 1.0 / self.cfg.hz
        key = (len(self.t), self.t[-1])  # (samples are appended in time order and pruned from the front only)
        if self._period[0] != key:
            t = self.t[-200:]
            self._period = (key, median([b - a for a, b in zip(t[:-1], t[1:], strict=True)]))  # (np.median of np.diff)
        return self._period[1]

    def add(self, r: Imu) -> None:
        self.extend((r,))

    def extend(self, recs: Iterable[Imu]) -> None:
        """IMU records in arrival order (one at the newest time replaces it; an older one is dropped: the
        interval it covers is held by its neighbour)."""
        ts, rows, cum = self.t, self.rows, self.cum
        for r in recs:
            six = r.six_axis
            if self.six is None:
                self.six = six
            row = (r.ax, r.ay, r.az, r.wx, r.wy, r.wz) if six else (r.ax, r.ay, 0.0, 0.0, 0.0, r.wz)
            rate = math.sqrt(row[3] ** 2 + row[4] ** 2 + row[5] ** 2)
            if ts and r.t <= ts[-1]:
                if r.t == ts[-1]:
                    rows[-1] = row
                    if len(ts) > 1:
                        cum[-1] = cum[-2] + rate * (ts[-1] - ts[-2])
                continue
            cum.append(cum[-1] + rate * (r.t - ts[-1]) if ts else 0.0)
            ts.append(r.t)
            rows.append(row)

    def samples(self, ta: float, tb: float) -> list[tuple[NDArray[np.float64], NDArray[np.float64], float]]:
        """``(acc, omega, dt)`` over ``[ta, tb]``: each record held over the interval since the
        previous one, the last one held on to ``tb`` (zero-order hold over a gap or a late sample)."""
        acc, omega, dt = self._arrays(self._pieces(ta, tb))
        return [(acc[k], omega[k], float(dt[k])) for k in range(len(dt))]

    def _arrays(self, pieces: Pieces, window: Window | None = None
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`samples` of the ``pieces`` (:meth:`_pieces`) as arrays: ``acc``, ``omega`` (n, 3), ``dt`` (n,);
        ``window``: their :func:`_window`, converted once for this and :func:`_hold`."""
        idx, lo, hi = pieces
        if not len(idx):
            return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
        b0, rows = window or (int(idx[0]), np.asarray(self.rows[int(idx[0]):int(idx[-1]) + 1], dtype=float))
        rows = rows[idx - b0]
        return rows[:, :3], rows[:, 3:], hi - lo

    def _pieces(self, ta: float, tb: float) -> Pieces:
        """Record indices with the ``lo``, ``hi`` of their pieces covering ``[ta, tb]``: record ``i`` over
        its share of ``(t[i-1], t[i]]``, the newest one held beyond its time (one more piece)."""
        n = len(self.t)
        if not n or tb <= ta + 1e-12:
            return np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0)
        i0 = bisect.bisect_right(self.t, ta)
        if i0 >= n:  # the whole interval beyond the newest record: it is held
            return np.array([n - 1], dtype=np.int64), np.array([ta]), np.array([tb])
        ie = bisect.bisect_left(self.t, tb, lo=i0)  # the first record at or after tb (n: none)
        idx = np.arange(i0, min(ie, n - 1) + 1, dtype=np.int64)
        off = max(i0 - 1, 0)
        t = np.asarray(self.t[off:int(idx[-1]) + 1], dtype=float)
        lo = np.maximum(t[np.maximum(idx - 1 - off, 0)], ta)  # each record from its predecessor's time ...
        lo[0] = ta  # ... the first from ta
        hi = np.minimum(t[idx - off], tb)
        if ie >= n:  # beyond the newest record: it is held on to tb
            idx, lo, hi = np.append(idx, n - 1), np.append(lo, self.t[-1]), np.append(hi, tb)
        keep = hi > lo
        return idx[keep], lo[keep], hi[keep]

    def hold_variance(self, ta: float, tb: float) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        """The variance [per axis: (m/s)^2 and rad^2] that holding the records' means over ``[ta, tb]``
        adds to the integrated specific force and rate: zero where the interval covers records whole.

        A record is the mean over ``(t[i-1], t[i]]`` (length ``T``); where the interval takes a share
        ``f`` of it, the true integral over that share differs from ``f T`` x the mean by the rate's
        variation within the record. With the quantity changing linearly by ``v`` over ``T`` (``v``: the
        larger step to a neighbouring record, the data's own measure of it) that error is
        ``v T f (1 - f) / 2`` (the integral of ``v (tau - 1/2)`` over ``[0, f]``), taken as one sigma.
        Beyond the newest record (a late sample or a gap, held over ``d``) the quantity drifts by about
        ``v d / T``: the error ``v d^2 / (2 T)``. Negligible for a fast IMU (``v`` small), it is what a
        slow one (1 Hz) gets wrong through a turn's reversal (docs/smoother.md).

        The third value [m^2] is the position's: even over whole records the double integral depends on
        how the specific force is spread within each, ``v_a T^2 f^3 / 12`` for a share ``f`` (the integral
        of ``(d - tau) v_a (tau / d - 1/2) f`` over the share's length ``d = f T``), summed over the axes."""
        return _hold(self.t, self.rows, self._pieces(ta, tb))

    def rotation(self, ta: float, tb: float) -> float:
        """An upper bound of the rotation over ``[ta, tb]`` [rad]: the integrated gyro rate's norm (each
        record held over the interval since the previous one, the last one beyond it)."""
        return max(self._cum_at(tb) - self._cum_at(ta), 0.0) if self.t else 0.0

    def _cum_at(self, t: float) -> float:
        i = bisect.bisect_left(self.t, t)
        if i >= len(self.t):  # beyond the newest sample: held
            r = self.rows[-1]
            return self.cum[-1] + math.sqrt(r[3] ** 2 + r[4] ** 2 + r[5] ** 2) * (t - self.t[-1])
        r = self.rows[i]
        return self.cum[i] - math.sqrt(r[3] ** 2 + r[4] ** 2 + r[5] ** 2) * (self.t[i] - t)

    def preintegrate(self, bias: gtsam.imuBias.ConstantBias, ta: float, tb: float, speed: float | None = None
                     ) -> gtsam.PreintegratedImuMeasurements:
        """GTSAM preintegration of ``[ta, tb]`` at ``bias`` (:func:`factors.imu.preintegrate`: planar
        records with the acceleration at the mid-step attitude, second order as the constant-turn arc).
        Without IMU records, the vessel model's white noise; ``speed`` [m/s] (the start's) scales its
        yaw-rate density at low speed (:class:`ImuConfig`)."""
        if self.params is None and self.t and (len(self.t) >= 2 or self.std[2]):
            self.params = self._make_params()
        if self.params is None:  # no IMU: the white-noise acceleration model
            yaw = self.rot.interval(ta, tb) if self.rot is not None else None
            if yaw is not None:  # ... its yaw rate the ROT's
                return self._rot_preintegrate(bias, yaw, self._vessel(speed))
            pim = gtsam.PreintegratedImuMeasurements(self._vessel(speed), bias)
            if tb > ta:
                pim.integrateMeasurement(np.asarray(bias.accelerometer()), np.asarray(bias.gyroscope()), tb - ta)
            return pim
        pieces = self._pieces(ta, tb)
        window = _window(self.rows, pieces)
        return F.preintegrate_arrays(self._held_params(pieces, tb - ta, window), bias, *self._arrays(pieces, window),
                                     self.cfg.substeps, planar=not self.six)

    def _rot_preintegrate(self, bias: gtsam.imuBias.ConstantBias, yaw: tuple[NDArray[np.float64], NDArray[np.float64],
                          float], base: gtsam.PreintegrationParams) -> gtsam.PreintegratedImuMeasurements:
        """The vessel model over an interval that ROT records cover (:meth:`RotChain.interval`: each piece's rate
        and length, the yaw's variance): the ROT's rates as the gyro z samples (so the z bias state is the ROT's
        bias), its variance as the gyro z density; acceleration and roll/pitch rate ``base``'s walks."""
        w, dt, var = yaw
        g = np.diag(base.getGyroscopeCovariance()).copy()
        g[2] = var / float(dt.sum())
        p = gtsam.PreintegrationParams.MakeSharedU(0.0)
        p.setAccelerometerCovariance(base.getAccelerometerCovariance())
        p.setGyroscopeCovariance(np.diag(g))
        p.setIntegrationCovariance(base.getIntegrationCovariance())
        pim = gtsam.PreintegratedImuMeasurements(p, bias)
        acc, b = np.asarray(bias.accelerometer()), np.asarray(bias.gyroscope())
        for wk, dk in zip(w, dt, strict=True):
            pim.integrateMeasurement(acc, np.array([b[0], b[1], wk]), float(dk))
        return pim

    def _held_params(self, pieces: Pieces, T: float, window: Window | None = None) -> gtsam.PreintegrationParams:
        """The parameters for an interval of ``T`` seconds made of ``pieces`` (``window``: their :func:`_window`):
        the shared ones, or with the densities raised by :meth:`hold_variance` where that is not negligible (1 % of
        the interval's white-noise variance on some axis)."""
        assert self.params is not None
        if T <= 0.0:
            return self.params
        va, vg, vp = _hold(self.t, self.rows, pieces, window)
        if self._densities[0] is not self.params:  # (read once per parameters: GTSAM copies each matrix out)
            self._densities = _densities(self.params)
        _, acc, gyro, ip = self._densities
        if not ((va > 0.01 * acc * T).any() or (vg > 0.01 * gyro * T).any() or vp > 0.01 * ip * T):
            return self.params
        return self._make_params(acc + va / T, gyro + vg / T, ip + vp / T)

    def tilt(self, t: float, window: float = 1.0) -> tuple[float, float] | None:
        """Roll and pitch [rad] of a 6-axis IMU from the gravity direction: the mean specific force of its
        records over ``window`` s up to ``t`` (at rest ``f = g (-sin p, sin r cos p, cos r cos p)``); ``None``
        for planar records or none yet. A moving hull's accelerations bias it by about ``|a| / g``."""
        if not self.six or not self.t:
            return None
        hi = bisect.bisect_right(self.t, t)
        lo = bisect.bisect_left(self.t, self.t[max(hi - 1, 0)] - window)
        rows = np.asarray(self.rows[lo:max(hi, lo + 1)], dtype=float)
        fx, fy, fz = rows[:, :3].mean(axis=0)
        if not np.isfinite([fx, fy, fz]).all() or fz <= 0.0:
            return None
        return float(math.atan2(fy, fz)), float(math.atan2(-fx, math.hypot(fy, fz)))

    def prune(self, t: float) -> None:
        """Drop samples no later interval can need (all before the last one at or before ``t``)."""
        if self.rot is not None:
            self.rot.prune(t)
        i = bisect.bisect_right(self.t, t) - 1
        if i > 1024:
            del self.t[:i - 1]
            del self.rows[:i - 1]
            del self.cum[:i - 1]

    def _axes(self) -> NDArray[np.float64]:
        """Per bias axis (acc x, y, z, gyro x, y, z): 1 where the records measure it; a planar record
        does not measure az, wx, wy (they are exactly 0): their bias prior is a tenth (nothing else
        observes them; tighter, the marginals' Cholesky factorisation failed near the bias variables)."""
        return np.ones(6) if self.six else np.array([1, 1, 0.1, 0.1, 0.1, 1.0])

    def bias_prior(self, k: int) -> gtsam.NonlinearFactor:
        c, ax = self.cfg, self._axes()
        return F.bias_prior(k, c.bias_sigma_acc * ax[:3], math.radians(c.bias_sigma_gyro_deg) * ax[3:])

    def bias_between(self, k0: int, k1: int, dt: float) -> gtsam.NonlinearFactor:
        c = self.cfg
        return F.bias_between(k0, k1, c.bias_rw_acc, math.radians(c.bias_rw_gyro_deg), dt)


def _hold(t_all: list[float], rows_all: list[tuple[float, ...]], pieces: Pieces, window: Window | None = None) -> Hold:
    """:meth:`ImuChain.hold_variance` of the records ``t_all``, ``rows_all`` over ``pieces`` (:meth:`ImuChain._pieces`;
    ``window``: their :func:`_window`)."""
    idx, lo, hi = pieces
    first = idx > 0  # the first record's interval is unknown
    if not first.all():  # (a mask that keeps every row is skipped here and below: the same arrays)
        idx, lo, hi = idx[first], lo[first], hi[first]
    if not len(idx):
        return np.zeros(3), np.zeros(3), 0.0
    n = len(t_all)
    k0, k1 = int(idx[0]) - 1, min(int(idx[-1]) + 2, n)  # the records the pieces and their neighbours use
    t = np.asarray(t_all[k0:k1], dtype=float)
    rows = np.asarray(rows_all[k0:k1], dtype=float) if window is None else window[1][k0 - window[0]:k1 - window[0]]
    j = idx - k0
    T = t[j] - t[j - 1]
    ok = T > 0.0
    if not ok.all():
        j, lo, hi, T = j[ok], lo[ok], hi[ok], T[ok]
    ti = t[j]
    step = np.abs(np.diff(rows, axis=0))  # |rows[i + 1] - rows[i]|
    v = step[j - 1]
    has_next = j + 1 < len(t)
    if has_next.all():
        v = np.maximum(v, step[j])
    else:
        v[has_next] = np.maximum(v[has_next], step[j[has_next]])
    share_of = (hi - lo) / T
    f_all = np.minimum(share_of, 1.0)
    vp = float(np.sum((v[:, :3] * (T * T * f_all**3 / 12.0)[:, None]) ** 2))
    beyond = hi > ti + 1e-12  # held beyond the newest record: extrapolated ...
    if beyond.any():
        d = np.where(beyond, hi - np.maximum(lo, ti), 0.0)
        f = np.where(beyond, np.clip((ti - lo) / T, 0.0, 1.0), share_of)  # ... and its share before that
        share = np.where(f >= 1.0 - 1e-9, 0.0, T * f * (1.0 - f) / 2.0)
        e2 = v**2 * ((d * d / (2.0 * T)) ** 2 + share**2)[:, None]
    else:  # (d = 0: the same sums)
        share = np.where(share_of >= 1.0 - 1e-9, 0.0, T * share_of * (1.0 - share_of) / 2.0)
        e2 = v**2 * (share**2)[:, None]
    va, vg = e2[:, :3].sum(axis=0), e2[:, 3:].sum(axis=0)
    return va, vg, vp


def _window(rows: list[tuple[float, ...]], pieces: Pieces) -> Window | None:
    """The records :meth:`ImuChain._arrays` and :func:`_hold` read for ``pieces`` (those of the pieces and
    their neighbours) as one array: ``(first index, rows)``, the same floats either converts alone (``None``: no
    pieces)."""
    idx = pieces[0]
    if not len(idx):
        return None
    b0 = max(int(idx[0]) - 1, 0)
    return b0, np.asarray(rows[b0:min(int(idx[-1]) + 2, len(rows))], dtype=float)


def _densities(params: gtsam.PreintegrationParams) -> tuple[Any, NDArray[np.float64], NDArray[np.float64], float]:
    """``(params, the accelerometer's and the gyro's density diagonals, the integration density)``."""
    return (params, np.diag(params.getAccelerometerCovariance()), np.diag(params.getGyroscopeCovariance()),
            float(params.getIntegrationCovariance()[0, 0]))


class RotChain(ImuChain):
    """A rate-of-turn sensor's records (NMEA 0183 ROT, NMEA 2000 127251, Signal K rateOfTurn, a simulator's ROT
    gyro), the vessel model's gyro z: each record the mean rate over the interval since the previous one,
    held as :class:`ImuChain`'s records are (its hold variance too), and its own 1-sigma (:func:`rot_sigma`)
    white at the records' rate: the yaw over an interval has the variance ``sum sigma_i^2 dt_i / rate``.
    One sensor: the first source's records (a second one, often the same sensor's rate relayed by another
    device, would count its noise twice); the others are counted in ``ignored``."""

    def __init__(self, cfg: ImuConfig) -> None:
        super().__init__(cfg)
        self.sigma: list[float] = []
        self.source: str | None = None
        self.ignored = 0
        self.implausible = 0  # records beyond ROT_MAX: left out

    def add_rot(self, rec: Odometry) -> None:
        """One ROT record (out of order: dropped; at the newest time: replaces it)."""
        n = len(self.t)
        if self.source is None:
            self.source = rec.source
        if not math.isfinite(rec.w) or rec.source != self.source:
            self.ignored += 1
            return
        if abs(rec.w) > ROT_MAX:  # beyond any gyro's full scale (the API checks finiteness only): a corrupt record
            self.implausible += 1
            return
        self.add(Imu(rec.t, 0.0, 0.0, float(rec.w)))
        if len(self.t) > n:
            self.sigma.append(rot_sigma(rec))
        elif self.t and rec.t == self.t[-1]:
            self.sigma[-1] = rot_sigma(rec)

    def prune(self, t: float) -> None:
        n = len(self.t)
        super().prune(t)
        del self.sigma[:n - len(self.t)]

    def covers(self, ta: float, tb: float) -> bool:
        """Whether the records cover ``[ta, tb]``: one at or before ``ta``, none of the records over it
        (nor the hold beyond the newest) longer than :data:`ROT_FRESH_S`."""
        t, n = self.t, len(self.t)
        if n < 2 or t[0] > ta or tb - t[-1] > ROT_FRESH_S:
            return False
        i0 = bisect.bisect_right(t, ta) - 1
        i1 = min(bisect.bisect_left(t, tb, lo=i0), n - 1)
        return i1 <= i0 or float(np.max(np.diff(t[i0:i1 + 1]))) <= ROT_FRESH_S

    def interval(self, ta: float, tb: float) -> tuple[NDArray[np.float64], NDArray[np.float64], float] | None:
        """The rates [rad/s] and lengths [s] of the pieces covering ``[ta, tb]`` and the integrated yaw's
        variance [rad^2] (white noise at the records' rate plus :meth:`hold_variance`'s); ``None`` where the
        records do not cover it (:meth:`covers`)."""
        if tb <= ta or not self.covers(ta, tb):
            return None
        pieces = self._pieces(ta, tb)
        idx, lo, hi = pieces
        dt = hi - lo
        sig = np.asarray(self.sigma[int(idx[0]):int(idx[-1]) + 1], dtype=float)[idx - idx[0]]
        var = float(np.sum(sig**2 * dt)) * self.period() + float(_hold(self.t, self.rows, pieces)[1][2])
        _, omega, _ = self._arrays(pieces)
        return omega[:, 2].copy(), dt, var


def relative_prediction(pim: gtsam.PreintegratedImuMeasurements, pose: gtsam.Pose3, vel: NDArray[np.float64],
                        bias: gtsam.imuBias.ConstantBias, vel_cov: NDArray[np.float64] | None
                        ) -> tuple[gtsam.NavState, NDArray[np.float64], NDArray[np.float64]]:
    """The predicted state at the end of ``pim``, the planar relative motion (x, y, yaw in the
    start's frame) and its covariance: the preintegration's own (``preintMeasCov``: rotation,
    position, velocity) plus the start velocity's uncertainty carried over ``dt``."""
    state = pim.predict(gtsam.NavState(pose, vel), bias) if pim.deltaTij() > 0 else gtsam.NavState(pose, vel)
    rel = pose.between(state.pose())
    t = rel.translation()
    rel_vec = np.array([t[0], t[1], rel.rotation().yaw()])
    c9 = np.asarray(pim.preintMeasCov()) if pim.deltaTij() > 0 else np.zeros((9, 9))
    cov = np.zeros((3, 3))
    cov[:2, :2] = c9[3:5, 3:5]
    cov[2, 2] = c9[2, 2]
    cov[:2, 2] = cov[2, :2] = c9[3:5, 2]
    if vel_cov is not None:
        R = pose.rotation().matrix()[:2, :2]
        dt = pim.deltaTij()
        cov[:2, :2] += R.T @ np.asarray(vel_cov)[:2, :2] @ R * dt * dt
    return state, rel_vec, cov
