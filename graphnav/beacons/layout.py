"""Beacon-layout study (Marchel, Naus & Specht 2019): batched EKF-SLAM covariance over layouts.

A vessel runs the paper's section 7 passage (1000 m along the centre line y = 200 m of a 400 m wide
fairway, V = 10 m/s, 200 steps of 0.5 s) and observes range and bearing to every beacon each step.
For each candidate beacon layout the range-bearing EKF-SLAM of sections 3-5 is propagated and the
layout is scored by the passage means of M_xy = sqrt(P00 + P11) (eq. 28), M_x (eq. 29), M_y (eq. 30).

Everything here is vectorised over configurations: the filter runs all layouts of a block at once
(numpy, matrices stored (n, n, C) so every entry is a contiguous vector over layouts; no Python loop
over layouts). The sparsity of G (eq. 19) and H (eq. 25) is exploited: the prediction is a rank-1
shear plus the 3x3 motion noise, every correction a rank-2 update built from H's five non-zero
columns. Linearised on the true track (the default), G, W, R and H do not depend on the noise
draw, so neither does P nor M_xy: each layout's score is deterministic and the search needs no
Monte Carlo. That case also has a compiled kernel (:mod:`graphnav.beacons._fast`, numba, the same
algorithm with the layouts on the SIMD axis), used when numba is importable (``backend="auto"``).
The single-configuration reference with dense matrices, exactly as the paper writes them
(Joseph form), is :class:`graphnav.estimators.ekf_slam.EkfSlam`; ``tests/beacons/test_beacon_layout.py``
checks the two agree, and that GTSAM's iSAM2 marginals (:mod:`graphnav.beacons.layout_graph`) agree.

Choices the paper leaves open are explicit fields of :class:`Choices` (see docs/beacon-layout.md).
"""

from __future__ import annotations

import importlib
from dataclasses import asdict, dataclass
from itertools import product
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import require
from ..geometry import wrap_angle


@dataclass(frozen=True)
class Fairway:
    """Section 7 set-up. Track along +x from ``start``; angles in radians."""

    length: float = 1000.0
    width: float = 400.0
    track_y: float = 200.0
    v: float = 10.0
    dt: float = 0.5
    steps: int = 200
    sigma_v: float = 0.5
    sigma_rot: float = float(np.radians(0.1))
    sigma_range: float = 0.5
    sigma_bearing: float = float(np.radians(0.5))

    @property
    def start(self) -> NDArray[np.float64]:
        return np.array([0.0, self.track_y, 0.0])

    def track(self) -> NDArray[np.float64]:
        """True poses at k = 0..steps, shape (steps+1, 3): constant V, ROT = 0."""
        k = np.arange(self.steps + 1, dtype=float)
        return np.column_stack([self.v * self.dt * k, np.full_like(k, self.track_y), np.zeros_like(k)])


@dataclass(frozen=True)
class Choices:
    """Modelling choices the paper leaves open (defaults: the sound reading of sections 3-5).

    ``linearize``: ``"truth"`` evaluates G, W, H on the true track and true beacons (the covariance
    then does not depend on the noise draw); ``"estimate"`` runs the actual filter on simulated
    noisy controls/measurements and linearises at its estimate (covariance depends on the draw).
    ``beacon_init``: the beacon's mean before its first update, ``"first-sighting"`` (inverse
    observation from the current estimate, Thrun et al. 2005 table 10.1), ``"zero"`` (eq. 15
    literally: 0, 0) or ``"truth"``. Only matters for ``linearize="estimate"``.
    ``p0_beacon``: the "infinite" beacon variance of eq. 14 [m^2] (the paper: "10^6 m").
    ``p0_cross``: ``"zero"`` (vessel-beacon and beacon-beacon covariances 0, a valid P0) or
    ``"paper"`` (eq. 14 as printed: ``p0_beacon`` in every entry outside the vessel block,
    an indefinite matrix).
    ``w_second``: second column of W (eq. 22), ``"rot"`` = dg/dROT = (0, 0, dt) or ``"theta"`` =
    dg/dtheta as printed = (-V dt sin, V dt cos, 1).
    ``seed``: noise seed for ``linearize="estimate"`` (each layout gets its own stream, a function
    of the seed and the layout only, so results do not depend on batching).
    """

    linearize: str = "truth"
    beacon_init: str = "first-sighting"
    p0_beacon: float = 1e6
    p0_cross: str = "zero"
    w_second: str = "rot"
    seed: int = 0

    def __post_init__(self) -> None:
        allowed = {"linearize": ("truth", "estimate"), "beacon_init": ("first-sighting", "zero", "truth"),
                   "p0_cross": ("zero", "paper"), "w_second": ("rot", "theta")}
        for k, vals in allowed.items():
            if getattr(self, k) not in vals:
                raise ValueError(f"Choices.{k} must be one of {vals}, got {getattr(self, k)!r}")


