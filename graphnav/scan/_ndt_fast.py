"""The kernels of :mod:`graphnav.scan.ndt`, its one implementation: the voxel map and the NDT score's derivatives.

Compiled by numba when importable, else run as plain Python (:mod:`graphnav.scan._jit`, the same code).
Voxels are found through an open-addressing hash table (Teschner et al. 2003's spatial hash, as
KISS-ICP's voxel map): memory is linear in the number of points and occupied voxels, no dense grid sized
from the bounding box. The tests check the derivatives against finite differences of the score and the
voxel Gaussians against the points' mean and covariance. Arguments travel in groups: the voxel map
``vox = (tkeys, tvals, means, icovs, inv_res)`` (hash table, Gaussians, 1 / voxel side), the 3D pose's
rotation terms ``rot = (R, t, dR, d2R)``, a point's scratch ``work = (ja, ha, gq, Aq, Aja)`` and the sums
``acc = (g, H, G, fse)`` (``fse``: f, sum e m, sum e).
"""

from __future__ import annotations

import math

import numpy as np

from ._jit import njit

# voxel coordinate range: +-2^20 cells per axis (3D), +-2^28 (2D); points outside are dropped
OFF3 = 1 << 20
OFF2 = 1 << 28
P1, P2, P3 = 73856093, 19349663, 83492791  # Teschner et al. 2003 spatial-hash primes


@njit(cache=True)
def pack3(ix, iy, iz):
    """One int64 key of a 3D voxel index (21 bits per axis); -1 when out of range."""
    a, b, c = ix + OFF3, iy + OFF3, iz + OFF3
    if a < 0 or b < 0 or c < 0 or a >= 2 * OFF3 or b >= 2 * OFF3 or c >= 2 * OFF3:
        return -1
    return (a << 42) | (b << 21) | c


@njit(cache=True)
def pack2(g, ix, iy):
    """One int64 key of a 2D cell of grid ``g`` (0-3, Biber's four shifted grids); -1 out of range."""
    a, b = ix + OFF2, iy + OFF2
    if a < 0 or b < 0 or a >= 2 * OFF2 or b >= 2 * OFF2:
        return -1
    return (g << 58) | (a << 29) | b


@njit(cache=True)
def cell(v):
    """floor(v) as int64, clamped to +-2^40 (far outside every key range; NaN -> out of range)."""
    if not v > -1099511627776.0:
        return -1099511627776
    if v >= 1099511627776.0:
        return 1099511627776
    return int(math.floor(v))


@njit(cache=True)
def _slot(key, mask):
    """Hash of a packed key (the voxel index's components times Teschner's primes, xor-ed)."""
    h = ((key & 0x1FFFFF) * P1) ^ (((key >> 21) & 0x1FFFFF) * P2) ^ ((key >> 42) * P3)
    return h & mask


@njit(cache=True)
def hash_build(vkeys):
    """Open-addressing table (linear probing, load <= 1/2) of the voxel keys -> their row."""
    cap = 8
    while cap < 2 * vkeys.shape[0]:
        cap *= 2
    tkeys = np.full(cap, -1, np.int64)
    tvals = np.empty(cap, np.int64)
    mask = cap - 1
    for v in range(vkeys.shape[0]):
        s = _slot(vkeys[v], mask)
        while tkeys[s] != -1:
            s = (s + 1) & mask
        tkeys[s] = vkeys[v]
        tvals[s] = v
    return tkeys, tvals


@njit(cache=True)
def hash_find(key, tkeys, tvals):
    """Row of ``key`` in the table, or -1."""
    if key < 0:
        return -1
    mask = tkeys.shape[0] - 1
    s = _slot(key, mask)
    while True:
        k = tkeys[s]
        if k == key:
            return tvals[s]
        if k == -1:
            return -1
        s = (s + 1) & mask


