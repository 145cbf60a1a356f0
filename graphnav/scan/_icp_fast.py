"""Compiled (numba) matcher of :mod:`graphnav.scan.weighted_icp`: every variant, from the points to the covariance.

The same algorithm as the numpy loop in :mod:`graphnav.scan.weighted_icp` (Algorithm 1, eq. 9-22), with an
exact grid-based nearest-neighbour search instead of ``cKDTree``; tests check that both give
the same matches. :func:`p2p_match` (K/H/HM/HD) and :func:`hdl_match` (HDL) run the whole
numeric part of one match in one call (the LiDAR error model of eq. 5-8, the target's lines,
the loop, the covariance and the point-to-line information); only the eigen-analysis of
:mod:`graphnav.scan.degeneracy` and the report stay in Python. Imported lazily; absent numba,
:mod:`graphnav.scan.weighted_icp` uses its numpy loop.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

MAX_CELLS_PER_POINT = 16
MIN_CELL_CAP = 1 << 16
"""A grid has at most ``max(MAX_CELLS_PER_POINT * n, MIN_CELL_CAP)`` cells: O(n) memory and work per
query whatever the points' spread (one far point would otherwise size the grid by its bounding box)."""


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


@njit(cache=True)
def cell_index(v, vmin, h, nv):
    """``floor((v - vmin) / h)`` clamped to ``[0, nv - 1]`` (in floating point first, so a far or
    non-finite coordinate cannot overflow the integer conversion)."""
    f = np.floor((v - vmin) / h)
    if not f >= 0.0:  # also NaN
        return 0
    if f > nv - 1:
        return nv - 1
    return int(f)


