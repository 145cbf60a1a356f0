"""A tiny polygon world for tests: a small synthetic log with exact truth for the scan matchers and
the compare command, ray-cast with the harbour simulator's :func:`graphnav.sim.harbour.raycast`
in a smaller, simpler basin (fast, and with a track known to stay clear of the obstacles).
"""

from __future__ import annotations

import numpy as np

from graphnav.log import Gnss, Heading, NavLog, Odometry, PosePrior, Scan, Truth
from graphnav.sim import harbour


def rect(x0: float, y0: float, x1: float, y1: float) -> list[tuple[float, float]]:
    return [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]


def basin() -> np.ndarray:
    """Segments (M, 4) of a 120 m x 70 m basin with piers and moored boxes (breaks symmetry)."""
    polys = [
        rect(-20, -30, 100, 40),            # quay walls
        rect(10, 25, 14, 40), rect(40, 18, 43, 40), rect(70, 28, 74, 40),   # piers from the north quay
        rect(25, -30, 28, -18), rect(60, -30, 62, -12),                     # piers from the south quay
        rect(30, -12, 33, -10), rect(55, -8, 58, -5), rect(5, 12, 8, 15),      # moored boats
    ]
    return harbour.segments([np.array(p, dtype=float) for p in polys])


def raycast(pose: np.ndarray, angles: np.ndarray, segs: np.ndarray, max_range: float = 40.0) -> np.ndarray:
    """Exact ranges [m] of beams at ``angles`` (body frame) from ``pose``; NaN where nothing is hit
    (the harbour simulator's ray caster)."""
    x, y, th = pose
    d = np.stack([np.cos(th + angles), np.sin(th + angles)], axis=1)
    return harbour.raycast(segs, np.array([x, y], dtype=float), d, max_range)


def track(n: int, dt: float = 0.5, v: float = 1.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times, poses (n, 3) and (v, w) of a straight run, a left turn, and a straight run (clear of
    the obstacles of :func:`basin` for n <= 80)."""
    t = np.arange(n) * dt
    w = np.where((t > 0.3 * t[-1]) & (t < 0.6 * t[-1]), 0.12, 0.0)
    poses = np.zeros((n, 3))
    poses[0] = (0.0, 0.0, 0.0)
    for k in range(1, n):
        x, y, th = poses[k - 1]
        mid = th + 0.5 * w[k - 1] * dt
        poses[k] = (x + v * dt * np.cos(mid), y + v * dt * np.sin(mid), th + w[k - 1] * dt)
    return t, poses, np.column_stack([np.full(n, v), w])


def synthetic_log(n: int = 40, *, seed: int = 0, beams: int = 360, range_sigma: float = 0.01,
                  gnss_sigma: float = 0.8, events: bool = True) -> NavLog:
    """Scans, truth, odometry, heading and GNSS on :func:`track`; a GNSS outage and a jump in meta."""
    rng = np.random.default_rng(seed)
    segs = basin()
    t, poses, vw = track(n)
    ang = np.linspace(-np.pi, np.pi, beams, endpoint=False)
    recs = [PosePrior(0.0, *map(float, poses[0]), 0.1, 0.01)]
    t_out = (0.4 * t[-1], 0.55 * t[-1])
    t_jump = (0.75 * t[-1], 0.8 * t[-1])
    for k in range(n):
        r = raycast(poses[k], ang, segs) + rng.normal(0, range_sigma, beams)
        r[rng.random(beams) < 0.05] = 0.0  # dropped returns
        recs.append(Scan(float(t[k]), r, ang.copy()))
        recs.append(Truth(float(t[k]), *map(float, poses[k])))
        v, w = vw[k, 0] + rng.normal(0, 0.05), vw[k, 1] + rng.normal(0, 0.005)
        recs.append(Odometry(float(t[k]), float(v), float(w), 0.05, 0.005))
        recs.append(Heading(float(t[k]), float(poses[k, 2] + rng.normal(0, 0.02)), 0.02))
        if not (events and t_out[0] <= t[k] <= t_out[1]):
            jump = 15.0 if events and t_jump[0] <= t[k] <= t_jump[1] else 0.0
            recs.append(Gnss(float(t[k]), float(poses[k, 0] + jump + rng.normal(0, gnss_sigma)),
                             float(poses[k, 1] + rng.normal(0, gnss_sigma)), gnss_sigma))
    meta = {"name": "polyworld", "source": "tests/_polyworld.py"}
    if events:
        meta["events"] = [{"kind": "gnss_outage", "t0": t_out[0], "t1": t_out[1]},
                          {"kind": "gnss_jump", "t0": t_jump[0], "t1": t_jump[1]}]
    return NavLog.from_unsorted(recs, meta=meta)
