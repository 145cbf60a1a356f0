"""A rotation-invariant place descriptor of one 2D scan, in the spirit of Scan Context (Kim and Kim,
IROS 2018), for proposing loop-closure candidates when the pose estimate has drifted too far for a
proximity search.

The scan's points (sensor frame) are binned in polar cells: ``rings`` annuli of equal width up to
``max_range`` and ``sectors`` equal angular sectors over the full turn. A cell holds the fraction of
the scan's returns that fall in it, smoothed over the two neighbouring rings (a 2D scan has no
height, which Scan Context stores; the return density takes its place).

* :func:`ring_key` -- the row sums (per-ring density): invariant to a rotation of the sensor, a
  short vector for a k-d tree (Scan Context's ring key, section III-C).
* :func:`distance` -- Scan Context's eq. 5-6: the mean cosine distance between corresponding
  columns (sectors), minimised over the circular column shift; the best shift is the yaw of the
  query scan in the candidate's frame (a multiple of ``2 pi / sectors``). Only the columns that
  hold returns in both descriptors count (a 180 deg LiDAR fills half of them), and at least
  ``min_overlap`` of them must.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class DescriptorConfig:
    """Polar binning of :func:`describe` (metres, counts)."""

    rings: int = 20
    sectors: int = 60  # 6 deg sectors
    max_range: float = 30.0  # [m] returns beyond are ignored (indoor and harbour scenes alike)
    min_points: int = 20  # fewer returns: no descriptor (``None``)
    min_overlap: float = 0.25  # fraction of the sectors that must hold returns in both descriptors


@dataclass(frozen=True)
class Descriptor:
    """The polar grid (``rings`` x ``sectors``), its ring key, and which sectors hold returns."""

    grid: NDArray[np.float64]
    key: NDArray[np.float64]
    filled: NDArray[np.bool_]

    @cached_property
    def columns(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The columns' norms and the grid with each column normalised (zero where empty): computed once
        per descriptor, which a loop search compares with many."""
        norm = np.linalg.norm(self.grid, axis=0)
        return norm, np.divide(self.grid, norm, out=np.zeros_like(self.grid), where=norm > 0)


def describe(xy: NDArray[np.float64], cfg: DescriptorConfig | None = None) -> Descriptor | None:
    """The descriptor of the points ``xy`` (N, 2) in the sensor frame; ``None`` with fewer than
    ``cfg.min_points`` returns within ``cfg.max_range``."""
    cfg = cfg or DescriptorConfig()
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    r = np.hypot(xy[:, 0], xy[:, 1])
    ok = np.isfinite(r) & (r < cfg.max_range) & (r > 0.0)
    if ok.sum() < cfg.min_points:
        return None
    r, a = r[ok], np.arctan2(xy[ok, 1], xy[ok, 0])
    ri = np.minimum((r / cfg.max_range * cfg.rings).astype(int), cfg.rings - 1)
    si = np.floor((a + math.pi) / (2 * math.pi) * cfg.sectors).astype(int) % cfg.sectors
    # the returns per cell (counts: exactly the sums of 1.0 that np.add.at made)
    grid = np.bincount(ri * cfg.sectors + si, minlength=cfg.rings * cfg.sectors).reshape(
        cfg.rings, cfg.sectors).astype(float)
    grid /= ok.sum()
    filled = grid.sum(0) > 0
    smooth = grid.copy()  # a return near a ring border counts half in the next ring
    smooth[1:] += 0.5 * grid[:-1]
    smooth[:-1] += 0.5 * grid[1:]
    return Descriptor(smooth, smooth.sum(1), filled)


def ring_key(d: Descriptor) -> NDArray[np.float64]:
    """Scan Context's ring key: the per-ring return density (rotation invariant)."""
    return d.key


_DIAG: dict[int, NDArray[np.int64]] = {}


def _diagonals(n: int) -> NDArray[np.int64]:
    """Flat indices of ``(j, (j + s) mod n)`` of an n x n matrix, row ``s`` (cached per ``n``)."""
    d = _DIAG.get(n)
    if d is None:
        j = np.arange(n)
        d = _DIAG[n] = j[None, :] * n + (j[None, :] + j[:, None]) % n
    return d


def distance(q: Descriptor, c: Descriptor, min_overlap: float = 0.25) -> tuple[float, float]:
    """Scan Context's distance (eq. 5-6) between the query ``q`` and candidate ``c``, and the yaw
    [rad] of the query's frame in the candidate's at the best column shift: ``(d, yaw)``, ``d`` in
    [0, 1] (0: identical after the shift; 1 when fewer than ``min_overlap`` of the sectors hold
    returns in both)."""
    n = q.grid.shape[1]
    (qn, qh), (cn, ch) = q.columns, c.columns
    cos = qh.T @ ch  # cos[j, l]: query column j against candidate column l
    both = (qn > 0)[:, None] & (cn > 0)  # (np.outer of the two masks)
    flat = _diagonals(n)  # row s: (j, j + s) for every j -- the query rotated by +s sectors
    sums = cos.ravel()[flat].sum(1)
    counts = both.ravel()[flat].sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.where(counts >= max(min_overlap * n, 1), 1.0 - sums / np.maximum(counts, 1), 1.0)
    s = int(np.argmin(d))
    yaw = s * 2 * math.pi / n
    return float(d[s]), math.atan2(math.sin(yaw), math.cos(yaw))