@njit(cache=True)
def build_grid(tx, ty, h):
    """Bucket target points into square cells (counting sort). The cell side is ``h`` or larger
    (:func:`grid_cell`: at most O(n) cells); returns it with the grid."""
    n = tx.shape[0]
    xmin, ymin = tx.min(), ty.min()
    h = grid_cell(h, tx.max() - xmin, ty.max() - ymin, n)
    nx = int((tx.max() - xmin) / h) + 1
    ny = int((ty.max() - ymin) / h) + 1
    cell = np.empty(n, np.int64)
    start = np.zeros(nx * ny + 1, np.int64)
    for i in range(n):
        c = int((tx[i] - xmin) / h) * ny + int((ty[i] - ymin) / h)
        cell[i] = c
        start[c + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    items = np.empty(n, np.int64)
    for i in range(n):
        items[fill[cell[i]]] = i
        fill[cell[i]] += 1
    return xmin, ymin, h, nx, ny, start, items


@njit(cache=True)
def _scan_cell(px, py, ix, iy, ny, start, items, tx, ty, best, bi):
    c = ix * ny + iy
    for k in range(start[c], start[c + 1]):
        j = items[k]
        dx = tx[j] - px
        dy = ty[j] - py
        d2 = dx * dx + dy * dy
        if d2 < best or (d2 == best and j < bi):
            best = d2
            bi = j
    return best, bi


@njit(cache=True)
def nearest(px, py, tx, ty, xmin, ymin, h, nx, ny, start, items):
    """Exact nearest target point of (px, py): rings of cells around the (clamped) home cell until
    no unvisited cell can hold a closer point. Returns (distance, index)."""
    cx = cell_index(px, xmin, h, nx)
    cy = cell_index(py, ymin, h, ny)
    # distance from p to the home cell's box (0 inside); inside, the margin to its nearest edge
    bx0, by0 = xmin + cx * h, ymin + cy * h
    ox = max(bx0 - px, 0.0, px - (bx0 + h))
    oy = max(by0 - py, 0.0, py - (by0 + h))
    off = math.sqrt(ox * ox + oy * oy)
    if off == 0.0:
        off = -min(px - bx0, bx0 + h - px, py - by0, by0 + h - py)
    best = np.inf
    bi = -1
    rmax = max(nx, ny)
    for r in range(rmax + 1):
        if r == 0:
            best, bi = _scan_cell(px, py, cx, cy, ny, start, items, tx, ty, best, bi)
        else:
            x0, x1 = cx - r, cx + r
            y0, y1 = cy - r, cy + r
            for ix in range(max(x0, 0), min(x1, nx - 1) + 1):
                if y0 >= 0:
                    best, bi = _scan_cell(px, py, ix, y0, ny, start, items, tx, ty, best, bi)
                if y1 <= ny - 1:
                    best, bi = _scan_cell(px, py, ix, y1, ny, start, items, tx, ty, best, bi)
            for iy in range(max(y0 + 1, 0), min(y1 - 1, ny - 1) + 1):
                if x0 >= 0:
                    best, bi = _scan_cell(px, py, x0, iy, ny, start, items, tx, ty, best, bi)
                if x1 <= nx - 1:
                    best, bi = _scan_cell(px, py, x1, iy, ny, start, items, tx, ty, best, bi)
        bound = r * h - off  # any point in a ring beyond r is at least this far
        if bi >= 0 and bound > 0 and best < bound * bound:
            break
    return math.sqrt(best), bi


@njit(cache=True)
def nearest_from(px, py, j0, tx, ty, xmin, ymin, h, nx, ny, start, items):
    """As :func:`nearest`, given a candidate ``j0``: the nearest point is no farther than ``j0``, so
    only the cells meeting the square around that disc are searched (exact, same tie rule)."""
    dx = tx[j0] - px
    dy = ty[j0] - py
    best = dx * dx + dy * dy
    bi = j0
    r = math.sqrt(best) * (1.0 + 1e-12) + 1e-12  # padded against rounding at the box's edge
    x0 = cell_index(px - r, xmin, h, nx)
    x1 = cell_index(px + r, xmin, h, nx)
    y0 = cell_index(py - r, ymin, h, ny)
    y1 = cell_index(py + r, ymin, h, ny)
    for ix in range(x0, x1 + 1):
        for iy in range(y0, y1 + 1):
            best, bi = _scan_cell(px, py, ix, iy, ny, start, items, tx, ty, best, bi)
    return math.sqrt(best), bi


@njit(cache=True)
def moved_pairs(sx, sy, tx, ty, idx, c, s, t_x, t_y, n):
    """Source points moved by ``(R(c, s), t)`` and their distances to the matched target points."""
    px = np.empty(n)
    py = np.empty(n)
    d = np.empty(n)
    for i in range(n):
        px[i] = c * sx[i] - s * sy[i] + t_x
        py[i] = s * sx[i] + c * sy[i] + t_y
        d[i] = math.sqrt((px[i] - tx[idx[i]]) ** 2 + (py[i] - ty[idx[i]]) ** 2)
    return px, py, d


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
def loop_start(sx, sy, tx, ty, h):
    """What both loops set up: the target's grid (:func:`build_grid`), the work arrays ``d``, ``idx``,
    ``w``, ``px``, ``py`` and the source's largest range (a step's bound on a point's motion)."""
    n = sx.shape[0]
    xmin, ymin, h, nx, ny, start, items = build_grid(tx, ty, h)
    src_r = 0.0
    for i in range(n):
        src_r = max(src_r, math.sqrt(sx[i] * sx[i] + sy[i] * sy[i]))
    return (xmin, ymin, h, nx, ny, start, items, np.empty(n), np.empty(n, np.int64), np.empty(n), np.empty(n),
            np.empty(n), src_r)


@njit(cache=True)
def move_and_match(sx, sy, c, s, t_x, t_y, first, tx, ty, xmin, ymin, h, nx, ny, start, items, px, py, d, idx):
    """Source points moved by ``(R(c, s), t)`` into ``px``, ``py`` and their nearest target points
    into ``d``, ``idx``: a full search on the ``first`` iteration, else bounded by the last match
    (the points moved little)."""
    for i in range(sx.shape[0]):
        px[i] = c * sx[i] - s * sy[i] + t_x
        py[i] = s * sx[i] + c * sy[i] + t_y
        if first:
            d[i], idx[i] = nearest(px[i], py[i], tx, ty, xmin, ymin, h, nx, ny, start, items)
        else:
            d[i], idx[i] = nearest_from(px[i], py[i], idx[i], tx, ty, xmin, ymin, h, nx, ny, start, items)


@njit(cache=True)
def step_pose(th, t_x, t_y, dth, dtx, dty):
    """Eq. 21-22: the pose after the left increment ``(dth, dtx, dty)``."""
    cd, sd = math.cos(dth), math.sin(dth)
    return th + dth, cd * t_x - sd * t_y + dtx, sd * t_x + cd * t_y + dty


@njit(cache=True)
def resolution(tx, ty, half):
    """As :func:`graphnav.scan.covariance.resolution`: ``r da`` per point, ``da`` the median of the
    ``2 half`` bearing gaps around it (bearing order, circular)."""
    n = tx.shape[0]
    out = np.zeros(n)
    if n < 2:
        return out
    a = np.arctan2(ty, tx)
    order = np.argsort(a, kind="mergesort")
    srt = a[order]
    gaps = np.empty(n)
    for i in range(n - 1):
        gaps[i] = srt[i + 1] - srt[i]
    gaps[n - 1] = srt[0] + 2.0 * np.pi - srt[n - 1]
    m = 2 * half
    win = np.empty(m)
    for i in range(n):
        for o in range(m):  # insertion sort of the window's gaps
            v = gaps[_wrap(i - half + o, n)]
            k = o
            while k > 0 and win[k - 1] > v:
                win[k] = win[k - 1]
                k -= 1
            win[k] = v
        med = win[m // 2] if m % 2 else 0.5 * (win[m // 2 - 1] + win[m // 2])  # as np.median
        j = order[i]
        out[j] = math.hypot(tx[j], ty[j]) * med
    return out


@njit(cache=True)
def target_resolution(tx, ty, half, min_res, tm2):
    """:func:`resolution` of the target, the distance a correct pair can have at each target point
    (:func:`graphnav.scan.weighted_icp.pair_scale`: ``sqrt(res^2 + 2 M^2)`` floored at ``min_res``) and its
    median ``D``."""
    res = resolution(tx, ty, half)
    scale = np.empty(res.shape[0])
    for i in range(res.shape[0]):
        scale[i] = max(math.sqrt(res[i] ** 2 + 2.0 * tm2[i]), min_res)
    return res, scale, np.median(scale)


@njit(cache=True)
def zhang_gate(d, idx, res, n, dmax):
    """:func:`graphnav.scan.weighted_icp.zhang_gate` on the distances ``d / res[idx]`` (``res``: pair scales)."""
    u = np.empty(n)
    m = 0
    for i in range(n):
        ui = d[i] / res[idx[i]]
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
def p2p_weights(px, py, d, idx, c, s, sux, suy, sa2, sb2, sm2, tx, ty, tux, tuy, ta2, tb2, tm2, variant, huber_c,
                wpow, max_corr, w):
    """Pair weights of :func:`graphnav.scan.weighted_icp._weights` for K/H/HM/HD into ``w`` (eq. 11-13, Huber)."""
    n = px.shape[0]
    khu = huber_c * np.median(d)
    anyw = False
    for i in range(n):
        j = idx[i]
        if variant == 2:
            wi = (sm2[i] + tm2[j]) ** (-wpow)
        elif variant == 3:  # eq. 9, 11, 12 (inline: this is the hot loop)
            if d[i] > 0:
                bx = (tx[j] - px[i]) / d[i]
                by = (ty[j] - py[i]) / d[i]
            else:
                bx, by = 1.0, 0.0
            urx = c * sux[i] - s * suy[i]
            ury = s * sux[i] + c * suy[i]
            cs = urx * bx + ury * by
            ct = tux[j] * bx + tuy[j] * by
            g = sa2[i] - (sa2[i] - sb2[i]) * cs * cs + (ta2[j] - (ta2[j] - tb2[j]) * ct * ct)
            wi = g ** (-wpow)
        else:
            wi = 1.0
        if variant != 0 and khu > 0 and d[i] > khu:
            wi *= khu / d[i]
        if d[i] > max_corr:
            wi = 0.0
        w[i] = wi
        if wi > 0:
            anyw = True
    if not anyw:
        for i in range(n):
            w[i] = 1.0


@njit(cache=True)
def p2p_loop(sx, sy, sux, suy, sa2, sb2, sm2, tx, ty, tux, tuy, ta2, tb2, tm2, variant, huber_c, wpow,
             max_corr, tol, tol_step, max_iter, th, t0x, t0y, h, res, big_d, gate0):
    """Algorithm 1 for variant 0=K, 1=H, 2=HM, 3=HD (tolerances in units of ``big_d``; Zhang's gate
    tracked from ``gate0`` for the inlier test, not applied to the weights). Returns (theta, tx, ty,
    idx, iterations, converged, gate)."""
    n = sx.shape[0]
    xmin, ymin, h, nx, ny, start, items, d, idx, w, px, py, src_r = loop_start(sx, sy, tx, ty, h)
    t_x, t_y = t0x, t0y
    old_res = -1.0
    converged = False
    it = 0
    dmax = gate0
    moved = np.inf
    for it in range(1, max_iter + 1):  # noqa: B007
        c, s = math.cos(th), math.sin(th)
        move_and_match(sx, sy, c, s, t_x, t_y, it == 1, tx, ty, xmin, ymin, h, nx, ny, start, items, px, py, d, idx)
        dmax = zhang_gate(d, idx, res, n, dmax)
        p2p_weights(px, py, d, idx, c, s, sux, suy, sa2, sb2, sm2, tx, ty, tux, tuy, ta2, tb2, tm2, variant,
                    huber_c, wpow, max_corr, w)
        sw = 0.0
        for i in range(n):
            sw += w[i]
        dth, dtx, dty = weighted_align(px, py, tx, ty, idx, w, n, sw)  # eq. 15-20
        th, t_x, t_y = step_pose(th, t_x, t_y, dth, dtx, dty)
        new_res, moved = residual_and_move(d, n, dth, dtx, dty, src_r)
        if old_res >= 0 and abs(new_res - old_res) < tol * big_d and moved < tol_step * big_d:
            converged = True
            break
        old_res = new_res
    return th, t_x, t_y, idx, it, converged, dmax, moved, src_r


@njit(cache=True)
def residual_and_move(d, n, dth, dtx, dty, src_r):
    """The convergence test's inputs: mean pair distance and how far the step moved the farthest
    source point (rotation at radius ``src_r`` plus translation)."""
    res = 0.0
    for i in range(n):
        res += d[i]
    return res / n, abs(dth) * src_r + math.sqrt(dtx * dtx + dty * dty)


@njit(cache=True)
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
def scan_order_normals(tx, ty, half, max_gap, res):
    """As :func:`graphnav.scan.weighted_icp.scan_order_normals` (PCA of beam-order windows; a gap wider than
    ``max_gap`` resolutions ``res`` (:func:`resolution`), the smaller of the two points', ends a surface)."""
    n = tx.shape[0]
    order = np.argsort(np.arctan2(ty, tx), kind="mergesort")
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
    for i in range(n):
        mx = my = 0.0
        wide = False
        for o in range(-half, half + 1):
            k = _wrap(i + o, n)
            mx += xs[k]
            my += ys[k]
            if o < half and gap[k] > lim[k]:
                wide = True
        mx /= m
        my /= m
        cxx = cyy = cxy = 0.0
        for o in range(-half, half + 1):
            k = _wrap(i + o, n)
            dx, dy = xs[k] - mx, ys[k] - my
            cxx += dx * dx
            cyy += dy * dy
            cxy += dx * dy
        phi = 0.5 * math.atan2(2 * cxy, cxx - cyy)
        j = order[i]
        nx_[j] = -math.sin(phi)
        ny_[j] = math.cos(phi)
        tr = cxx + cyy
        disc = math.sqrt(0.25 * (cxx - cyy) ** 2 + cxy * cxy)
        fl[j] = 0.0 if (wide or not tr > 0) else 2.0 * disc / tr
    return nx_, ny_, fl


@njit(cache=True)
def pair_cov(i, j, c, s, sux, suy, sa2, sb2, tux, tuy, ta2, tb2):
    """Eq. 8 covariance ``(sxx, sxy, syy)`` of pair ``(i, j)``: source point ``i`` rotated by
    ``R(c, s)`` plus target point ``j`` (:func:`graphnav.scan.weighted_icp._pair_cov`)."""
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
def final_pairs(sx, sy, sux, suy, sa2, sb2, tx, ty, tux, tuy, ta2, tb2, th, t_x, t_y, idx, model):
    """The pairs at the solution for :func:`graphnav.scan.weighted_icp._report`: moved source points and the
    eq. 8 pair covariance entries (``model`` False: identity, the unweighted variants)."""
    n = sx.shape[0]
    c, s = math.cos(th), math.sin(th)
    px, py, d = moved_pairs(sx, sy, tx, ty, idx, c, s, t_x, t_y, n)
    sxx = np.ones(n)
    sxy = np.zeros(n)
    syy = np.ones(n)
    if model:
        for i in range(n):
            sxx[i], sxy[i], syy[i] = pair_cov(i, idx[i], c, s, sux, suy, sa2, sb2, tux, tuy, ta2, tb2)
    return c, s, px, py, d, sxx, sxy, syy


# ----------------------------------------------------------------------------- HDL (point-to-line)


@njit(cache=True)
def hdl_weights(px, py, d, idx, c, s, sux, suy, sa2, sb2, tx, ty, tux, tuy, ta2, tb2, nrx, nry, fl,
                huber_c, wpow, max_corr, flat_pow, res, dmax, p2p, w):
    """Pair weights of :func:`graphnav.scan.weighted_icp._weights` for HDL into ``w`` (``p2p``: the HD weights
    of the point-to-point warm-up): directional error along the target normal (eq. 9, 11), Huber
    on the point-to-line distance, x flatness^power, 0 outside Zhang's gate ``d / res[idx] <= dmax``
    (``res``: the target's pair scales, :func:`target_resolution`)."""
    n = px.shape[0]
    if p2p:
        khu = huber_c * np.median(d)
        for i in range(n):
            j = idx[i]  # HD weight (eq. 9, 11, 12), inline as in p2p_weights
            if d[i] > 0:
                bx = (tx[j] - px[i]) / d[i]
                by = (ty[j] - py[i]) / d[i]
            else:
                bx, by = 1.0, 0.0
            cs = (c * sux[i] - s * suy[i]) * bx + (s * sux[i] + c * suy[i]) * by
            ct = tux[j] * bx + tuy[j] * by
            wi = (sa2[i] - (sa2[i] - sb2[i]) * cs * cs + (ta2[j] - (ta2[j] - tb2[j]) * ct * ct)) ** (-wpow)
            if khu > 0 and d[i] > khu:
                wi *= khu / d[i]
            w[i] = wi if d[i] / res[idx[i]] <= dmax else 0.0
    else:
        dist = np.empty(n)
        for i in range(n):
            j = idx[i]
            dist[i] = abs((px[i] - tx[j]) * nrx[j] + (py[i] - ty[j]) * nry[j])
        khu = huber_c * np.median(dist)
        for i in range(n):
            j = idx[i]
            bx, by = nrx[j], nry[j]
            cs = (c * sux[i] - s * suy[i]) * bx + (s * sux[i] + c * suy[i]) * by
            ct = tux[j] * bx + tuy[j] * by
            g = sa2[i] - (sa2[i] - sb2[i]) * cs * cs + (ta2[j] - (ta2[j] - tb2[j]) * ct * ct)
            wi = g ** (-wpow)
            if khu > 0 and dist[i] > khu:
                wi *= khu / dist[i]
            wi = wi * fl[j] ** flat_pow
            w[i] = wi if d[i] / res[j] <= dmax else 0.0
    anyw = False
    for i in range(n):
        if d[i] > max_corr:
            w[i] = 0.0
        if w[i] > 0:
            anyw = True
    if not anyw:
        for i in range(n):
            w[i] = 1.0


@njit(cache=True)
def _solve3(h, b):
    """``-(h + 1e-12 I)^-1 b`` as :func:`graphnav.scan.weighted_icp._p2l_step` (least squares when singular)."""
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
def hdl_loop(sx, sy, sux, suy, sa2, sb2, tx, ty, tux, tuy, ta2, tb2, nrx, nry, fl, huber_c, wpow, max_corr,
             tol, tol_step, max_iter, th, t0x, t0y, h, flat_pow, warmup, res, big_d, gate0):
    """Algorithm 1 for HDL: HD point-to-point steps (eq. 15-20) while a step moves a point more than
    ``warmup`` x ``big_d``, then Gauss-Newton steps of the point-to-line cost, both within Zhang's
    gate (:func:`zhang_gate`, from ``gate0``). Returns (theta, tx, ty, idx, iterations, converged,
    gate), as :func:`p2p_loop`."""
    n = sx.shape[0]
    xmin, ymin, h, nx, ny, start, items, d, idx, w, px, py, src_r = loop_start(sx, sy, tx, ty, h)
    t_x, t_y = t0x, t0y
    old_res = -1.0
    converged = False
    warm = warmup > 0
    it = 0
    dmax = gate0
    moved = np.inf
    hm = np.empty((3, 3))
    bv = np.empty(3)
    for it in range(1, max_iter + 1):  # noqa: B007
        c, s = math.cos(th), math.sin(th)
        move_and_match(sx, sy, c, s, t_x, t_y, it == 1, tx, ty, xmin, ymin, h, nx, ny, start, items, px, py, d, idx)
        dmax = zhang_gate(d, idx, res, n, dmax)
        hdl_weights(px, py, d, idx, c, s, sux, suy, sa2, sb2, tx, ty, tux, tuy, ta2, tb2, nrx, nry, fl,
                    huber_c, wpow, max_corr, flat_pow, res, dmax, warm, w)
        if warm:  # eq. 15-20, 2D closed form
            sw = 0.0
            for i in range(n):
                sw += w[i]
            dth, dtx, dty = weighted_align(px, py, tx, ty, idx, w, n, sw)
        else:  # one Gauss-Newton step of sum w (n.(p' - q))^2 (graphnav.scan.weighted_icp._p2l_step)
            hm[:] = 0.0
            bv[:] = 0.0
            for i in range(n):
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
            dth, dtx, dty = x[2], x[0], x[1]
        th, t_x, t_y = step_pose(th, t_x, t_y, dth, dtx, dty)
        new_res, moved = residual_and_move(d, n, dth, dtx, dty, src_r)
        if warm:
            warm = moved > warmup * big_d
            old_res = -1.0
            continue
        if old_res >= 0 and abs(new_res - old_res) < tol * big_d and moved < tol_step * big_d:
            converged = True
            break
        old_res = new_res
    return th, t_x, t_y, idx, it, converged, dmax, moved, src_r


@njit(cache=True)
def _scan_cell_k(px, py, ix, iy, ny, start, items, tx, ty, bd, bi, cnt):
    """Insert the points of cell (ix, iy) into the sorted k-best lists ``bd``/``bi`` (``cnt`` filled)."""
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
def knn_line_normals(tx, ty, k, h):
    """As :func:`graphnav.scan.weighted_icp.line_normals`: unit normal and flatness of the line through each
    target point's ``k`` nearest neighbours (PCA; exact k nearest by rings of grid cells)."""
    n = tx.shape[0]
    k = min(k, n)
    xmin, ymin, h, nx, ny, start, items = build_grid(tx, ty, h)
    bd = np.empty(k)
    bi = np.empty(k, np.int64)
    nrx = np.empty(n)
    nry = np.empty(n)
    fl = np.empty(n)
    rmax = max(nx, ny)
    for i in range(n):
        px, py = tx[i], ty[i]
        cx = cell_index(px, xmin, h, nx)
        cy = cell_index(py, ymin, h, ny)
        bx0, by0 = xmin + cx * h, ymin + cy * h
        edge = max(min(px - bx0, bx0 + h - px, py - by0, by0 + h - py), 0.0)  # margin to the home cell's edge
        cnt = 0
        for r in range(rmax + 1):
            if r == 0:
                cnt = _scan_cell_k(px, py, cx, cy, ny, start, items, tx, ty, bd, bi, cnt)
            else:
                x0, x1 = cx - r, cx + r
                y0, y1 = cy - r, cy + r
                for ix in range(max(x0, 0), min(x1, nx - 1) + 1):
                    if y0 >= 0:
                        cnt = _scan_cell_k(px, py, ix, y0, ny, start, items, tx, ty, bd, bi, cnt)
                    if y1 <= ny - 1:
                        cnt = _scan_cell_k(px, py, ix, y1, ny, start, items, tx, ty, bd, bi, cnt)
                for iy in range(max(y0 + 1, 0), min(y1 - 1, ny - 1) + 1):
                    if x0 >= 0:
                        cnt = _scan_cell_k(px, py, x0, iy, ny, start, items, tx, ty, bd, bi, cnt)
                    if x1 <= nx - 1:
                        cnt = _scan_cell_k(px, py, x1, iy, ny, start, items, tx, ty, bd, bi, cnt)
            bound = r * h + edge  # the query lies in its home cell: a point beyond ring r is at least this far
            if cnt == k and bd[k - 1] < bound * bound:
                break
        mx = my = 0.0
        for m in range(k):
            mx += tx[bi[m]]
            my += ty[bi[m]]
        mx /= k
        my /= k
        cxx = cyy = cxy = 0.0
        for m in range(k):
            dx, dy = tx[bi[m]] - mx, ty[bi[m]] - my
            cxx += dx * dx
            cyy += dy * dy
            cxy += dx * dy
        phi = 0.5 * math.atan2(2 * cxy, cxx - cyy)
        nrx[i] = -math.sin(phi)
        nry[i] = math.cos(phi)
        tr = cxx + cyy
        disc = math.sqrt(0.25 * (cxx - cyy) ** 2 + cxy * cxy)
        fl[i] = 2.0 * disc / tr if tr > 0 else 0.0
    return nrx, nry, fl


# ----------------------------------------------------------------------------- one whole match


@njit(cache=True)
def cloud_terms(x, y, sig, use_sig, sigma_alpha, sigma_r_rel):
    """As :class:`graphnav.scan.weighted_icp._Cloud`: unit radial vector, squared semi-axes ``a^2, b^2`` (eq. 6-7;
    ``use_sig``: the caller's isotropic 1-sigma per point, a = b) and the mean error ``M^2`` (eq. 5)."""
    n = x.shape[0]
    ux = np.empty(n)
    uy = np.empty(n)
    a2 = np.empty(n)
    b2 = np.empty(n)
    m2 = np.empty(n)
    for i in range(n):
        r = math.hypot(x[i], y[i])
        rs = r if r > 0 else 1.0
        ux[i] = x[i] / rs
        uy[i] = y[i] / rs
        if use_sig:
            a2[i] = sig[i] ** 2
            b2[i] = a2[i]
        else:
            a2[i] = (sigma_alpha * r) ** 2
            b2[i] = (sigma_r_rel * r) ** 2
        m2[i] = a2[i] + b2[i]
    return ux, uy, a2, b2, m2


@njit(cache=True)
def p2p_match(sx, sy, ssig, use_ssig, tx, ty, tsig, use_tsig, sigma_alpha, sigma_r_rel, variant, huber_c, wpow,
              max_corr, tol, tol_step, max_iter, th, t0x, t0y, h, half, max_gap, gate0, min_res):
    """One K/H/HM/HD match (:func:`p2p_loop`), then its final pairs for the shared covariance and
    report (:func:`graphnav.scan.weighted_icp._report`): ``(theta, tx, ty, iterations, converged, idx, px,
    py, w, sxx, sxy, syy, nrx, nry, flat, res, gate, radius, last_moved, src_range)``, the normals
    and flatness (beam order, :func:`scan_order_normals`) and resolution per target point, the
    last step's largest point displacement and the source's largest range."""
    sux, suy, sa2, sb2, sm2 = cloud_terms(sx, sy, ssig, use_ssig, sigma_alpha, sigma_r_rel)
    tux, tuy, ta2, tb2, tm2 = cloud_terms(tx, ty, tsig, use_tsig, sigma_alpha, sigma_r_rel)
    res, scale, big_d = target_resolution(tx, ty, half, min_res, tm2)
    nrx, nry, fl = scan_order_normals(tx, ty, half, max_gap, res)
    th, t_x, t_y, idx, it, converged, dmax, moved, src_r = p2p_loop(
        sx, sy, sux, suy, sa2, sb2, sm2, tx, ty, tux, tuy, ta2, tb2, tm2, variant, huber_c, wpow, max_corr, tol,
        tol_step, max_iter, th, t0x, t0y, h, scale, big_d, gate0)
    c, s, px, py, d, sxx, sxy, syy = final_pairs(sx, sy, sux, suy, sa2, sb2, tx, ty, tux, tuy, ta2, tb2, th, t_x,
                                                 t_y, idx, variant >= 2)
    w = np.empty(sx.shape[0])
    p2p_weights(px, py, d, idx, c, s, sux, suy, sa2, sb2, sm2, tx, ty, tux, tuy, ta2, tb2, tm2, variant, huber_c,
                wpow, max_corr, w)
    return (th, t_x, t_y, it, converged, idx, px, py, w, sxx, sxy, syy, nrx, nry, fl, res, scale, dmax,
            rms_radius(sx, sy, sx.shape[0]), moved, src_r)


@njit(cache=True)
def hdl_match(sx, sy, ssig, use_ssig, tx, ty, tsig, use_tsig, sigma_alpha, sigma_r_rel, knn, normal_k, max_gap,
              huber_c, wpow, max_corr, tol, tol_step, max_iter, th, t0x, t0y, h, flat_pow, warmup, gate0, min_res):
    """One HDL match: the target's lines (``knn``: :func:`knn_line_normals`, else beam order,
    :func:`scan_order_normals`), :func:`hdl_loop`, the final pairs; returns as :func:`p2p_match`."""
    sux, suy, sa2, sb2, _ = cloud_terms(sx, sy, ssig, use_ssig, sigma_alpha, sigma_r_rel)
    tux, tuy, ta2, tb2, tm2 = cloud_terms(tx, ty, tsig, use_tsig, sigma_alpha, sigma_r_rel)
    res, scale, big_d = target_resolution(tx, ty, normal_k // 2, min_res, tm2)
    if knn:
        nrx, nry, fl = knn_line_normals(tx, ty, normal_k, h)
    else:
        nrx, nry, fl = scan_order_normals(tx, ty, normal_k // 2, max_gap, res)
    th, t_x, t_y, idx, it, converged, dmax, moved, src_r = hdl_loop(
        sx, sy, sux, suy, sa2, sb2, tx, ty, tux, tuy, ta2, tb2, nrx, nry, fl, huber_c, wpow, max_corr, tol, tol_step,
        max_iter, th, t0x, t0y, h, flat_pow, warmup, scale, big_d, gate0)
    c, s, px, py, d, sxx, sxy, syy = final_pairs(sx, sy, sux, suy, sa2, sb2, tx, ty, tux, tuy, ta2, tb2, th, t_x,
                                                 t_y, idx, True)
    w = np.empty(sx.shape[0])
    hdl_weights(px, py, d, idx, c, s, sux, suy, sa2, sb2, tx, ty, tux, tuy, ta2, tb2, nrx, nry, fl, huber_c, wpow,
                max_corr, flat_pow, scale, dmax, False, w)
    return (th, t_x, t_y, it, converged, idx, px, py, w, sxx, sxy, syy, nrx, nry, fl, res, scale, dmax,
            rms_radius(sx, sy, sx.shape[0]), moved, src_r)


# ----------------------------------------------------------------------------- the report's sums


@njit(cache=True)
def report_sums(px, py, qx, qy, w, sxx, sxy, syy, nx, ny, fl, spacing, scale, gate, tx, ty, c, s, radius, hdl,
                block, samp_var):
    """One pass over the final pairs for :func:`graphnav.scan.covariance.from_sums` (the sums of
    :func:`graphnav.scan.covariance.between`): ``(k, n_inliers, H, B_lidar, B_sampling, rms, info,
    inlier_fraction, points_used, median scale)`` with ``H = sum w J^T J``, ``B_lidar = sum w^2 J^T S
    J``, ``B_sampling = sum w^2 (block samp_var spacing^2) J^T J`` (``B = k B_lidar + B_sampling``) and
    ``info`` the point-to-line information of the flat inlier pairs (rotation column / ``radius``)."""
    n = px.shape[0]
    h = np.zeros((3, 3))
    bl = np.zeros((3, 3))
    bs = np.zeros((3, 3))
    info = np.zeros((3, 3))
    ksum = 0.0
    n_inl = 0
    n_gate = 0
    used = 0
    rss = 0.0
    sw = 0.0
    ja = np.empty(3)
    jb = np.empty(3)
    for i in range(n):
        ex = px[i] - qx[i]
        ey = py[i] - qy[i]
        d = math.hypot(ex, ey)
        inl = d / scale[i] <= gate
        if inl:
            n_gate += 1
        wi = w[i]
        if wi > 0:
            used += 1
        c2x = -(py[i] - ty)
        c2y = px[i] - tx
        r0 = nx[i] * c + ny[i] * s
        r1 = -nx[i] * s + ny[i] * c
        r2 = nx[i] * c2x + ny[i] * c2y
        both = inl and wi > 0
        if both:
            f = fl[i]
            r2s = r2 / radius
            sc = (r0, r1, r2s)
            for a in range(3):
                for b in range(3):
                    info[a, b] += f * sc[a] * sc[b]
        samp = block * samp_var * spacing[i] ** 2
        w2 = wi * wi
        if hdl:
            res = ex * nx[i] + ey * ny[i]
            sv = sxx[i] * nx[i] ** 2 + 2 * sxy[i] * nx[i] * ny[i] + syy[i] * ny[i] ** 2
            if both:
                ksum += res * res / sv
                n_inl += 1
            rss += wi * res * res
            ja[0], ja[1], ja[2] = r0, r1, r2
            for a in range(3):
                for b in range(3):
                    jj = ja[a] * ja[b]
                    h[a, b] += wi * jj
                    bl[a, b] += w2 * sv * jj
                    bs[a, b] += w2 * samp * jj
        else:
            if both:
                det = sxx[i] * syy[i] - sxy[i] ** 2
                ksum += (syy[i] * ex * ex - 2 * sxy[i] * ex * ey + sxx[i] * ey * ey) / det
                n_inl += 1
            rss += wi * (ex * ex + ey * ey)
            ja[0], ja[1], ja[2] = c, -s, c2x  # the Jacobian's rows: d(x)/d xi, d(y)/d xi
            jb[0], jb[1], jb[2] = s, c, c2y
            for a in range(3):
                for b in range(3):
                    jtj = ja[a] * ja[b] + jb[a] * jb[b]
                    jsj = sxx[i] * ja[a] * ja[b] + sxy[i] * (ja[a] * jb[b] + jb[a] * ja[b]) + syy[i] * jb[a] * jb[b]
                    h[a, b] += wi * jtj
                    bl[a, b] += w2 * jsj
                    bs[a, b] += w2 * samp * jtj
        sw += wi
    dim = 1 if hdl else 2
    k = ksum / max(dim * n_inl - 3, 1) if n_inl > 0 else np.nan
    rms = math.sqrt(rss / sw) if sw > 0 else np.nan
    big_d = np.median(scale) if n > 0 else np.nan
    frac = n_gate / n if n > 0 else np.nan
    return k, n_inl, h, bl, bs, rms, info, frac, used, big_d
