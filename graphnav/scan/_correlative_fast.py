"""Compiled (numba) kernels of :mod:`graphnav.scan.correlative`: the block scorer (the same sums as
:func:`graphnav.scan.correlative.block_scores_numpy`) and the whole multi-level branch and bound
(Cartographer's loop closer, Hess et al. 2016, Algorithm 3, depth-first, best child first). Tests
check both against the numpy search. Imported lazily."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def block_scores(grid, base, step, nb):
    """``out[y, a, b] = mean_p grid[base[y, p] + step (a, b)]`` (0 outside the grid)."""
    ny = base.shape[0]
    out = np.zeros((ny, nb, nb))
    for y in range(ny):
        for a in range(nb):
            for b in range(nb):
                out[y, a, b] = _score(grid, base, y, step * a, step * b)
    return out


@njit(cache=True)
def _score(grid, base, y, di, dj):
    ni, nj = grid.shape[0], grid.shape[1]
    n = base.shape[1]
    acc = 0.0
    for p in range(n):
        i = base[y, p, 0] + di
        j = base[y, p, 1] + dj
        if i >= 0 and j >= 0 and i < ni and j < nj:
            acc += grid[i, j]
    return acc / n


@njit(cache=True)
def _near(y, i, j, yb, ib, jb, ny, circular, far_t, far_y):
    dy = abs(y - yb)
    if circular:
        dy = min(dy, ny - dy)
    return dy < far_y and math.hypot(i - ib, j - jb) < far_t


@njit(cache=True)
def branch_and_bound(bounds, base, nfine, floor, yb, ib, jb, circular, far_t, far_y):
    """The best fine pose ``(score, y, i, j)`` with ``0 <= i, j < nfine`` over all yaws of ``base``
    (Y, N, 2); ``bounds[h]`` holds the maximum likelihood over ``2^h x 2^h`` windows (``bounds[0]``
    the likelihood itself). Only scores above ``floor`` are looked for. With ``yb >= 0`` the poses
    near ``(yb, ib, jb)`` (``far_t`` fine cells, ``far_y`` yaw steps) are excluded (the second peak).
    Returns also the number of leaf poses scored."""
    L = bounds.shape[0] - 1
    w = 1 << L
    nb = (nfine + w - 1) // w
    ny = base.shape[0]
    # the stack: level, yaw, i, j, bound (children pushed worst first so the best pops first)
    cap = ny * nb * nb + 4 * (L + 1) * 64
    st_h = np.empty(cap, np.int64)
    st_y = np.empty(cap, np.int64)
    st_i = np.empty(cap, np.int64)
    st_j = np.empty(cap, np.int64)
    st_b = np.empty(cap, np.float64)
    top = np.empty(ny * nb * nb)
    for y in range(ny):
        for a in range(nb):
            for b in range(nb):
                top[(y * nb + a) * nb + b] = _score(bounds[L], base, y, a * w, b * w)
    order = np.argsort(top)  # ascending: the best ends on the top of the stack
    sp = 0
    for q in order:
        if top[q] > floor:
            y = q // (nb * nb)
            r = q % (nb * nb)
            st_h[sp] = L
            st_y[sp] = y
            st_i[sp] = (r // nb) * w
            st_j[sp] = (r % nb) * w
            st_b[sp] = top[q]
            sp += 1
    best = floor
    by, bi, bj = -1, -1, -1
    leaves = 0
    cb = np.empty(4)
    ci = np.empty(4, np.int64)
    cj = np.empty(4, np.int64)
    while sp > 0:
        sp -= 1
        h, y, i0, j0, bd = st_h[sp], st_y[sp], st_i[sp], st_j[sp], st_b[sp]
        if bd <= best:
            continue
        if h == 0:  # a leaf: its bound is its score
            if yb >= 0 and _near(y, i0, j0, yb, ib, jb, ny, circular, far_t, far_y):
                continue
            best, by, bi, bj = bd, y, i0, j0
            continue
        s = 1 << (h - 1)
        m = 0
        for a in range(2):
            for b in range(2):
                ii, jj = i0 + a * s, j0 + b * s
                if ii >= nfine or jj >= nfine:
                    continue
                leaves += 1 if h == 1 else 0
                ci[m] = ii
                cj[m] = jj
                cb[m] = _score(bounds[h - 1], base, y, ii, jj)
                m += 1
        idx = np.argsort(cb[:m])
        for t in range(m):
            k = idx[t]
            if cb[k] > best:
                if sp >= cap:
                    break
                st_h[sp] = h - 1
                st_y[sp] = y
                st_i[sp] = ci[k]
                st_j[sp] = cj[k]
                st_b[sp] = cb[k]
                sp += 1
    return best, by, bi, bj, leaves
