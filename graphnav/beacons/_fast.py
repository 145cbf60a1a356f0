"""Compiled (numba) covariance propagation of the beacon-layout EKF-SLAM, many layouts at once.

The same filter as the numpy path of :func:`graphnav.beacons.layout.propagate` (eq. 18-26),
linearised on the true track. There G (eq. 19), W (eq. 22) and so R (eq. 20-23) are the same for
every layout, and H (eq. 25) depends only on the layout and the true track, never on the noise
draw: the covariance, and so M_xy (eq. 28), is a deterministic function of the layout (a
covariance analysis; the search needs no Monte Carlo). Only P is propagated; no state, no noise.

Sparsity used (n = 3 + 2i): beacons are static, so the prediction only shears rows/columns 0, 1 by
column 2 and adds the 3x3 motion noise (O(n)); the beacon-beacon blocks change only in the
corrections. Each correction (one beacon, K (n x 2), eq. 24) needs just H's five non-zero columns:
A = P H^T from P's columns x, y, theta, x_b, y_b (O(n)), then the symmetric rank-2 update
P -= K A^T = A S^-1 A^T (O(n^2)); no n x n product, no O(n^3) step. P is symmetric, so only its
upper triangle is stored and updated.

Layout: P is (n, n, W) for a block of W layouts, the layout index innermost, so every scalar
operation of the filter is a loop over W contiguous values that LLVM vectorises (SIMD).

Imported lazily; absent numba, :mod:`graphnav.beacons.layout` uses its numpy path. ``cache=True``:
the first call compiles (a few seconds), later processes load the cached machine code.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

WIDTH = 128
"""Layouts per block (P of one 4-beacon block: 11 x 11 x 128 doubles = 124 kB)."""


@njit(cache=True, error_model="numpy")
def _predict(P, g0, g1, rq_k, n, wn):
    """Eq. 23, P <- G P G^T + R on the upper triangle (G's only off-diagonal entries G[0, 2] = ``g0``,
    G[1, 2] = ``g1``; ``rq_k`` the step's R), in the numpy path's order of operations."""
    for w in range(wn):
        r02 = P[0, 2, w] + g0 * P[2, 2, w]
        r12 = P[1, 2, w] + g1 * P[2, 2, w]
        P[0, 0, w] = P[0, 0, w] + g0 * P[0, 2, w] + g0 * r02
        P[0, 1, w] = P[0, 1, w] + g0 * P[1, 2, w] + g1 * r02
        P[1, 1, w] = P[1, 1, w] + g1 * P[1, 2, w] + g1 * r12
        P[0, 2, w] = r02
        P[1, 2, w] = r12
    for m in range(3, n):
        for w in range(wn):
            P[0, m, w] += g0 * P[2, m, w]
            P[1, m, w] += g1 * P[2, m, w]
    for i in range(3):
        for m in range(i, 3):
            r = rq_k[i, m]
            for w in range(wn):
                P[i, m, w] += r


@njit(cache=True, error_model="numpy")
def _jacobian(h, bxj, byj, px, py, wn):
    """H's position entries (eq. 25) per layout into ``h`` (4, W): the beacon at (``bxj``, ``byj``)
    seen from the true position (``px``, ``py``)."""
    for w in range(wn):
        dx = bxj[w] - px
        dy = byj[w] - py
        q = dx * dx + dy * dy
        r = math.sqrt(q)
        h[0, w] = -dx / r
        h[1, w] = -dy / r
        h[2, w] = dy / q
        h[3, w] = -dx / q


@njit(cache=True, error_model="numpy")
def _correct(P, h, b, q_r, q_b, n, wn, work):
    """Eq. 24-26 for the beacon whose x column is ``b``: A = P H^T from the five columns H touches,
    S = H P H^T + Q and its inverse, then P -= K A^T with K = A S^-1. ``work``: scratch arrays
    (A's two columns, S^-1, a row of K, P's five columns)."""
    a0, a1, si, k0, k1, col = work
    for t in range(5):                      # the five columns H touches
        cc = t if t < 3 else b + t - 3
        for i in range(n):
            lo, hi = (i, cc) if i <= cc else (cc, i)
            for w in range(wn):
                col[t, i, w] = P[lo, hi, w]
    for i in range(n):                      # A = P H^T (H's beacon columns = -position)
        for w in range(wn):
            ddx = col[0, i, w] - col[3, i, w]
            ddy = col[1, i, w] - col[4, i, w]
            a0[i, w] = h[0, w] * ddx + h[1, w] * ddy
            a1[i, w] = h[2, w] * ddx + h[3, w] * ddy - col[2, i, w]
    for w in range(wn):                     # S = H P H^T + Q, its inverse
        ex0 = a0[0, w] - a0[b, w]
        ex1 = a1[0, w] - a1[b, w]
        ey0 = a0[1, w] - a0[b + 1, w]
        ey1 = a1[1, w] - a1[b + 1, w]
        s00 = h[0, w] * ex0 + h[1, w] * ey0 + q_r
        s01 = h[0, w] * ex1 + h[1, w] * ey1
        s11 = h[2, w] * ex1 + h[3, w] * ey1 - a1[2, w] + q_b
        det = s00 * s11 - s01 * s01
        si[0, w] = s11 / det
        si[1, w] = -s01 / det
        si[2, w] = s00 / det
    for i in range(n):                      # eq. 24 K = A S^-1; eq. 26 P -= K A^T
        for w in range(wn):
            k0[w] = a0[i, w] * si[0, w] + a1[i, w] * si[1, w]
            k1[w] = a0[i, w] * si[1, w] + a1[i, w] * si[2, w]
        for m in range(i, n):
            for w in range(wn):
                P[i, m, w] -= k0[w] * a0[m, w] + k1[w] * a1[m, w]


@njit(cache=True, error_model="numpy")
def propagate_truth(bx, by, track, p0, ga, gb, rq, q_r, q_b, keep, width):
    """EKF-SLAM covariance over the true track for each layout.

    ``bx``, ``by`` (C, B) beacon coordinates; ``track`` (steps+1, 3) true poses; ``p0`` (n, n) P0
    (eq. 14, symmetric); ``ga``, ``gb`` (steps,) G[0, 2] and G[1, 2] of eq. 19 (G's only non-zero
    off-diagonal entries); ``rq`` (steps, 3, 3) R = W M W^T (eq. 20-23); ``q_r``, ``q_b`` Q's
    diagonal (eq. 16); ``width`` layouts per block. Returns ``mx``, ``my`` (C, steps) = sqrt(P00),
    sqrt(P11) after each step's corrections (eq. 29-30), and the final P (C, n, n) when ``keep``
    (else an empty (0, n, n) array).
    """
    n_cfg, n_b = bx.shape
    steps = ga.shape[0]
    n = 3 + 2 * n_b
    # numba does not bounds-check: every array the loops index must have the shape they assume, so
    # the work and memory are those of the inputs (no read or write outside them)
    if by.shape != bx.shape or track.shape[0] != steps + 1 or track.shape[1] < 2 or gb.shape[0] != steps:
        raise ValueError("propagate_truth: bx/by, track, ga/gb shapes disagree")
    if rq.shape[0] != steps or rq.shape[1] != 3 or rq.shape[2] != 3 or p0.shape[0] != n or p0.shape[1] != n:
        raise ValueError("propagate_truth: rq or p0 shape disagrees")
    if width < 1:
        raise ValueError("propagate_truth: width must be >= 1")
    mx = np.empty((n_cfg, steps))
    my = np.empty((n_cfg, steps))
    p_out = np.empty((n_cfg if keep else 0, n, n))
    P = np.empty((n, n, width))            # upper triangle (i <= m) used
    h = np.empty((4, width))               # H's position entries (eq. 25)
    work = (np.empty((n, width)), np.empty((n, width)), np.empty((3, width)),  # A's columns, S^-1
            np.empty(width), np.empty(width), np.empty((5, n, width)))        # a row of K, P's five columns
    for c0 in range(0, n_cfg, width):
        wn = min(width, n_cfg - c0)
        for i in range(n):
            for m in range(i, n):
                for w in range(wn):
                    P[i, m, w] = p0[i, m]
        for k in range(1, steps + 1):
            _predict(P, ga[k - 1], gb[k - 1], rq[k - 1], n, wn)
            for j in range(n_b):               # corrections, one beacon at a time
                _jacobian(h, bx[c0:c0 + wn, j], by[c0:c0 + wn, j], track[k, 0], track[k, 1], wn)
                _correct(P, h, 3 + 2 * j, q_r, q_b, n, wn, work)
            for w in range(wn):
                mx[c0 + w, k - 1] = math.sqrt(max(P[0, 0, w], 0.0))
                my[c0 + w, k - 1] = math.sqrt(max(P[1, 1, w], 0.0))
        if keep:
            for w in range(wn):
                for i in range(n):
                    for m in range(i, n):
                        p_out[c0 + w, i, m] = P[i, m, w]
                        p_out[c0 + w, m, i] = P[i, m, w]
    return mx, my, p_out
