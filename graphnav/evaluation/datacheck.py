"""What can be judged in a log without looking at an estimate: gaps in time, jumps in the GNSS
fixes, and the speed log's calibration against the GNSS velocity. ``graphnav info`` lists them; the
comparison report shows them (most useful without truth)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..graph.keyframes import nearest
from ..log import NavLog

#: A gap is a step between consecutive records longer than this many times the median step (and
#: than GAP_MIN_S): a GNSS outage, a logger pause, a lost stretch of file.
GAP_FACTOR = 5.0
GAP_MIN_S = 1.0
GAPS_LISTED = 10
#: A GNSS jump: consecutive fixes farther apart than JUMP_SPEED_FACTOR x the fixes' 95th-percentile
#: speed (+ JUMP_SPEED_FLOOR m/s) covers in the interval, plus JUMP_SIGMAS x the two fixes' sigma.
JUMP_SPEED_FACTOR = 3.0
JUMP_SPEED_FLOOR = 1.0
JUMP_SIGMAS = 5.0
JUMPS_LISTED = 10


def time_gaps(t: np.ndarray) -> dict[str, Any]:
    """The gaps of a sorted time series: steps longer than ``max(GAP_MIN_S, GAP_FACTOR x median
    step)``; their count, total length [s] and the longest :data:`GAPS_LISTED` as ``[t0, t1]``."""
    dt = np.diff(t)
    pos = dt[dt > 0]
    threshold = max(GAP_MIN_S, GAP_FACTOR * float(np.median(pos))) if pos.size else GAP_MIN_S
    idx = np.flatnonzero(dt > threshold)
    longest = idx[np.argsort(-dt[idx], kind="stable")][:GAPS_LISTED]
    return {"threshold_s": threshold, "count": int(idx.size), "total_s": float(dt[idx].sum()),
            "longest": [[float(t[i]), float(t[i + 1])] for i in sorted(longest)]}


def gaps(log: NavLog) -> dict[str, dict[str, Any]]:
    """:func:`time_gaps` of all records together (``"all"``) and of each timed record kind with at
    least 3 records."""
    t_all = np.array([r.t for r in log.records], dtype=float)
    out = {"all": time_gaps(t_all)} if t_all.size >= 3 else {}
    kinds = np.array([r.kind for r in log.records])
    for k in log.counts():
        sel = kinds == k
        if int(sel.sum()) >= 3:
            out[k] = time_gaps(t_all[sel])
    return out


def gnss_jumps(log: NavLog) -> dict[str, Any]:
    """Jumps between consecutive GNSS fixes (see :data:`JUMP_SPEED_FACTOR`): ``count``, the speed
    bound used [m/s] and the largest :data:`JUMPS_LISTED` as ``{"t0", "t1", "distance_m"}``."""
    if len(log.of("gnss")) < 3:
        return {"count": 0, "speed_bound_mps": None, "largest": []}
    c = log.columns("gnss")
    t, x, y, s = (np.asarray(c[k], float) for k in ("t", "x", "y", "sigma"))
    dt, d = np.diff(t), np.hypot(np.diff(x), np.diff(y))
    ok = dt > 0
    v = d[ok] / dt[ok]
    bound = JUMP_SPEED_FACTOR * float(np.percentile(v, 95)) + JUMP_SPEED_FLOOR if v.size else JUMP_SPEED_FLOOR
    allowed = bound * np.maximum(dt, 0.0) + JUMP_SIGMAS * np.hypot(s[1:], s[:-1])
    idx = np.flatnonzero(d > allowed)
    big = sorted(idx[np.argsort(-d[idx], kind="stable")][:JUMPS_LISTED])
    return {"count": int(idx.size), "speed_bound_mps": bound,
            "largest": [{"t0": float(t[i]), "t1": float(t[i + 1]), "distance_m": float(d[i])} for i in big]}


#: The speed log's calibration (:func:`speed_log_scale`): a water-speed reading, a compass heading and a GNSS
#: velocity at most PAIR_S apart make one sample; the samples of each LOG_WINDOW_S, at least LOG_MIN_PAIRS of
#: them through the water faster than LOG_MIN_SPEED, fit one scale, offset and current.
PAIR_S = 1.0
LOG_WINDOW_S = 600.0
LOG_MIN_PAIRS = 60
LOG_MIN_SPEED = 0.5  # [m/s]
#: a window counts when its scale's standard error is below this: its heading varied enough to tell the
#: scale along the bow from a current (on a straight leg the two are one unknown)
LOG_MAX_SE = 0.03


def speed_log_scale(log: NavLog) -> dict[str, Any] | None:
    """The speed log against the GNSS velocity: in each window of :data:`LOG_WINDOW_S`, the least squares of
    ``v_gnss = s v_log R(delta) (cos h, sin h) + c`` over its samples (module constants): the log's scale ``s``
    (above 1: it under-reads), an angle ``delta`` between the compass's bow and the track through the water
    (compass deviation, mean leeway) and a constant current ``c``, linear in ``(s cos delta, s sin delta, c)``.
    ``None`` without water speed, heading and GNSS velocity; else the windows that tell the scale from the
    current (:data:`LOG_MAX_SE`) as ``[t0, s, se, delta_deg, cx, cy, n]``, their inverse-variance mean scale
    and angle, and the spread of the scale between them (the honest uncertainty: a log's error is not white)."""
    if min(len(log.of("water_speed")), len(log.of("heading")), len(log.of("gnss_velocity"))) < LOG_MIN_PAIRS:
        return None
    g, h, w = log.columns("gnss_velocity"), log.columns("heading"), log.columns("water_speed")
    t = np.asarray(g["t"], float)
    ht, wt = np.asarray(h["t"], float), np.asarray(w["t"], float)
    ih, iw = nearest(ht, t), nearest(wt, t)
    okh, okw = np.abs(ht[ih] - t) <= PAIR_S, np.abs(wt[iw] - t) <= PAIR_S
    yaw, v = np.asarray(h["yaw"], float)[ih], np.asarray(w["v"], float)[iw]
    vx, vy = np.asarray(g["vx"], float), np.asarray(g["vy"], float)
    ok = okh & okw & (v > LOG_MIN_SPEED) & np.isfinite(yaw) & np.isfinite(vx) & np.isfinite(vy)
    windows = []
    for a in np.arange(t[0], t[-1], LOG_WINDOW_S):
        m = ok & (t >= a) & (t < a + LOG_WINDOW_S)
        n = int(m.sum())
        if n < LOG_MIN_PAIRS:
            continue
        bx, by = v[m] * np.cos(yaw[m]), v[m] * np.sin(yaw[m])
        A = np.zeros((2 * n, 4))  # unknowns (s cos delta, s sin delta, cx, cy)
        A[0::2, 0], A[0::2, 1], A[0::2, 2] = bx, -by, 1.0
        A[1::2, 0], A[1::2, 1], A[1::2, 3] = by, bx, 1.0
        b = np.empty(2 * n)
        b[0::2], b[1::2] = vx[m], vy[m]
        x, *_ = np.linalg.lstsq(A, b, rcond=None)
        r = A @ x - b
        try:
            cov = float(r @ r) / (2 * n - 4) * np.linalg.inv(A.T @ A)
        except np.linalg.LinAlgError:
            continue
        scale = float(np.hypot(x[0], x[1]))
        u = x[:2] / max(scale, 1e-12)  # the scale's standard error: its gradient along (cos delta, sin delta)
        se = float(np.sqrt(max(u @ cov[:2, :2] @ u, 0.0)))
        if se < LOG_MAX_SE:
            windows.append([float(a), scale, se, float(np.degrees(np.arctan2(x[1], x[0]))), float(x[2]),
                            float(x[3]), n])
    if not windows:
        return {"windows": [], "scale": None, "scale_se": None, "scale_spread": None, "angle_deg": None}
    arr = np.array([row[1:4] for row in windows])
    wgt = 1.0 / arr[:, 1] ** 2
    return {"windows": windows, "scale": float(wgt @ arr[:, 0] / wgt.sum()), "scale_se": float(wgt.sum() ** -0.5),
            "scale_spread": float(np.std(arr[:, 0])) if len(windows) > 1 else None,
            "angle_deg": float(wgt @ arr[:, 2] / wgt.sum())}


def data_checks(log: NavLog) -> dict[str, Any]:
    """``{"gaps": gaps(log), "gnss_jumps": gnss_jumps(log), "speed_log": speed_log_scale(log)}``."""
    return {"gaps": gaps(log), "gnss_jumps": gnss_jumps(log), "speed_log": speed_log_scale(log)}
