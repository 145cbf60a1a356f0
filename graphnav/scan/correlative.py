"""Wide-basin correlative scan matching for loop-closure verification: Olson's real-time correlative
scan matching (ICRA 2009) searched by branch and bound as in Cartographer's loop closer (Hess et al.,
ICRA 2016, section V).

The reference scan (or a submap of several, each in scan order) is drawn as polylines -- consecutive
returns closer than ``line_gap`` are joined, so a sparse 180-beam scan still gives continuous walls
-- on a grid of ``resolution``; each cell holds the likelihood ``exp(-d^2 / 2 sigma^2)`` of a return
at distance ``d`` from the nearest drawn surface (Olson's eq. 3 with a Gaussian sensor model). The
score of a pose is the mean likelihood of the source points moved by it. The search is exhaustive
over a square window of ``+-window`` metres around the guess and over yaw (all yaws by default) on
the fine lattice (``resolution``; yaw step = ``resolution`` / the farthest source point used, so no
point moves by more than a cell between two yaws), and exact for that lattice: a precomputed grid
holding the maximum likelihood over each ``2^h x 2^h`` window bounds the score of a whole block of
translations (Cartographer's precomputation grids, eq. 14-15), blocks are expanded best bound first
and a block whose bound is below the best score found is pruned.

Fit scores that work on sparse scans: ``score`` (mean likelihood) and ``hits`` (fraction of source
points within ``hit_radius`` of a reference surface); ``second`` is the best score at least
``distinct`` metres (or ``distinct_yaw_deg``) away from the peak -- a look-alike place (repeated
structure, a corridor) shows as ``second`` close to ``score``. The compiled kernel (numba, as
:mod:`graphnav.scan._icp_fast`) is used when importable and ``backend`` allows; the numpy one
gives the same scores (tested).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class CorrelativeConfig:
    """Settings of :func:`correlative_match` (metres, degrees)."""

    resolution: float = 0.2  # [m] fine lattice and grid cell (the ICP refinement does the rest)
    levels: int = 4  # branch-and-bound depth: top blocks of 2^levels x 2^levels fine translations (3.2 m)
    sigma: float = 0.2  # [m] range of the likelihood field (1-sigma of a return about its surface)
    hit_radius: float = 0.3  # [m] a source point within this of a reference surface is a hit
    line_gap: float = 1.0  # [m] consecutive reference returns closer than this are one surface
    max_range: float = 30.0  # [m] farther returns are not used (sets the yaw step with resolution)
    voxel: float = 0.3  # [m] the source points are thinned to one per voxel ...
    max_points: int = 200  # ... and at most this many (evenly in scan order)
    min_points: int = 20
    distinct: float = 1.0  # [m] the second peak lies at least this far from the best ...
    distinct_yaw_deg: float = 10.0  # ... or turned at least this much
    backend: str = "auto"  # "auto" (numba when importable), "numba", "numpy"


@dataclass
class CorrelativeResult:
    """``pose`` (dx, dy, dyaw): the source scan's pose in the reference frame; ``score`` the mean
    likelihood there, ``hits`` the fraction of source points within ``hit_radius``, ``second``
    the best score of a distinct pose (0 when none was searched); ``points`` source points used,
    ``evaluated`` fine poses scored."""

    pose: NDArray[np.float64]
    score: float
    hits: float
    second: float
    points: int
    evaluated: int
    ok: bool = True
    reason: str = ""


def thin(xy: NDArray[np.float64], voxel: float, max_points: int, max_range: float) -> NDArray[np.float64]:
    """One point per ``voxel`` cell (the first in scan order), at most ``max_points`` (evenly
    spaced), finite and within ``max_range`` of the sensor."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    r = np.hypot(xy[:, 0], xy[:, 1])
    xy = xy[np.isfinite(r) & (r <= max_range)]
    if len(xy) == 0:
        return xy
    cells = np.floor(xy / voxel).astype(np.int64)
    _, first = np.unique(cells, axis=0, return_index=True)
    xy = xy[np.sort(first)]
    if len(xy) > max_points:
        xy = xy[np.linspace(0, len(xy) - 1, max_points).round().astype(int)]
    return xy


