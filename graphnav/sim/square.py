"""A small synthetic square loop with exact truth, for tests and quick checks (no CLI scenario).

The vessel drives ``laps`` squares of side ``side`` [m] at ``speed`` [m/s], turning 90 degrees at
each corner at a constant rate; odometry at 10 Hz, and optionally GNSS, compass and beacon
range/bearing sightings (within ``beacon_range``). Deterministic per seed.
"""

from __future__ import annotations

import math

import numpy as np

from ..geometry import wrap_angle
from ..log import BeaconObs, Gnss, Heading, KnownBeacon, NavLog, Odometry, PosePrior, Truth


def square_path(
    side: float = 40.0, speed: float = 1.0, turn_time: float = 8.0, laps: int = 1, dt: float = 0.02
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times, poses (N, 3) and controls (N, 2: v, w) of the loop, integrated exactly."""
    segs = []
    for _ in range(4 * laps):
        segs.append((side / speed, speed, 0.0))
        segs.append((turn_time, speed, (math.pi / 2) / turn_time))
    t, poses, ctl = [0.0], [np.zeros(3)], []
    for dur, v, w in segs:
        n = int(round(dur / dt))
        for _ in range(n):
            x, y, th = poses[-1]
            if abs(w) < 1e-12:
                nx, ny = x + v * dt * math.cos(th), y + v * dt * math.sin(th)
            else:
                nx = x + v / w * (math.sin(th + w * dt) - math.sin(th))
                ny = y - v / w * (math.cos(th + w * dt) - math.cos(th))
            ctl.append((v, w))
            poses.append(np.array([nx, ny, th + w * dt]))
            t.append(t[-1] + dt)
    ctl.append(ctl[-1])
    p = np.array(poses)
    p[:, 2] = wrap_angle(p[:, 2])
    return np.array(t), p, np.array(ctl)


def square_loop(
    seed: int = 0,
    *,
    side: float = 40.0,
    speed: float = 1.0,
    laps: int = 1,
    odometry: bool = True,
    gnss: bool = True,
    compass: bool = True,
    beacons: dict[str, tuple[float, float]] | None = None,
    charted: bool = True,
    pose_prior: bool = True,
    sigma_v: float = 0.05,
    sigma_w: float = math.radians(0.5),
    sigma_gnss: float = 2.0,
    sigma_compass: float = math.radians(2.0),
    compass_bias: float = 0.0,
    sigma_range: float = 0.5,
    sigma_bearing: float = math.radians(0.5),
    beacon_range: float = 150.0,
    gnss_jump: tuple[float, float, float, float] | None = None,
) -> NavLog:
    """A square-loop log. ``gnss_jump = (t0, t1, dx, dy)`` offsets the fixes in ``[t0, t1)``."""
    rng = np.random.default_rng(seed)
    t, p, ctl = square_path(side, speed, laps=laps)
    recs: list = []
    every = lambda period: range(0, len(t), int(round(period / (t[1] - t[0]))))  # noqa: E731
    for i in every(0.1):
        recs.append(Truth(float(t[i]), *map(float, p[i])))
        if odometry:
            recs.append(
                Odometry(
                    float(t[i]),
                    float(ctl[i, 0] + rng.normal(0, sigma_v)),
                    float(ctl[i, 1] + rng.normal(0, sigma_w)),
                    sigma_v,
                    sigma_w,
                )
            )
    events = []
    for i in every(1.0):
        ti = float(t[i])
        if gnss:
            dx = dy = 0.0
            if gnss_jump is not None and gnss_jump[0] <= ti < gnss_jump[1]:
                dx, dy = gnss_jump[2], gnss_jump[3]
            recs.append(
                Gnss(
                    ti,
                    float(p[i, 0] + dx + rng.normal(0, sigma_gnss)),
                    float(p[i, 1] + dy + rng.normal(0, sigma_gnss)),
                    sigma_gnss,
                )
            )
        if compass:
            yaw = p[i, 2] + compass_bias + rng.normal(0, sigma_compass)
            recs.append(Heading(ti, float(wrap_angle(yaw)), sigma_compass))
        for bid, (bx, by) in (beacons or {}).items():
            dx, dy = bx - p[i, 0], by - p[i, 1]
            r = math.hypot(dx, dy)
            if r <= beacon_range:
                b = math.atan2(dy, dx) - p[i, 2] + rng.normal(0, sigma_bearing)
                recs.append(
                    BeaconObs(
                        ti,
                        bid,
                        float(r + rng.normal(0, sigma_range)),
                        float(wrap_angle(b)),
                        sigma_range,
                        sigma_bearing,
                    )
                )
    if gnss_jump is not None:
        events.append({"kind": "gnss_jump", "t0": gnss_jump[0], "t1": gnss_jump[1]})
    if pose_prior:
        recs.append(PosePrior(0.0, *map(float, p[0]), 0.1, math.radians(1.0)))
    known = (
        [KnownBeacon(b, float(x), float(y), 0.2) for b, (x, y) in (beacons or {}).items()] if charted else []
    )
    return NavLog.from_unsorted(recs, known, {"name": "square", "events": events})
