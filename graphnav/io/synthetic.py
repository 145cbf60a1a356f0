"""A small synthetic sea-trial log (GNSS + gyrocompass + SOG/ROT odometry + optional scans + truth)
for I/O round trips, live-mode tests and the live benchmark. Not a scenario simulator (those live in
:mod:`graphnav.sim`): a vessel on a constant-speed lawn-mower/arc track with white-noise sensors."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from ..geometry import wrap_angle
from ..log import Gnss, Heading, NavLog, Odometry, Record, Scan, Truth

#: Quay walls and piers of the synthetic harbour, segments (x0, y0, x1, y1) [m] in the local frame.
HARBOUR = np.array([
    [-150.0, -150.0, 250.0, -150.0], [250.0, -150.0, 250.0, 250.0], [250.0, 250.0, -150.0, 250.0],
    [-150.0, 250.0, -150.0, -150.0], [30.0, -60.0, 30.0, -20.0], [60.0, 70.0, 110.0, 70.0],
    [-30.0, 40.0, 0.0, 80.0], [120.0, -10.0, 150.0, 20.0], [-60.0, -40.0, -40.0, -90.0],
])


def _moorings(n: int = 60, seed: int = 11) -> np.ndarray:
    """Moored boats: 3 x 3 m squares at fixed pseudo-random places (structure for scan matching)."""
    c = np.random.default_rng(seed).uniform([-120.0, -120.0], [220.0, 220.0], (n, 2))
    sq = 1.5 * np.array([[-1, -1, 1, -1], [1, -1, 1, 1], [1, 1, -1, 1], [-1, 1, -1, -1]], dtype=float)
    return (c[:, None, [0, 1, 0, 1]] + sq[None]).reshape(-1, 4)


HARBOUR = np.vstack([HARBOUR, _moorings()])


def raycast(pose: np.ndarray, angles: np.ndarray, segments: np.ndarray = HARBOUR,
            max_range: float = 120.0) -> np.ndarray:
    """Ranges from ``pose`` along body-frame ``angles`` to the nearest segment (NaN: no return)."""
    x, y, yaw = pose
    d = np.stack([np.cos(angles + yaw), np.sin(angles + yaw)], axis=1)[:, None, :]  # (N,1,2)
    a = segments[None, :, :2] - np.array([x, y])  # (1,M,2)
    e = (segments[:, 2:] - segments[:, :2])[None]  # (1,M,2)
    den = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        r = (a[..., 0] * e[..., 1] - a[..., 1] * e[..., 0]) / den
        u = (a[..., 0] * d[..., 1] - a[..., 1] * d[..., 0]) / den
    r = np.where((np.abs(den) > 1e-12) & (r > 0) & (u >= 0) & (u <= 1), r, np.inf).min(axis=1)
    return np.where(r <= max_range, r, np.nan)


def synthetic_records(duration: float = 60.0, rate: float = 10.0, *, t0: float = 1.7e9, speed: float = 2.0,
                      sigma_gnss: float = 1.5, sigma_heading_deg: float = 0.5, scans: bool = False,
                      seed: int = 0) -> Iterator[Record]:
    """The records of :func:`synthetic_trial` one epoch after the other (constant memory, any length)."""
    rng = np.random.default_rng(seed)
    n = int(round(duration * rate))
    dt = 1.0 / rate
    x = y = 0.0
    yaw = 0.3
    beams = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    for k in range(n):
        t = t0 + k * dt
        w = 0.05 * math.sin(2 * math.pi * k * dt / 40.0)
        yield Truth(t, x, y, float(wrap_angle(yaw)))
        yield Gnss(t, x + rng.normal(0, sigma_gnss), y + rng.normal(0, sigma_gnss), sigma_gnss)
        yield Heading(t, float(wrap_angle(yaw + rng.normal(0, math.radians(sigma_heading_deg)))),
                      math.radians(sigma_heading_deg))
        yield Odometry(t, speed + rng.normal(0, 0.05), w + rng.normal(0, 0.002), 0.05, 0.002)
        if scans and k % int(max(1, round(rate))) == 0:  # 1 Hz scans of the harbour, 2 cm noise
            r = raycast(np.array([x, y, yaw]), beams) + rng.normal(0, 0.02, beams.size)
            yield Scan(t, r, beams.copy())
        # exact unicycle step to the next epoch
        if abs(w) < 1e-12:
            x, y = x + speed * dt * math.cos(yaw), y + speed * dt * math.sin(yaw)
        else:
            x += speed / w * (math.sin(yaw + w * dt) - math.sin(yaw))
            y -= speed / w * (math.cos(yaw + w * dt) - math.cos(yaw))
        yaw += w * dt


def synthetic_trial(duration: float = 60.0, rate: float = 10.0, *, t0: float = 1.7e9, speed: float = 2.0,
                    sigma_gnss: float = 1.5, sigma_heading_deg: float = 0.5, scans: bool = False,
                    seed: int = 0, origin: tuple[float, float] = (43.5, 16.4)) -> NavLog:
    """A ``duration`` s log at ``rate`` Hz, all sensors at every epoch. The yaw rate is a slow
    sinusoid (turns of up to ~3 deg/s), so SOG/ROT/heading all vary. Truth is exact."""
    recs = list(synthetic_records(duration, rate, t0=t0, speed=speed, sigma_gnss=sigma_gnss,
                                  sigma_heading_deg=sigma_heading_deg, scans=scans, seed=seed))
    meta = {"name": "synthetic-trial", "origin": {"lat": origin[0], "lon": origin[1]}}
    return NavLog.from_unsorted(recs, meta=meta)
