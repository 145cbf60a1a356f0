"""A planar log on a heeled, rolling hull: its IMU records made 6-axis (gravity included) and its
beacon bearings measured in the hull's plane.

The simulators' IMU records are planar (levelled ``ax``, ``ay``, ``wz``: docs/log-format.md); a real
strapdown IMU reads the specific force and the angular rate in a body frame that heels and rolls.
:func:`heeled` rotates each record into the body of a hull at a constant ``heel`` [rad] plus the wave
roll and pitch of :mod:`graphnav.sim.harbour3d` (scaled to ``roll_amp``): with ``R = R_y(pitch) R_x(roll)``
(levelled -> body, REP-103 ZYX), the specific force ``f_b = R^T (ax, ay, g)`` and the body rates
``(p, q, r) = (roll' - yaw' sin pitch, pitch' cos roll + yaw' cos pitch sin roll, -pitch' sin roll +
yaw' cos pitch cos roll)``, evaluated at each record's interval middle (each record is the mean over
its interval; second order at 100 Hz). The added axes get the log's stated white noise. A beacon
bearing becomes the azimuth of the mark's direction in the hull's plane (a radar or 2D LiDAR heels
with the hull). A 2D scan becomes the slice of the scene the hull's plane cuts (:func:`tilted_scan`:
the scene of the simulators is vertical walls, so each level return keeps its place on its wall and is
seen in the hull's plane, at a height, at another bearing and a longer range). ``attitude_hz`` adds
AHRS roll and pitch records (``ahrs_sigma``).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from ..log import Attitude, BeaconObs, Imu, NavLog, Record, Scan
from .harbour3d import Lidar3dConfig, attitude, rot_zyx

GRAVITY = 9.80665  # [m/s^2] standard gravity (the graph's: graphnav.graph.imu_chain.GRAVITY)
_H = 1e-4  # [s] the central difference of the roll and pitch rates


def _roll_pitch(cfg: Lidar3dConfig, phase_rng_seed: int, heel: float, t: NDArray[np.float64]
                ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    a = attitude(cfg, np.random.default_rng(phase_rng_seed), np.atleast_1d(t))  # the same phases every call
    return heel + a[:, 0], a[:, 1]


def _waves(roll_amp: float) -> Lidar3dConfig:
    """The harbour3d wave model with its roll scaled to ``roll_amp`` [rad] (the sum of its two sinusoids), its
    pitch alike, no heave."""
    base = Lidar3dConfig()
    scale = roll_amp / math.radians(sum(base.roll_amp_deg)) if roll_amp else 0.0
    return replace(base, roll_amp_deg=tuple(a * scale for a in base.roll_amp_deg),
                   pitch_amp_deg=tuple(a * scale for a in base.pitch_amp_deg), heave_amp=0.0)


def heeled(log: NavLog, heel: float = math.radians(10.0), roll_amp: float = math.radians(5.0), *,
           seed: int = 0, attitude_hz: float = 0.0, ahrs_sigma: float = math.radians(0.2)) -> NavLog:
    """``log`` on a hull heeled ``heel`` [rad] and rolling with waves of ``roll_amp`` [rad] (the harbour3d
    model's roll, its pitch at half that; see the module docstring). ``meta["heel"]`` states what was done."""
    cfg = _waves(roll_amp)
    imu_meta = log.meta.get("imu") if isinstance(log.meta.get("imu"), dict) else {}
    hz = float(imu_meta.get("hz", 100.0))
    acc_sd, gyro_sd = float(imu_meta.get("acc_std", 0.02)), float(imu_meta.get("gyro_std", 1e-3))
    rng = np.random.default_rng(seed + 1)
    att_every = 1.0 / attitude_hz if attitude_hz > 0 else math.inf
    next_att = -math.inf
    out: list[Record] = []
    for r in log.records:
        if isinstance(r, Imu) and not r.six_axis:
            tm = r.t - 0.5 / hz
            (phi,), (th,) = _roll_pitch(cfg, seed, heel, np.array([tm]))
            (p1,), (t1,) = _roll_pitch(cfg, seed, heel, np.array([tm + _H]))
            (p0,), (t0,) = _roll_pitch(cfg, seed, heel, np.array([tm - _H]))
            dphi, dth = (p1 - p0) / (2 * _H), (t1 - t0) / (2 * _H)
            f = rot_zyx(0.0, th, phi).T @ np.array([r.ax, r.ay, GRAVITY])
            cp, sp, ct, st = math.cos(phi), math.sin(phi), math.cos(th), math.sin(th)
            w = np.array([dphi - r.wz * st, dth * cp + r.wz * ct * sp, -dth * sp + r.wz * ct * cp])
            f[2] += rng.normal(0.0, acc_sd)
            w[:2] += rng.normal(0.0, gyro_sd, 2)
            out.append(Imu(r.t, float(f[0]), float(f[1]), float(w[2]), float(f[2]), float(w[0]), float(w[1])))
            if attitude_hz > 0 and r.t >= next_att:
                (phi,), (th,) = _roll_pitch(cfg, seed, heel, np.array([r.t]))
                out.append(Attitude(r.t, float(phi + rng.normal(0.0, ahrs_sigma)),
                                    float(th + rng.normal(0.0, ahrs_sigma)), ahrs_sigma))
                next_att = r.t + att_every - 1e-9
            continue
        if isinstance(r, Scan):
            (phi,), (th,) = _roll_pitch(cfg, seed, heel, np.array([r.t]))
            r = tilted_scan(r, phi, th)
        if isinstance(r, BeaconObs):
            (phi,), (th,) = _roll_pitch(cfg, seed, heel, np.array([r.t]))
            d = rot_zyx(0.0, th, phi).T @ np.array([math.cos(r.bearing), math.sin(r.bearing), 0.0])
            r = replace(r, bearing=float(math.atan2(d[1], d[0])))
        out.append(r)
    meta = dict(log.meta)
    meta["heel"] = {"heel_deg": math.degrees(heel), "roll_amp_deg": math.degrees(roll_amp), "seed": seed,
                    "attitude_hz": attitude_hz, "model": "graphnav.sim.heel"}
    return NavLog(out, list(log.beacons_known), meta)


def tilted_scan(scan: Scan, roll: float, pitch: float) -> Scan:
    """The level ``scan`` of a scene of vertical walls as a 2D LiDAR in the hull's plane sees it at
    ``roll``, ``pitch`` [rad]: each return's horizontal point ``(x, y)`` (levelled sensor frame) lifted
    onto the hull's plane (``z = -(n_x x + n_y y) / n_z``, ``n = R e_z`` its normal, ``R = R_y(pitch)
    R_x(roll)`` body -> levelled) and expressed in the body, ``b = R^T (x, y, z)`` (``b_z = 0``): range
    ``|b|``, bearing ``atan2(b_y, b_x)``; a missing return keeps its range at its new bearing, a return
    beyond ``range_max`` becomes missing. Known answer: level (0, 0) returns the scan unchanged."""
    R = rot_zyx(0.0, pitch, roll)
    n = R[:, 2]
    ok = scan.valid()
    r = np.where(ok, scan.ranges, 1.0)
    x, y = r * np.cos(scan.angles), r * np.sin(scan.angles)
    z = -(n[0] * x + n[1] * y) / n[2]
    b = np.stack([x, y, z], axis=1) @ R  # rows R^T p
    rng = np.hypot(b[:, 0], b[:, 1])
    ang = np.arctan2(b[:, 1], b[:, 0])
    ranges = np.where(ok, rng, scan.ranges)
    if math.isfinite(scan.range_max):
        ranges = np.where(ok & (ranges > scan.range_max), math.inf, ranges)
    order = np.argsort(ang, kind="stable") if np.any(np.diff(ang) < 0) and np.all(np.diff(scan.angles) >= 0) else None
    if order is not None:  # keep the beams in bearing order when the level scan was (the bearings wrap at pi)
        ranges, ang = ranges[order], ang[order]
    return replace(scan, ranges=ranges, angles=ang)


def roll_pitch_at(log: NavLog, t: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The true roll and pitch [rad] of a :func:`heeled` log at times ``t``."""
    h = log.meta["heel"]
    return _roll_pitch(_waves(math.radians(h["roll_amp_deg"])), int(h["seed"]), math.radians(h["heel_deg"]),
                       np.asarray(t, dtype=float))