@njit(cache=True)
def keys3(pts, inv_res):
    n = pts.shape[0]
    out = np.empty(n, np.int64)
    for i in range(n):
        out[i] = pack3(cell(pts[i, 0] * inv_res), cell(pts[i, 1] * inv_res), cell(pts[i, 2] * inv_res))
    return out


@njit(cache=True)
def keys2(pts, inv_res, g, ox, oy):
    n = pts.shape[0]
    out = np.empty(n, np.int64)
    for i in range(n):
        out[i] = pack2(g, cell((pts[i, 0] - ox) * inv_res), cell((pts[i, 1] - oy) * inv_res))
    return out


@njit(cache=True)
def gaussians(pts, keys, min_points, eig_ratio):
    """Mean and regularised inverse covariance of the points of each key (Magnusson 2009 eq. 6.11:
    eigenvalues below ``eig_ratio`` times the largest are raised to it). Keys < 0 are skipped; keys
    with fewer than ``min_points`` points or a zero largest eigenvalue are dropped.
    Returns sorted keys (V,), means (V, D), inverse covariances (V, D, D), counts (V,)."""
    d = pts.shape[1]
    order = np.argsort(keys, kind="mergesort")
    n = keys.shape[0]
    nmax = 0
    i = 0
    while i < n:  # count runs
        j = i
        while j < n and keys[order[j]] == keys[order[i]]:
            j += 1
        nmax += 1
        i = j
    vkeys = np.empty(nmax, np.int64)
    means = np.empty((nmax, d))
    icovs = np.empty((nmax, d, d))
    counts = np.empty(nmax, np.int64)
    v = 0
    i = 0
    while i < n:
        j = i
        k0 = keys[order[i]]
        while j < n and keys[order[j]] == k0:
            j += 1
        m = j - i
        if k0 >= 0 and m >= min_points:
            mu = np.zeros(d)
            for r in range(i, j):
                for a in range(d):
                    mu[a] += pts[order[r], a]
            mu /= m
            c = np.zeros((d, d))
            for r in range(i, j):
                for a in range(d):
                    da = pts[order[r], a] - mu[a]
                    for b in range(d):
                        c[a, b] += da * (pts[order[r], b] - mu[b])
            c /= m - 1
            w, vec = np.linalg.eigh(c)
            if w[d - 1] > 0:
                floor = eig_ratio * w[d - 1]
                ic = np.zeros((d, d))
                for e in range(d):
                    lam = max(w[e], floor)
                    for a in range(d):
                        for b in range(d):
                            ic[a, b] += vec[a, e] * vec[b, e] / lam
                vkeys[v] = k0
                means[v] = mu
                icovs[v] = ic
                counts[v] = m
                v += 1
        i = j
    return vkeys[:v].copy(), means[:v].copy(), icovs[:v].copy(), counts[:v].copy()


