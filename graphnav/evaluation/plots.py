"""Comparison figures (matplotlib, Agg): trajectories, position error, error CDF, SOG/COG errors,
covariance ellipses. Each function takes trajectories and writes one PNG; nothing else.

Errors are taken at the estimate/reference pairs of :func:`graphnav.evaluation.metrics.associate` — the same
pairs that the report's numbers use. SOG/COG errors follow the weighted-ICP paper's Figs. 12-15
(difference versus time and its histogram), with COG scored only while the reference moves.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Ellipse, Patch  # noqa: E402
from matplotlib.ticker import FuncFormatter  # noqa: E402

from ..geometry import wrap_angle  # noqa: E402
from ..io.outputs import atomic_path  # noqa: E402
from ..trajectory import Trajectory  # noqa: E402
from .metrics import associate, movement  # noqa: E402

# (face colour, hatch, label): light fills/hatches, so they do not read as an estimator's line colour
EVENT_STYLE = {"gnss_outage": ("#f2d64b", "", "GNSS outage"), "gnss_jump": ("#e8a0a0", "xx", "GNSS jump")}
MAX_DT = 0.02
CDF_FLOOR = 1e-3


def colors(names: Sequence[str]) -> dict[str, Any]:
    cmap = plt.get_cmap("tab10")
    return {n: cmap(i % 10) for i, n in enumerate(names)}


def widths(names: Sequence[str], thick: float = 2.8, thin: float = 1.1) -> dict[str, float]:
    """Line widths decreasing in drawing order: a curve drawn over an identical one (batch and
    isam2 often coincide) leaves the earlier one visible as a coloured outline."""
    n = max(len(names) - 1, 1)
    return {name: thick - (thick - thin) * i / n for i, name in enumerate(names)}


def paired(est: Trajectory, ref: Trajectory, max_dt: float = MAX_DT) -> tuple[Trajectory, Trajectory]:
    ie, ir = associate(est, ref, max_dt)
    return Trajectory(est.t[ie], est.poses[ie]), Trajectory(ref.t[ir], ref.poses[ir])


def position_errors(est: Trajectory, ref: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """Times and unaligned position errors [m] at the associated pairs."""
    e, r = paired(est, ref)
    return e.t, np.hypot(e.x - r.x, e.y - r.y)


def movement_error_series(est: Trajectory, ref: Trajectory, min_speed: float = 0.2) -> dict[str, np.ndarray]:
    """Signed errors (estimate minus reference) versus interval mid-time: SOG [m/s], COG [deg] and
    the weighted-ICP paper's ΔCOG [deg] (change of COG between consecutive intervals, Figs. 14-15),
    COG and ΔCOG only while the reference moves faster than ``min_speed``."""
    e, r = paired(est, ref)
    a, b = movement(e), movement(r)
    moving = b["sog"] > min_speed
    both = moving[1:] & moving[:-1]
    dcog = np.degrees(wrap_angle(np.diff(a["cog"]) - np.diff(b["cog"])))
    return {"t": a["t"], "sog": a["sog"] - b["sog"],
            "t_cog": a["t"][moving], "cog": np.degrees(wrap_angle(a["cog"] - b["cog"]))[moving],
            "t_dcog": a["t"][1:][both], "dcog": dcog[both]}


def _shade_events(ax, events: Sequence[dict], span: tuple[float, float] | None = None) -> list[Patch]:
    """Shade event intervals; one legend handle per kind. Events other than GNSS outages/jumps that
    cover most of ``span`` (a condition of the whole log, e.g. a compass bias) are not shaded."""
    handles, seen = [], set()
    for ev in events or ():
        kind = str(ev.get("kind", "event"))
        if kind not in EVENT_STYLE and span is not None and span[1] > span[0]:
            if (min(ev["t1"], span[1]) - max(ev["t0"], span[0])) > 0.8 * (span[1] - span[0]):
                continue
        color, hatch, label = EVENT_STYLE.get(kind, ("#bbbbbb", "..", kind))
        ax.axvspan(ev["t0"], ev["t1"], facecolor=color, alpha=0.3, hatch=hatch, edgecolor="0.5", lw=0)
        if label not in seen:
            seen.add(label)
            handles.append(Patch(facecolor=color, alpha=0.45, hatch=hatch, edgecolor="0.5", lw=0,
                                 label=label))
    return handles


def _finish(fig, path: Path) -> Path:
    try:
        with atomic_path(path) as tmp:  # a reader never sees half a PNG
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)
    return path


def plot_trajectories(trajs: dict[str, Trajectory], truth: Trajectory | None, path: Path,
                      gnss: np.ndarray | None = None, title: str = "") -> Path:
    fig, ax = plt.subplots(figsize=(8, 7), layout="constrained")
    col = colors(list(trajs))
    if gnss is not None and len(gnss):
        ax.plot(gnss[:, 0], gnss[:, 1], ".", ms=2.5, color="0.6", label="GNSS fixes", zorder=1)
    if truth is not None and len(truth):
        ax.plot(truth.x, truth.y, "-", color="k", lw=1.3, label="truth", zorder=5)  # on top: always visible
        ax.plot(truth.x[0], truth.y[0], "o", color="k", ms=6, zorder=6)
    lw = widths(list(trajs))
    for name, tr in trajs.items():
        ax.plot(tr.x, tr.y, "-", lw=lw[name], color=col[name], label=name, zorder=3)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (east) [m]")
    ax.set_ylabel("y (north) [m]")
    ax.set_title(title or "Trajectories over the truth (start: black dot)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=False)
    return _finish(fig, path)


def plot_position_error(trajs: dict[str, Trajectory], truth: Trajectory, path: Path,
                        events: Sequence[dict] = (), online: dict[str, Trajectory] | None = None) -> Path:
    """Position error versus time; ``online`` estimates (smoothers) dashed in the same colour."""
    fig, ax = plt.subplots(figsize=(10, 4.5), layout="constrained")
    col = colors(list(trajs))
    medians = []
    lw = widths(list(trajs))
    for name, tr in trajs.items():
        t, e = position_errors(tr, truth)
        ax.plot(t, e, "-", lw=lw[name], color=col[name], label=name)
        if len(e):
            medians.append(float(np.median(e)))
        if online and name in online:
            t, e = position_errors(online[name], truth)
            ax.plot(t, e, "--", lw=1.0, color=col[name], label=f"{name} (online)")
    handles = _shade_events(ax, events, (float(truth.t[0]), float(truth.t[-1])) if len(truth) else None)
    # errors spanning orders of magnitude (a diverged estimator beside a smoother): log scale,
    # so the good estimators stay readable
    wide = len(medians) > 1 and max(medians) > 30.0 * max(min(medians), CDF_FLOOR)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("position error [m]" + (" (log scale)" if wide else ""))
    ax.set_title("Position error versus time (unaligned, log frame)")
    if wide:
        ax.set_yscale("log")
        ax.set_ylim(bottom=CDF_FLOOR)
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    else:
        ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    h, _ = ax.get_legend_handles_labels()
    ax.legend(handles=h + handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=False)
    return _finish(fig, path)


def plot_error_cdf(trajs: dict[str, Trajectory], truth: Trajectory, path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(7.5, 4.5), layout="constrained")
    col = colors(list(trajs))
    lw = widths(list(trajs))
    for name, tr in trajs.items():
        _, e = position_errors(tr, truth)
        if len(e):
            s = np.sort(np.maximum(e, CDF_FLOOR))
            ax.step(s, np.arange(1, len(s) + 1) / len(s), where="post", color=col[name], lw=lw[name],
                    label=name)
    ax.set_xscale("log")
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.set_xlabel(f"position error [m] (log scale; below {CDF_FLOOR:g} m shown at {CDF_FLOOR:g})")
    ax.set_ylabel("fraction of poses")
    ax.set_ylim(0, 1.02)
    ax.set_title("Cumulative distribution of the position error")
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=False)
    return _finish(fig, path)


def plot_sog_cog(trajs: dict[str, Trajectory], truth: Trajectory, path: Path,
                 events: Sequence[dict] = ()) -> Path:
    """The weighted-ICP paper's Figs. 12-15: SOG, COG and ΔCOG differences versus time, and their
    histograms."""
    fig, axes = plt.subplots(3, 2, figsize=(12, 10.5), gridspec_kw={"width_ratios": [2.2, 1]},
                             layout="constrained")
    col = colors(list(trajs))
    series = {n: movement_error_series(tr, truth) for n, tr in trajs.items()}

    def robust_range(key: str, floor: float) -> float:
        vals = np.concatenate([np.abs(s[key][np.isfinite(s[key])]) for s in series.values()] or [np.zeros(0)])
        return max(float(np.percentile(vals, 98)) if len(vals) else floor, floor)

    rows = [("sog", "t", "m/s", "SOG"), ("cog", "t_cog", "deg", "COG"), ("dcog", "t_dcog", "deg", "ΔCOG")]
    for row, (key, tkey, unit, label) in enumerate(rows):
        ax_t, ax_h = axes[row]
        lim = robust_range(key, 0.05 if key == "sog" else 0.2)
        bins = np.linspace(-lim, lim, 41)
        # the noisiest series first (underneath, faded), the most accurate on top
        def rms(n: str, key: str = key) -> float:
            v = series[n][key][np.isfinite(series[n][key])]
            return float(np.sqrt(np.mean(v**2))) if len(v) else np.inf

        order = sorted(series, key=rms, reverse=True)
        for z, name in enumerate(order):
            s = series[name]
            alpha = 0.45 if z < len(order) - 3 else 0.95
            ax_t.plot(s[tkey], s[key], "-", lw=0.9, color=col[name], alpha=alpha, zorder=2 + z)
            v = s[key][np.isfinite(s[key])]
            ax_h.hist(np.clip(v, -lim, lim), bins=bins, histtype="step", lw=1.4, color=col[name])
        shade = _shade_events(ax_t, events, (float(truth.t[0]), float(truth.t[-1])) if len(truth) else None)
        ax_t.set_ylim(-1.1 * lim, 1.1 * lim)
        ax_t.axhline(0, color="k", lw=0.6)
        ax_t.set_xlabel("time [s]")
        ax_t.set_ylabel(f"{label} error [{unit}]")
        moving = " (moving only)" if key != "sog" else ""
        ax_t.set_title(f"{label}$_{{est}}$ − {label}$_{{truth}}${moving}")
        ax_t.grid(alpha=0.3)
        ax_h.set_xlabel(f"{label} error [{unit}] (clipped at ±{lim:.2g})")
        ax_h.set_ylabel("count")
        ax_h.set_title(f"Histogram of {label} error")
        ax_h.grid(alpha=0.3)
    handles = [Line2D([], [], color=col[n], lw=1.5, label=n) for n in trajs] + shade
    fig.legend(handles=handles, loc="outside right center", fontsize=9, frameon=False)
    return _finish(fig, path)


def _nice_magnification(m: float) -> float:
    """1 when ellipses are already visible, else the next 1/2/5 x 10^k at or below ``m``."""
    if m <= 1.0:
        return 1.0
    k = 10 ** np.floor(np.log10(m))
    return float(max(s * k for s in (1, 2, 5) if s * k <= m))


def plot_covariance(trajs: dict[str, Trajectory], truth: Trajectory | None, path: Path, *,
                    n_ellipses: int = 25, nsigma: float = 2.0) -> Path | None:
    """Position covariance ellipses (``nsigma``) at regular intervals, one panel per estimator with
    covariances; ``None`` (no file) when no trajectory carries covariances."""
    with_cov = {n: t for n, t in trajs.items() if t.cov is not None and len(t)}
    if not with_cov:
        return None
    n = len(with_cov)
    ncol = min(n, 3)
    nrow = int(np.ceil(n / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(5.5 * ncol, 5 * nrow), squeeze=False,
                             layout="constrained")
    col = colors(list(trajs))
    allxy = np.vstack([np.column_stack([t.x, t.y]) for t in with_cov.values()])
    extent = float(np.max(np.ptp(allxy, axis=0))) or 1.0
    # one magnification for every panel (sizes stay comparable), chosen so the typical ellipse is
    # visible at the scale of the track
    semi = [np.sqrt(max(np.linalg.eigvalsh(c[:2, :2]).max(), 0.0)) for t in with_cov.values()
            for c in t.cov[:: max(1, len(t) // n_ellipses)] if np.all(np.isfinite(c[:2, :2]))]
    mag = _nice_magnification(0.02 * extent / max(nsigma * float(np.median(semi)) if semi else 1.0, 1e-9))
    label = f" (magnified ×{mag:g})" if mag != 1 else ""
    for ax, (name, tr) in zip(axes.ravel(), with_cov.items(), strict=False):
        if truth is not None and len(truth):
            ax.plot(truth.x, truth.y, "-", color="k", lw=1.5, label="truth")
        ax.plot(tr.x, tr.y, "-", color=col[name], lw=1.0, label=name)
        idx = np.unique(np.linspace(0, len(tr) - 1, n_ellipses).astype(int))
        for i in idx:
            c = tr.cov[i, :2, :2]
            if not np.all(np.isfinite(c)):
                continue
            w, v = np.linalg.eigh(0.5 * (c + c.T))
            w = np.clip(w, 0, None)
            ang = np.degrees(np.arctan2(v[1, 1], v[0, 1]))
            a, b = 2 * mag * nsigma * np.sqrt(w[1]), 2 * mag * nsigma * np.sqrt(w[0])
            ax.add_patch(Ellipse((tr.x[i], tr.y[i]), a, b, angle=ang, fill=False, color=col[name], lw=1.0))
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x (east) [m]")
        ax.set_ylabel("y (north) [m]")
        ax.set_title(f"{name}: {nsigma:g}σ position ellipses{label}")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="best")
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    return _finish(fig, path)