# --------------------------------------------------------------------------------------------------
# search grids (section 6-7)

def grid(beacons: int) -> NDArray[np.float64]:
    """All layouts of one search, shape (C, beacons, 2).

    1 beacon: 10 m grid, x in 0..990, y in 0..190 or 210..400 (4,000); 2 beacons: 50 m grid, one
    beacon per side, x in 0..950, y1 in 0..150, y2 in 205..355 (6,400); 4 beacons: 100 m grid,
    one per quadrant, x in 0..400 / 500..900, y in {0, 100} / {205, 305} (10,000). The paper gives
    the ranges and steps, not the grid origins; these reproduce its counts and its Table 1 layouts.
    """
    if beacons == 1:
        xs = np.arange(0.0, 1000.0, 10.0)
        ys = np.concatenate([np.arange(0.0, 196.0, 10.0), np.arange(210.0, 401.0, 10.0)])
        return np.array([[[x, y]] for x, y in product(xs, ys)])
    if beacons == 2:
        xs = np.arange(0.0, 1000.0, 50.0)
        side1 = [(x, y) for x in xs for y in np.arange(0.0, 196.0, 50.0)]
        side2 = [(x, y) for x in xs for y in np.arange(205.0, 401.0, 50.0)]
        return np.array([[a, b] for a, b in product(side1, side2)])
    if beacons == 4:
        lo, hi = np.arange(0.0, 500.0, 100.0), np.arange(500.0, 1000.0, 100.0)
        ys_lo, ys_hi = np.arange(0.0, 196.0, 100.0), np.arange(205.0, 401.0, 100.0)
        sides = ((lo, ys_lo), (hi, ys_lo), (lo, ys_hi), (hi, ys_hi))
        quads = [[(x, y) for x in xs for y in ys] for xs, ys in sides]
        return np.array([list(q) for q in product(*quads)])
    raise ValueError(f"the paper's searches have 1, 2 or 4 beacons, not {beacons}")


# --------------------------------------------------------------------------------------------------
# noise (shared with the fairway simulator so a simulated log and the batched filter see one draw)

def layout_rng(seed: int, layout: NDArray[np.float64]) -> np.random.Generator:
    """The random stream of one layout: a function of ``seed`` and the layout (decimetres) only."""
    key = [int(seed) & 0xFFFFFFFF] + [int(round(v * 10.0)) & 0xFFFFFFFF for v in np.ravel(layout)]
    return np.random.default_rng(key)


def draw_noise(fw: Fairway, layout: NDArray[np.float64], seed: int) -> dict[str, NDArray[np.float64]]:
    """Control and measurement errors of one passage (eq. 4-5, 7-8): ``dv``, ``drot`` (steps,),
    ``dr``, ``db`` (steps, beacons)."""
    rng = layout_rng(seed, layout)
    n = len(layout)
    return {"dv": rng.normal(0.0, fw.sigma_v, fw.steps), "drot": rng.normal(0.0, fw.sigma_rot, fw.steps),
            "dr": rng.normal(0.0, fw.sigma_range, (fw.steps, n)),
            "db": rng.normal(0.0, fw.sigma_bearing, (fw.steps, n))}


# --------------------------------------------------------------------------------------------------
# the batched filter

def initial_covariance(n_beacons: int, ch: Choices) -> NDArray[np.float64]:
    """P0 of eq. 14: zero vessel block; ``p0_beacon`` on the beacon diagonal (and, with
    ``p0_cross="paper"``, in every entry outside the vessel block)."""
    n = 3 + 2 * n_beacons
    if ch.p0_cross == "paper":
        p0 = np.full((n, n), ch.p0_beacon)
        p0[:3, :3] = 0.0
    else:
        p0 = np.zeros((n, n))
        p0[3:, 3:] = np.eye(n - 3) * ch.p0_beacon
    return p0


