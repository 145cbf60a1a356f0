"""Trajectory metrics: ATE, RPE, position NEES and the movement parameters (SOG, COG, ROT, heading).

Pure numerics on :class:`Trajectory` objects. ATE/RPE follow evo's definitions (translation
part, planar poses) and are cross-checked against evo in the tests.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geometry import se2_between, se2_compose, wrap_angle
from ..trajectory import Trajectory


def associate(est: Trajectory, ref: Trajectory, max_dt: float = 0.02) -> tuple[NDArray, NDArray]:
    """Index pairs ``(i_est, i_ref)`` of nearest time stamps within ``max_dt`` seconds.

    Like evo's ``sync.associate_trajectories``: each reference stamp takes the nearest estimate
    stamp; pairs farther apart than ``max_dt`` are dropped; an estimate is used at most once.
    """
    if len(est) == 0 or len(ref) == 0:
        return np.zeros(0, int), np.zeros(0, int)
    j = np.searchsorted(est.t, ref.t)
    j0 = np.clip(j - 1, 0, len(est) - 1)
    j1 = np.clip(j, 0, len(est) - 1)
    pick = np.where(np.abs(est.t[j0] - ref.t) <= np.abs(est.t[j1] - ref.t), j0, j1)
    ok = np.abs(est.t[pick] - ref.t) <= max_dt
    i_est, i_ref = pick[ok], np.nonzero(ok)[0]
    _, first = np.unique(i_est, return_index=True)
    return i_est[first], i_ref[first]


def _stats(e: NDArray) -> dict[str, float]:
    if e.size == 0:
        nan = float("nan")
        return {"rmse": nan, "mean": nan, "median": nan, "std": nan, "max": nan, "n": 0}
    return {
        "rmse": float(np.sqrt(np.mean(e**2))),
        "mean": float(np.mean(e)),
        "median": float(np.median(e)),
        "std": float(np.std(e)),
        "max": float(np.max(e)),
        "n": int(e.size),
    }


def umeyama_se2(src: NDArray, dst: NDArray) -> NDArray:
    """The SE(2) pose ``(x, y, yaw)`` that best maps points ``src`` onto ``dst`` (least squares).

    Umeyama (1991) without scale, in 2D: rotation from the SVD of the cross-covariance.
    """
    ms, md = src.mean(0), dst.mean(0)
    h = (dst - md).T @ (src - ms)
    u, _, vt = np.linalg.svd(h)
    s = np.diag([1.0, np.sign(np.linalg.det(u @ vt))])
    r = u @ s @ vt
    t = md - r @ ms
    return np.array([t[0], t[1], np.arctan2(r[1, 0], r[0, 0])])


def ate(est: Trajectory, ref: Trajectory, *, align: bool = False, max_dt: float = 0.02) -> dict[str, float]:
    """Absolute trajectory (position) error statistics in metres.

    With ``align`` the estimate is first moved by the SE(2) transform that best fits it to the
    reference (evo's ``--align``); without it, errors are in the log's own frame.
    """
    ie, ir = associate(est, ref, max_dt)
    p = est.poses[ie]
    q = ref.poses[ir]
    if align and len(p) >= 2:
        p = se2_compose(umeyama_se2(p[:, :2], q[:, :2]), p)
    return _stats(np.hypot(p[:, 0] - q[:, 0], p[:, 1] - q[:, 1]))


def heading_error(est: Trajectory, ref: Trajectory, *, max_dt: float = 0.02) -> dict[str, float]:
    """Absolute heading (yaw) error statistics in degrees."""
    ie, ir = associate(est, ref, max_dt)
    return _stats(np.degrees(np.abs(wrap_angle(est.yaw[ie] - ref.yaw[ir]))))


def position_nees(est: Trajectory, ref: Trajectory, *, max_dt: float = 0.02) -> dict[str, Any] | None:
    """Position NEES of the estimate's own covariance against the reference, per associated pair.

    ``nees_k = e_k^T P_k^-1 e_k`` with ``e_k`` the (x, y) error and ``P_k`` the estimate's 2x2
    position covariance (Bar-Shalom, Li & Kirubarajan 2001, sec. 5.4); a consistent estimator has
    ``E[nees] = 2`` (chi-square, 2 dof). The pairs are :func:`associate`'s, as for :func:`ate`.
    ``None`` when the estimate carries no covariance. Pairs whose ``P_k`` is not positive definite
    (or not finite) are dropped; ``dropped`` counts them. Returns ``t``, ``nees``, ``i_est``, ``dropped``.
    """
    if est.cov is None:
        return None
    ie, ir = associate(est, ref, max_dt)
    c = est.cov[ie]
    a, b, d = c[:, 0, 0], 0.5 * (c[:, 0, 1] + c[:, 1, 0]), c[:, 1, 1]
    det = a * d - b * b
    ok = np.isfinite(a) & np.isfinite(b) & np.isfinite(d) & (a > 0) & (det > 1e-12 * np.maximum(a * d, 1e-300))
    ex = est.x[ie] - ref.x[ir]
    ey = est.y[ie] - ref.y[ir]
    # the 2x2 inverse in closed form: [d, -b; -b, a] / det
    with np.errstate(divide="ignore", invalid="ignore"):
        n = (d * ex * ex - 2.0 * b * ex * ey + a * ey * ey) / det
    return {"t": est.t[ie][ok], "nees": n[ok], "i_est": ie[ok], "dropped": int(np.count_nonzero(~ok))}


def nees_stats(est: Trajectory, ref: Trajectory, *, max_dt: float = 0.02) -> dict[str, float] | None:
    """Statistics of :func:`position_nees` (``mean``, ``median``, ``max``, ``n``) plus ``in95``, the
    fraction of samples inside the two-sided 95 % chi-square(2) interval; ``None`` without covariance."""
    r = position_nees(est, ref, max_dt=max_dt)
    if r is None:
        return None
    v = r["nees"]
    lo, hi = -2.0 * np.log1p(-0.025), -2.0 * np.log(0.025)  # chi2(2).ppf: -2 ln(1 - p), closed form
    nan = float("nan")
    return {"mean": float(np.mean(v)) if v.size else nan, "median": float(np.median(v)) if v.size else nan,
            "max": float(np.max(v)) if v.size else nan, "n": int(v.size), "dropped": r["dropped"],
            "in95": float(np.mean((v >= lo) & (v <= hi))) if v.size else nan}


def rpe(
    est: Trajectory, ref: Trajectory, *, delta: int = 1, all_pairs: bool = False, max_dt: float = 0.02
) -> dict[str, dict[str, float]]:
    """Relative pose error over ``delta`` associated poses (evo ``rpe`` with ``--delta_unit f``).

    Returns ``{"trans": stats [m], "rot": stats [deg]}``. ``all_pairs=False`` uses the
    non-overlapping pairs ``(0, d), (d, 2d), ...`` as evo does by default.
    """
    ie, ir = associate(est, ref, max_dt)
    p, q = est.poses[ie], ref.poses[ir]
    n = len(p)
    if n <= delta:
        return {"trans": _stats(np.zeros(0)), "rot": _stats(np.zeros(0))}
    i = np.arange(0, n - delta) if all_pairs else np.arange(0, n - delta, delta)
    j = i + delta
    e = se2_between(se2_between(q[i], q[j]), se2_between(p[i], p[j]))
    return {
        "trans": _stats(np.hypot(e[:, 0], e[:, 1])),
        "rot": _stats(np.degrees(np.abs(wrap_angle(e[:, 2])))),
    }


def movement(traj: Trajectory) -> dict[str, NDArray]:
    """Movement parameters between consecutive poses (the weighted-ICP paper, eq. 23-25).

    Returns arrays of length N-1 stamped at the interval midpoints ``t``: ``sog`` [m/s],
    ``cog`` [rad, CCW from east; the nautical COG is ``yaw_to_heading_deg(cog)``],
    ``rot`` [rad/s], ``hdg`` [rad, the yaw at the interval start].
    """
    d = np.diff(traj.poses, axis=0)
    dt = np.diff(traj.t)
    dt = np.where(dt > 0, dt, np.nan)
    return {
        "t": 0.5 * (traj.t[1:] + traj.t[:-1]),
        "sog": np.hypot(d[:, 0], d[:, 1]) / dt,
        "cog": np.arctan2(d[:, 1], d[:, 0]),
        "rot": wrap_angle(d[:, 2]) / dt,
        "hdg": traj.yaw[:-1].copy(),
    }


#: the interval [s] over which run and compare score SOG, COG and ROT (:func:`thinned`): about the same for
#: every estimator, whatever its output rate
MOVEMENT_DT_S = 1.0


def thinned(est: Trajectory, ref: Trajectory, dt: float, *, max_dt: float = 0.02) -> tuple[Trajectory, Trajectory]:
    """The time-associated pairs of :func:`paired`, thinned to about ``dt`` apart: from the first pair, each
    next one is the later pair whose time is nearest to the previous kept time plus ``dt``. Nothing is
    interpolated: the intervals are the estimate's own poses (and the reference's at the same times), as
    close to ``dt`` as its output allows. Movement parameters then span comparable intervals for every
    estimator: differencing a 100 Hz filter's poses over 0.01-0.1 s scores its jitter, and interpolating a
    smoother's ~1 s keyframes onto a common clock scores the interpolation at every turn's onset."""
    if dt <= 0:
        raise ValueError(f"thinned needs dt > 0, got {dt}")
    e, r = paired(est, ref, max_dt)
    t = e.t
    keep = [0] if len(t) else []
    while keep:
        i = keep[-1]
        j = int(np.searchsorted(t, t[i] + dt))
        cand = [k for k in (j - 1, j) if i < k < len(t)]
        if not cand:
            break
        keep.append(min(cand, key=lambda k: abs(t[k] - t[i] - dt)))
    k = np.asarray(keep, int)
    cov = None if e.cov is None else e.cov[k]
    return Trajectory(e.t[k], e.poses[k], cov), Trajectory(r.t[k], r.poses[k])


def rpe_over(est: Trajectory, ref: Trajectory, dt: float, *, max_dt: float = 0.02) -> dict[str, dict[str, float]]:
    """Relative pose error between consecutive pairs of :func:`thinned`: the estimate's own poses about
    ``dt`` seconds apart, whatever its output rate (:func:`rpe` counts poses: one filter step of 0.01-0.1 s
    against one smoother keyframe of ~1 s); an interval over ``2 dt`` (a hole) is not scored.
    Returns ``{"trans": stats [m], "rot": stats [deg]}``."""
    e, r, spans = _spans(est, ref, dt, max_dt)
    i = np.flatnonzero(spans)
    err = se2_between(se2_between(r.poses[i], r.poses[i + 1]), se2_between(e.poses[i], e.poses[i + 1]))
    return {"trans": _stats(np.hypot(err[:, 0], err[:, 1])), "rot": _stats(np.degrees(np.abs(wrap_angle(err[:, 2]))))}


def _spans(est: Trajectory, ref: Trajectory, dt: float, max_dt: float) -> tuple[Trajectory, Trajectory, NDArray]:
    """The pairs of :func:`thinned` and, per interval between consecutive ones, whether it is scored: not when
    longer than ``2 dt`` (across a hole in the estimate)."""
    e, r = thinned(est, ref, dt, max_dt=max_dt)
    return e, r, np.diff(e.t) <= 2 * dt


def _movements(est: Trajectory, ref: Trajectory, dt: float | None, max_dt: float) -> tuple[dict, dict]:
    """:func:`movement` of the estimate and the reference over the same intervals (:func:`movement_errors`);
    with ``dt``, the intervals of :func:`_spans`, an unscored one NaN."""
    if dt is None:
        e, r = paired(est, ref, max_dt)
        return movement(e), movement(r)
    e, r, spans = _spans(est, ref, dt, max_dt)
    a, b = movement(e), movement(r)
    for k in ("sog", "cog", "rot"):
        a[k][~spans] = np.nan
    return a, b


def movement_errors(
    est: Trajectory, ref: Trajectory, *, min_speed: float = 0.2, max_dt: float = 0.02,
    windows: list[tuple[float, float]] | None = None, dt: float | None = None,
) -> dict[str, dict[str, float]]:
    """Signed errors of SOG [m/s], COG [deg], ROT [deg/s] and heading [deg], estimate minus reference.

    Both trajectories are first associated by time, so the parameters are taken over the same
    intervals: between consecutive associated poses (the weighted-ICP paper's scan to scan), or with
    ``dt`` between the pairs of :func:`thinned` (about ``dt`` apart for every estimator). COG is scored
    only where the reference moves faster than ``min_speed``; with ``windows`` (``[(t0, t1), ...]``)
    only the intervals whose midpoint lies inside one. Statistics of signed errors: ``mean``,
    ``std``, ``max`` (of |e|), ``rmse``.
    """
    a, b = _movements(est, ref, dt, max_dt)
    if windows is not None:
        inside = np.zeros(len(b["t"]), bool)
        for t0, t1 in windows:
            inside |= (b["t"] >= t0) & (b["t"] <= t1)
        a = {k: v[inside] for k, v in a.items()}
        b = {k: v[inside] for k, v in b.items()}
    moving = b["sog"] > min_speed

    def signed(e: NDArray) -> dict[str, float]:
        e = e[np.isfinite(e)]
        s = _stats(np.abs(e))
        return {"mean": float(np.mean(e)) if e.size else float("nan"), "std": float(np.std(e)) if e.size
                else float("nan"), "max": s["max"], "rmse": s["rmse"], "n": s["n"]}

    return {
        "sog": signed(a["sog"] - b["sog"]),
        "cog": signed(np.degrees(wrap_angle(a["cog"] - b["cog"]))[moving]),
        "rot": signed(np.degrees(a["rot"] - b["rot"])),
        "hdg": signed(np.degrees(wrap_angle(a["hdg"] - b["hdg"]))),
    }


def event_windows(events: Any) -> dict[str, list[tuple[float, float]]]:
    """A log's ``meta["events"]`` (``[{"kind", "t0", "t1"}, ...]``) -> ``{kind: [(t0, t1), ...]}`` in
    the order given. Entries that are not such a window (no kind, a bound not finite, ``t1 < t0``) are
    left out."""
    out: dict[str, list[tuple[float, float]]] = {}
    for ev in events if isinstance(events, list | tuple) else ():
        if not isinstance(ev, dict) or not isinstance(ev.get("kind"), str) or not ev["kind"]:
            continue
        try:
            t0, t1 = float(ev["t0"]), float(ev["t1"])
        except (KeyError, TypeError, ValueError):
            continue
        if np.isfinite(t0) and np.isfinite(t1) and t1 >= t0:
            out.setdefault(ev["kind"], []).append((t0, t1))
    return out


def window_errors(est: Trajectory, ref: Trajectory, windows: list[tuple[float, float]], *,
                  max_dt: float = 0.02) -> dict[str, float]:
    """Position error statistics (:func:`ate`'s, unaligned) over the pairs of :func:`associate` whose
    reference time lies inside one of ``windows`` (``t0 <= t <= t1``, bounds included). Returns
    ``rmse``, ``max`` [m] and ``n`` (pairs; 0 with NaN figures when none falls inside)."""
    ie, ir = associate(est, ref, max_dt)
    t = ref.t[ir]
    inside = np.zeros(len(t), bool)
    for t0, t1 in windows:
        inside |= (t >= t0) & (t <= t1)
    p, q = est.poses[ie[inside]], ref.poses[ir[inside]]
    s = _stats(np.hypot(p[:, 0] - q[:, 0], p[:, 1] - q[:, 1]))
    return {"rmse": s["rmse"], "max": s["max"], "n": s["n"]}


# -- error series (what the figures draw; the same pairs as the statistics above) --------------------

def paired(est: Trajectory, ref: Trajectory, max_dt: float = 0.02) -> tuple[Trajectory, Trajectory]:
    """The estimate and the reference at the pairs of :func:`associate` (the estimate's covariance kept)."""
    ie, ir = associate(est, ref, max_dt)
    cov = None if est.cov is None else est.cov[ie]
    return Trajectory(est.t[ie], est.poses[ie], cov), Trajectory(ref.t[ir], ref.poses[ir])


def position_errors(est: Trajectory, ref: Trajectory, max_dt: float = 0.02) -> tuple[NDArray, NDArray]:
    """Times and unaligned position errors [m] at the associated pairs (the samples of :func:`ate`)."""
    e, r = paired(est, ref, max_dt)
    return e.t, np.hypot(e.x - r.x, e.y - r.y)


def heading_errors(est: Trajectory, ref: Trajectory, max_dt: float = 0.02) -> tuple[NDArray, NDArray]:
    """Times and signed heading errors [deg] (estimate minus reference, wrapped) at the associated pairs."""
    e, r = paired(est, ref, max_dt)
    return e.t, np.degrees(wrap_angle(e.yaw - r.yaw))


def movement_error_series(est: Trajectory, ref: Trajectory, min_speed: float = 0.2,
                          max_dt: float = 0.02, dt: float | None = None) -> dict[str, NDArray]:
    """Signed errors (estimate minus reference) versus interval mid-time: SOG [m/s], COG [deg] and
    the weighted-ICP paper's ΔCOG [deg] (change of COG between consecutive intervals, Figs. 14-15),
    COG and ΔCOG only while the reference moves faster than ``min_speed``; intervals as in
    :func:`movement_errors` (``dt``: the pairs of :func:`thinned`)."""
    a, b = _movements(est, ref, dt, max_dt)
    moving = b["sog"] > min_speed
    both = moving[1:] & moving[:-1]
    dcog = np.degrees(wrap_angle(np.diff(a["cog"]) - np.diff(b["cog"])))
    cog = np.degrees(wrap_angle(a["cog"] - b["cog"]))
    moving &= np.isfinite(cog)
    both &= np.isfinite(dcog)
    return {"t": a["t"], "sog": a["sog"] - b["sog"],
            "t_cog": a["t"][moving], "cog": cog[moving],
            "t_dcog": a["t"][1:][both], "dcog": dcog[both]}


def gnss_residuals(est: Trajectory, t: NDArray, xy: NDArray, sigma: NDArray, *,
                   max_gap: float = 10.0, bridge: bool = False) -> dict[str, Any]:
    """The estimate against GNSS position fixes, for a log without truth: per fix, ``residual_m`` =
    |fix - estimate| with the estimate at the fix's time: linear between the two estimates around
    it when they are at most ``max_gap`` seconds apart, else the last estimate before it (what the
    estimator had to say then: an estimate made after a gap is never used for a time inside it) --
    unless ``bridge`` (a smoothed track, whose poses on either side of a hole are tied by the motion
    model's factor across it: linear between them is its own answer inside) --, and
    ``nis`` = ``e^T (P + sigma^2 I)^-1 e`` (the normalised innovation, chi-square with 2 degrees of
    freedom when the estimate's covariance ``P`` (the last estimate's; across a bridged hole the
    nearer one's) and the fix's ``sigma`` are honest and the fix is independent of the estimate;
    ``None`` without covariance). Fixes before the first estimate or more than ``max_gap`` after the
    last are not scored; ``i_fix``: those scored."""
    t = np.asarray(t, float)
    xy = np.asarray(xy, float).reshape(-1, 2)
    sigma = np.asarray(sigma, float)
    n = len(est)
    empty = {"t": np.zeros(0), "residual_m": np.zeros(0), "nis": None if est.cov is None else np.zeros(0),
             "i_fix": np.zeros(0, int)}
    if n == 0 or t.size == 0:
        return empty
    j = np.searchsorted(est.t, t, side="right")  # est.t[j-1] <= t < est.t[j]
    ok = (j >= 1) & np.isfinite(xy).all(axis=1) & ((j < n) | (t - est.t[-1] <= max_gap))
    i_fix = np.flatnonzero(ok)
    if not i_fix.size:
        return empty
    t, xy, sigma, prev = t[ok], xy[ok], sigma[ok], j[ok] - 1
    nxt = np.minimum(prev + 1, n - 1)
    close = est.t[nxt] - est.t[prev] <= max_gap
    interp = (nxt > prev) & (close | bridge)
    p = np.column_stack([np.where(interp, np.interp(t, est.t, est.x), est.x[prev]),
                         np.where(interp, np.interp(t, est.t, est.y), est.y[prev])])
    e = xy - p
    out: dict[str, Any] = {"t": t, "residual_m": np.hypot(e[:, 0], e[:, 1]), "nis": None, "i_fix": i_fix}
    if est.cov is not None:
        near = np.where(interp & ~close & (est.t[nxt] - t < t - est.t[prev]), nxt, prev)  # bridged: the nearer
        c = est.cov[near][:, :2, :2] + (sigma ** 2)[:, None, None] * np.eye(2)
        a, b, d = c[:, 0, 0], 0.5 * (c[:, 0, 1] + c[:, 1, 0]), c[:, 1, 1]
        det = a * d - b * b
        with np.errstate(divide="ignore", invalid="ignore"):
            nis = (d * e[:, 0] ** 2 - 2.0 * b * e[:, 0] * e[:, 1] + a * e[:, 1] ** 2) / det
        out["nis"] = nis[np.isfinite(nis) & (det > 0)]
    return out
