"""Compiled (numba) inner loop of the point-to-point variants K/H/HM/HD.

The same algorithm as the numpy loop in :mod:`graphnav.icp` (Algorithm 1, eq. 9-22), with an
exact grid-based nearest-neighbour search instead of ``cKDTree``; tests check that both give
the same matches. Imported lazily; absent numba, :mod:`graphnav.icp` uses its numpy loop.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def build_grid(tx, ty, h):
    """Bucket target points into square cells of side ``h`` (counting sort)."""
    n = tx.shape[0]
    xmin, ymin = tx.min(), ty.min()
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
    return xmin, ymin, nx, ny, start, items


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
    cx = int(math.floor((px - xmin) / h))
    cy = int(math.floor((py - ymin) / h))
    cx = min(max(cx, 0), nx - 1)
    cy = min(max(cy, 0), ny - 1)
    # distance from p to the home cell's box (0 inside)
    bx0, by0 = xmin + cx * h, ymin + cy * h
    ox = max(bx0 - px, 0.0, px - (bx0 + h))
    oy = max(by0 - py, 0.0, py - (by0 + h))
    off = math.sqrt(ox * ox + oy * oy)
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
        if bi >= 0 and bound > 0 and best <= bound * bound:
            break
    return math.sqrt(best), bi


@njit(cache=True)
def p2p_loop(sx, sy, sux, suy, sa2, sb2, sm2, tx, ty, tux, tuy, ta2, tb2, tm2, variant, huber_c, wpow,
             max_corr, tol, tol_step, max_iter, th, t0x, t0y, h):
    """Algorithm 1 for variant 0=K, 1=H, 2=HM, 3=HD. Returns (theta, tx, ty, idx, iterations,
    converged)."""
    n = sx.shape[0]
    xmin, ymin, nx, ny, start, items = build_grid(tx, ty, h)
    d = np.empty(n)
    idx = np.empty(n, np.int64)
    w = np.empty(n)
    px = np.empty(n)
    py = np.empty(n)
    src_r = 0.0
    for i in range(n):
        src_r = max(src_r, math.sqrt(sx[i] * sx[i] + sy[i] * sy[i]))
    t_x, t_y = t0x, t0y
    old_res = -1.0
    converged = False
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007
        c, s = math.cos(th), math.sin(th)
        for i in range(n):
            px[i] = c * sx[i] - s * sy[i] + t_x
            py[i] = s * sx[i] + c * sy[i] + t_y
            d[i], idx[i] = nearest(px[i], py[i], tx, ty, xmin, ymin, h, nx, ny, start, items)
        khu = huber_c * np.median(d)
        sw = 0.0
        for i in range(n):
            j = idx[i]
            if variant == 2:
                wi = (sm2[i] + tm2[j]) ** (-wpow)
            elif variant == 3:
                if d[i] > 0:
                    bx = (tx[j] - px[i]) / d[i]
                    by = (ty[j] - py[i]) / d[i]
                else:
                    bx, by = 1.0, 0.0
                urx = c * sux[i] - s * suy[i]
                ury = s * sux[i] + c * suy[i]
                cs = urx * bx + ury * by
                ct = tux[j] * bx + tuy[j] * by
                g = sa2[i] - (sa2[i] - sb2[i]) * cs * cs + ta2[j] - (ta2[j] - tb2[j]) * ct * ct
                wi = g ** (-wpow)
            else:
                wi = 1.0
            if variant != 0 and khu > 0 and d[i] > khu:
                wi *= khu / d[i]
            if d[i] > max_corr:
                wi = 0.0
            w[i] = wi
            sw += wi
        if not sw > 0:
            for i in range(n):
                w[i] = 1.0
            sw = n
        # eq. 15-20, 2D closed form
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
        dtx = mqx - (cd * mpx - sd * mpy)
        dty = mqy - (sd * mpx + cd * mpy)
        # eq. 21-22
        nxx = cd * t_x - sd * t_y + dtx
        nyy = sd * t_x + cd * t_y + dty
        t_x, t_y = nxx, nyy
        th += dth
        new_res = 0.0
        for i in range(n):
            new_res += d[i]
        new_res /= n
        moved = abs(dth) * src_r + math.sqrt(dtx * dtx + dty * dty)
        if old_res >= 0 and abs(new_res - old_res) < tol and moved < tol_step:
            converged = True
            break
        old_res = new_res
    return th, t_x, t_y, idx, it, converged


@njit(cache=True)
def scan_order_normals(tx, ty, half, max_gap):
    """As :func:`graphnav.icp.scan_order_normals` (PCA of beam-order windows, gap check)."""
    n = tx.shape[0]
    order = np.argsort(np.arctan2(ty, tx), kind="mergesort")
    xs = tx[order]
    ys = ty[order]
    gap = np.empty(n)
    for i in range(n):
        k = (i + 1) % n
        gap[i] = math.sqrt((xs[k] - xs[i]) ** 2 + (ys[k] - ys[i]) ** 2)
    nx_ = np.empty(n)
    ny_ = np.empty(n)
    fl = np.empty(n)
    m = 2 * half + 1
    for i in range(n):
        mx = my = 0.0
        wide = False
        for o in range(-half, half + 1):
            k = (i + o) % n
            mx += xs[k]
            my += ys[k]
            if o < half and gap[k] > max_gap:
                wide = True
        mx /= m
        my /= m
        cxx = cyy = cxy = 0.0
        for o in range(-half, half + 1):
            k = (i + o) % n
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
def p2p_stats(sx, sy, sux, suy, sa2, sb2, sm2, tx, ty, tux, tuy, ta2, tb2, tm2, variant, huber_c, wpow,
              max_corr, th, t_x, t_y, idx, half, max_gap, inlier_dist):
    """The terms of :func:`graphnav.icp._finish` for K/H/HM/HD: ``H``, ``B``, the residual scale's
    numerator and dof, the weighted RMS residual, the point-to-line information (degeneracy),
    the number of pairs used and of inliers."""
    n = sx.shape[0]
    c, s = math.cos(th), math.sin(th)
    px = np.empty(n)
    py = np.empty(n)
    d = np.empty(n)
    for i in range(n):
        px[i] = c * sx[i] - s * sy[i] + t_x
        py[i] = s * sx[i] + c * sy[i] + t_y
        d[i] = math.sqrt((px[i] - tx[idx[i]]) ** 2 + (py[i] - ty[idx[i]]) ** 2)
    khu = huber_c * np.median(d)
    nx_, ny_, fl = scan_order_normals(tx, ty, half, max_gap)
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
    h = np.zeros((3, 3))
    b = np.zeros((3, 3))
    info = np.zeros((3, 3))
    a = np.empty((2, 3))
    sa = np.empty((2, 3))
    jl = np.empty(3)
    ksum = 0.0
    n_sel = 0
    n_use = 0
    n_inl = 0
    sw = 0.0
    swe = 0.0
    ws = np.empty(n)
    for i in range(n):
        j = idx[i]
        ex, ey = px[i] - tx[j], py[i] - ty[j]
        if variant == 2:
            wi = (sm2[i] + tm2[j]) ** (-wpow)
        elif variant == 3:
            if d[i] > 0:
                bx, by = -ex / d[i], -ey / d[i]
            else:
                bx, by = 1.0, 0.0
            urx = c * sux[i] - s * suy[i]
            ury = s * sux[i] + c * suy[i]
            cs = urx * bx + ury * by
            ct = tux[j] * bx + tuy[j] * by
            g = sa2[i] - (sa2[i] - sb2[i]) * cs * cs + ta2[j] - (ta2[j] - tb2[j]) * ct * ct
            wi = g ** (-wpow)
        else:
            wi = 1.0
        if variant != 0 and khu > 0 and d[i] > khu:
            wi *= khu / d[i]
        if d[i] > max_corr:
            wi = 0.0
        ws[i] = wi
    tot = 0.0
    for i in range(n):
        tot += ws[i]
    if not tot > 0:
        for i in range(n):
            ws[i] = 1.0
    for i in range(n):
        j = idx[i]
        wi = ws[i]
        ex, ey = px[i] - tx[j], py[i] - ty[j]
        if variant >= 2:  # eq. 8 pair covariance: source rotated + target
            ux = c * sux[i] - s * suy[i]
            uy = s * sux[i] + c * suy[i]
            dsv = sb2[i] - sa2[i]
            dtv = tb2[j] - ta2[j]
            a2 = sa2[i] + ta2[j]
            sxx = a2 + dsv * ux * ux + dtv * tux[j] * tux[j]
            syy = a2 + dsv * uy * uy + dtv * tuy[j] * tuy[j]
            sxy = dsv * ux * uy + dtv * tux[j] * tuy[j]
        else:
            sxx, sxy, syy = 1.0, 0.0, 1.0
        c2x, c2y = -(py[i] - t_y), px[i] - t_x
        a[0, 0], a[0, 1], a[0, 2] = c, -s, c2x
        a[1, 0], a[1, 1], a[1, 2] = s, c, c2y
        for k in range(3):
            sa[0, k] = sxx * a[0, k] + sxy * a[1, k]
            sa[1, k] = sxy * a[0, k] + syy * a[1, k]
        for r_ in range(3):
            for q_ in range(3):
                h[r_, q_] += wi * (a[0, r_] * a[0, q_] + a[1, r_] * a[1, q_])
                b[r_, q_] += wi * wi * (a[0, r_] * sa[0, q_] + a[1, r_] * sa[1, q_])
        inl = d[i] <= inlier_dist
        use = wi > 0
        n_inl += inl
        n_use += use
        sw += wi
        swe += wi * (ex * ex + ey * ey)
        if inl and use:
            n_sel += 1
            det = sxx * syy - sxy * sxy
            ksum += (syy * ex * ex - 2 * sxy * ex * ey + sxx * ey * ey) / det
            # point-to-line row n^T [R, J (p - t)], rotation scaled by lsc
            nxj, nyj = nx_[j], ny_[j]
            jl[0] = nxj * c + nyj * s
            jl[1] = -nxj * s + nyj * c
            jl[2] = (nxj * c2x + nyj * c2y) / lsc
            for r_ in range(3):
                for q_ in range(3):
                    info[r_, q_] += fl[j] * jl[r_] * jl[q_]
    res_rms = math.sqrt(swe / sw) if sw > 0 else np.nan
    return h, b, ksum, max(2 * n_sel - 3, 1), n_sel, res_rms, info, n_use, n_inl