class LikelihoodGrid:
    """The reference as a likelihood field and its branch-and-bound precomputation grids.

    ``polylines``: point arrays (each in scan order, reference frame). The grid extends beyond them
    by the likelihood's reach (3 sigma) and a branch-and-bound block: farther out every score is 0."""

    def __init__(self, polylines: list[NDArray[np.float64]], cfg: CorrelativeConfig) -> None:
        self.cfg = cfg
        self._stack: NDArray[np.float64] | None = None
        res = cfg.resolution
        margin = 3.0 * cfg.sigma + ((1 << cfg.levels) + 1) * res
        pts = [np.asarray(p, dtype=float).reshape(-1, 2) for p in polylines]
        pts = [p[np.all(np.isfinite(p), axis=1)] for p in pts]
        allp = np.vstack([p for p in pts if len(p)] or [np.zeros((0, 2))])
        self.n_ref = len(allp)
        if self.n_ref == 0:
            self.origin = np.zeros(2)
            self.like = np.zeros((1, 1))
            self.dist = np.full((1, 1), np.inf)
            self.bounds = [self.like]
            return
        lo = allp.min(0) - margin
        hi = allp.max(0) + margin
        self.origin = lo
        shape = tuple(np.ceil((hi - lo) / res).astype(int) + 1)
        occ = np.zeros(shape, dtype=bool)
        # consecutive returns closer than line_gap: the surface between them, sampled every res / 2 at most
        f = np.linspace(0.0, 1.0, int(math.ceil(2 * cfg.line_gap / res)) + 1)[None, :, None]
        for p in pts:
            dense = [p]
            if len(p) > 1:
                a, b = p[:-1], p[1:]
                seg = np.hypot(*(b - a).T)
                keep = (seg < cfg.line_gap) & (seg > res / 2)
                dense.append((a[keep, None, :] + f * (b[keep] - a[keep])[:, None, :]).reshape(-1, 2))
            q = np.vstack(dense)
            ij = np.floor((q - lo) / res).astype(int)
            ij = ij[(ij[:, 0] >= 0) & (ij[:, 1] >= 0) & (ij[:, 0] < shape[0]) & (ij[:, 1] < shape[1])]
            occ[ij[:, 0], ij[:, 1]] = True
        from scipy import ndimage  # (here: 0.04 s to import, and a run that builds no grid never needs it)

        # distance from a cell's centre to the nearest drawn cell's centre
        self.dist = ndimage.distance_transform_edt(~occ) * res
        self.like = np.exp(-0.5 * (self.dist / cfg.sigma) ** 2)
        # bounds[h][i, j] = max of like over [i, i + 2^h) x [j, j + 2^h): bounds a block of translations
        self.bounds = [self.like]
        for h in range(1, cfg.levels + 1):
            w = 1 << h
            mf = ndimage.maximum_filter(self.like, size=w, mode="constant", cval=0.0, origin=-(w // 2))
            self.bounds.append(mf)

    def stack(self) -> NDArray[np.float64]:
        """The likelihood and its bound grids as one (levels + 1, ni, nj) array (the compiled search)."""
        if self._stack is None:
            self._stack = np.ascontiguousarray(np.stack(self.bounds))
        return self._stack

    def cells(self, xy: NDArray[np.float64]) -> NDArray[np.int64]:
        return np.floor((xy - self.origin) / self.cfg.resolution).astype(np.int64)

    def lookup(self, grid: NDArray[np.float64], ij: NDArray[np.int64]) -> NDArray[np.float64]:
        ok = (ij[..., 0] >= 0) & (ij[..., 1] >= 0) & (ij[..., 0] < grid.shape[0]) & (ij[..., 1] < grid.shape[1])
        out = np.zeros(ij.shape[:-1])
        out[ok] = grid[ij[..., 0][ok], ij[..., 1][ok]]
        return out


_KERNEL: list[Any] = []


def _kernel(backend: str) -> Any:
    """The compiled branch and bound, or ``None`` (numpy)."""
    if backend == "numpy":
        return None
    if not _KERNEL:
        try:
            from ._correlative_fast import branch_and_bound
        except ImportError as exc:
            _KERNEL.append(exc)
        else:
            _KERNEL.append(branch_and_bound)
    k = _KERNEL[0]
    if isinstance(k, ImportError):
        if backend == "numba":
            raise k.with_traceback(None)
        return None
    return k


def block_scores_numpy(grid: NDArray[np.float64], base: NDArray[np.int64], step: int, nb: int) -> NDArray[np.float64]:
    """Scores of ``nb x nb`` translation blocks for every yaw: ``out[y, a, b] = mean_p grid[base[y, p]
    + step (a, b)]`` (0 outside the grid). ``base`` (Y, N, 2): the source's cells at each yaw."""
    ny, n, _ = base.shape
    out = np.zeros((ny, nb, nb))
    off = step * np.arange(nb)
    for y in range(ny):
        i = base[y, :, 0][None, None, :] + off[:, None, None]
        j = base[y, :, 1][None, None, :] + off[None, :, None]
        i, j = np.broadcast_arrays(i, j)
        ok = (i >= 0) & (j >= 0) & (i < grid.shape[0]) & (j < grid.shape[1])
        v = np.zeros(i.shape)
        v[ok] = grid[i[ok], j[ok]]
        out[y] = v.sum(-1) / n
    return out


def _rotated_cells(g: LikelihoodGrid, src: NDArray[np.float64], yaws: NDArray[np.float64],
                   corner: NDArray[np.float64]) -> NDArray[np.int64]:
    c, s = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
    out = np.empty((len(yaws), len(src), 2), dtype=np.int64)
    res = g.cfg.resolution
    out[..., 0] = np.floor((c * src[None, :, 0] - s * src[None, :, 1] + corner[0] - g.origin[0]) / res)
    out[..., 1] = np.floor((s * src[None, :, 0] + c * src[None, :, 1] + corner[1] - g.origin[1]) / res)
    return out


def correlative_match(src_xy: NDArray[np.float64], ref: LikelihoodGrid | list[NDArray[np.float64]],
                      guess: NDArray[np.float64] | None = None, *, window: float = 4.0,
                      yaw_window_deg: float = 180.0, second_above: float = 0.0,
                      cfg: CorrelativeConfig | None = None) -> CorrelativeResult:
    """Best pose of the source points ``src_xy`` (N, 2, sensor frame) on the reference (a
    :class:`LikelihoodGrid`, or polylines in the reference frame) within ``+-window`` metres and
    ``+-yaw_window_deg`` of ``guess`` (dx, dy, dyaw; default the identity). Exact on the fine lattice
    (branch and bound, see the module docstring). The second peak is looked for only above
    ``second_above`` x the best score (0 is reported when there is none: a cheaper search)."""
    cfg = cfg or (ref.cfg if isinstance(ref, LikelihoodGrid) else CorrelativeConfig())
    guess = np.zeros(3) if guess is None else np.asarray(guess, dtype=float)
    src = thin(src_xy, cfg.voxel, cfg.max_points, cfg.max_range)
    if len(src) < cfg.min_points:
        return CorrelativeResult(guess.copy(), 0.0, 0.0, 0.0, len(src), 0, False,
                                 f"too few source points ({len(src)} < {cfg.min_points})")
    g = ref if isinstance(ref, LikelihoodGrid) else LikelihoodGrid(ref, cfg)
    if g.n_ref < cfg.min_points:
        return CorrelativeResult(guess.copy(), 0.0, 0.0, 0.0, len(src), 0, False,
                                 f"too few reference points ({g.n_ref} < {cfg.min_points})")
    res = cfg.resolution
    reach = float(np.hypot(src[:, 0], src[:, 1]).max())
    dyaw = res / max(reach, res)
    half = math.radians(min(yaw_window_deg, 180.0))
    ny = int(math.floor(half / dyaw))
    if yaw_window_deg >= 180.0:  # the full turn, each yaw once
        ny = int(math.ceil(math.pi / dyaw))
        yaws = guess[2] + dyaw * np.arange(-ny, ny)
    else:
        yaws = guess[2] + dyaw * np.arange(-ny, ny + 1)
    nfine = int(math.ceil(2 * window / res)) + 1
    corner = guess[:2] - window  # translation of lattice index (0, 0)
    base = _rotated_cells(g, src, yaws, corner)
    far_t = cfg.distinct / res
    far_y = math.radians(cfg.distinct_yaw_deg) / dyaw
    circular = yaw_window_deg >= 180.0
    bnb = _kernel(cfg.backend)
    if bnb is not None:
        stack = g.stack()
        best, yb, ib, jb, n1 = bnb(stack, base, nfine, -1.0, -1, -1, -1, circular, far_t, far_y)
        second, _, _, _, n2 = bnb(stack, base, nfine, second_above * best, yb, ib, jb, circular, far_t, far_y)
        if second <= second_above * best:
            second = 0.0
        evaluated = n1 + n2
    else:
        best, yb, ib, jb, second, evaluated = _search_numpy(g, base, nfine, circular, far_t, far_y, second_above)
    pose = np.array([corner[0] + ib * res, corner[1] + jb * res, yaws[yb]])
    hits = fit(g, src, pose)
    pose[2] = math.remainder(pose[2], 2 * math.pi)
    return CorrelativeResult(pose, float(best), hits, float(max(second, 0.0)), len(src), int(evaluated))


def _search_numpy(g: LikelihoodGrid, base: NDArray[np.int64], nfine: int, circular: bool, far_t: float,
                  far_y: float, second_above: float) -> tuple[float, int, int, int, float, int]:
    """The same search without numba: one level of blocks (``2^levels`` fine cells a side) scored
    by their bound, expanded best first until the bound falls below the best score; then the best
    pose outside the peak's neighbourhood likewise."""
    L = g.cfg.levels
    w = 1 << L
    nb = (nfine + w - 1) // w
    ny = base.shape[0]
    bound = block_scores_numpy(g.bounds[L], base, w, nb)
    order = np.argsort(bound, axis=None)[::-1]
    cache: dict[int, NDArray[np.float64]] = {}
    evaluated = 0

    def fine(flat: int) -> NDArray[np.float64]:
        nonlocal evaluated
        if flat not in cache:
            y, a, b = np.unravel_index(flat, bound.shape)
            sc = block_scores_numpy(g.like, base[y:y + 1] + np.array([a * w, b * w]), 1, w)[0]
            ii = a * w + np.arange(w)[:, None]
            jj = b * w + np.arange(w)[None, :]
            cache[flat] = np.where((ii < nfine) & (jj < nfine), sc, -1.0)
            evaluated += int(((ii < nfine) & (jj < nfine)).sum())
        return cache[flat]

    best, yb, ib, jb = -1.0, -1, -1, -1
    for flat in order:
        if bound.flat[flat] <= best:
            break
        sc = fine(int(flat))
        i, j = np.unravel_index(int(np.argmax(sc)), sc.shape)
        if sc[i, j] > best:
            y, a, b = np.unravel_index(int(flat), bound.shape)
            best, yb, ib, jb = float(sc[i, j]), int(y), int(a * w + i), int(b * w + j)
    second = second_above * best
    for flat in order:
        if bound.flat[flat] <= second:
            break
        y, a, b = np.unravel_index(int(flat), bound.shape)
        dy = abs(int(y) - yb)
        if circular:
            dy = min(dy, ny - dy)
        ii = a * w + np.arange(w)[:, None]
        jj = b * w + np.arange(w)[None, :]
        near = (np.hypot(ii - ib, jj - jb) < far_t) & (dy < far_y)
        if near.all():
            continue
        second = max(second, float(np.where(near, -1.0, fine(int(flat))).max()))
    return best, yb, ib, jb, (second if second > second_above * best else 0.0), evaluated


def fit(g: LikelihoodGrid, src: NDArray[np.float64], pose: NDArray[np.float64]) -> float:
    """Fraction of the points ``src`` (source frame) within ``hit_radius`` of a reference surface
    at ``pose``."""
    if len(src) == 0:
        return 0.0
    c, s = math.cos(pose[2]), math.sin(pose[2])
    p = src @ np.array([[c, s], [-s, c]]) + pose[:2]
    d = g.lookup(np.minimum(g.dist, 1e9), g.cells(p))  # outside the grid: 0 from lookup, so mark it
    ij = g.cells(p)
    inside = (ij[:, 0] >= 0) & (ij[:, 1] >= 0) & (ij[:, 0] < g.dist.shape[0]) & (ij[:, 1] < g.dist.shape[1])
    return float(np.mean(inside & (d <= g.cfg.hit_radius)))
