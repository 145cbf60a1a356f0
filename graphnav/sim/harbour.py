"""``harbour``: a vessel crossing a small harbour, every sensor a USV carries, exact truth (the embedded dataset).

Geometry: a 300 m x 200 m basin closed by quay walls (entrance gap in the south wall), three
piers from the north quay, a jetty from the west quay and moored hulls alongside, all polygons.
The vessel follows a waypoint route through the slips at ~1.5 m/s through the water
(heading-rate-limited turns), about 11 minutes a lap; ``laps`` (or a ``duration`` longer than a lap)
repeats the route, so the same scenario also makes hours-long logs for the live-mode benchmarks.

Two profiles (``HarbourConfig()`` / ``graphnav simulate harbour``: ``usv``; ``HarbourConfig.legacy()`` /
``--profile legacy``: the robot-style log ``data/harbour.npz`` was first made with, draw for draw).
Sensors of the ``usv`` profile (all deterministic per seed; docs/datasets.md has every number):

* a tidal current of 0.3-0.5 m/s (0.4 +- 0.1 over a 20 min period, flowing towards 30 +- 25 deg
  CCW from east over 30 min, uniform over the basin; :mod:`graphnav.sim.water_current`, the truth in
  ``meta["current"]``): over ground the vessel moves through the water plus the current, and it
  steers the heading that makes good its course, so heading and course over ground differ (crab
  angle ~10 deg typical, up to ~25 deg);
* IMU at 100 Hz (``imu_hz``): planar records ``ax`` (forward), ``ay`` (left), ``wz``, each the exact
  mean over (t_{k-1}, t_k] of the body-frame specific force and yaw rate of the simulated motion
  (speed changes along the bow, the centripetal ``u w``, the current's own acceleration), with the
  ``solent`` bias model (Table 3's bias calibrated to a 10 % residual) plus a bias random walk and
  white noise at Table 3's noise density (:mod:`graphnav.sim.imu_errors`; ``meta["imu"]`` with the
  bias left in the records every 10 s);
* GNSS at 1 Hz (``fix_hz``), sigma 3 m per axis, plus a multipath bias near the quays (up to 4 m,
  pointing away from the nearest wall, fading out 15 m from it) and one 30 s outage; with every
  fix a Doppler velocity over ground (``gnss_velocity``, sigma 0.05 m/s per axis), absent in the outage too;
* compass at the GNSS rate: white noise 1 deg plus a constant deviation of 1.5 deg (``meta["compass"]``;
  the record's sigma is their root-sum-square, 1.8 deg, as a datasheet's accuracy);
* speed log (``water_speed``) at 1 Hz: the speed through the water along the bow, sigma 0.05 m/s;
* 2D LiDAR at 10 Hz (``lidar_hz``; 0: no scans), 1 deg beam spacing, 40 m range, ray-cast against
  the polygons (vectorised over beams and segments), with the weighted-ICP paper's error model:
  range sigma ``0.004258 r`` and an angular (beam-direction) sigma of 0.5 deg; beyond range or
  dropped (1 %) = NaN;
* 4 charted beacons (chart sigma 0.2 m), range/bearing at 1 Hz within 150 m, sigma 0.5 m / 0.5 deg;
* no odometer (``odometer=True`` / ``--odometer``: 10 Hz SOG + ROT records, sigma 0.05 m/s, 0.3 deg/s);
* truth at 10 Hz, a pose prior at the start, ``meta["initial_velocity"]`` (over ground), and
  ``meta["events"]`` for the outage and the multipath intervals. Times start at ``t0`` (0; a POSIX
  time makes NMEA-ready logs).

The ``legacy`` profile: still water, 10 Hz odometry, IMU at 1 Hz without bias drift (the UKFs'
T = 1 s), 5 Hz LiDAR, compass 2 deg without deviation, no GNSS velocity, no speed log. Each sensor
has its own random stream (``SeedSequence(seed).spawn(8)``, the legacy five first), so the legacy
log is unchanged, record for record and key for key of its meta.

Geodetic origin (``meta["origin"]``, the convention of :mod:`graphnav.io.nmea`): the local frame
(x east, y north) is the east-north tangent plane whose origin, the basin's south-west corner, lies
150 m west and 100 m south of Marina Gdynia (54 deg 30.98' N, 18 deg 33.22' E, WGS84), so the
basin's centre sits on the marina: the yacht basin where the weighted-ICP paper's real LiDAR data
(``icp_data_marina``) was recorded. Only the position is real; the quays, piers and hulls are
schematic, not Gdynia's (a chart overlay shows the track in the right place, not along its walls).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geometry import wrap_angle
from ..log import (
    BeaconObs,
    Gnss,
    GnssVelocity,
    Heading,
    Imu,
    KnownBeacon,
    NavLog,
    Odometry,
    PosePrior,
    Scan,
    Truth,
    WaterSpeed,
)
from .imu_errors import imu_with_drift
from .solent import imu_measurements
from .water_current import TidalCurrent

SIGMA_R_REL = 0.004258


def _box(x0: float, y0: float, x1: float, y1: float) -> NDArray[np.float64]:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


def _hull(cx: float, cy: float, length: float, beam: float, yaw: float) -> NDArray[np.float64]:
    """A moored hull: a pointed-bow pentagon centred at (cx, cy)."""
    h, b = length / 2, beam / 2
    local = np.array([[-h, -b], [h - b * 1.5, -b], [h, 0.0], [h - b * 1.5, b], [-h, b]])
    c, s = math.cos(yaw), math.sin(yaw)
    return local @ np.array([[c, s], [-s, c]]) + [cx, cy]


def harbour_polygons() -> list[NDArray[np.float64]]:
    """Quay walls, piers, jetty and moored hulls (closed polygons, vertices in order)."""
    polys = [
        _box(-6, -6, 0, 206),
        _box(300, -6, 306, 206),
        _box(-6, 200, 306, 206),  # west, east, north quays
        _box(-6, -6, 200, 0),
        _box(260, -6, 306, 0),  # south quay with the entrance 200..260
        _box(70, 120, 76, 200),
        _box(150, 110, 156, 200),
        _box(230, 120, 236, 200),  # piers
        _box(0, 60, 55, 66),  # jetty from the west quay
    ]
    for y in (135.0, 152.0, 170.0, 186.0):  # hulls alongside the piers
        polys.append(_hull(78.0, y, 11.0, 3.2, math.pi / 2))
        polys.append(_hull(148.0, y - 6.0, 9.0, 3.0, -math.pi / 2))
        polys.append(_hull(238.0, y + 3.0, 12.0, 3.6, math.pi / 2))
    for x in (12.0, 26.0, 40.0):  # hulls along the jetty's south side
        polys.append(_hull(x, 57.5, 10.0, 3.0, 0.0))
    polys.append(_hull(285.0, 40.0, 14.0, 4.0, math.pi / 2))  # along the east quay
    for x in (115.0, 140.0, 165.0, 190.0, 215.0, 240.0):  # mooring dolphins
        polys.append(_box(x - 1.0, 79.0, x + 1.0, 81.0))
    polys.append(_box(225.0, 40.0, 229.0, 44.0))  # a pontoon near the entrance
    polys += _piles()
    return polys


def _piles(spacing: float = 9.0, size: float = 0.7) -> list[NDArray[np.float64]]:
    """Fender piles along the quay and pier faces (what makes straight walls matchable along-track)."""
    h = size / 2
    faces = [
        ((0.0, 70.0), (0.0, 199.0), (1.0, 0.0)),
        ((1.0, 0.0), (199.0, 0.0), (0.0, 1.0)),
        ((261.0, 0.0), (299.0, 0.0), (0.0, 1.0)),
        ((300.0, 1.0), (300.0, 199.0), (-1.0, 0.0)),
        ((1.0, 200.0), (299.0, 200.0), (0.0, -1.0)),
        ((0.0, 1.0), (0.0, 59.0), (1.0, 0.0)),
        ((56.0, 67.0), (56.0, 67.0), (1.0, 0.0)),
        ((157.0, 112.0), (157.0, 199.0), (0.0, 0.0)),
        ((229.0, 122.0), (229.0, 199.0), (0.0, 0.0)),
        ((77.0, 122.0), (77.0, 128.0), (0.0, 0.0)),
    ]
    out = []
    for (x0, y0), (x1, y1), (nx, ny) in faces:
        n = max(int(np.hypot(x1 - x0, y1 - y0) // spacing), 0) + 1
        for f in np.linspace(0.0, 1.0, n):
            cx, cy = x0 + f * (x1 - x0) + 1.2 * nx, y0 + f * (y1 - y0) + 1.2 * ny
            out.append(_box(cx - h, cy - h, cx + h, cy + h))
    return out


def segments(polys: list[NDArray[np.float64]]) -> NDArray[np.float64]:
    """All polygon edges as an (M, 4) array ``x0, y0, x1, y1``."""
    return np.vstack([np.hstack([p, np.roll(p, -1, axis=0)]) for p in polys])


def raycast(
    segs: NDArray[np.float64], origin: NDArray[np.float64], directions: NDArray[np.float64], max_range: float
) -> NDArray[np.float64]:
    """Range to the first segment hit along each unit direction (B, 2) from ``origin``; NaN if none
    within ``max_range``. Vectorised over beams x segments."""
    lo = np.minimum(segs[:, :2], segs[:, 2:]) - origin
    hi = np.maximum(segs[:, :2], segs[:, 2:]) - origin
    near = np.all((lo <= max_range) & (hi >= -max_range), axis=1)  # bounding boxes within range
    segs = segs[near]
    if len(segs) == 0:
        return np.full(len(directions), np.nan)
    p = segs[:, :2] - origin  # (M, 2)
    e = segs[:, 2:] - segs[:, :2]
    d = directions[:, None, :]  # (B, 1, 2)
    den = d[..., 0] * e[None, :, 1] - d[..., 1] * e[None, :, 0]  # cross(d, e)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (p[None, :, 0] * e[None, :, 1] - p[None, :, 1] * e[None, :, 0]) / den
        u = (p[None, :, 0] * d[..., 1] - p[None, :, 1] * d[..., 0]) / den
    hit = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
    t = np.where(hit, t, np.inf).min(axis=1)
    return np.where(t <= max_range, t, np.nan)


def raycast_from(
    segs: NDArray[np.float64], origin: NDArray[np.float64], directions: NDArray[np.float64], max_range: float
) -> NDArray[np.float64]:
    """:func:`raycast` from one ``origin`` (2,) or from one origin per beam (B, 2) (a sweeping sensor)."""
    origin = np.asarray(origin, dtype=float)
    if origin.ndim == 1:
        return raycast(segs, origin, directions, max_range)
    return _raycast_each(segs, origin, directions, max_range)


def _raycast_each(segs: NDArray[np.float64], origins: NDArray[np.float64], directions: NDArray[np.float64],
                  max_range: float) -> NDArray[np.float64]:
    """:func:`raycast` with an origin per beam (B, 2)."""
    c = origins.mean(axis=0)
    spread = float(np.max(np.hypot(*(origins - c).T)))
    lo = np.minimum(segs[:, :2], segs[:, 2:]) - c
    hi = np.maximum(segs[:, :2], segs[:, 2:]) - c
    reach = max_range + spread
    segs = segs[np.all((lo <= reach) & (hi >= -reach), axis=1)]
    if len(segs) == 0:
        return np.full(len(directions), np.nan)
    p = segs[None, :, :2] - origins[:, None, :]  # (B, M, 2)
    e = segs[None, :, 2:] - segs[None, :, :2]
    d = directions[:, None, :]
    den = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        tt = (p[..., 0] * e[..., 1] - p[..., 1] * e[..., 0]) / den
        u = (p[..., 0] * d[..., 1] - p[..., 1] * d[..., 0]) / den
    hit = (np.abs(den) > 1e-12) & (tt > 0) & (u >= 0) & (u <= 1)
    tt = np.where(hit, tt, np.inf).min(axis=1)
    return np.where(tt <= max_range, tt, np.nan)


def sweep_poses(p: NDArray[np.float64], f: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Positions (B, 2) and headings (B,) of the track ``p`` (N, 3) at fractional sample indices ``f`` (B,),
    linear between samples (heading along the shorter way round)."""
    i0 = np.minimum(np.floor(f).astype(int), len(p) - 2)
    w = f - i0
    a, b = p[i0], p[i0 + 1]
    dyaw = np.arctan2(np.sin(b[:, 2] - a[:, 2]), np.cos(b[:, 2] - a[:, 2]))
    return a[:, :2] + w[:, None] * (b[:, :2] - a[:, :2]), a[:, 2] + w * dyaw


