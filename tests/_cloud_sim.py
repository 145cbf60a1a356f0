"""Small synthetic 3D scenes for the registration tests: points sampled on boxes, walls, a floor and
cylinders (every direction constrained), rigid transforms to move them; and where the KITTI pair is."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

REPO = Path(__file__).resolve().parents[1]


def find_kitti() -> Path | None:
    """The KITTI pair at ../shared/data/kitti_pair (one level further up for worktrees), or None."""
    for c in (REPO.parent / "shared" / "data" / "kitti_pair", REPO.parent.parent / "shared" / "data" / "kitti_pair"):
        if (c / "source.ply").exists() and (c / "target.ply").exists() and (c / "T_target_source.txt").exists():
            return c
    return None


def _box(rng, n, lo, hi):
    """``n`` points on the five visible faces (no bottom) of an axis-aligned box."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    ext = hi - lo
    areas = np.array([ext[0] * ext[1], ext[1] * ext[2], ext[1] * ext[2], ext[0] * ext[2], ext[0] * ext[2]])
    face = rng.choice(5, n, p=areas / areas.sum())
    u = rng.uniform(0, 1, (n, 3))
    p = lo + u * ext
    p[face == 0, 2] = hi[2]
    p[face == 1, 0] = lo[0]
    p[face == 2, 0] = hi[0]
    p[face == 3, 1] = lo[1]
    p[face == 4, 1] = hi[1]
    return p


def _cylinder(rng, n, cx, cy, r, h, z0=-0.37):
    a = rng.uniform(0, 2 * np.pi, n)
    return np.column_stack([cx + r * np.cos(a), cy + r * np.sin(a), rng.uniform(z0, z0 + h, n)])


def scene(rng: np.random.Generator, n: int = 6000, noise: float = 0.01) -> np.ndarray:
    """(n, 3) points of a 30 m x 20 m yard: a floor, two quay walls, three boxes, two bollards. The
    planes lie off the integer coordinates (voxel faces at 1 m) and ``noise`` [m] is added: a
    noiseless floor exactly on a voxel face is a discontinuity no voxel method is expected to meet."""
    z0 = -0.37
    parts = [
        (0.30, lambda k: np.column_stack([rng.uniform(-15, 15, k), rng.uniform(-10, 10, k), np.full(k, z0)])),
        (0.15, lambda k: np.column_stack([rng.uniform(-15, 15, k), np.full(k, 9.61), rng.uniform(z0, 4, k)])),
        (0.12, lambda k: np.column_stack([np.full(k, -14.77), rng.uniform(-10, 10, k), rng.uniform(z0, 4, k)])),
        (0.12, lambda k: _box(rng, k, (2.3, -6.2, z0), (6.1, -3.3, 2.45))),
        (0.10, lambda k: _box(rng, k, (-8.4, 2.2, z0), (-5.3, 7.15, 3.05))),
        (0.09, lambda k: _box(rng, k, (7.3, 4.4, z0), (9.2, 8.3, 1.55))),
        (0.06, lambda k: _cylinder(rng, k, -2, -2, 0.4, 1.2)),
        (0.06, lambda k: _cylinder(rng, k, 3, 3, 0.3, 1.0)),
    ]
    counts = rng.multinomial(n, [w for w, _ in parts])
    pts = np.vstack([f(k) for (_, f), k in zip(parts, counts, strict=True)])
    return pts + rng.normal(0, noise, pts.shape)


def rigid(t, rpy_deg) -> np.ndarray:
    """4x4 of a translation and roll/pitch/yaw in degrees (R = Rz Ry Rx)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("ZYX", np.asarray(rpy_deg, float)[::-1], degrees=True).as_matrix()
    T[:3, 3] = t
    return T


def apply(T: np.ndarray, pts: np.ndarray) -> np.ndarray:
    return pts @ T[:3, :3].T + T[:3, 3]


def pair(rng: np.random.Generator, T_target_source: np.ndarray, n: int = 6000, noise: float = 0.01):
    """(source, target): two independent samplings of the scene; the target in the scene frame, the
    source in the frame that ``T_target_source`` maps into it."""
    target = scene(rng, n, noise)
    source = apply(np.linalg.inv(T_target_source), scene(rng, n, noise))
    return source, target