def propagate(layouts: NDArray[np.float64], fw: Fairway = Fairway(), ch: Choices = Choices(),
              *, keep_state: bool = False, block: int | None = None,
              seeds: NDArray[np.int64] | None = None, backend: str = "auto") -> dict[str, NDArray[np.float64]]:
    """Run the EKF-SLAM of eq. 9-27 over every layout at once (in cache-sized blocks of layouts).

    ``layouts`` (C, B, 2) beacon positions. Returns ``mx``, ``my`` (C, steps): sqrt(P00), sqrt(P11)
    after the correction of steps 1..steps; with ``keep_state`` also ``P`` (C, n, n) and ``x``
    (C, n) after the last step (with ``linearize="truth"``: the true state, the linearisation
    point). ``seeds`` (C,) overrides ``ch.seed`` per layout (Monte Carlo over
    draws of one layout). Beacons are updated one at a time (K is (3+2i) x 2, eq. 24), in
    layout order; each correction is the rank-2 update P - K A^T with A = P H^T (K optimal, so it
    equals the Joseph form to rounding; the dense reference uses the Joseph form and the tests
    compare the two).

    ``backend``: ``"numba"`` runs the compiled kernel of :mod:`graphnav.beacons._fast` (the same
    figures to ~1e-9 relative, ~7x less CPU; truth linearisation only, where the covariance does
    not depend on the noise draw, so ``seeds`` do not matter; ``block`` is the numpy path's),
    ``"numpy"`` the vectorised numpy filter below, ``"auto"`` numba when it is importable and
    ``ch.linearize == "truth"``, else numpy.
    """
    layouts = np.asarray(layouts, dtype=float)
    if layouts.ndim != 3 or layouts.shape[2] != 2:
        raise ValueError(f"layouts must have shape (C, beacons, 2), got {layouts.shape}")
    kernel = _fast_kernel(backend, ch)
    if kernel is not None:
        return _propagate_compiled(kernel, layouts, fw, ch, keep_state)
    seeds = np.full(len(layouts), ch.seed) if seeds is None else np.asarray(seeds)
    n = 3 + 2 * layouts.shape[1]
    block = block or max(256, 65536 // (n * n))  # P of one block ~0.5 MB: stays in cache
    parts = [_propagate_block(layouts[i:i + block], fw, ch, keep_state, seeds[i:i + block])
             for i in range(0, len(layouts), block)]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def _fast_kernel(backend: str, ch: Choices) -> Any:
    """The compiled kernel when ``backend`` asks for it (or ``"auto"`` and it applies), else None."""
    if backend not in ("auto", "numba", "numpy"):
        raise ValueError(f"unknown backend {backend!r}; known: auto, numba, numpy")
    if backend == "numpy" or (backend == "auto" and ch.linearize != "truth"):
        return None
    if ch.linearize != "truth":
        raise ValueError('backend="numba" covers linearize="truth" only (the covariance analysis); '
                         'use backend="numpy" for linearize="estimate"')
    try:
        return importlib.import_module(f"{__package__}._fast")
    except ImportError:
        if backend == "numba":
            require("numba", 'backend "numba"')
            raise
        return None


def motion_terms(fw: Fairway, ch: Choices) -> tuple[NDArray, NDArray, NDArray]:
    """On the true track: G's entries G[0, 2], G[1, 2] (eq. 19) per step, shape (steps,) each, and
    R = W M W^T (eq. 20-23) per step, shape (steps, 3, 3). The same for every layout."""
    th = fw.track()[:-1, 2]
    c, s = np.cos(th), np.sin(th)
    ga, gb = -s * fw.dt * fw.v, c * fw.dt * fw.v
    w0 = np.column_stack([c * fw.dt, s * fw.dt, np.zeros_like(th)])
    if ch.w_second == "rot":
        w1 = np.column_stack([np.zeros_like(th), np.zeros_like(th), np.full_like(th, fw.dt)])
    else:
        w1 = np.column_stack([ga, gb, np.ones_like(th)])
    rq = fw.sigma_v**2 * w0[:, :, None] * w0[:, None, :] + fw.sigma_rot**2 * w1[:, :, None] * w1[:, None, :]
    return ga, gb, rq


def _propagate_compiled(kernel: Any, layouts: NDArray[np.float64], fw: Fairway, ch: Choices,
                        keep_state: bool) -> dict[str, NDArray[np.float64]]:
    ga, gb, rq = motion_terms(fw, ch)
    mx, my, P = kernel.propagate_truth(
        np.ascontiguousarray(layouts[:, :, 0]), np.ascontiguousarray(layouts[:, :, 1]), fw.track(),
        initial_covariance(layouts.shape[1], ch), ga, gb, rq, fw.sigma_range**2, fw.sigma_bearing**2,
        keep_state, kernel.WIDTH)
    out = {"mx": mx, "my": my}
    if keep_state:
        x = np.zeros((len(layouts), P.shape[1]))
        x[:, :3] = fw.track()[-1]        # linearised on the truth: the state is the true one
        x[:, 3:] = layouts.reshape(len(layouts), -1)
        out["P"], out["x"] = P, x
    return out


class _BlockFilter:
    """The numpy EKF-SLAM of eq. 18-27 over a block of C layouts at once: P is (n, n, C), so every
    matrix entry is a contiguous vector over layouts. With ``linearize="estimate"`` the state ``x``
    (n, C) is estimated from each layout's own noise draw; on the truth only P is propagated."""

    def __init__(self, layouts: NDArray[np.float64], fw: Fairway, ch: Choices, seeds: NDArray) -> None:
        C, B, _ = layouts.shape
        n = 3 + 2 * B
        self.fw, self.ch, self.track = fw, ch, fw.track()
        self.P = np.repeat(initial_covariance(B, ch)[:, :, None], C, axis=2)
        self.tmp = np.empty_like(self.P)
        self.est = ch.linearize == "estimate"
        self.x = np.zeros((n, C))
        self.x[:3] = fw.start[:, None]
        if self.est:
            noise = [draw_noise(fw, lay, int(sd)) for lay, sd in zip(layouts, seeds, strict=True)]
            self.dv = np.array([d["dv"] for d in noise]).T               # (steps, C)
            self.drot = np.array([d["drot"] for d in noise]).T
            self.dr = np.array([d["dr"] for d in noise]).transpose(1, 2, 0)  # (steps, B, C)
            self.db = np.array([d["db"] for d in noise]).transpose(1, 2, 0)
            if ch.beacon_init == "truth":
                self.x[3:] = layouts.reshape(C, -1).T
        self.bx, self.by = layouts[:, :, 0].T, layouts[:, :, 1].T                # (B, C)
        self.seen = np.zeros(B, dtype=bool)

    def predict(self, k: int) -> None:
        """Eq. 18-23 for step ``k``: G = I + g e_theta^T (rows/cols 0, 1), R = W M W^T."""
        fw, P, x, C = self.fw, self.P, self.x, self.x.shape[1]
        dt = fw.dt
        if self.est:
            v = fw.v + self.dv[k - 1]
            th = x[2].copy()
            c, s = np.cos(th), np.sin(th)
            zero, one = np.zeros(C), np.ones(C)
        else:  # on the true track G and R are the same for every layout: scalars, not vectors
            v, th = fw.v, self.track[k - 1, 2]
            c, s = float(np.cos(th)), float(np.sin(th))
            zero, one = 0.0, 1.0
        ga, gb = -s * dt * v, c * dt * v
        P[0] += ga * P[2]
        P[1] += gb * P[2]
        P[:, 0] += ga * P[:, 2]
        P[:, 1] += gb * P[:, 2]
        w0 = (c * dt, s * dt, zero)
        w1 = (zero, zero, dt * one) if self.ch.w_second == "rot" else (ga, gb, one)
        m_v, m_rot = fw.sigma_v**2, fw.sigma_rot**2
        for a in range(3):
            for e in range(a, 3):
                r = m_v * w0[a] * w0[e] + m_rot * w1[a] * w1[e]
                P[a, e] += r
                if e != a:
                    P[e, a] += r
        if self.est:
            x[0] += v * dt * c
            x[1] += v * dt * s
            x[2] = wrap_angle(x[2] + self.drot[k - 1] * dt)

    def correct(self, k: int, j: int) -> None:
        """Eq. 24-27 for beacon ``j`` at step ``k``."""
        P, x, track, b = self.P, self.x, self.track, 3 + 2 * j
        n, C = x.shape
        if self.est:
            tdx, tdy = self.bx[j] - track[k, 0], self.by[j] - track[k, 1]
            z_r = np.hypot(tdx, tdy) + self.dr[k - 1, j]
            z_b = wrap_angle(np.arctan2(tdy, tdx) - track[k, 2] + self.db[k - 1, j])
            if not self.seen[j] and self.ch.beacon_init == "first-sighting":
                x[b] = x[0] + z_r * np.cos(z_b + x[2])
                x[b + 1] = x[1] + z_r * np.sin(z_b + x[2])
            px, py, pth, lx, ly = x[0], x[1], x[2], x[b], x[b + 1]
        else:
            px, py, pth, lx, ly = track[k, 0], track[k, 1], track[k, 2], self.bx[j], self.by[j]
        dx, dy = lx - px, ly - py
        q = dx * dx + dy * dy
        r = np.sqrt(q)
        # H (eq. 25): the beacon columns are minus the position columns, so H P^T needs only
        # D = P[:, (x, y)] - P[:, (xb, yb)] and P[:, theta]
        hx0, hy0, hx1, hy1 = -dx / r, -dy / r, dy / q, -dx / q
        Dx = P[:, 0] - P[:, b]
        Dy = P[:, 1] - P[:, b + 1]
        A = np.empty((n, 2, C))                                             # P H^T
        A[:, 0] = hx0 * Dx + hy0 * Dy
        A[:, 1] = hx1 * Dx + hy1 * Dy - P[:, 2]
        ex, ey = A[0] - A[b], A[1] - A[b + 1]                               # (2, C)
        s00 = hx0 * ex[0] + hy0 * ey[0] + self.fw.sigma_range**2
        s01 = hx0 * ex[1] + hy0 * ey[1]
        s11 = hx1 * ex[1] + hy1 * ey[1] - A[2, 1] + self.fw.sigma_bearing**2
        det = s00 * s11 - s01 * s01
        i00, i01, i11 = s11 / det, -s01 / det, s00 / det
        K = np.empty((n, 2, C))                                             # eq. 24
        K[:, 0] = A[:, 0] * i00 + A[:, 1] * i01
        K[:, 1] = A[:, 0] * i01 + A[:, 1] * i11
        # P -= K H P = sum_m K_m (x) A_m (rank 2; K is optimal, so this equals the Joseph
        # form up to rounding: see the dense Joseph-form reference in ekf_slam.EkfSlam)
        np.einsum("ikc,jkc->ijc", K, A, out=self.tmp)
        P -= self.tmp
        if self.est:
            nu0 = z_r - r
            nu1 = wrap_angle(z_b - (np.arctan2(dy, dx) - pth))
            x += K[:, 0] * nu0 + K[:, 1] * nu1
            x[2] = wrap_angle(x[2])
        self.seen[j] = True


def _propagate_block(layouts: NDArray[np.float64], fw: Fairway, ch: Choices, keep_state: bool,
                     seeds: NDArray) -> dict[str, NDArray[np.float64]]:
    """:func:`propagate`'s numpy path over one block of layouts (:class:`_BlockFilter`)."""
    C, B, _ = layouts.shape
    f = _BlockFilter(layouts, fw, ch, seeds)
    mx = np.empty((fw.steps, C))
    my = np.empty((fw.steps, C))
    for k in range(1, fw.steps + 1):
        f.predict(k)
        for j in range(B):  # corrections, one beacon at a time
            f.correct(k, j)
        mx[k - 1] = np.sqrt(np.maximum(f.P[0, 0], 0.0))
        my[k - 1] = np.sqrt(np.maximum(f.P[1, 1], 0.0))
    out = {"mx": mx.T.copy(), "my": my.T.copy()}
    if keep_state:
        x = f.x
        if not f.est:  # nothing is estimated: report the linearisation point (the truth)
            x[:3] = f.track[-1][:, None]
            x[3:] = layouts.reshape(C, -1).T
        out["P"], out["x"] = f.P.transpose(2, 0, 1).copy(), x.T.copy()
    return out


def score(layouts: NDArray[np.float64], fw: Fairway = Fairway(),
          ch: Choices = Choices(), backend: str = "auto") -> NDArray[np.float64]:
    """Passage means per layout, shape (C, 3): mean M_xy (eq. 28), mean M_x (29), mean M_y (30).

    M_xy is computed per step, then averaged (mean of sqrt, not sqrt of means).
    """
    o = propagate(layouts, fw, ch, backend=backend)
    mxy = np.sqrt(o["mx"] ** 2 + o["my"] ** 2)
    return np.column_stack([mxy.mean(axis=1), o["mx"].mean(axis=1), o["my"].mean(axis=1)])


# --------------------------------------------------------------------------------------------------
# the search: a sweep task per chunk of layouts (picklable, for graphnav.evaluation.sweep)

def score_chunk(task: dict[str, Any]) -> dict[str, Any]:
    """Sweep task: ``{"layouts": [[[x, y], ...], ...], "fairway": {...}, "choices": {...},
    "backend": "auto"}`` -> ``{"scores": [[mean_mxy, mean_mx, mean_my], ...]}`` in the same order."""
    fw = Fairway(**task.get("fairway", {}))
    ch = Choices(**task.get("choices", {}))
    lay = np.asarray(task["layouts"], dtype=float)
    return {"scores": score(lay, fw, ch, backend=task.get("backend", "auto")).tolist()}


def resolve_backend(backend: str, ch: Choices = Choices()) -> str:
    """The filter :func:`propagate` runs for ``backend``: ``"numba"`` or ``"numpy"``."""
    return "numba" if _fast_kernel(backend, ch) is not None else "numpy"


def layout_cost_s(beacons: int, backend: str, fw: Fairway = Fairway()) -> float:
    """Rough CPU seconds to score one layout (for the sweep's ``scheduler="auto"``). Measured on
    the shared 2-core test machine: 10 / 20 / 53 us (numba) and 65 / 133 / 400 us (numpy) for
    1 / 2 / 4 beacons; modelled, on the high side, as a + b * steps * beacons * n^2 (the rank-2
    updates' O(n^2) work)."""
    n = 3 + 2 * beacons
    work = fw.steps / 200.0 * beacons * n * n
    return 2e-5 + 1.1e-7 * work if backend == "numba" else 1e-4 + 1.0e-6 * work


def chunk_tasks(layouts: NDArray[np.float64], chunk: int, fw: Fairway = Fairway(), ch: Choices = Choices(),
                extra: dict[str, Any] | None = None) -> list[dict[str, Any]]:
    """Split a search into sweep tasks of ``chunk`` layouts each (each task carries its own key)."""
    out = []
    for i in range(0, len(layouts), chunk):
        out.append({"key": f"{i}", "start": i, "layouts": layouts[i:i + chunk].tolist(),
                    "fairway": asdict(fw), "choices": asdict(ch), **(extra or {})})
    return out


def summarize_search(layouts: NDArray[np.float64], scores: NDArray[np.float64]) -> dict[str, Any]:
    """The issue's JSON fields (without ``criterion``/``wall_s``) from per-layout scores (C, 3)."""
    i = int(np.argmin(scores[:, 0]))
    return {"beacons": int(layouts.shape[1]), "configs": int(len(layouts)),
            "best": {"layout": layouts[i].tolist(), "mean_mxy": float(scores[i, 0]),
                     "mean_mx": float(scores[i, 1]), "mean_my": float(scores[i, 2])},
            "worst_mean_mxy": float(scores[:, 0].max()),
            "mean_over_configs_mxy": float(scores[:, 0].mean()),
            "mean_over_configs_mx": float(scores[:, 1].mean()),
            "mean_over_configs_my": float(scores[:, 2].mean())}


PAPER_TABLE1: dict[int, dict[str, Any]] = {
    1: {"layout": [[650.0, 370.0]], "min": 3.46, "min_mx": 1.74, "min_my": 2.87, "max": 58.07, "mean": 9.06,
        "mean_mx": 2.0, "mean_my": 8.58, "configs": 4000},
    2: {"layout": [[750.0, 0.0], [150.0, 355.0]], "min": 2.32, "min_mx": 0.62, "min_my": 2.23, "max": 16.79,
        "mean": 3.78, "mean_mx": 0.6, "mean_my": 3.71, "configs": 6400},
    4: {"layout": None, "min": 0.54, "min_mx": 0.27, "min_my": 0.47, "max": 2.15, "mean": 0.94,
        "mean_mx": 0.27, "mean_my": 0.89, "configs": 10000},
}
"""Table 1 of the paper (the 4-beacon layout is garbled in the source text)."""