def distance_to_segments(segs: NDArray[np.float64], pts: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """Distance from each point (N, 2) to the nearest segment, and the unit vector from it to the point."""
    a, b = segs[:, :2], segs[:, 2:]
    ab = b - a
    ap = pts[:, None, :] - a[None]
    s = np.clip((ap * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    near = a[None] + s[..., None] * ab[None]
    diff = pts[:, None, :] - near
    dist = np.hypot(diff[..., 0], diff[..., 1])
    j = dist.argmin(axis=1)
    i = np.arange(len(pts))
    dmin = dist[i, j]
    u = diff[i, j] / np.maximum(dmin, 1e-9)[:, None]
    return dmin, u


ROUTE = np.array(
    [
        [30, 25],
        [180, 25],
        [268, 30],
        [272, 95],
        [208, 102],
        [208, 160],
        [193, 182],
        [178, 160],
        [178, 104],
        [125, 100],
        [125, 160],
        [111, 182],
        [97, 160],
        [97, 96],
        [74, 82],
        [70, 45],
        [40, 36],
        [22, 30],
    ],
    dtype=float,
)
BEACONS = {"B1": (100.0, 5.0), "B2": (250.0, 110.0), "B3": (20.0, 190.0), "B4": (190.0, 60.0)}
MARINA_GDYNIA = (54.0 + 30.98 / 60.0, 18.0 + 33.22 / 60.0)  # lat, lon [deg]: South Coast Baltic marina guide
ORIGIN = {"lat": 54.515435, "lon": 18.551351, "h": 0.0}
"""WGS84 position of the local frame's (0, 0): 150 m west, 100 m south of :data:`MARINA_GDYNIA`
(the tangent-plane offset, rounded to 1e-6 deg; ``h`` [m] ellipsoidal, unused by a surface vessel)."""


PROFILES = ("usv", "legacy")
EMBEDDED_PROFILE = "usv"
"""The profile ``data/harbour.npz`` was simulated with (seed 0, defaults otherwise): what ``graphnav
demo`` simulates when the file is absent and what the regeneration test compares it against (the
USV's sensors since issue 21; ``--profile legacy`` makes the robot-style log it was before)."""

LEGACY_CURRENT = TidalCurrent(speed=0.0, speed_amp=0.0)


@dataclass
class HarbourConfig:
    """Everything that defines a harbour run. The defaults are the ``usv`` profile (a real USV's
    sensors); :meth:`legacy` gives the robot-style log ``data/harbour.npz`` was first made with."""

    profile: str = "usv"  # "usv" or "legacy" (legacy: the old random-stream layout and meta, draw for draw)
    speed: float = 1.5  # speed through the water [m/s]
    max_rot: float = math.radians(6.0)
    dt: float = 0.01  # truth integration step [s] (1/imu_hz, 1/lidar_hz, ... multiples of it)
    lidar_hz: float = 10.0
    lidar_sweep: float = 0.0  # [s] beam i of N taken at stamp + i * lidar_sweep / N on the true track (0: all at once)
    beam_deg: float = 1.0
    max_range: float = 40.0
    sigma_alpha: float = math.radians(0.5)
    dropout: float = 0.01
    gnss_sigma: float = 3.0
    gnss_vel_sigma: float = 0.05  # Doppler velocity 1-sigma per axis [m/s]; 0: no velocity records
    multipath_amp: float = 4.0
    multipath_dist: float = 15.0
    outage_t0: float = 300.0
    outage_len: float = 30.0
    compass_sigma: float = math.radians(1.0)  # white noise
    compass_deviation: float = math.radians(1.5)  # constant (uncorrected deviation); the record's sigma covers both
    odometer: bool = False  # 10 Hz odometry (SOG, ROT) records
    odo_sigma_v: float = 0.05
    odo_sigma_w: float = math.radians(0.3)
    water_speed_hz: float = 1.0  # speed log (through water, along the bow); 0: none
    water_speed_sigma: float = 0.05
    current: TidalCurrent = TidalCurrent()
    beacon_range: float = 150.0
    beacon_sigma_r: float = 0.5
    beacon_sigma_b: float = math.radians(0.5)
    chart_sigma: float = 0.2
    prior_sigma_xy: float = 0.3
    prior_sigma_yaw: float = math.radians(1.0)
    fix_hz: float = 1.0  # GNSS and compass rate (beacons stay at 1 Hz)
    imu_hz: float = 100.0  # IMU rate (1/imu_hz a multiple of dt; 0: no IMU)
    imu_bias_drift: bool = True  # bias random walk + noise density (graphnav.sim.imu_errors); False: solent's
    imu_calibrate: bool = True  # log raw - bias estimate (solent's calibration); False: the raw IMU
    imu_calib_residual: float = 0.1  # residual bias after calibration, as a fraction of the bias
    t0: float = 0.0  # time of the first record [s]

    def __post_init__(self) -> None:
        if self.profile not in PROFILES:
            raise ValueError(f"harbour profile must be one of {', '.join(PROFILES)}, not {self.profile!r}")

    @classmethod
    def legacy(cls, **overrides: Any) -> HarbourConfig:
        """The robot-style profile (``data/harbour.npz`` before issue 21): 10 Hz odometry, 1 Hz IMU
        without bias drift, 5 Hz LiDAR, compass 2 deg without deviation, still water, no GNSS
        velocity or speed log; seed for seed the very records (and meta) it always gave."""
        base = dict(profile="legacy", dt=0.02, lidar_hz=5.0, gnss_vel_sigma=0.0, compass_sigma=math.radians(2.0),
                    compass_deviation=0.0, odometer=True, water_speed_hz=0.0, current=LEGACY_CURRENT,
                    imu_hz=1.0, imu_bias_drift=False)
        return cls(**{**base, **overrides})

    @classmethod
    def for_profile(cls, profile: str, **overrides: Any) -> HarbourConfig:
        """The config of a named profile (``usv`` or ``legacy``) with some fields overridden."""
        if profile == "legacy":
            return cls.legacy(**overrides)
        return cls(**{"profile": profile, **overrides})


def vessel_track(cfg: HarbourConfig, rng: np.random.Generator, *, laps: int = 1,
                 t_max: float = math.inf) -> tuple[NDArray, NDArray, NDArray]:
    """Times, poses (N, 3) and (u, w) controls (speed through the water along the bow, yaw rate)
    following :data:`ROUTE` ``laps`` times with rate-limited turns (each further lap continues from
    the last waypoint to the second one), up to ``t_max`` [s]. Over ground the vessel moves by its
    arc through the water plus ``cfg.current`` (at the step's middle); in a current it steers the
    heading that makes good the course to the next waypoint (crabbing)."""
    route = np.vstack([ROUTE] + [ROUTE[1:]] * (laps - 1))
    cur = None if cfg.current.still else cfg.current
    pos = route[0].copy()
    yaw = math.atan2(*(route[1] - route[0])[::-1])
    wp = 1
    t_l, p_l, c_l = [], [], []
    t = 0.0
    v_slow = 0.0
    t_wp = 0.0
    a_slow, b_slow = 0.995 ** (cfg.dt / 0.02), 0.005 * math.sqrt(cfg.dt / 0.02)  # the same process at any dt
    u_prev = cfg.speed
    legacy, k = cfg.profile == "legacy", 0
    while wp < len(route) and t <= t_max:
        to = route[wp] - pos
        if np.hypot(*to) < 6.0 or t - t_wp > 3.0 * np.hypot(*(route[wp] - route[wp - 1])) / cfg.speed + 30.0:
            wp += 1  # reached (or unreachable within the turn radius: go on)
            t_wp = t
            continue
        course = math.atan2(to[1], to[0])
        if cur is not None:  # the heading whose water track plus the current points at the waypoint
            cx, cy = cur.at(t)
            across = (to[0] * cy - to[1] * cx) / math.hypot(to[0], to[1])
            course -= math.asin(max(-0.8, min(0.8, across / max(u_prev, 0.3))))
        err = wrap_angle(course - yaw)
        w = float(np.clip(0.8 * err, -cfg.max_rot, cfg.max_rot))
        v_slow = a_slow * v_slow + b_slow * rng.normal(0.0, 1.0)
        v = cfg.speed * (1.0 - 0.25 * min(abs(err), 1.0)) + 0.1 * v_slow
        u_prev = v
        t_l.append(t)
        p_l.append((pos[0], pos[1], yaw))
        c_l.append((v, w))
        if abs(w) < 1e-9:
            pos = pos + v * cfg.dt * np.array([math.cos(yaw), math.sin(yaw)])
        else:
            pos = pos + (v / w) * np.array(
                [math.sin(yaw + w * cfg.dt) - math.sin(yaw), -math.cos(yaw + w * cfg.dt) + math.cos(yaw)]
            )
        if cur is not None:
            pos = pos + cfg.dt * np.array(cur.at(t + 0.5 * cfg.dt))
        yaw = wrap_angle(yaw + w * cfg.dt)
        k += 1
        t = t + cfg.dt if legacy else k * cfg.dt  # legacy: the accumulated times data/harbour.npz has
    return np.array(t_l), np.array(p_l), np.array(c_l)


def ground_velocity(cfg: HarbourConfig, t: NDArray, p: NDArray, ctl: NDArray) -> NDArray[np.float64]:
    """True velocity over ground (N, 2) at the track's times ``t`` (run time): the water track
    ``u (cos yaw, sin yaw)`` plus the current."""
    v = ctl[:, :1] * np.column_stack([np.cos(p[:, 2]), np.sin(p[:, 2])])
    return v if cfg.current.still else v + cfg.current.velocity(t)


def imu_truth(t: NDArray, p: NDArray, ctl: NDArray, every: int, dt: float,
              current: TidalCurrent | None = None) -> tuple[NDArray, NDArray, NDArray]:
    """Exact IMU truth of :func:`vessel_track`'s motion: for the samples ``i = every, 2 every, ...``
    the mean body-frame acceleration (m, 2) and yaw rate (m,) over (t_{i-every}, t_i]. Step ``j``
    runs the arc of constant ``(v_j, w_j)`` over ``[t_j, t_j + dt)``: along it the body acceleration
    is ``(0, v_j w_j)`` (centripetal, to port for ``w > 0``); at its start the speed jumps from
    ``v_{j-1}`` to ``v_j`` along the bow (``v_{-1} = v_0``). A ``current`` (the one the track was
    made with) adds its acceleration, rotated into the body frame at the step's middle (midpoint
    rule, error ~1e-12 m/s^2). Returns the sample indices too."""
    v, w = ctl[:, 0], ctl[:, 1]
    jump = np.diff(v, prepend=v[0])  # at the start of step j
    ii = np.arange(every, len(t), every)
    cx = np.concatenate([[0.0], np.cumsum(jump)])  # cumulative sums over steps [0, j)
    cy = np.concatenate([[0.0], np.cumsum(v * w * dt)])
    if current is not None and not current.still:
        a = current.acceleration(t + 0.5 * dt)
        mid = p[:, 2] + 0.5 * dt * w
        c, s = np.cos(mid), np.sin(mid)
        cx = cx + np.concatenate([[0.0], np.cumsum((c * a[:, 0] + s * a[:, 1]) * dt)])
        cy = cy + np.concatenate([[0.0], np.cumsum((-s * a[:, 0] + c * a[:, 1]) * dt)])
    cw = np.concatenate([[0.0], np.cumsum(w * dt)])
    T = every * dt
    acc_b = np.column_stack([(cx[ii] - cx[ii - every]) / T, (cy[ii] - cy[ii - every]) / T])
    return ii, acc_b, (cw[ii] - cw[ii - every]) / T


def simulate_harbour(
    seed: int = 0, cfg: HarbourConfig | None = None, *, duration: float | None = None, laps: int | None = None
) -> NavLog:
    """The harbour log: ``laps`` of the route (default 1, or as many as ``duration`` needs),
    truncated to ``duration`` [s] if given."""
    cfg = cfg or HarbourConfig()
    legacy = cfg.profile == "legacy"
    # spawn(8)'s first five children are spawn(5)'s (the legacy layout): the streams added since leave
    # the other sensors' draws as they were
    rng_track, rng_lidar, rng_gnss, rng_misc, rng_imu, rng_vel, rng_water, rng_odo = (
        np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(8)
    )
    if legacy:
        rng_odo = rng_misc  # the legacy log drew its odometry noise before the compass's, from one stream
    if laps is None:
        laps = 1 if duration is None else 1 + int(duration // 300.0)  # a lap takes > 600 s
    t, p, ctl = vessel_track(cfg, rng_track, laps=laps, t_max=math.inf if duration is None else duration)
    if duration is not None:
        keep = t <= duration
        t, p, ctl = t[keep], p[keep], ctl[keep]
    current = None if cfg.current.still else cfg.current
    vel = ground_velocity(cfg, t, p, ctl)
    segs = segments(harbour_polygons())
    recs: list = []
    step = lambda hz: max(int(round(1.0 / (hz * cfg.dt))), 1)  # noqa: E731
    ts = t + cfg.t0  # record time stamps

    for i in range(0, len(t), step(10.0)):
        recs.append(Truth(float(ts[i]), float(p[i, 0]), float(p[i, 1]), float(p[i, 2])))
        if cfg.odometer:  # speed over ground (the record's meaning) and yaw rate
            sog = ctl[i, 0] if current is None else math.hypot(vel[i, 0], vel[i, 1])
            recs.append(
                Odometry(
                    float(ts[i]),
                    float(sog + rng_odo.normal(0, cfg.odo_sigma_v)),
                    float(ctl[i, 1] + rng_odo.normal(0, cfg.odo_sigma_w)),
                    cfg.odo_sigma_v,
                    cfg.odo_sigma_w,
                )
            )

    imu_meta = None
    if cfg.imu_hz > 0:
        if abs(1.0 / (cfg.imu_hz * cfg.dt) - step(cfg.imu_hz)) > 1e-6:
            raise ValueError(f"imu_hz {cfg.imu_hz:g} needs a sample time that is a multiple of dt {cfg.dt:g} s")
        ii, acc_b, rate = imu_truth(t, p, ctl, step(cfg.imu_hz), cfg.dt, current)
        if cfg.imu_bias_drift:
            acc, gyr, imu_meta = imu_with_drift(rng_imu, ts[ii], acc_b, rate, cfg.imu_hz, calibrate=cfg.imu_calibrate,
                                                calib_residual=cfg.imu_calib_residual)
        else:
            acc, gyr, imu_meta = imu_measurements(rng_imu, acc_b, rate, calibrate=cfg.imu_calibrate,
                                                  calib_residual=cfg.imu_calib_residual)
            imu_meta["hz"] = cfg.imu_hz
        recs += [Imu(float(ts[i]), float(a[0]), float(a[1]), float(g)) for i, a, g in zip(ii, acc, gyr, strict=True)]

    nb = int(round(360.0 / cfg.beam_deg))
    angles = np.radians(np.arange(nb) * cfg.beam_deg) - math.pi
    sweep_steps = np.arange(nb) * (cfg.lidar_sweep / (nb * cfg.dt))  # each beam's time after the stamp [steps]
    for i in range(0, len(t) if cfg.lidar_hz > 0 else 0, step(max(cfg.lidar_hz, 1e-9))):
        if cfg.lidar_sweep > 0.0:  # each beam from the true pose at its own time (the sweep's skew)
            if i + sweep_steps[-1] > len(t) - 1:
                break  # the track ends inside this sweep
            origin, yaw_b = sweep_poses(p, i + sweep_steps)
        else:
            origin, yaw_b = p[i, :2], p[i, 2]
        true_dir = yaw_b + angles + rng_lidar.normal(0.0, cfg.sigma_alpha, nb)
        r = raycast_from(segs, origin, np.column_stack([np.cos(true_dir), np.sin(true_dir)]), cfg.max_range)
        r = r + rng_lidar.normal(0.0, 1.0, nb) * SIGMA_R_REL * np.nan_to_num(r)
        r[rng_lidar.random(nb) < cfg.dropout] = np.nan
        recs.append(Scan(float(ts[i]), r.astype(float), angles.copy()))

    gi = np.arange(0, len(t), step(cfg.fix_hz))
    dist, away = np.full(len(gi), np.inf), np.zeros((len(gi), 2))
    if cfg.multipath_amp > 0:
        for c in range(0, len(gi), 2000):  # chunks: the distance matrix is points x segments
            dist[c:c + 2000], away[c:c + 2000] = distance_to_segments(segs, p[gi[c:c + 2000], :2])
    amp = cfg.multipath_amp * np.clip(1.0 - dist / cfg.multipath_dist, 0.0, 1.0)
    vel_noise = rng_vel.normal(0.0, cfg.gnss_vel_sigma, (len(gi), 2)) if cfg.gnss_vel_sigma > 0 else None
    compass_sigma = math.hypot(cfg.compass_sigma, cfg.compass_deviation) if cfg.compass_deviation else cfg.compass_sigma
    events = [{"kind": "gnss_outage", "t0": cfg.t0 + cfg.outage_t0, "t1": cfg.t0 + cfg.outage_t0 + cfg.outage_len}]
    in_mp = False
    beacon_every = step(1.0)
    for j, i in enumerate(gi):
        t_rel, ti = float(t[i]), float(ts[i])
        noise = rng_gnss.normal(0.0, cfg.gnss_sigma, 2)
        mp = amp[j] > 0.5
        if mp and not in_mp:
            events.append({"kind": "gnss_multipath", "t0": ti, "t1": ti})
        if mp:
            events[-1]["t1"] = ti
        in_mp = mp
        if not (cfg.outage_t0 <= t_rel < cfg.outage_t0 + cfg.outage_len):
            gx, gy = p[i, :2] + amp[j] * away[j] + noise
            recs.append(Gnss(ti, float(gx), float(gy), cfg.gnss_sigma))
            if vel_noise is not None:
                vx, vy = vel[i] + vel_noise[j]
                recs.append(GnssVelocity(ti, float(vx), float(vy), cfg.gnss_vel_sigma))
        hd = p[i, 2] + rng_misc.normal(0.0, cfg.compass_sigma)
        if cfg.compass_deviation:
            hd += cfg.compass_deviation
        recs.append(Heading(ti, float(wrap_angle(hd)), compass_sigma))
        for bid, (bx, by) in BEACONS.items() if i % beacon_every == 0 else ():
            dx, dy = bx - p[i, 0], by - p[i, 1]
            rng_ = math.hypot(dx, dy)
            if rng_ <= cfg.beacon_range:
                br = math.atan2(dy, dx) - p[i, 2] + rng_misc.normal(0.0, cfg.beacon_sigma_b)
                recs.append(
                    BeaconObs(
                        ti,
                        bid,
                        float(rng_ + rng_misc.normal(0.0, cfg.beacon_sigma_r)),
                        float(wrap_angle(br)),
                        cfg.beacon_sigma_r,
                        cfg.beacon_sigma_b,
                    )
                )
    if cfg.water_speed_hz > 0:
        wi = np.arange(0, len(t), step(cfg.water_speed_hz))
        ws = ctl[wi, 0] + rng_water.normal(0.0, cfg.water_speed_sigma, len(wi))
        recs += [WaterSpeed(float(ts[i]), float(v), cfg.water_speed_sigma) for i, v in zip(wi, ws, strict=True)]
    px, py = p[0, :2] + rng_misc.normal(0.0, cfg.prior_sigma_xy, 2)
    pyaw = p[0, 2] + rng_misc.normal(0.0, cfg.prior_sigma_yaw)
    recs.append(
        PosePrior(float(ts[0]), float(px), float(py), float(pyaw), cfg.prior_sigma_xy, cfg.prior_sigma_yaw)
    )
    known = [KnownBeacon(b, bx, by, cfg.chart_sigma) for b, (bx, by) in BEACONS.items()]
    if current is None:
        v0 = [float(ctl[0, 0] * math.cos(p[0, 2])), float(ctl[0, 0] * math.sin(p[0, 2]))]
    else:
        v0 = [float(vel[0, 0]), float(vel[0, 1])]
    meta = {
        "name": "harbour",
        "seed": seed,
        "source": "graphnav simulate harbour",
        "events": events,
        "lidar": {
            "sigma_r_rel": SIGMA_R_REL,
            "sigma_alpha": cfg.sigma_alpha,
            "max_range": cfg.max_range,
            "hz": cfg.lidar_hz,
            "beam_deg": cfg.beam_deg,
            **({"sweep_s": cfg.lidar_sweep} if cfg.lidar_sweep > 0.0 else {}),
        },
        "frame": "local harbour frame: x east, y north, origin at the basin's south-west corner (meta.origin)",
        "origin": dict(ORIGIN),
        "initial_velocity": v0,
    }
    if imu_meta is not None:
        meta["imu"] = imu_meta
    if not legacy:  # the legacy log's meta is kept as it was, key for key
        meta["profile"] = cfg.profile
        meta["gnss"] = {"hz": cfg.fix_hz, "sigma": cfg.gnss_sigma, "velocity_sigma": cfg.gnss_vel_sigma,
                        "multipath_amp": cfg.multipath_amp, "multipath_dist": cfg.multipath_dist}
        meta["compass"] = {"hz": cfg.fix_hz, "sigma": cfg.compass_sigma, "deviation": cfg.compass_deviation,
                           "record_sigma": compass_sigma}
        meta["water_speed"] = {"hz": cfg.water_speed_hz, "sigma": cfg.water_speed_sigma}
        meta["odometer"] = ({"hz": 10.0, "sigma_v": cfg.odo_sigma_v, "sigma_w": cfg.odo_sigma_w}
                            if cfg.odometer else None)
    if current is not None:
        meta["current"] = current.to_meta(0.0, float(t[-1]), cfg.t0)
    return NavLog.from_unsorted(recs, known, meta)
