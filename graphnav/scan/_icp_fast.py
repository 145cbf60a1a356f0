"""The weighted ICP of :mod:`graphnav.scan.weighted_icp` (Algorithm 1, eq. 5-22): its one implementation.

Compiled by numba when importable, else run as plain Python (:mod:`graphnav.scan._jit`, the same code).
:func:`match` runs the whole numeric part of one match in one call: the LiDAR error model of eq. 5-8,
the target's resolution and lines, the loop (exact grid-based nearest neighbours, or the paper's
Delaunay nearest apex), the final pairs' weights and the sums the covariance and degeneracy analysis
need (:func:`report_sums`), and from them the covariance and the degeneracy's eigen-analysis
(:func:`report_algebra`, the numbers of :mod:`graphnav.scan.covariance` and :mod:`graphnav.scan.degeneracy`).
The flags and the report stay in Python. The data travel in groups:

* a cloud, ``(x, y, ux, uy, a2, b2, m2)`` (:func:`cloud_terms`: points, unit radial vectors, squared
  semi-axes of eq. 6-7, squared mean error of eq. 5), one array each;
* the target's grid, ``(xmin, ymin, h, nx, ny, start, items, 1 / h)`` (:func:`build_grid`);
* the target's lines, ``(nx, ny, flat)`` per target point;
* an iteration's pairs, ``(px, py, d, idx, w)``: moved source points, distance and index of the match,
  weight;
* the Delaunay triangulation, ``(transform, neighbors, simplices)`` (scipy's; empty when unused);
* the settings, :class:`Params`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ._jit import njit

MAX_CELLS_PER_POINT = 16
MIN_CELL_CAP = 1 << 16
"""A grid has at most ``max(MAX_CELLS_PER_POINT * n, MIN_CELL_CAP)`` cells: O(n) memory and work per
query whatever the points' spread (one far point would otherwise size the grid by its bounding box)."""
HDL = 4  # Params.variant: 0 K, 1 H, 2 HM, 3 HD, 4 HDL
_TRI_EPS = 100 * np.finfo(float).eps  # scipy's find_simplex tolerance on barycentric coordinates


class Params(NamedTuple):
    """The settings of one match (:class:`graphnav.scan.weighted_icp.IcpConfig`'s, as the kernels take them)."""

    variant: int  # 0 K, 1 H, 2 HM, 3 HD, 4 HDL
    huber_c: float
    wpow: float  # weight = G^-wpow
    max_corr: float  # inf: no fixed gate
    tol: float  # in units of D
    tol_step: float  # in units of D
    max_iter: int
    cell: float  # [m] the grids' cell side
    normal_k: int
    knn: bool  # HDL: k-nearest line normals (else beam order)
    max_gap: float
    flat_pow: float
    warmup: float
    gate0: float
    min_res: float
    sigma_alpha: float
    sigma_r_rel: float
    delaunay: bool
    samp_var: float  # variance of the sampling error per unit spacing^2 (covariance.SAMPLING_VARIANCE)
    max_condition: float  # degeneracy: condition number of the point-to-line information above -> weak
    max_sigma: float  # degeneracy: 1-sigma along a direction above max_sigma x D -> weak (in units of D)


# ----------------------------------------------------------------------------- nearest neighbours


@njit(cache=True)
def grid_cell(h, ex, ey, n):
    """The cell side for points spanning ``ex`` x ``ey``: ``h``, doubled until the grid has at most
    ``max(MAX_CELLS_PER_POINT * n, MIN_CELL_CAP)`` cells (nearest-neighbour search is exact at any
    side; only its speed depends on it). The extents must be finite."""
    if not (math.isfinite(ex) and math.isfinite(ey) and math.isfinite(h) and h > 0.0):
        raise ValueError("grid: non-finite extent or cell side")
    cap = max(MAX_CELLS_PER_POINT * n, MIN_CELL_CAP)
    while (np.floor(ex / h) + 1.0) * (np.floor(ey / h) + 1.0) > cap:
        h *= 2.0
    return h


@njit(cache=True, inline="always")
def cell_index(v, vmin, inv_h, nv):
    """``floor((v - vmin) / h)`` clamped to ``[0, nv - 1]`` (in floating point first, so a far or
    non-finite coordinate cannot overflow the integer conversion), as ``(v - vmin) * inv_h``, ``inv_h = 1 /
    h``: exactly the quotient for a cell side that is a power of two (:func:`build_grid`), and in any case the
    mapping the grid was bucketed with."""
    f = np.floor((v - vmin) * inv_h)
    if not f >= 0.0:  # also NaN
        return 0
    if f > nv - 1:
        return nv - 1
    return int(f)