@njit(cache=True)
def derivs3(pts, rot, vox, offsets, d12, hess):
    """Magnusson's P2D-NDT objective f = sum d1 exp(-d2 m / 2) (the negated score of eq. 6.9-6.10;
    m = q' Sigma^-1 q, q = T(p) x - mu) over every point and every voxel at ``offsets`` from the
    voxel holding T(p) x, with its gradient (eq. 6.12) and, if ``hess``, Hessian (eq. 6.13).

    p = (t_x, t_y, t_z, phi_x, phi_y, phi_z), T(p) x = R_x R_y R_z x + t (eq. 6.17); in ``rot = (R, t, dR,
    d2R)``, ``dR`` (3, 3, 3) and ``d2R`` (6, 3, 3: xx, xy, xz, yy, yz, zz) are the first and second
    derivatives of R by the angles, so ``dR[k] @ x`` and ``d2R[kl] @ x`` are the angular terms of eq.
    6.18-6.21; ``d12 = (d1, d2)``. Returns f, g (6,), H (6, 6), G (6, 6) the Gauss-Newton part of H (sum c
    J' A J, c = -d1 d2 e: positive semi-definite), points with at least one voxel, sum e*m, sum e (e =
    exp(-d2 m / 2)).
    """
    R, t, dR, d2R = rot
    inv_res = vox[4]
    acc = (np.zeros(6), np.zeros((6, 6)), np.zeros((6, 6)), np.zeros(3))
    work = (np.empty((3, 3)), np.empty((6, 3)), np.empty(6), np.empty(3), np.empty((3, 3)))
    ja, ha = work[0], work[1]
    hits = 0
    for i in range(pts.shape[0]):
        x0, x1, x2 = pts[i, 0], pts[i, 1], pts[i, 2]
        xp0 = R[0, 0] * x0 + R[0, 1] * x1 + R[0, 2] * x2 + t[0]
        xp1 = R[1, 0] * x0 + R[1, 1] * x1 + R[1, 2] * x2 + t[1]
        xp2 = R[2, 0] * x0 + R[2, 1] * x1 + R[2, 2] * x2 + t[2]
        for k in range(3):
            for a in range(3):
                ja[k, a] = dR[k, a, 0] * x0 + dR[k, a, 1] * x1 + dR[k, a, 2] * x2
        if hess:
            for k in range(6):
                for a in range(3):
                    ha[k, a] = d2R[k, a, 0] * x0 + d2R[k, a, 1] * x1 + d2R[k, a, 2] * x2
        cx, cy, cz = cell(xp0 * inv_res), cell(xp1 * inv_res), cell(xp2 * inv_res)
        hit = False
        for o in range(offsets.shape[0]):
            v = hash_find(pack3(cx + offsets[o, 0], cy + offsets[o, 1], cz + offsets[o, 2]), vox[0], vox[1])
            if v < 0:
                continue
            hit = True
            _gaussian3(xp0 - vox[2][v, 0], xp1 - vox[2][v, 1], xp2 - vox[2][v, 2], vox[3][v], d12, hess, work, acc)
        if hit:
            hits += 1
    g, H, G, fse = acc
    _symmetric(H, G, 6)
    return fse[0], g, H, G, hits, fse[1], fse[2]


@njit(cache=True)
def _gaussian3(q0, q1, q2, A, d12, hess, work, acc):
    """One point's terms against one voxel Gaussian (``q = T(p) x - mu``, ``A`` its inverse covariance) into
    ``acc``: f, sum e m, sum e, the gradient and (``hess``) the upper triangles of H (without G) and G."""
    d1, d2 = d12
    ja, ha, gq, Aq, Aja = work
    g, H, G, fse = acc
    for a in range(3):
        Aq[a] = A[a, 0] * q0 + A[a, 1] * q1 + A[a, 2] * q2
    m = q0 * Aq[0] + q1 * Aq[1] + q2 * Aq[2]
    e = math.exp(-0.5 * d2 * m)
    fse[0] += d1 * e
    fse[1] += e * m
    fse[2] += e
    c = -d1 * d2 * e
    gq[0], gq[1], gq[2] = Aq[0], Aq[1], Aq[2]
    for k in range(3):
        gq[3 + k] = Aq[0] * ja[k, 0] + Aq[1] * ja[k, 1] + Aq[2] * ja[k, 2]
    for r in range(6):
        g[r] += c * gq[r]
    if not hess:
        return
    # c (-d2 (q'A J_i)(q'A J_j) + J_j' A J_i + q' A d2x'/dp_i dp_j), upper triangle
    for r in range(6):
        cr = -c * d2 * gq[r]
        for s in range(r, 6):
            H[r, s] += cr * gq[s]
    for a in range(3):
        for b in range(a, 3):
            G[a, b] += c * A[a, b]
    for k in range(3):
        for a in range(3):
            Aja[k, a] = A[a, 0] * ja[k, 0] + A[a, 1] * ja[k, 1] + A[a, 2] * ja[k, 2]
        for a in range(3):
            G[a, 3 + k] += c * Aja[k, a]
    pi = 0
    for k in range(3):
        for l2 in range(k, 3):  # pi enumerates xx, xy, xz, yy, yz, zz
            G[3 + k, 3 + l2] += c * (ja[k, 0] * Aja[l2, 0] + ja[k, 1] * Aja[l2, 1] + ja[k, 2] * Aja[l2, 2])
            H[3 + k, 3 + l2] += c * (Aq[0] * ha[pi, 0] + Aq[1] * ha[pi, 1] + Aq[2] * ha[pi, 2])
            pi += 1


