"""``harbour --lidar 3d``: the harbour scenario (:mod:`graphnav.sim.harbour`) with a 16-beam 3D LiDAR.

The vessel, its track and every other sensor (GNSS, compass, odometry, beacons, truth, pose prior)
are the 2D harbour's, same seed, same records; the 2D scans are replaced by 3D clouds:

* **the scene**: the harbour's polygons extruded from 2 m below the water (z = 0) to a top height
  per kind -- quays 2.0 m, piers 1.5 m, the jetty 1.2 m, moored hulls 1.2-2.0 m (freeboard),
  dolphins 2.5 m, the pontoon 0.6 m, fender piles 3.5 m -- plus sheds and warehouses 5-11 m tall
  behind the quays (what the upward beams see), as a triangle mesh ray-cast by open3d's
  ``RaycastingScene`` (Embree);
* **the sensor** (VLP-16-like): 16 beams from -15 to +15 deg elevation (2 deg apart), ``az_deg``
  (0.2 deg, the VLP-16's at 10 Hz) azimuth steps, 10 Hz (one cloud per truth pose), 100 m range, range sigma 3 cm, 1 %
  dropout, mounted ``mast`` (2.5 m) above the water at the body origin; one cloud is one instant
  (no motion distortion within the sweep);
* **waves**: roll (3 deg at 5.5 s + 1 deg at 3.1 s), pitch (1.5 deg at 6.5 s + 0.5 deg at 2.7 s)
  and heave (0.15 m at 6 s), random phases per seed; the cloud is in the tilted sensor frame
  (docs/conventions.md) and carries the AHRS's roll and pitch (truth + 0.2 deg noise);
* **water and spray**: the water is a specular surface: a beam that reaches it returns with
  probability ``water_p`` (2 %, within 40 m), at the wave height (sigma 0.15 m); spray: Poisson
  (``spray_n`` = 25) points a frame 0.6-3.5 m from the sensor, 0-1.5 m above the water. Intensity:
  structures ~40, water ~4, spray ~2 (``ring`` = beam index, 0 = the lowest).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..log import NavLog, make_cloud
from .harbour import HarbourConfig, _box, _piles, harbour_polygons, simulate_harbour

N_STRUCT, N_HULLS, N_SMALL = 9, 16, 7  # harbour_polygons(): 9 quays/piers/jetty, 16 hulls, 6 dolphins + pontoon
BUILDINGS = [  # (x0, y0, x1, y1, height [m]) behind the quays
    (10, 212, 60, 230, 8.0), (90, 210, 140, 222, 6.0), (170, 214, 210, 236, 11.0), (240, 210, 290, 225, 7.0),
    (-30, 20, -14, 70, 9.0), (-26, 110, -12, 180, 6.5), (314, 30, 332, 90, 10.0), (312, 130, 330, 190, 5.0),
    (20, -24, 90, -12, 7.5), (120, -20, 180, -10, 5.5), (270, -26, 300, -12, 8.5),
]


@dataclass
class Lidar3dConfig:
    hz: float = 10.0
    beams: int = 16
    fov_deg: float = 15.0  # +- vertical field of view
    az_deg: float = 0.2
    max_range: float = 100.0
    sigma_r: float = 0.03
    dropout: float = 0.01
    mast: float = 2.5  # sensor height above the water [m]
    roll_amp_deg: tuple[float, float] = (3.0, 1.0)
    roll_period: tuple[float, float] = (5.5, 3.1)
    pitch_amp_deg: tuple[float, float] = (1.5, 0.5)
    pitch_period: tuple[float, float] = (6.5, 2.7)
    heave_amp: float = 0.15
    heave_period: float = 6.0
    ahrs_sigma_deg: float = 0.2
    water_p: float = 0.02
    water_range: float = 40.0
    wave_sigma: float = 0.15
    spray_n: float = 25.0
    spray_range: tuple[float, float] = (0.6, 3.5)


def scene_prisms() -> list[tuple[NDArray[np.float64], float, int]]:
    """Every extruded solid: (polygon (K, 2), top height [m], class 0 structure / 1 hull / 2 building)."""
    polys = harbour_polygons()
    n_piles = len(_piles())
    if len(polys) != N_STRUCT + N_HULLS + N_SMALL + n_piles:
        raise RuntimeError("harbour_polygons() changed its layout: update harbour3d's heights")
    tops = [2.0, 2.0, 2.0, 2.0, 2.0, 1.5, 1.5, 1.5, 1.2]
    out = [(p, h, 0) for p, h in zip(polys[:N_STRUCT], tops, strict=True)]
    out += [(p, 1.2 + 0.4 * (i % 3), 1) for i, p in enumerate(polys[N_STRUCT:N_STRUCT + N_HULLS])]
    small = polys[N_STRUCT + N_HULLS:N_STRUCT + N_HULLS + N_SMALL]
    out += [(p, 2.5 if i < N_SMALL - 1 else 0.6, 0) for i, p in enumerate(small)]
    out += [(p, 3.5, 0) for p in polys[N_STRUCT + N_HULLS + N_SMALL:]]
    out += [(_box(x0, y0, x1, y1), h, 2) for x0, y0, x1, y1, h in BUILDINGS]
    return out


def scene_mesh(bottom: float = -2.0) -> tuple[NDArray[np.float32], NDArray[np.uint32], NDArray[np.int64]]:
    """Vertices, triangles and each triangle's class of the extruded scene (walls and convex tops)."""
    verts, tris, cls = [], [], []
    n = 0
    for poly, top, c in scene_prisms():
        k = len(poly)
        lo = np.column_stack([poly, np.full(k, bottom)])
        hi = np.column_stack([poly, np.full(k, top)])
        verts += [lo, hi]
        i = np.arange(k)
        j = (i + 1) % k
        walls = np.vstack([np.column_stack([n + i, n + j, n + k + j]), np.column_stack([n + i, n + k + j, n + k + i])])
        cap = np.column_stack([np.full(k - 2, n + k), n + k + np.arange(1, k - 1), n + k + np.arange(2, k)])
        tris += [walls, cap]
        cls += [np.full(len(walls) + len(cap), c)]
        n += 2 * k
    return (np.vstack(verts).astype(np.float32), np.vstack(tris).astype(np.uint32), np.concatenate(cls))