@njit(cache=True)
def build_grid(tx, ty, h):
    """Bucket target points into square cells (counting sort). The cell side is ``h`` or larger
    (:func:`grid_cell`: at most O(n) cells; a power of two when ``h`` is one, as the matcher's 1 m). Returns the
    grid ``(xmin, ymin, h, nx, ny, start, items, 1 / h)``; points are bucketed by ``(v - vmin) * (1 / h)``, as
    :func:`cell_index` finds them (a multiplication, not a division, per coordinate and query)."""
    n = tx.shape[0]
    xmin, ymin = tx.min(), ty.min()
    h = grid_cell(h, tx.max() - xmin, ty.max() - ymin, n)
    inv = 1.0 / h
    nx = int((tx.max() - xmin) * inv) + 1
    ny = int((ty.max() - ymin) * inv) + 1
    cell = np.empty(n, np.int64)
    start = np.zeros(nx * ny + 1, np.int64)
    for i in range(n):
        c = int((tx[i] - xmin) * inv) * ny + int((ty[i] - ymin) * inv)
        cell[i] = c
        start[c + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    items = np.empty(n, np.int64)
    for i in range(n):
        items[fill[cell[i]]] = i
        fill[cell[i]] += 1
    return xmin, ymin, h, nx, ny, start, items, inv


@njit(cache=True, inline="always")
def _scan_cell(px, py, ix, iy, tx, ty, grid, best, bi):
    return _scan_cells(px, py, ix, iy, iy, tx, ty, grid, best, bi)


@njit(cache=True, inline="always")
def _scan_cells(px, py, ix, iy0, iy1, tx, ty, grid, best, bi):
    """The nearest of ``best``/``bi`` (squared distance, index) and the points of cells ``(ix, iy0..iy1)``: one
    run of ``items`` (a column's cells are consecutive)."""
    ny, start, items = grid[4], grid[5], grid[6]
    c = ix * ny
    for k in range(start[c + iy0], start[c + iy1 + 1]):
        j = items[k]
        dx = tx[j] - px
        dy = ty[j] - py
        d2 = dx * dx + dy * dy
        if d2 < best or (d2 == best and j < bi):
            best = d2
            bi = j
    return best, bi


@njit(cache=True)
def nearest(px, py, tx, ty, grid):
    """Exact nearest target point of (px, py): rings of cells around the (clamped) home cell until
    no unvisited cell can hold a closer point. Returns (distance, index)."""
    xmin, ymin, h, nx, ny, inv = grid[0], grid[1], grid[2], grid[3], grid[4], grid[7]
    cx = cell_index(px, xmin, inv, nx)
    cy = cell_index(py, ymin, inv, ny)
    # distance from p to the home cell's box (0 inside); inside, the margin to its nearest edge
    bx0, by0 = xmin + cx * h, ymin + cy * h
    ox = max(bx0 - px, 0.0, px - (bx0 + h))
    oy = max(by0 - py, 0.0, py - (by0 + h))
    off = math.sqrt(ox * ox + oy * oy)
    if off == 0.0:
        off = -min(px - bx0, bx0 + h - px, py - by0, by0 + h - py)
    best = np.inf
    bi = -1
    for r in range(max(nx, ny) + 1):
        if r == 0:
            best, bi = _scan_cell(px, py, cx, cy, tx, ty, grid, best, bi)
        else:
            x0, x1 = cx - r, cx + r
            y0, y1 = cy - r, cy + r
            for ix in range(max(x0, 0), min(x1, nx - 1) + 1):
                if y0 >= 0:
                    best, bi = _scan_cell(px, py, ix, y0, tx, ty, grid, best, bi)
                if y1 <= ny - 1:
                    best, bi = _scan_cell(px, py, ix, y1, tx, ty, grid, best, bi)
            for iy in range(max(y0 + 1, 0), min(y1 - 1, ny - 1) + 1):
                if x0 >= 0:
                    best, bi = _scan_cell(px, py, x0, iy, tx, ty, grid, best, bi)
                if x1 <= nx - 1:
                    best, bi = _scan_cell(px, py, x1, iy, tx, ty, grid, best, bi)
        bound = r * h - off  # any point in a ring beyond r is at least this far
        if bi >= 0 and bound > 0 and best < bound * bound:
            break
    return math.sqrt(best), bi


@njit(cache=True, inline="always")
def nearest_from(px, py, j0, tx, ty, grid):
    """As :func:`nearest`, given a candidate ``j0``: the nearest point is no farther than ``j0``, so
    only the cells meeting the square around that disc are searched (exact, same tie rule)."""
    xmin, ymin, nx, ny, inv = grid[0], grid[1], grid[3], grid[4], grid[7]
    dx = tx[j0] - px
    dy = ty[j0] - py
    best = dx * dx + dy * dy
    bi = j0
    r = math.sqrt(best) * (1.0 + 1e-12) + 1e-12  # padded against rounding at the box's edge
    x0 = cell_index(px - r, xmin, inv, nx)
    x1 = cell_index(px + r, xmin, inv, nx)
    y0 = cell_index(py - r, ymin, inv, ny)
    y1 = cell_index(py + r, ymin, inv, ny)
    for ix in range(x0, x1 + 1):
        best, bi = _scan_cells(px, py, ix, y0, y1, tx, ty, grid, best, bi)
    return math.sqrt(best), bi


@njit(cache=True)
def _barycentric(tri, s, px, py):
    """Barycentric coordinates of (px, py) in simplex ``s`` (scipy's ``Delaunay.transform``)."""
    t = tri[0]
    dx, dy = px - t[s, 2, 0], py - t[s, 2, 1]
    c0 = t[s, 0, 0] * dx + t[s, 0, 1] * dy
    c1 = t[s, 1, 0] * dx + t[s, 1, 1] * dy
    return c0, c1, 1.0 - c0 - c1


@njit(cache=True)
def locate(px, py, tri, s0):
    """The Delaunay triangle holding (px, py), or -1 outside the hull: a visibility walk from ``s0``
    (across the edge of the most negative coordinate; a hull edge there means outside), by brute
    force if the walk does not end."""
    nt = tri[0].shape[0]
    s = s0 if 0 <= s0 < nt else 0
    for _ in range(4 * nt + 4):
        c0, c1, c2 = _barycentric(tri, s, px, py)
        k, m = 0, c0
        if c1 < m:
            k, m = 1, c1
        if c2 < m:
            k, m = 2, c2
        if m >= -_TRI_EPS:
            return s
        if not m == m:  # a degenerate simplex (NaN)
            break
        s = tri[1][s, k]
        if s < 0:
            return -1
    for s in range(nt):
        c0, c1, c2 = _barycentric(tri, s, px, py)
        if c0 >= -_TRI_EPS and c1 >= -_TRI_EPS and c2 >= -_TRI_EPS:
            return s
    return -1


@njit(cache=True)
def move_and_match(src, tgt, grid, motion, first, pairs, tri, sim):
    """Source points moved by ``motion = (c, s, tx, ty)`` (``R(c, s)``, ``t``) into ``pairs``' ``px``, ``py``
    and their matches into ``d``, ``idx``: the nearest target point (a full search on the ``first``
    iteration, else bounded by the last match), or with a triangulation (the paper's matching) the nearest
    apex of the target triangle holding the point (the nearest point outside the hull; ``sim``: each
    point's last triangle)."""
    sx, sy, tx, ty = src[0], src[1], tgt[0], tgt[1]
    px, py, d, idx = pairs[0], pairs[1], pairs[2], pairs[3]
    c, s, t_x, t_y = motion
    simp = tri[2]
    for i in range(sx.shape[0]):
        px[i] = c * sx[i] - s * sy[i] + t_x
        py[i] = s * sx[i] + c * sy[i] + t_y
        if first:
            d[i], idx[i] = nearest(px[i], py[i], tx, ty, grid)
        else:
            d[i], idx[i] = nearest_from(px[i], py[i], idx[i], tx, ty, grid)
        if simp.shape[0] > 0:
            k = locate(px[i], py[i], tri, sim[i])
            if k >= 0:
                sim[i] = k
                best = np.inf
                for a in range(3):
                    v = simp[k, a]
                    dd = math.sqrt((tx[v] - px[i]) ** 2 + (ty[v] - py[i]) ** 2)
                    if dd < best:
                        best = dd
                        idx[i] = v
                d[i] = best


# ----------------------------------------------------------------------------- the scans' terms


@njit(cache=True)
def cloud_terms(x, y, sig, prm):
    """The cloud ``(x, y, ux, uy, a2, b2, m2)``: unit radial vector, squared semi-axes ``a^2, b^2``
    (eq. 6-7; with ``sig`` (one per point, else empty), the caller's isotropic 1-sigma, a = b) and the
    squared mean error ``M^2`` (eq. 5)."""
    n = x.shape[0]
    use_sig = sig.shape[0] > 0
    ux = np.empty(n)
    uy = np.empty(n)
    a2 = np.empty(n)
    b2 = np.empty(n)
    m2 = np.empty(n)
    for i in range(n):
        r = math.sqrt(x[i] * x[i] + y[i] * y[i])
        inv = 1.0 / r if r > 0 else 1.0
        ux[i] = x[i] * inv
        uy[i] = y[i] * inv
        if use_sig:
            a2[i] = sig[i] ** 2
            b2[i] = a2[i]
        else:
            a2[i] = (prm.sigma_alpha * r) ** 2
            b2[i] = (prm.sigma_r_rel * r) ** 2
        m2[i] = a2[i] + b2[i]
    return x, y, ux, uy, a2, b2, m2


@njit(cache=True, inline="always")
def _wrap(k, n):
    """``k % n`` (no division for ``-n <= k < 2 n``, the usual case)."""
    if 0 <= k < n:
        return k
    if -n <= k < 0:
        return k + n
    if n <= k < 2 * n:
        return k - n
    return k % n


@njit(cache=True)
def bearing_order(tx, ty):
    """The points' bearings and their indices sorted by bearing (stable): the beam order of a scan."""
    a = np.arctan2(ty, tx)
    return a, np.argsort(a, kind="mergesort")


@njit(cache=True)
def resolution(tx, ty, half, bearing):
    """As :func:`graphnav.scan.covariance.resolution`: ``r da`` per point, ``da`` the median of the
    ``2 half`` bearing gaps around it (``bearing``: :func:`bearing_order`; circular; the window's gaps
    kept sorted as it slides)."""
    n = tx.shape[0]
    out = np.zeros(n)
    if n < 2:
        return out
    order = bearing[1]
    srt = bearing[0][order]
    gaps = np.empty(n)
    for i in range(n - 1):
        gaps[i] = srt[i + 1] - srt[i]
    gaps[n - 1] = srt[0] + 2.0 * np.pi - srt[n - 1]
    m = 2 * half
    win = np.empty(m)
    for o in range(m):  # the first window, by insertion
        _insert(win, o, gaps[_wrap(-half + o, n)])
    for i in range(n):
        if i > 0:  # slide: drop gaps[i - 1 - half], take gaps[i - 1 + half]
            _remove(win, m, gaps[_wrap(i - 1 - half, n)])
            _insert(win, m - 1, gaps[_wrap(i - 1 + half, n)])
        med = win[m // 2] if m % 2 else 0.5 * (win[m // 2 - 1] + win[m // 2])  # as np.median
        j = order[i]
        out[j] = math.sqrt(tx[j] * tx[j] + ty[j] * ty[j]) * med
    return out


@njit(cache=True)
def _insert(win, k, v):
    """Insert ``v`` into the sorted ``win[:k]``."""
    while k > 0 and win[k - 1] > v:
        win[k] = win[k - 1]
        k -= 1
    win[k] = v


@njit(cache=True)
def _remove(win, m, v):
    """Remove one element equal to ``v`` from the sorted ``win[:m]``."""
    k = 0
    while k < m - 1 and win[k] != v:
        k += 1
    for a in range(k, m - 1):
        win[a] = win[a + 1]


@njit(cache=True)
def target_resolution(tgt, half, min_res, bearing):
    """:func:`resolution` of the target, the distance a correct pair can have at each target point
    (``sqrt(res^2 + 2 M^2)`` floored at ``min_res``: the unit of :func:`zhang_gate`'s distances) and
    its median ``D``, the unit of the tolerances."""
    res = resolution(tgt[0], tgt[1], half, bearing)
    tm2 = tgt[6]
    scale = np.empty(res.shape[0])
    for i in range(res.shape[0]):
        scale[i] = max(math.sqrt(res[i] ** 2 + 2.0 * tm2[i]), min_res)
    return res, scale, np.median(scale)


@njit(cache=True, inline="always")
def _pca_line(xs, ys, pick, m):
    """Normal, flatness ((l1 - l2) / (l1 + l2), 0..1) of points ``pick[:m]`` by PCA: the scatter in one pass,
    from the moments about the middle point (offsets of the window's size: no cancellation of the
    coordinates' magnitude)."""
    x0, y0 = xs[pick[m // 2]], ys[pick[m // 2]]
    sx = sy = sxx = syy = sxy = 0.0
    for o in range(m):
        dx, dy = xs[pick[o]] - x0, ys[pick[o]] - y0
        sx += dx
        sy += dy
        sxx += dx * dx
        syy += dy * dy
        sxy += dx * dy
    return _line_of_moments(sxx - sx * sx / m, syy - sy * sy / m, sxy - sx * sy / m)


@njit(cache=True, inline="always")
def _line_of_moments(cxx, cyy, cxy):
    """Normal ``(-sin phi, cos phi)`` and flatness ``(l1 - l2) / (l1 + l2)`` of the scatter ``[[cxx, cxy], [cxy,
    cyy]]``, ``phi = atan2(b, a) / 2`` the major axis (``a = cxx - cyy``, ``b = 2 cxy``), by the half-angle
    formulas (no trigonometric call): ``cos 2phi = a / rr``, ``sin 2phi = b / rr``, ``rr = hypot(a, b)``;
    ``cos phi >= 0``, the larger of ``cos phi``, ``|sin phi|`` taken from its square root and the other as
    ``sin 2phi / (2 x it)`` (no cancellation)."""
    a = cxx - cyy
    b = 2.0 * cxy
    rr = math.sqrt(a * a + b * b)
    tr = cxx + cyy
    flat = rr / tr if tr > 0 else 0.0
    if not rr > 0:  # a circle, or one point: phi = 0
        return -0.0, 1.0, flat
    if a >= 0:
        cph = math.sqrt(0.5 * (rr + a) / rr)
        sph = b / (2.0 * rr * cph)
    else:
        sph = math.copysign(math.sqrt(0.5 * (rr - a) / rr), b)
        cph = b / (2.0 * rr * sph)
    return -sph, cph, flat


@njit(cache=True)
def scan_order_normals(tx, ty, half, max_gap, res, order):
    """Normal and flatness of each target point from its ``2 half + 1`` neighbours in beam order (sorted
    by bearing), by PCA; a window with a gap between beam neighbours wider than ``max_gap``
    resolutions ``res`` (the smaller of the two points') spans two surfaces: flatness 0 (``order``:
    :func:`bearing_order`). (A surface
    seen at incidence ``i`` has gaps of ``r da / cos i``: 8 resolutions is ``i`` > 83 deg.)"""
    n = tx.shape[0]
    xs = tx[order]
    ys = ty[order]
    gap = np.empty(n)
    lim = np.empty(n)
    for i in range(n):
        k = (i + 1) % n
        gap[i] = math.sqrt((xs[k] - xs[i]) ** 2 + (ys[k] - ys[i]) ** 2)
        lim[i] = max_gap * min(res[order[i]], res[order[k]])
    nx_ = np.empty(n)
    ny_ = np.empty(n)
    fl = np.empty(n)
    m = 2 * half + 1
    pick = np.empty(m, np.int64)
    for i in range(n):
        wide = False
        for o in range(-half, half + 1):
            k = _wrap(i + o, n)
            pick[o + half] = k
            if o < half and gap[k] > lim[k]:
                wide = True
        j = order[i]
        nx_[j], ny_[j], f = _pca_line(xs, ys, pick, m)
        fl[j] = 0.0 if wide else f
    return nx_, ny_, fl


@njit(cache=True, inline="always")
def _scan_cell_k(px, py, ix, iy, tx, ty, grid, bd, bi, cnt):
    """Insert the points of cell (ix, iy) into the sorted k-best lists ``bd``/``bi`` (``cnt`` filled)."""
    ny, start, items = grid[4], grid[5], grid[6]
    k = bd.shape[0]
    c = ix * ny + iy
    for m in range(start[c], start[c + 1]):
        j = items[m]
        dx = tx[j] - px
        dy = ty[j] - py
        d2 = dx * dx + dy * dy
        if cnt == k and (d2 > bd[k - 1] or (d2 == bd[k - 1] and j > bi[k - 1])):
            continue
        pos = cnt if cnt < k else k - 1
        while pos > 0 and (bd[pos - 1] > d2 or (bd[pos - 1] == d2 and bi[pos - 1] > j)):
            if pos < k:
                bd[pos] = bd[pos - 1]
                bi[pos] = bi[pos - 1]
            pos -= 1
        bd[pos] = d2
        bi[pos] = j
        if cnt < k:
            cnt += 1
    return cnt


@njit(cache=True)
def k_nearest(px, py, tx, ty, grid, bd, bi):
    """The ``len(bd)`` nearest target points of (px, py), a target point, into ``bi`` (squared
    distances ``bd``; exact, by rings of grid cells; ties by index)."""
    xmin, ymin, h, nx, ny, inv = grid[0], grid[1], grid[2], grid[3], grid[4], grid[7]
    k = bd.shape[0]
    cx = cell_index(px, xmin, inv, nx)
    cy = cell_index(py, ymin, inv, ny)
    bx0, by0 = xmin + cx * h, ymin + cy * h
    edge = max(min(px - bx0, bx0 + h - px, py - by0, by0 + h - py), 0.0)  # margin to the home cell's edge
    cnt = 0
    for r in range(max(nx, ny) + 1):
        if r == 0:
            cnt = _scan_cell_k(px, py, cx, cy, tx, ty, grid, bd, bi, cnt)
        else:
            x0, x1 = cx - r, cx + r
            y0, y1 = cy - r, cy + r
            for ix in range(max(x0, 0), min(x1, nx - 1) + 1):
                if y0 >= 0:
                    cnt = _scan_cell_k(px, py, ix, y0, tx, ty, grid, bd, bi, cnt)
                if y1 <= ny - 1:
                    cnt = _scan_cell_k(px, py, ix, y1, tx, ty, grid, bd, bi, cnt)
            for iy in range(max(y0 + 1, 0), min(y1 - 1, ny - 1) + 1):
                if x0 >= 0:
                    cnt = _scan_cell_k(px, py, x0, iy, tx, ty, grid, bd, bi, cnt)
                if x1 <= nx - 1:
                    cnt = _scan_cell_k(px, py, x1, iy, tx, ty, grid, bd, bi, cnt)
        bound = r * h + edge  # the query lies in its home cell: a point beyond ring r is at least this far
        if cnt == k and bd[k - 1] < bound * bound:
            break


@njit(cache=True)
def knn_line_normals(tx, ty, k, grid):
    """Unit normal and flatness of the line through each target point's ``k`` nearest neighbours (PCA)."""
    n = tx.shape[0]
    k = min(k, n)
    bd = np.empty(k)
    bi = np.empty(k, np.int64)
    nrx = np.empty(n)
    nry = np.empty(n)
    fl = np.empty(n)
    for i in range(n):
        k_nearest(tx[i], ty[i], tx, ty, grid, bd, bi)
        nrx[i], nry[i], fl[i] = _pca_line(tx, ty, bi, k)
    return nrx, nry, fl


# ----------------------------------------------------------------------------- weights and steps


@njit(cache=True, inline="always")
def _dir_weight(i, j, c, s, bx, by, src, tgt, wpow):
    """Eq. 9, 11, 12: ``(sigma_beta_i^2 + sigma_beta_j^2)^-wpow`` along unit ``(bx, by)``, the source's
    radial direction rotated by ``R(c, s)`` into the target frame."""
    sux, suy, sa2, sb2 = src[2], src[3], src[4], src[5]
    tux, tuy, ta2, tb2 = tgt[2], tgt[3], tgt[4], tgt[5]
    urx = c * sux[i] - s * suy[i]
    ury = s * sux[i] + c * suy[i]
    cs = urx * bx + ury * by
    ct = tux[j] * bx + tuy[j] * by
    return _inv_pow(sa2[i] - (sa2[i] - sb2[i]) * cs * cs + (ta2[j] - (ta2[j] - tb2[j]) * ct * ct), wpow)


@njit(cache=True, inline="always")
def _inv_pow(g, wpow):
    """``g^-wpow``: eq. 11's ``1 / sqrt(g)`` for ``wpow = 0.5`` (a square root, not a ``pow``), else ``pow``."""
    if wpow == 0.5:
        return 1.0 / math.sqrt(g)
    return g ** (-wpow)


@njit(cache=True)
def p2p_weights(pairs, c, s, src, tgt, prm, gate, dmax):
    """Pair weights of Algorithm 1 into ``pairs``' ``w``: K 1, H 1, HM ``(M_i^2 + M_j^2)^-wpow`` (eq. 11,
    13), HD the directional weight along the pair (eq. 9, 11, 12); x Huber (``kHu = huber_c`` x the
    median distance); 0 beyond ``max_corr``; with ``gate`` (pair scales), 0 outside Zhang's gate
    ``d / gate[idx] <= dmax`` (HDL's warm-up steps)."""
    px, py, d, idx, w = pairs
    tx, ty, sm2, tm2 = tgt[0], tgt[1], src[6], tgt[6]
    variant = 3 if prm.variant == HDL else prm.variant
    khu = prm.huber_c * np.median(d)
    for i in range(px.shape[0]):
        j = idx[i]
        if variant == 2:
            wi = _inv_pow(sm2[i] + tm2[j], prm.wpow)
        elif variant == 3:
            if d[i] > 0:
                inv = 1.0 / d[i]
                wi = _dir_weight(i, j, c, s, (tx[j] - px[i]) * inv, (ty[j] - py[i]) * inv, src, tgt, prm.wpow)
            else:
                wi = _dir_weight(i, j, c, s, 1.0, 0.0, src, tgt, prm.wpow)
        else:
            wi = 1.0
        if variant != 0 and khu > 0 and d[i] > khu:
            wi *= khu / d[i]
        if gate.shape[0] > 0 and not d[i] / gate[j] <= dmax:
            wi = 0.0
        w[i] = wi
    _gate_fixed(pairs, prm.max_corr)


@njit(cache=True)
def hdl_weights(pairs, c, s, src, tgt, lines, prm, gate, dmax):
    """HDL's pair weights into ``w``: the directional weight along the target's normal (eq. 9, 11),
    Huber on the point-to-line distance, x flatness^flat_pow, 0 outside Zhang's gate ``d / gate[idx] <=
    dmax`` and beyond ``max_corr``."""
    px, py, d, idx, w = pairs
    tx, ty, nrx, nry, fl = tgt[0], tgt[1], lines[0], lines[1], lines[2]
    n = px.shape[0]
    dist = np.empty(n)
    for i in range(n):
        j = idx[i]
        dist[i] = abs((px[i] - tx[j]) * nrx[j] + (py[i] - ty[j]) * nry[j])
    khu = prm.huber_c * np.median(dist)
    for i in range(n):
        j = idx[i]
        wi = _dir_weight(i, j, c, s, nrx[j], nry[j], src, tgt, prm.wpow)
        if khu > 0 and dist[i] > khu:
            wi *= khu / dist[i]
        wi = wi * fl[j] ** prm.flat_pow
        w[i] = wi if d[i] / gate[j] <= dmax else 0.0
    _gate_fixed(pairs, prm.max_corr)


@njit(cache=True, inline="always")
def _gate_fixed(pairs, max_corr):
    """Weight 0 beyond ``max_corr``; all weights 1 when none is left."""
    d, w = pairs[2], pairs[4]
    anyw = False
    for i in range(w.shape[0]):
        if d[i] > max_corr:
            w[i] = 0.0
        if w[i] > 0:
            anyw = True
    if not anyw:
        for i in range(w.shape[0]):
            w[i] = 1.0


@njit(cache=True)
def zhang_gate(d, idx, scale, n, dmax):
    """Zhang's adaptive distance gate (Z. Zhang, *Iterative point matching for registration of free-form
    curves and surfaces*, IJCV 13(2), 1994, sect. 4.3; the weighted-ICP paper's ref. [14]) on the
    distances ``u = d / scale[idx]`` in units of the distance a correct pair can have there: from the
    mean ``mu`` and standard deviation ``sd`` of those within the previous gate ``dmax``, the next gate
    is ``mu + 3 sd`` when ``mu < 1`` (registered), ``mu + 2 sd`` when ``mu < 3``, ``mu + sd`` when
    ``mu < 6``, else the median (Zhang: the valley of the histogram). Fewer than 3 pairs: unchanged."""
    u = np.empty(n)
    m = 0
    for i in range(n):
        ui = d[i] / scale[idx[i]]
        if ui <= dmax:
            u[m] = ui
            m += 1
    if m < 3:
        return dmax
    sel = u[:m]
    mu = np.mean(sel)
    sd = math.sqrt(np.mean((sel - mu) ** 2))
    if mu < 1.0:
        return mu + 3.0 * sd
    if mu < 3.0:
        return mu + 2.0 * sd
    if mu < 6.0:
        return mu + sd
    return np.median(sel)


@njit(cache=True)
def weighted_align(px, py, tx, ty, idx, w, n, sw):
    """Weighted SVD alignment of ``p`` onto ``t[idx]`` in closed form for 2D (eq. 15-20): the
    rotation ``dth`` and translation ``(dtx, dty)`` with ``t ~ R(dth) p + d``; ``sw`` = sum of ``w``."""
    mpx = mpy = mqx = mqy = 0.0
    for i in range(n):
        mpx += w[i] * px[i]
        mpy += w[i] * py[i]
        mqx += w[i] * tx[idx[i]]
        mqy += w[i] * ty[idx[i]]
    mpx /= sw
    mpy /= sw
    mqx /= sw
    mqy /= sw
    sxx = syy = sxy = syx = 0.0
    for i in range(n):
        ax, ay = px[i] - mpx, py[i] - mpy
        bx2, by2 = tx[idx[i]] - mqx, ty[idx[i]] - mqy
        sxx += w[i] * ax * bx2
        syy += w[i] * ay * by2
        sxy += w[i] * ax * by2
        syx += w[i] * ay * bx2
    dth = math.atan2(sxy - syx, sxx + syy)
    cd, sd = math.cos(dth), math.sin(dth)
    return dth, mqx - (cd * mpx - sd * mpy), mqy - (sd * mpx + cd * mpy)


@njit(cache=True)
def _solve3(h, b):
    """``-(h + 1e-12 I)^-1 b`` (least squares when singular; no step when not finite)."""
    if not (np.all(np.isfinite(h)) and np.all(np.isfinite(b))):
        return np.zeros(3)  # no step (numba's solvers raise on non-finite input, and a raise in the
        # except branch below is a numba internal error, not an exception)
    a = h.copy()
    for k in range(3):
        a[k, k] += 1e-12
    try:
        return -np.linalg.solve(a, b)
    except Exception:  # noqa: BLE001
        return -np.linalg.lstsq(h, b)[0]


@njit(cache=True)
def p2l_step(pairs, tgt, lines):
    """One Gauss-Newton step of ``sum w (n.(p' - q))^2`` over a left increment ``p' = R(dth) p + dt``
    (linearised as ``p + dt + dth J p``, applied as a rotation about the origin): ``(dth, dtx, dty)``."""
    px, py, _, idx, w = pairs
    tx, ty, nrx, nry = tgt[0], tgt[1], lines[0], lines[1]
    hm = np.zeros((3, 3))
    bv = np.zeros(3)
    for i in range(px.shape[0]):
        j = idx[i]
        a0, a1 = nrx[j], nry[j]
        a2 = px[i] * nry[j] - py[i] * nrx[j]
        rn = (px[i] - tx[j]) * a0 + (py[i] - ty[j]) * a1
        wi = w[i]
        hm[0, 0] += wi * a0 * a0
        hm[0, 1] += wi * a0 * a1
        hm[0, 2] += wi * a0 * a2
        hm[1, 1] += wi * a1 * a1
        hm[1, 2] += wi * a1 * a2
        hm[2, 2] += wi * a2 * a2
        bv[0] += wi * a0 * rn
        bv[1] += wi * a1 * rn
        bv[2] += wi * a2 * rn
    hm[1, 0], hm[2, 0], hm[2, 1] = hm[0, 1], hm[0, 2], hm[1, 2]
    x = _solve3(hm, bv)
    return x[2], x[0], x[1]


@njit(cache=True)
def step_pose(th, t_x, t_y, dth, dtx, dty):
    """Eq. 21-22: the pose after the left increment ``(dth, dtx, dty)``."""
    cd, sd = math.cos(dth), math.sin(dth)
    return th + dth, cd * t_x - sd * t_y + dtx, sd * t_x + cd * t_y + dty


# ----------------------------------------------------------------------------- the loop


@njit(cache=True)
def icp_loop(src, tgt, grid, lines, prm, pose0, scale, big_d, tri):
    """Algorithm 1 from ``pose0 = (theta, tx, ty)``: match, Zhang's gate (tracked from ``gate0``; it
    weighs HDL's pairs, and is the inlier test of all), weights, then the weighted SVD step (eq. 15-20;
    HDL: while a step moves a point more than ``warmup`` x ``big_d``) or HDL's Gauss-Newton point-to-line
    step, accumulated (eq. 21-22), until the mean pair distance changes less than ``tol`` D and the step
    moves no point more than ``tol_step`` D. Returns the final pairs, pose, iterations, converged,
    gate, the last step's largest point displacement and the source's largest range."""
    sx, sy, tx, ty = src[0], src[1], tgt[0], tgt[1]
    n = sx.shape[0]
    pairs = (np.empty(n), np.empty(n), np.empty(n), np.empty(n, np.int64), np.empty(n))
    px, py, d, idx, w = pairs
    sim = np.zeros(n, np.int64)
    src_r = 0.0
    for i in range(n):
        src_r = max(src_r, math.sqrt(sx[i] * sx[i] + sy[i] * sy[i]))
    hdl = prm.variant == HDL
    th, t_x, t_y = pose0
    old_res, converged, it, dmax, moved = -1.0, False, 0, prm.gate0, np.inf
    warm = hdl and prm.warmup > 0
    for it in range(1, prm.max_iter + 1):  # noqa: B007
        c, s = math.cos(th), math.sin(th)
        move_and_match(src, tgt, grid, (c, s, t_x, t_y), it == 1, pairs, tri, sim)
        dmax = zhang_gate(d, idx, scale, n, dmax)
        if hdl and not warm:
            hdl_weights(pairs, c, s, src, tgt, lines, prm, scale, dmax)
            dth, dtx, dty = p2l_step(pairs, tgt, lines)
        else:
            p2p_weights(pairs, c, s, src, tgt, prm, scale if hdl else scale[:0], dmax)
            sw = 0.0
            for i in range(n):
                sw += w[i]
            dth, dtx, dty = weighted_align(px, py, tx, ty, idx, w, n, sw)
        th, t_x, t_y = step_pose(th, t_x, t_y, dth, dtx, dty)
        new_res = 0.0
        for i in range(n):
            new_res += d[i]
        new_res /= n
        moved = abs(dth) * src_r + math.sqrt(dtx * dtx + dty * dty)  # the farthest point's displacement
        if warm:
            warm = moved > prm.warmup * big_d
            old_res = -1.0
            continue
        if old_res >= 0 and abs(new_res - old_res) < prm.tol * big_d and moved < prm.tol_step * big_d:
            converged = True
            break
        old_res = new_res
    return pairs, (th, t_x, t_y), it, converged, dmax, moved, src_r


@njit(cache=True)
def rms_radius(sx, sy, n):
    """RMS distance of the points from their centroid (1 for a degenerate cloud): the length that
    makes rotation commensurate with translation in the degeneracy test."""
    msx = msy = 0.0
    for i in range(n):
        msx += sx[i]
        msy += sy[i]
    msx /= n
    msy /= n
    lsc = 0.0
    for i in range(n):
        lsc += (sx[i] - msx) ** 2 + (sy[i] - msy) ** 2
    lsc = math.sqrt(lsc / n)
    if not lsc > 0:
        lsc = 1.0
    return lsc


@njit(cache=True, inline="always")
def pair_cov(i, j, c, s, src, tgt):
    """Eq. 8 covariance ``(sxx, sxy, syy)`` of pair ``(i, j)``: source point ``i`` rotated by ``R(c, s)``
    plus target point ``j``."""
    sux, suy, sa2, sb2 = src[2], src[3], src[4], src[5]
    tux, tuy, ta2, tb2 = tgt[2], tgt[3], tgt[4], tgt[5]
    ux = c * sux[i] - s * suy[i]
    uy = s * sux[i] + c * suy[i]
    dsv = sb2[i] - sa2[i]
    dtv = tb2[j] - ta2[j]
    a2 = sa2[i] + ta2[j]
    sxx = a2 + dsv * ux * ux + dtv * tux[j] * tux[j]
    syy = a2 + dsv * uy * uy + dtv * tuy[j] * tuy[j]
    sxy = dsv * ux * uy + dtv * tux[j] * tuy[j]
    return sxx, sxy, syy


@njit(cache=True)
def final_pairs(src, tgt, lines, prm, pose, idx, scale, dmax):
    """The pairs at the solution: the source moved by ``pose``, its last matches ``idx`` (the last step
    moved no point more than ``tol_step``), their weights and eq. 8 covariances ``(sxx, sxy, syy)``
    (identity for K and H, which have no error model)."""
    th, t_x, t_y = pose
    sx, sy, tx, ty = src[0], src[1], tgt[0], tgt[1]
    n = sx.shape[0]
    c, s = math.cos(th), math.sin(th)
    px, py, d = np.empty(n), np.empty(n), np.empty(n)
    sxx, sxy, syy = np.ones(n), np.zeros(n), np.ones(n)
    for i in range(n):
        px[i] = c * sx[i] - s * sy[i] + t_x
        py[i] = s * sx[i] + c * sy[i] + t_y
        d[i] = math.sqrt((px[i] - tx[idx[i]]) ** 2 + (py[i] - ty[idx[i]]) ** 2)
        if prm.variant >= 2:
            sxx[i], sxy[i], syy[i] = pair_cov(i, idx[i], c, s, src, tgt)
    pairs = (px, py, d, idx, np.empty(n))
    if prm.variant == HDL:
        hdl_weights(pairs, c, s, src, tgt, lines, prm, scale, dmax)
    else:
        p2p_weights(pairs, c, s, src, tgt, prm, scale[:0], dmax)
    return pairs, (sxx, sxy, syy)


# ----------------------------------------------------------------------------- the report's sums


@njit(cache=True, inline="always")
def _add_sums(sums, ja, jb, wi, samp, cov, hdl):
    """One pair's terms of ``sums = (H, B_lidar, B_sampling)``: ``H = sum w J^T J``, ``B_lidar = sum w^2 J^T S
    J``, ``B_sampling = sum w^2 samp J^T J`` (HDL: the one row ``ja``, ``S = cov[0]``, the residual's
    variance; else the rows ``ja``, ``jb`` and ``S = cov = (sxx, sxy, syy)``, 2x2). The upper triangles only
    (:func:`_mirror`)."""
    h, bl, bs = sums
    sxx, sxy, syy = cov
    sv = sxx
    w2 = wi * wi
    if hdl:
        for a in range(3):
            for b in range(a, 3):
                jj = ja[a] * ja[b]
                h[a, b] += wi * jj
                bl[a, b] += w2 * sv * jj
                bs[a, b] += w2 * samp * jj
        return
    for a in range(3):
        for b in range(a, 3):
            jtj = ja[a] * ja[b] + jb[a] * jb[b]
            jsj = sxx * ja[a] * ja[b] + sxy * (ja[a] * jb[b] + jb[a] * ja[b]) + syy * jb[a] * jb[b]
            h[a, b] += wi * jtj
            bl[a, b] += w2 * jsj
            bs[a, b] += w2 * samp * jtj


@njit(cache=True, inline="always")
def _mirror(m):
    """The lower triangle of the 3x3 ``m`` from its upper one (each term is symmetric in its two indices)."""
    m[1, 0], m[2, 0], m[2, 1] = m[0, 1], m[0, 2], m[1, 2]


@njit(cache=True)
def report_sums(pairs, cov, tgt, lines, res, scale, gate, pose, radius, prm):
    """One pass over the final pairs for :func:`graphnav.scan.covariance.from_sums`: ``(k, n_inliers, H,
    B_lidar, B_sampling, rms, info, inlier_fraction, points_used, median scale)`` (:func:`_add_sums`;
    ``B = k B_lidar + B_sampling``, the sampling variance ``normal_k samp_var spacing^2``) and ``info`` the
    point-to-line information of the flat inlier pairs (rotation column / ``radius``). Jacobians with
    respect to the right perturbation at ``pose = (theta, tx, ty)``: ``[R, J (p - t)]``; HDL the row
    ``n^T [R, J (p - t)]`` of the point-to-line residual."""
    px, py, _, idx, w = pairs
    tx, ty, nx, ny, fl = tgt[0], tgt[1], lines[0], lines[1], lines[2]
    sxx, sxy, syy = cov
    th, t_x, t_y = pose
    c, s = math.cos(th), math.sin(th)
    hdl = prm.variant == HDL
    n = px.shape[0]
    h, bl, bs, info = np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3))
    ksum, rss, sw = 0.0, 0.0, 0.0
    n_inl = n_gate = used = 0
    ja, jb, sc = np.empty(3), np.empty(3), np.empty(3)
    for i in range(n):
        j = idx[i]
        ex, ey = px[i] - tx[j], py[i] - ty[j]
        inl = math.sqrt(ex * ex + ey * ey) / scale[j] <= gate
        wi = w[i]
        if inl:
            n_gate += 1
        if wi > 0:
            used += 1
        c2x, c2y = -(py[i] - t_y), px[i] - t_x
        row0, row1, row2 = nx[j] * c + ny[j] * s, -nx[j] * s + ny[j] * c, nx[j] * c2x + ny[j] * c2y
        both = inl and wi > 0
        if both:
            sc[0], sc[1], sc[2] = row0, row1, row2 / radius
            for a in range(3):
                for b in range(a, 3):
                    info[a, b] += fl[j] * sc[a] * sc[b]
        samp = prm.normal_k * prm.samp_var * res[j] ** 2
        if hdl:
            r = ex * nx[j] + ey * ny[j]
            sv = sxx[i] * nx[j] ** 2 + 2 * sxy[i] * nx[j] * ny[j] + syy[i] * ny[j] ** 2
            if both:
                ksum += r * r / sv
            rss += wi * r * r
            ja[0], ja[1], ja[2] = row0, row1, row2
        else:
            if both:
                det = sxx[i] * syy[i] - sxy[i] ** 2
                ksum += (syy[i] * ex * ex - 2 * sxy[i] * ex * ey + sxx[i] * ey * ey) / det
            rss += wi * (ex * ex + ey * ey)
            sv = 0.0
            ja[0], ja[1], ja[2] = c, -s, c2x  # the Jacobian's rows: d(x)/d xi, d(y)/d xi
            jb[0], jb[1], jb[2] = s, c, c2y
        if both:
            n_inl += 1
        _add_sums((h, bl, bs), ja, jb, wi, samp, (sv, 0.0, 0.0) if hdl else (sxx[i], sxy[i], syy[i]), hdl)
        sw += wi
    for m in (h, bl, bs, info):
        _mirror(m)
    k = ksum / max((1 if hdl else 2) * n_inl - 3, 1) if n_inl > 0 else np.nan
    rms = math.sqrt(rss / sw) if sw > 0 else np.nan
    big_d = np.median(scale[idx]) if n > 0 else np.nan
    frac = n_gate / n if n > 0 else np.nan
    return k, n_inl, h, bl, bs, rms, info, frac, used, big_d


@njit(cache=True, inline="always")
def _mul3(a: np.ndarray, b: np.ndarray, b_transposed: bool) -> np.ndarray:
    """``a @ b`` (``a @ b.T`` with ``b_transposed``) of 3x3 matrices, each entry summed in index order."""
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for m in range(3):
                acc += a[i, m] * (b[j, m] if b_transposed else b[m, j])
            out[i, j] = acc
    return out


@njit(cache=True)
def report_algebra(k, h, b_lidar, b_sampling, info, radius, max_condition, max_sigma):
    """:func:`graphnav.scan.covariance.from_sums` and :func:`graphnav.scan.degeneracy.analyse_both` (without a
    prior) on :func:`report_sums`' sums, in the kernel: the sandwich ``cov = H^-1 (k B_lidar + B_sampling)
    H^-1`` (NaN when ``k`` or ``H`` is not finite or ``H`` is singular) and the eigen-analysis of ``info``
    (LAPACK's, as numpy's): ``(cov, var, sigmas, vectors, weak, condition, finite, n_weak, weakest)``, ``var``
    the covariance's variance along each eigenvector (scaled coordinates x, y, ``radius`` theta; inf when
    ``cov`` is not finite), ``finite`` whether ``cov`` is, ``n_weak`` the number of weak directions and
    ``weakest`` the weakest one in tangent coordinates (:attr:`graphnav.scan.degeneracy.Degeneracy.weakest`).
    The same numbers as the numpy functions, to rounding (tests/scan/test_icp_report_algebra.py)."""
    cov = np.full((3, 3), np.nan)
    hi = np.zeros((3, 3))
    ok = False
    if math.isfinite(k) and np.all(np.isfinite(h)):
        try:
            hi = np.linalg.inv(h)
            ok = True
        except Exception:  # noqa: BLE001  (singular)
            ok = False
    if ok:
        b = k * b_lidar + b_sampling
        full = _mul3(_mul3(hi, b, False), hi, True)  # H^-1 B H^-T
        for a in range(3):
            for c in range(3):
                cov[a, c] = 0.5 * (full[a, c] + full[c, a])
    sym = 0.5 * (info + info.T)
    if np.all(np.isfinite(sym)):
        ev, vec = np.linalg.eigh(sym)
    else:  # (no direction known)
        ev, vec = np.full(3, np.nan), np.eye(3)
    cond = ev[2] / ev[0] if ev[0] > 0 else np.inf
    finite = np.all(np.isfinite(cov))
    var = np.full(3, np.inf)
    sig = np.full(3, np.inf)
    weak = np.ones(3, np.bool_)
    tm = (1.0, 1.0, radius)
    for i in range(3):
        if finite:
            acc = 0.0
            for a in range(3):
                for c in range(3):
                    acc += vec[a, i] * tm[a] * cov[a, c] * tm[c] * vec[c, i]
            var[i] = acc
            sig[i] = math.sqrt(max(acc, 0.0))
            weak[i] = not ev[i] > 0 or ev[i] * max_condition < ev[2] or sig[i] > max_sigma
    n_weak = 0
    for i in range(3):
        n_weak += 1 if weak[i] else 0
    weakest = (vec[0, 0], vec[1, 0], vec[2, 0] * (1.0 / radius))
    return cov, var, sig, vec, weak, cond, finite, n_weak, weakest


# ----------------------------------------------------------------------------- one whole match


@njit(cache=True)
def bounded(a, b, m):
    """Whether every coordinate of ``a`` and ``b`` is finite and within ``[-m, m]`` (the matcher's input check,
    without temporaries)."""
    return _bounded(a, m) and _bounded(b, m)


@njit(cache=True, inline="always")
def _bounded(xy, m):
    for i in range(xy.shape[0]):
        for c in range(xy.shape[1]):
            if not abs(xy[i, c]) <= m:  # (NaN: False)
                return False
    return True


@njit(cache=True)
def match_xy(src_xy, tgt_xy, ssig, tsig, prm, pose0, tri):
    """:func:`match` of the (N, 2) and (M, 2) point arrays (their columns copied here), with the pose also as an
    array ``(tx, ty, theta)``: ``(pose array, the output of match)``."""
    out = match(src_xy[:, 0].copy(), src_xy[:, 1].copy(), ssig, tgt_xy[:, 0].copy(), tgt_xy[:, 1].copy(), tsig,
                prm, pose0, tri)
    th, t_x, t_y = out[0]
    pose = np.empty(3)
    pose[0], pose[1], pose[2] = t_x, t_y, th
    return pose, out


@njit(cache=True)
def match(sx, sy, ssig, tx, ty, tsig, prm, pose0, tri):
    """One match of source ``(sx, sy)`` onto target ``(tx, ty)`` from ``pose0 = (theta, tx, ty)``
    (``ssig``/``tsig``: the caller's 1-sigma per point, or empty for the LiDAR model): the clouds'
    terms, the target's resolution, grid and lines (beam order, or HDL's k nearest), :func:`icp_loop`,
    :func:`final_pairs`, :func:`report_sums` at the pose with its angle wrapped to [-pi, pi) and
    :func:`report_algebra` of the sums. Returns ``(pose, iterations, converged, gate, moved, src_range,
    radius, sums, algebra)``."""
    src = cloud_terms(sx, sy, ssig, prm)
    tgt = cloud_terms(tx, ty, tsig, prm)
    half = prm.normal_k // 2
    bearing = bearing_order(tx, ty)
    res, scale, big_d = target_resolution(tgt, half, prm.min_res, bearing)
    grid = build_grid(tx, ty, prm.cell)
    if prm.variant == HDL and prm.knn:
        lines = knn_line_normals(tx, ty, prm.normal_k, grid)
    else:
        lines = scan_order_normals(tx, ty, half, prm.max_gap, res, bearing[1])
    pairs, pose, it, converged, dmax, moved, src_r = icp_loop(src, tgt, grid, lines, prm, pose0, scale, big_d, tri)
    pairs, cov = final_pairs(src, tgt, lines, prm, pose, pairs[3], scale, dmax)
    radius = rms_radius(sx, sy, sx.shape[0])
    wrapped = ((pose[0] + math.pi) % (2.0 * math.pi) - math.pi, pose[1], pose[2])
    sums = report_sums(pairs, cov, tgt, lines, res, scale, dmax, wrapped, radius, prm)
    k, _, h, bl, bs, _, info, _, _, big_d = sums
    algebra = report_algebra(k, h, bl, bs, info, radius, prm.max_condition, prm.max_sigma * big_d)
    return wrapped, it, converged, dmax, moved, src_r, radius, sums, algebra