@njit(cache=True)
def _symmetric(H, G, n):
    """H += G on the upper triangle, then both mirrored to the lower."""
    for r in range(n):
        for s in range(r, n):
            H[r, s] += G[r, s]
    for r in range(n):
        for s in range(r):
            H[r, s] = H[s, r]
            G[r, s] = G[s, r]


@njit(cache=True)
def derivs2(pts, p, vox, shifts):
    """Biber & Strasser 2003's objective f = -sum exp(-m / 2) over every point and each of the
    shifted grids (``shifts`` (G, 2), the grid origins) of the map ``vox``, with its gradient and Hessian in
    p = (t_x, t_y, phi), x' = R(phi) x + t. Returns f, g (3,), H (3, 3), points with at least one
    cell, sum e*m, sum e; and G, the Gauss-Newton part of H (sum e J' A J)."""
    g = np.zeros(3)
    H = np.zeros((3, 3))
    G = np.zeros((3, 3))
    f = 0.0
    hits = 0
    sem = 0.0
    se = 0.0
    tkeys, tvals, means, icovs, inv_res = vox
    c, s = math.cos(p[2]), math.sin(p[2])
    for i in range(pts.shape[0]):
        x, y = pts[i, 0], pts[i, 1]
        xp = c * x - s * y + p[0]
        yp = s * x + c * y + p[1]
        j0, j1 = -s * x - c * y, c * x - s * y          # dx'/dphi
        h0, h1 = -c * x + s * y, -s * x - c * y          # d2x'/dphi2
        hit = False
        for gi in range(shifts.shape[0]):
            v = hash_find(pack2(gi, cell((xp - shifts[gi, 0]) * inv_res), cell((yp - shifts[gi, 1]) * inv_res)),
                          tkeys, tvals)
            if v < 0:
                continue
            hit = True
            q0, q1 = xp - means[v, 0], yp - means[v, 1]
            A = icovs[v]
            a0 = A[0, 0] * q0 + A[0, 1] * q1
            a1 = A[1, 0] * q0 + A[1, 1] * q1
            m = q0 * a0 + q1 * a1
            e = math.exp(-0.5 * m)
            f -= e
            sem += e * m
            se += e
            gq0, gq1, gq2 = a0, a1, a0 * j0 + a1 * j1
            g[0] += e * gq0
            g[1] += e * gq1
            g[2] += e * gq2
            Aj0 = A[0, 0] * j0 + A[0, 1] * j1
            Aj1 = A[1, 0] * j0 + A[1, 1] * j1
            G[0, 0] += e * A[0, 0]
            G[0, 1] += e * A[0, 1]
            G[1, 1] += e * A[1, 1]
            G[0, 2] += e * Aj0
            G[1, 2] += e * Aj1
            G[2, 2] += e * (j0 * Aj0 + j1 * Aj1)
            H[0, 0] -= e * gq0 * gq0
            H[0, 1] -= e * gq0 * gq1
            H[1, 1] -= e * gq1 * gq1
            H[0, 2] -= e * gq0 * gq2
            H[1, 2] -= e * gq1 * gq2
            H[2, 2] += e * (-gq2 * gq2 + a0 * h0 + a1 * h1)
        if hit:
            hits += 1
    _symmetric(H, G, 3)
    return f, g, H, G, hits, sem, se