def rot_zyx(yaw: float, pitch: float, roll: float) -> NDArray[np.float64]:
    """``R_z(yaw) R_y(pitch) R_x(roll)``: sensor (body) frame -> world (REP-103 ZYX Euler angles)."""
    cy, sy, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def beam_directions(cfg: Lidar3dConfig) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Unit directions (B, 3) in the sensor frame and each one's ring (0 = the lowest beam)."""
    el = np.radians(np.linspace(-cfg.fov_deg, cfg.fov_deg, cfg.beams))
    az = np.radians(np.arange(0.0, 360.0, cfg.az_deg)) - math.pi
    E, A = np.meshgrid(el, az, indexing="ij")
    d = np.column_stack([(np.cos(E) * np.cos(A)).ravel(), (np.cos(E) * np.sin(A)).ravel(), np.sin(E).ravel()])
    ring = np.repeat(np.arange(cfg.beams), len(az))
    return d, ring


def attitude(cfg: Lidar3dConfig, rng: np.random.Generator, t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Roll, pitch [rad] and heave [m] at times ``t`` (N, 3): sums of sinusoids with random phases."""
    ph = rng.uniform(0.0, 2.0 * math.pi, 5)
    roll = sum(math.radians(a) * np.sin(2 * math.pi * t / p + f)
               for a, p, f in zip(cfg.roll_amp_deg, cfg.roll_period, ph[:2], strict=True))
    pitch = sum(math.radians(a) * np.sin(2 * math.pi * t / p + f)
                for a, p, f in zip(cfg.pitch_amp_deg, cfg.pitch_period, ph[2:4], strict=True))
    heave = cfg.heave_amp * np.sin(2 * math.pi * t / cfg.heave_period + ph[4])
    return np.column_stack([roll, pitch, heave])


class Lidar3d:
    """The ray-casting sensor: :meth:`cloud` gives one frame's sensor-frame points, intensity, ring."""

    def __init__(self, cfg: Lidar3dConfig) -> None:
        from ..errors import require

        o3d = require("open3d", "the 3D harbour's ray casting (simulate harbour --lidar 3d)")
        self.cfg = cfg
        v, tr, self.tri_class = scene_mesh()
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(o3d.core.Tensor(v), o3d.core.Tensor(tr))
        self.dirs, self.ring = beam_directions(cfg)
        self._o3d = o3d

    def cloud(self, pose: NDArray[np.float64], att: NDArray[np.float64], rng: np.random.Generator
              ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
        cfg = self.cfg
        x, y, yaw = pose
        roll, pitch, heave = att
        R = rot_zyx(yaw, pitch, roll)
        o = np.array([x, y, cfg.mast + heave])
        dw = self.dirs @ R.T  # world directions
        rays = np.hstack([np.broadcast_to(o, dw.shape), dw]).astype(np.float32)
        ans = self.scene.cast_rays(self._o3d.core.Tensor(rays))
        t_hit = ans["t_hit"].numpy().astype(float)
        prim = ans["primitive_ids"].numpy().astype(np.int64)
        nb = len(dw)
        hit = np.isfinite(t_hit) & (t_hit <= cfg.max_range)
        inten = np.where(hit, 40.0, 0.0)
        cls = self.tri_class[prim[hit]]
        inten[hit] = np.where(cls == 1, 25.0, np.where(cls == 2, 55.0, 40.0))
        # the water: where a downward beam reaches z = 0 (the wave height) first, a sparse return
        with np.errstate(divide="ignore", invalid="ignore"):
            t_w = np.where(dw[:, 2] < 0, -o[2] / dw[:, 2], np.inf)
        water = t_w < np.where(hit, t_hit, np.inf)  # the sea surface comes first: no structure return
        hit &= ~water
        wret = water & (t_w <= cfg.water_range) & (rng.random(nb) < cfg.water_p)
        t_w = t_w + rng.normal(0.0, cfg.wave_sigma, nb) / np.maximum(-dw[:, 2], 0.05)
        rng_ = np.where(hit, t_hit, np.where(wret, t_w, np.nan))
        inten = np.where(wret, 4.0, inten)
        keep = (hit | wret) & (rng.random(nb) >= cfg.dropout) & (rng_ > 0.3)
        r = rng_[keep] + rng.normal(0.0, cfg.sigma_r, int(keep.sum()))
        pts = self.dirs[keep] * r[:, None]  # sensor frame: the beam direction times the range
        inten = inten[keep] * (1.0 + 0.1 * rng.standard_normal(int(keep.sum())))
        ring = self.ring[keep]
        k = rng.poisson(cfg.spray_n)  # spray: close to the sensor, above the water
        if k:
            az = rng.uniform(-math.pi, math.pi, k)
            rh = rng.uniform(*cfg.spray_range, k)
            zw = rng.uniform(0.0, 1.5, k)
            pw = np.column_stack([x + rh * np.cos(az), y + rh * np.sin(az), zw]) - o
            ps = pw @ R  # world -> sensor: R^T p
            pts = np.vstack([pts, ps])
            inten = np.concatenate([inten, rng.uniform(0.5, 3.0, k)])
            el = np.degrees(np.arctan2(ps[:, 2], np.hypot(ps[:, 0], ps[:, 1])))
            ring = np.concatenate([ring, np.clip(np.round((el + cfg.fov_deg) / (2 * cfg.fov_deg) * (cfg.beams - 1)),
                                                 0, cfg.beams - 1).astype(np.int64)])
        return pts, np.maximum(inten, 0.0), ring


def simulate_harbour3d(seed: int = 0, cfg: HarbourConfig | None = None, lidar: Lidar3dConfig | None = None, *,
                       duration: float | None = None, laps: int | None = None) -> NavLog:
    """The harbour log with 3D clouds instead of 2D scans (see the module doc); the true attitude of
    every cloud is in ``meta["attitude"]`` (``t``, ``roll``, ``pitch``, ``heave`` lists)."""
    cfg = replace(cfg or HarbourConfig(), lidar_hz=0.0)
    lcfg = lidar or Lidar3dConfig()
    base = simulate_harbour(seed, cfg, duration=duration, laps=laps)
    truth = base.of("truth")
    rng_att, rng_lidar, rng_ahrs = (np.random.default_rng(s) for s in np.random.SeedSequence([seed, 3]).spawn(3))
    every = max(int(round(10.0 / lcfg.hz)), 1)  # truth is at 10 Hz
    frames = truth[::every]
    t = np.array([r.t for r in frames])
    att = attitude(lcfg, rng_att, t - cfg.t0)
    sensor = Lidar3d(lcfg)
    clouds = []
    for r, a in zip(frames, att, strict=True):
        pts, inten, ring = sensor.cloud(np.array([r.x, r.y, r.yaw]), a, rng_lidar)
        noise = np.radians(lcfg.ahrs_sigma_deg) * rng_ahrs.standard_normal(2)
        clouds.append(make_cloud(r.t, pts, inten, ring, float(a[0] + noise[0]), float(a[1] + noise[1])))
    meta = dict(base.meta)
    meta["name"] = "harbour3d"
    meta["source"] = "graphnav simulate harbour --lidar 3d"
    meta.pop("lidar", None)
    meta["lidar3d"] = {"beams": lcfg.beams, "fov_deg": lcfg.fov_deg, "az_deg": lcfg.az_deg, "hz": lcfg.hz,
                       "max_range": lcfg.max_range, "sigma_r": lcfg.sigma_r, "mast": lcfg.mast}
    meta["attitude"] = {"t": t.tolist(), "roll": att[:, 0].tolist(), "pitch": att[:, 1].tolist(),
                        "heave": att[:, 2].tolist()}
    return NavLog.from_unsorted(list(base.records) + clouds, base.beacons_known, meta)
