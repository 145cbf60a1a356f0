"""Tiny 2D ray caster for the ICP tests: exact scans of line-segment worlds."""

from __future__ import annotations

import numpy as np

from graphnav.geometry import se2_compose


def room(w: float = 20.0, h: float = 12.0) -> np.ndarray:
    """Segments (S, 4) of a rectangular basin with a pier and two boxes (well constrained)."""
    segs = [
        (-w / 2, -h / 2, w / 2, -h / 2), (w / 2, -h / 2, w / 2, h / 2),
        (w / 2, h / 2, -w / 2, h / 2), (-w / 2, h / 2, -w / 2, -h / 2),
        (2.0, -h / 2, 2.0, -2.5),  # a pier
        (-5.0, 2.0, -3.0, 2.0), (-3.0, 2.0, -3.0, 3.5), (-3.0, 3.5, -5.0, 3.5), (-5.0, 3.5, -5.0, 2.0),
        (4.0, 1.0, 6.0, 3.0), (6.0, 3.0, 7.0, 1.5), (7.0, 1.5, 4.0, 1.0),
    ]
    return np.array(segs, dtype=float)


def corridor(length: float = 200.0, half_width: float = 2.0) -> np.ndarray:
    """Two long parallel walls: translation along x is unobservable."""
    return np.array([(-length / 2, -half_width, length / 2, -half_width),
                     (-length / 2, half_width, length / 2, half_width)], dtype=float)


def raycast(segs: np.ndarray, pose, angles: np.ndarray, max_range: float = 40.0) -> np.ndarray:
    """Ranges (NaN = no return) of beams at ``angles`` (sensor frame) from ``pose``."""
    x, y, th = pose
    a = angles + th
    d = np.stack([np.cos(a), np.sin(a)], 1)  # (B, 2)
    p0 = segs[:, :2]
    e = segs[:, 2:] - p0  # (S, 2)
    w = p0 - np.array([x, y])  # (S, 2)
    den = d[:, 0:1] * e[None, :, 1] - d[:, 1:2] * e[None, :, 0]  # cross(d, e)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # (parallel: den ~ 0, masked below)
        t = (w[None, :, 0] * e[None, :, 1] - w[None, :, 1] * e[None, :, 0]) / den
        u = (w[None, :, 0] * d[:, 1:2] - w[None, :, 1] * d[:, 0:1]) / den
    hit = (np.abs(den) > 1e-12) & (t > 1e-9) & (u >= 0) & (u <= 1)
    t = np.where(hit, t, np.inf)
    r = t.min(1)
    r[~np.isfinite(r) | (r > max_range)] = np.nan
    return r


def noisy_scan(segs, pose, rng, n_beams=360, sigma_r_rel=0.004258, sigma_alpha=0.0, jitter=True):
    """A ray-cast scan with the LiDAR error model: range noise ``sigma_r_rel * r``; ``sigma_alpha``
    perturbs the true beam direction (the reported angle stays nominal)."""
    off = rng.uniform(0, 2 * np.pi / n_beams) if jitter else 0.0
    ang = off + np.arange(n_beams) * 2 * np.pi / n_beams
    true_ang = ang + rng.normal(0, sigma_alpha, n_beams) if sigma_alpha > 0 else ang
    r = raycast(segs, pose, true_ang)
    r = r + rng.normal(0, 1, n_beams) * sigma_r_rel * np.nan_to_num(r)
    return r, ang


def points(r: np.ndarray, a: np.ndarray) -> np.ndarray:
    ok = np.isfinite(r)
    return np.column_stack([r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])])


def world_points(segs: np.ndarray, n: int, rng) -> np.ndarray:
    """``n`` points spread on the segments in proportion to their length."""
    length = np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1])
    k = rng.choice(len(segs), n, p=length / length.sum())
    u = rng.uniform(0, 1, n)
    return segs[k, :2] + u[:, None] * (segs[k, 2:] - segs[k, :2])


def to_frame(pts_world: np.ndarray, pose) -> np.ndarray:
    """World points expressed in the frame of ``pose``."""
    x, y, th = pose
    c, s = np.cos(th), np.sin(th)
    d = pts_world - np.array([x, y])
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])


def even_points(segs: np.ndarray, spacing: float) -> np.ndarray:
    out = []
    for s in segs:
        n = max(int(np.hypot(s[2] - s[0], s[3] - s[1]) / spacing), 1)
        u = (np.arange(n) + 0.5) / n
        out.append(s[:2] + u[:, None] * (s[2:] - s[:2]))
    return np.vstack(out)


def observe(world: np.ndarray, pose, rng, s_rel: float, s_a: float) -> np.ndarray:
    """World points seen from ``pose`` with the LiDAR error model (range and angle noise)."""
    p = to_frame(world, pose)
    r = np.hypot(p[:, 0], p[:, 1])
    a = np.arctan2(p[:, 1], p[:, 0])
    r = r + rng.normal(0, 1, len(r)) * s_rel * r
    a = a + rng.normal(0, s_a, len(r))
    return np.column_stack([r * np.cos(a), r * np.sin(a)])


__all__ = ["room", "corridor", "raycast", "noisy_scan", "points", "world_points", "to_frame", "se2_compose",
           "even_points", "observe"]
