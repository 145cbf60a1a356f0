"""A small synthetic sea-trial log (GNSS + gyrocompass + SOG/ROT odometry + optional scans + truth)
for I/O round trips, live-mode tests and the live benchmark. Not a scenario simulator (those live in
:mod:`graphnav.sim`): a vessel on a constant-speed lawn-mower/arc track with white-noise sensors."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from ..geometry import wrap_angle
from ..log import Gnss, Heading, NavLog, Odometry, Record, Scan, Truth


def synthetic_records(duration: float = 60.0, rate: float = 10.0, *, t0: float = 1.7e9, speed: float = 2.0,
                      sigma_gnss: float = 1.5, sigma_heading_deg: float = 0.5, scans: bool = False,
                      seed: int = 0) -> Iterator[Record]:
    """The records of :func:`synthetic_trial` one epoch after the other (constant memory, any length)."""
    rng = np.random.default_rng(seed)
    n = int(round(duration * rate))
    dt = 1.0 / rate
    x = y = 0.0
    yaw = 0.3
    beams = np.linspace(-math.pi, math.pi, 90, endpoint=False)
    for k in range(n):
        t = t0 + k * dt
        w = 0.05 * math.sin(2 * math.pi * k * dt / 40.0)
        yield Truth(t, x, y, float(wrap_angle(yaw)))
        yield Gnss(t, x + rng.normal(0, sigma_gnss), y + rng.normal(0, sigma_gnss), sigma_gnss)
        yield Heading(t, float(wrap_angle(yaw + rng.normal(0, math.radians(sigma_heading_deg)))),
                      math.radians(sigma_heading_deg))
        yield Odometry(t, speed + rng.normal(0, 0.05), w + rng.normal(0, 0.002), 0.05, 0.002)
        if scans and k % int(max(1, round(rate))) == 0:
            r = 20.0 + 5.0 * np.cos(beams + yaw) + rng.normal(0, 0.02, beams.size)
            r[rng.random(beams.size) < 0.1] = np.nan
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
