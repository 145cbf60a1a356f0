"""Comparison figures: trajectories (overview and per-estimator panels), position and heading error,
error CDF, SOG/COG errors, error with ±3σ bounds, NEES with its chi-square band, covariance ellipses.

Every function builds on :class:`matplotlib.figure.Figure` objects, never on pyplot: importing this
module selects no backend and touches no global state, so it is safe in a notebook (pass ``ax=`` or
``fig=`` from ``plt.subplots()`` to draw inline) and needs no backend to write files (:func:`save`).
Each ``plot_*`` function takes an optional ``ax`` (one-axes figures) or ``fig`` (multi-panel figures)
and returns the Figure it drew on; the ``*_panel`` functions draw one estimator into given axes.

Series far denser than a panel's pixels are drawn thinned to them (:func:`thin_minmax`, :func:`thin_xy`,
:func:`thin_track`: every extreme and gap kept at 300 dpi; zooming far into a drawn figure shows the
thinning); every number in a title or caption comes from the full series.

Errors are taken at the estimate/reference pairs of :func:`graphnav.evaluation.metrics.associate` — the same
pairs that the report's numbers use. SOG/COG errors follow the weighted-ICP paper's Figs. 12-15
(difference versus time and its histogram), with COG scored only while the reference moves.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Ellipse, Patch
from matplotlib.ticker import FixedLocator, FuncFormatter, Locator, MaxNLocator, NullLocator

from ..geometry import wrap_angle
from ..graph.chi2 import chi2_ppf
from ..io.outputs import atomic_path
from ..trajectory import Trajectory
from . import palette
from .metrics import (  # noqa: F401  (the error series live in metrics; plots re-exports them)
    MOVEMENT_DT_S,
    heading_errors,
    movement_error_series,
    paired,
    position_errors,
    position_nees,
)

# (face colour, hatch, label): light fills/hatches, so they do not read as an estimator's line colour
EVENT_STYLE = {"gnss_outage": ("#f2d64b", "", "GNSS outage"), "gnss_jump": ("#e8a0a0", "xx", "GNSS jump")}
MAX_DT = 0.02
CDF_FLOOR = 1e-3
NEES_BAND = (chi2_ppf(0.025, 2), chi2_ppf(0.975, 2))  # two-sided 95 %, 2 dof: (0.0506, 7.38)


def colors(names: Sequence[str]) -> dict[str, Any]:
    """One colour per estimator, the same in every figure and on map.html (:mod:`.palette`)."""
    return palette.colors(names)


def widths(names: Sequence[str], thick: float = 2.8, thin: float = 1.1) -> dict[str, float]:
    """Line widths decreasing in drawing order: a curve drawn over an identical one (batch and
    isam2 often coincide) leaves the earlier one visible as a coloured outline."""
    n = max(len(names) - 1, 1)
    return {name: thick - (thick - thin) * i / n for i, name in enumerate(names)}


def save(fig: Figure, path: str | Path, dpi: int = 110) -> Path:
    """Write ``fig`` (format from the suffix: .png, .svg, .pdf) without any pyplot backend, atomically
    (a reader never sees half a file)."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi)
    return Path(path)


def _axes(ax: Axes | None, figsize: tuple[float, float]) -> tuple[Figure, Axes]:
    if ax is not None:
        return ax.figure, ax
    fig = Figure(figsize=figsize, layout="constrained")
    return fig, fig.add_subplot()


def _panel_figure(width: float, height: float, nrow: int, ncol: int, *, left: float = 0.8, right: float = 0.25,
                  top: float = 0.45, bottom: float = 0.55, hspace: float = 0.75, wspace: float = 0.9) -> Figure:
    """A figure for a grid of panels with fixed margins and gaps in inches. No layout engine: on
    grids of 6-18 panels constrained layout doubled the time to write the figure."""
    fig = Figure(figsize=(width, height))
    ph = (height - top - bottom - hspace * (nrow - 1)) / nrow
    pw = (width - left - right - wspace * (ncol - 1)) / ncol
    fig.subplots_adjust(left=left / width, right=1 - right / width, top=1 - top / height, bottom=bottom / height,
                        hspace=hspace / max(ph, 1e-3), wspace=wspace / max(pw, 1e-3))
    return fig


def _grid(fig: Figure | None, n: int, ncol: int, panel: tuple[float, float], **kw: Any) -> tuple[Figure, np.ndarray]:
    """``n`` panels in ``ncol`` columns on ``fig`` (a new Figure sized ``panel`` per panel if None);
    the unused panels are switched off."""
    ncol = max(1, min(n, ncol))
    nrow = max(1, int(np.ceil(n / ncol)))
    if fig is None:
        fig = _panel_figure(panel[0] * ncol, panel[1] * nrow, nrow, ncol)
    axes = np.asarray(fig.subplots(nrow, ncol, squeeze=False, **kw))
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    return fig, axes


def _cell_keep(pts: np.ndarray, cell: float) -> np.ndarray | None:
    """Indices of the points (N, 2) where a track enters another ``cell``-sized square, and its last
    point; ``None`` when nothing would be dropped (or ``cell <= 0``, or a point is not finite)."""
    if not (cell > 0) or len(pts) <= 2 or not np.all(np.isfinite(pts)):
        return None
    c = np.floor((pts - pts.min(axis=0)) / cell).astype(np.int64)
    keep = np.r_[0, np.flatnonzero((c[1:] != c[:-1]).any(axis=1)) + 1]
    if keep[-1] != len(pts) - 1:
        keep = np.r_[keep, len(pts) - 1]
    return keep if len(keep) < len(pts) else None


def thin_xy(x: np.ndarray, y: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """A track (an x-y line) thinned for drawing: its points where it enters another ``cell``-sized
    square (a pixel's size in data units), and its last; as is when ``cell <= 0``."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    keep = _cell_keep(np.column_stack([x, y]), cell)
    return (x, y) if keep is None else (x[keep], y[keep])


def _pixel(ax: Axes, lims: tuple[tuple[float, float], ...] | None, dpi: float = 300.0) -> float:
    """The data size of a pixel of ``ax`` at ``dpi`` (at least the figure's) once its limits are
    ``lims``: the finer of the two axes (an equal aspect only makes pixels larger); 0 without limits."""
    if lims is None:
        return 0.0
    w, h = ax.get_position().size * ax.figure.get_size_inches() * max(dpi, ax.figure.dpi)
    return float(min((lims[0][1] - lims[0][0]) / max(w, 1.0), (lims[1][1] - lims[1][0]) / max(h, 1.0)))


def _in_window(x: np.ndarray, y: np.ndarray, x0: float, x1: float, y0: float,
               y1: float) -> tuple[np.ndarray, np.ndarray]:
    """The parts of a line that can show in the window [x0, x1] x [y0, y1]: every segment whose
    bounding box meets it, with a NaN (a break) between runs that are not consecutive."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if len(x) < 2:
        return x, y
    meet = ((np.minimum(x[:-1], x[1:]) <= x1) & (np.maximum(x[:-1], x[1:]) >= x0)
            & (np.minimum(y[:-1], y[1:]) <= y1) & (np.maximum(y[:-1], y[1:]) >= y0))
    use = np.zeros(len(x), bool)
    use[:-1] |= meet
    use[1:] |= meet
    use |= (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)  # (a lone point still shows as a marker)
    idx = np.flatnonzero(use)
    if len(idx) == len(x):
        return x, y
    brk = np.flatnonzero(np.diff(idx) > 1) + 1
    return np.insert(x[idx], brk, np.nan), np.insert(y[idx], brk, np.nan)


def thin_track(x: np.ndarray, y: np.ndarray, seg_values: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """A track's segments (M, 2, 2) and their values, thinned for a colour-coded drawing: the points
    where the track enters another ``cell``-sized square are kept (and the last), each kept segment
    spanning a run of original ones and taking the largest of their ``seg_values`` (N - 1), so no
    peak is lost. ``cell <= 0``: every segment."""
    pts = np.column_stack([x, y])
    v = np.asarray(seg_values, dtype=float)
    keep = _cell_keep(pts, cell)
    if keep is not None:
        return np.stack([pts[keep[:-1]], pts[keep[1:]]], axis=1), np.maximum.reduceat(v, keep[:-1])
    return np.stack([pts[:-1], pts[1:]], axis=1), v


def _shared_grid(fig: Figure, nrow: int, ncol: int) -> np.ndarray:
    """``nrow`` x ``ncol`` axes meant to share their time axis: not matplotlib-shared (sharing is
    quadratic in the number of axes at draw time); :func:`_finish_grid` gives them one x range."""
    return np.asarray(fig.subplots(nrow, ncol, squeeze=False))


def _finish_grid(axes: np.ndarray, *, margin: float = 0.05) -> None:
    """One x range for every axes of ``axes`` (the union of their data, with matplotlib's default
    margin), x tick labels on the bottom row only, and each axis's ticks computed once per distinct
    (limits, length) and fixed: panels that look alike get the same ticks without recomputing them."""
    on = [a for a in axes.ravel() if a.axison]
    lims = [a.dataLim.intervalx for a in on if a.has_data() and np.all(np.isfinite(a.dataLim.intervalx))]
    if lims:
        lo, hi = min(v[0] for v in lims), max(v[1] for v in lims)
        pad = margin * (hi - lo) if hi > lo else 0.5
        for a in on:
            a.set_xlim(lo - pad, hi + pad)
    for a in axes[:-1].ravel():
        a.tick_params(labelbottom=False)
        a.set_xlabel("")
    cache: dict[tuple, np.ndarray] = {}
    for a in on:
        size = a.get_position().size
        for axis, lim, length in ((a.xaxis, a.get_xlim(), size[0]), (a.yaxis, a.get_ylim(), size[1])):
            if axis.get_scale() != "linear":
                continue
            key = (axis.axis_name, tuple(lim), round(float(length), 6))
            if key not in cache:  # (only the ticks inside the view: the others are never drawn)
                locs, (v0, v1), tol = axis.get_majorticklocs(), sorted(lim), 1e-10 * abs(lim[1] - lim[0])
                cache[key] = locs[(locs >= v0 - tol) & (locs <= v1 + tol)]
            axis.set_major_locator(FixedLocator(cache[key]))


class _InView(Locator):
    """Another locator's ticks, without those outside the view: matplotlib builds a tick (lines, labels)
    for every location a locator returns but draws only those inside, so the others cost for nothing."""

    def __init__(self, base: Locator) -> None:
        self.base = base

    def set_axis(self, axis: Any) -> None:
        super().set_axis(axis)
        self.base.set_axis(axis)

    def __call__(self) -> np.ndarray:
        locs = np.asarray(self.base(), dtype=float)
        v0, v1 = sorted(self.axis.get_view_interval())
        tol = 1e-10 * max(abs(v0), abs(v1), v1 - v0)
        return locs[(locs >= v0 - tol) & (locs <= v1 + tol)]

    def tick_values(self, vmin: float, vmax: float) -> np.ndarray:
        return self.base.tick_values(vmin, vmax)

    def nonsingular(self, v0: float, v1: float) -> tuple[float, float]:  # (autoscaling: the base's rule)
        return self.base.nonsingular(v0, v1)

    def view_limits(self, vmin: float, vmax: float) -> tuple[float, float]:
        return self.base.view_limits(vmin, vmax)


def _ticks_in_view(*axes: Axes) -> None:
    """Each axis of ``axes`` builds ticks only for the locations inside its view (:class:`_InView`)."""
    for ax in axes:
        for axis in (ax.xaxis, ax.yaxis):
            for get, put in ((axis.get_major_locator, axis.set_major_locator),
                             (axis.get_minor_locator, axis.set_minor_locator)):
                loc = get()
                if not isinstance(loc, (_InView, NullLocator, FixedLocator)):
                    put(_InView(loc))


def _columns(ax: Axes, dpi: float = 300.0) -> int:
    """Pixel columns of ``ax`` at ``dpi`` (at least the figure's): how finely a series needs drawing."""
    return max(int(np.ceil(ax.get_position().width * ax.figure.get_figwidth() * max(dpi, ax.figure.dpi))), 1)


def thin_minmax(x: np.ndarray, y: np.ndarray, columns: int) -> tuple[np.ndarray, np.ndarray]:
    """A series sorted in ``x``, thinned to what ``columns`` pixel columns can show: in each column
    its first and last sample, its minimum and maximum, and its first NaN (a gap stays a gap), in
    their order. Every extreme stays visible; a series with at most four samples per column, or not
    sorted, is returned as is. For drawing only: numbers are computed from the full series."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    n = len(x)
    if n <= 4 * columns or not (np.isfinite(x[0]) and np.isfinite(x[-1]) and x[-1] > x[0]):
        return x, y
    dx = np.diff(x)
    if not np.all(dx >= 0):
        return x, y
    b = np.minimum(((x - x[0]) * (columns / (x[-1] - x[0]))).astype(np.int64), columns - 1)
    starts = np.flatnonzero(np.r_[True, b[1:] != b[:-1]])
    ends = np.r_[starts[1:], n] - 1
    fin = np.isfinite(y)
    lo = np.lexsort((np.where(fin, y, np.inf), b))[starts]
    hi = np.lexsort((np.where(fin, y, -np.inf), b))[ends]
    nan = np.flatnonzero(~fin)
    first_nan = nan[np.unique(b[nan], return_index=True)[1]] if len(nan) else nan
    keep = np.unique(np.concatenate([starts, ends, lo, hi, first_nan]))
    return x[keep], y[keep]


def _as_dict(trajs: dict[str, Trajectory] | Trajectory) -> dict[str, Trajectory]:
    return {trajs.name or "estimate": trajs} if isinstance(trajs, Trajectory) else dict(trajs)


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


def _span(truth: Trajectory | None) -> tuple[float, float] | None:
    return (float(truth.t[0]), float(truth.t[-1])) if truth is not None and len(truth) else None


def _legend_right(ax: Axes, extra: Sequence[Any] = ()) -> None:
    h, _ = ax.get_legend_handles_labels()
    ax.legend(handles=list(h) + list(extra), loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9,
              frameon=False)


# -- trajectories ---------------------------------------------------------------------------------

def track_limits(trajs: dict[str, Trajectory], truth: Trajectory | None, gnss: np.ndarray | None = None, *,
                 margin: float = 0.06, min_ratio: float = 0.25) -> tuple[tuple[float, float], tuple[float, float]]:
    """Axis limits that fit the data: the truth and the central 98 % of each estimate (a diverged
    estimator does not stretch the view of the others; GNSS fixes count only without truth), with a
    relative margin; the short side at least ``min_ratio`` of the long one (a straight track keeps
    a readable band around it instead of hundreds of metres of empty axis)."""
    pts = []
    if truth is not None and len(truth):
        pts.append(np.column_stack([truth.x, truth.y]))
    elif gnss is not None and len(gnss):
        g = np.asarray(gnss, float)
        lo, hi = np.nanpercentile(g, [1, 99], axis=0)
        pts.append(g[((g >= lo) & (g <= hi)).all(axis=1)])
    for tr in trajs.values():
        if len(tr):
            xy = np.column_stack([tr.x, tr.y])
            xy = xy[np.isfinite(xy).all(axis=1)]
            if len(xy):
                lo, hi = np.percentile(xy, [1, 99], axis=0)
                pts.append(xy[((xy >= lo) & (xy <= hi)).all(axis=1)])
    xy = np.vstack(pts) if pts else np.zeros((1, 2))
    lo, hi = np.nanmin(xy, 0), np.nanmax(xy, 0)
    span = np.maximum(hi - lo, 1.0)
    span = np.maximum(span, min_ratio * span.max()) * (1 + 2 * margin)
    c = 0.5 * (lo + hi)
    return (c[0] - span[0] / 2, c[0] + span[0] / 2), (c[1] - span[1] / 2, c[1] + span[1] / 2)


def plot_trajectories(trajs: dict[str, Trajectory] | Trajectory, truth: Trajectory | None,
                      gnss: np.ndarray | None = None, *, title: str = "", ax: Axes | None = None) -> Figure:
    """Every trajectory over the truth (and the GNSS fixes), one axes whose limits fit the data
    (:func:`track_limits`, equal scale; a new figure takes the data's shape)."""
    trajs = _as_dict(trajs)
    (x0, x1), (y0, y1) = track_limits(trajs, truth, gnss)
    own = ax is None
    if own:
        h = float(np.clip(6.5 * (y1 - y0) / (x1 - x0), 3.0, 9.0))
        fig, ax = _axes(None, (8.5, h + 1.0))
    else:
        fig = ax.figure
    col = colors(list(trajs))
    if gnss is not None and len(gnss):
        ax.plot(gnss[:, 0], gnss[:, 1], ".", ms=2.5, color="0.6", label="GNSS fixes", zorder=1)
    if truth is not None and len(truth):
        ax.plot(truth.x, truth.y, "-", color="k", lw=1.3, label="truth", zorder=5)  # on top: always visible
        ax.plot(truth.x[0], truth.y[0], "o", color="k", ms=6, zorder=6)
    lw = widths(list(trajs))
    for name, tr in trajs.items():
        ax.plot(tr.x, tr.y, "-", lw=lw[name], color=col[name], label=name, zorder=3)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (east) [m]")
    ax.set_ylabel("y (north) [m]")
    ax.set_title(title or ("Trajectories over the truth (start: black dot)" if truth is not None else
                           "Trajectories (no truth)"))
    ax.grid(alpha=0.3)
    if own:  # (a figure legend: the constrained layout keeps it and the labels inside the figure)
        fig.legend(handles=ax.get_legend_handles_labels()[0], loc="outside right upper", fontsize=9, frameon=False)
    else:
        _legend_right(ax)
    return fig


def _limits(xy: np.ndarray, margin: float = 0.06, floor: float = 1.0) -> tuple[tuple[float, float], ...]:
    """Square-ish axis limits around the points ``xy`` (N, 2), with a relative margin."""
    lo, hi = np.nanmin(xy, 0), np.nanmax(xy, 0)
    c, half = 0.5 * (lo + hi), 0.5 * np.maximum(hi - lo, floor) * (1 + 2 * margin)
    return (c[0] - half[0], c[0] + half[0]), (c[1] - half[1], c[1] + half[1])


def loop_segments(est: Trajectory, edge_times: Sequence[Sequence[float]]) -> np.ndarray:
    """(M, 2, 2) segments joining the estimate's poses at each loop edge's two times (the nearest pose
    of each; edges outside the track are left out)."""
    if not len(est) or not len(edge_times):
        return np.zeros((0, 2, 2))
    te = np.asarray(edge_times, dtype=float).reshape(-1, 2)
    keep = (te >= est.t[0] - MAX_DT).all(axis=1) & (te <= est.t[-1] + MAX_DT).all(axis=1)
    idx = np.clip(np.searchsorted(est.t, te[keep]), 0, len(est) - 1)
    prev = np.clip(idx - 1, 0, len(est) - 1)
    idx = np.where(np.abs(est.t[prev] - te[keep]) < np.abs(est.t[idx] - te[keep]), prev, idx)
    xy = np.column_stack([est.x, est.y])
    return xy[idx]


def trajectory_panel(ax: Axes, name: str, est: Trajectory, truth: Trajectory | None, *,
                     zoom_ax: Axes | None = None, color: Any = "tab:red",
                     loops: Sequence[Sequence[float]] = ()) -> Figure:
    """One estimator over the truth, the track coloured by its position error; the view spans this
    estimator's track and the truth over the same time (not every estimator's). ``zoom_ax``, when
    given, shows the neighbourhood of the largest error, a few errors wide. ``loops``: accepted loop
    closures as (older, newer) times (``RunResult.info["loop_edge_times"]``), drawn as thin edges."""
    fig = ax.figure
    segs_loop = loop_segments(est, loops)
    if len(segs_loop):
        ax.add_collection(LineCollection(segs_loop, colors="tab:orange", lw=0.7, alpha=0.8, zorder=4,
                                         label=f"loop closures ({len(segs_loop)})"))
    err = None
    tr_xy = np.zeros((0, 2))
    if truth is not None and len(truth):
        e, r = paired(est, truth)
        err = np.hypot(e.x - r.x, e.y - r.y) if len(e) else None
        if len(est):
            inside = (truth.t >= est.t[0] - MAX_DT) & (truth.t <= est.t[-1] + MAX_DT)
            tr_xy = np.column_stack([truth.x[inside], truth.y[inside]])
    xy = np.vstack([np.column_stack([est.x, est.y]), tr_xy]) if len(est) else tr_xy
    lims = _limits(xy) if len(xy) else None
    cell = _pixel(ax, lims)  # the lines drawn thinned to this panel's pixels (numbers: full series)
    if truth is not None and len(truth):
        ax.plot(*thin_xy(truth.x, truth.y, cell), "-", color="k", lw=0.8, label="truth", zorder=2)
    if err is not None:
        segs, seg_err = thin_track(e.x, e.y, 0.5 * (err[:-1] + err[1:]), cell)
        norm = Normalize(0.0, max(float(np.percentile(err, 99)), 1e-6))
        lc = LineCollection(segs, cmap="viridis", norm=norm, lw=2.0, zorder=3)
        lc.set_array(seg_err)
        ax.add_collection(lc)
        fig.colorbar(lc, ax=ax, shrink=0.8, pad=0.01, label="position error [m]", extend="max")
    else:
        ax.plot(*thin_xy(est.x, est.y, cell), "-", lw=1.5, color=color, label=name, zorder=3)
    if lims is not None:
        (x0, x1), (y0, y1) = lims
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (east) [m]")
    ax.set_ylabel("y (north) [m]")
    title = name
    if err is not None:
        title += f" — ATE RMSE {np.sqrt(np.mean(err**2)):.3g} m, max {err.max():.3g} m"
    ax.set_title(title, fontsize=10, y=1.0)
    ax.grid(alpha=0.3)
    _ticks_in_view(ax)
    if zoom_ax is not None:
        if err is None or not len(err):
            zoom_ax.axis("off")
            return fig
        k = int(np.argmax(err))
        half = max(4.0 * float(err[k]), 1.0)  # a window a few errors wide (at least 2 m)
        cx, cy = 0.5 * (e.x[k] + r.x[k]), 0.5 * (e.y[k] + r.y[k])
        win = (cx - 1.05 * half, cx + 1.05 * half, cy - 1.05 * half, cy + 1.05 * half)  # (what can show)
        zoom_ax.plot(*_in_window(truth.x, truth.y, *win), "-", color="k", lw=1.2, label="truth")
        zoom_ax.plot(*_in_window(e.x, e.y, *win), ".-", color=color, lw=1.2, ms=3, label=name)
        zoom_ax.plot([e.x[k], r.x[k]], [e.y[k], r.y[k]], "-", color="0.4", lw=0.8)
        zoom_ax.set_xlim(cx - half, cx + half)
        zoom_ax.set_ylim(cy - half, cy + half)
        zoom_ax.set_aspect("equal", adjustable="box")
        zoom_ax.tick_params(labelsize=7)
        zoom_ax.xaxis.set_major_locator(MaxNLocator(4))
        zoom_ax.yaxis.set_major_locator(MaxNLocator(5))
        zoom_ax.set_title(f"largest error {err[k]:.3g} m at t = {e.t[k]:.1f} s", fontsize=9, y=1.0)
        zoom_ax.grid(alpha=0.3)
        zoom_ax.legend(fontsize=7, loc="best")
        _ticks_in_view(zoom_ax)
        ax.plot([e.x[k]], [e.y[k]], "s", ms=9, mfc="none", mec="r", zorder=6)
    return fig


def plot_trajectory_panels(trajs: dict[str, Trajectory] | Trajectory, truth: Trajectory | None, *,
                           fig: Figure | None = None, ncol: int = 2,
                           loops: dict[str, Sequence[Sequence[float]]] | None = None) -> Figure:
    """One panel per estimator (:func:`trajectory_panel`), each zoomed to its own track, and beside it
    (when there is a truth) a close-up of its largest error; ``loops`` (per estimator name) marks
    the accepted loop closures."""
    trajs = _as_dict(trajs)
    col = colors(list(trajs))
    zoom = truth is not None and len(truth) > 0
    per = 2 if zoom else 1
    ncol = max(1, min(len(trajs), ncol))
    nrow = int(np.ceil(len(trajs) / ncol))
    if fig is None:
        fig = _panel_figure((6.4 + 3.6 * (per - 1)) * ncol, 4.6 * nrow, nrow, ncol * per, wspace=0.85)
    axes = np.asarray(fig.subplots(nrow, ncol * per, squeeze=False,
                                   gridspec_kw={"width_ratios": ([2.0, 1.0] if zoom else [1.0]) * ncol}))
    cells = [(axes[i // ncol, per * (i % ncol)], axes[i // ncol, per * (i % ncol) + 1] if zoom else None)
             for i in range(nrow * ncol)]
    for (ax, zax), (name, tr) in zip(cells, trajs.items(), strict=False):
        trajectory_panel(ax, name, tr, truth, zoom_ax=zax, color=col[name], loops=(loops or {}).get(name, ()))
    for ax, zax in cells[len(trajs):]:
        ax.axis("off")
        if zax is not None:
            zax.axis("off")
    return fig


# -- errors versus time -----------------------------------------------------------------------------

def plot_position_error(trajs: dict[str, Trajectory] | Trajectory, truth: Trajectory, events: Sequence[dict] = (),
                        online: dict[str, Trajectory] | None = None, *, ax: Axes | None = None) -> Figure:
    """Position error versus time; ``online`` estimates (smoothers) dashed in the same colour."""
    trajs = _as_dict(trajs)
    fig, ax = _axes(ax, (10, 4.5))
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
    handles = _shade_events(ax, events, _span(truth))
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
    _legend_right(ax, handles)
    return fig


def plot_heading_error(trajs: dict[str, Trajectory] | Trajectory, truth: Trajectory, events: Sequence[dict] = (),
                       *, ax: Axes | None = None) -> Figure:
    """Signed heading error (estimate minus truth, wrapped) versus time, the noisiest series drawn
    underneath; a symmetric-log axis when the RMSEs span more than a factor 10, else a linear one
    clipped at the 99th percentile of |error| (either stated on the axis)."""
    trajs = _as_dict(trajs)
    fig, ax = _axes(ax, (10, 4.5))
    col = colors(list(trajs))
    series = {n: heading_errors(tr, truth) for n, tr in trajs.items()}
    rms = {n: float(np.sqrt(np.mean(e**2))) if len(e) else np.inf for n, (_, e) in series.items()}
    for z, name in enumerate(sorted(series, key=lambda n: rms[n], reverse=True)):
        t, e = series[name]
        ax.plot(t, e, "-", lw=1.0, color=col[name], zorder=2 + z, label=f"{name} (RMSE {rms[name]:.3g}°)")
    vals = np.concatenate([np.abs(e) for _, e in series.values()] or [np.zeros(0)])
    handles = _shade_events(ax, events, _span(truth))
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlabel("time [s]")
    finite = [v for v in rms.values() if np.isfinite(v) and v > 0]
    if len(finite) > 1 and max(finite) > 10 * min(finite):
        # a diverged estimator beside good ones: symmetric log, linear near zero, nothing clipped
        lin = max(2.0 * min(finite), 0.01)
        ax.set_yscale("symlog", linthresh=lin)
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        top = 1.3 * float(vals.max())
        ax.set_ylim(-top, top)
        ax.set_ylabel(f"heading error [deg] (symmetric log; linear within ±{lin:.2g})")
    else:
        lim = max(float(np.percentile(vals, 99)) if len(vals) else 1.0, 0.05)
        clipped = len(vals) and float(vals.max()) > 1.1 * lim
        ax.set_ylim(-1.1 * lim, 1.1 * lim)
        ax.set_ylabel("heading error [deg]" + (f" (clipped at ±{1.1 * lim:.2g})" if clipped else ""))
    ax.set_title("Heading error versus time (estimate − truth)")
    ax.grid(alpha=0.3)
    _legend_right(ax, handles)
    return fig


def plot_error_cdf(trajs: dict[str, Trajectory] | Trajectory, truth: Trajectory, *, ax: Axes | None = None) -> Figure:
    trajs = _as_dict(trajs)
    fig, ax = _axes(ax, (7.5, 4.5))
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
    _legend_right(ax)
    return fig


def plot_sog_cog(trajs: dict[str, Trajectory] | Trajectory, truth: Trajectory, events: Sequence[dict] = (), *,
                 fig: Figure | None = None) -> Figure:
    """The weighted-ICP paper's Figs. 12-15 as small multiples: one row per estimator (in its colour),
    SOG, COG and ΔCOG errors versus time in three columns with one y-scale per column (the 98th
    percentile of every estimator's error), each panel titled with its RMS; the log's events shaded.
    Each panel draws its series thinned to the extremes of each pixel column (:func:`thin_minmax`);
    the RMS and the scales come from the full series."""
    trajs = _as_dict(trajs)
    n = max(len(trajs), 1)
    if fig is None:
        fig = _panel_figure(13, 1.55 * n + 1.2, n, 3, left=0.75, right=0.2, top=0.65, bottom=0.75,
                            hspace=0.32, wspace=0.6)
    series = {name: movement_error_series(tr, truth, dt=MOVEMENT_DT_S) for name, tr in trajs.items()}
    axes = _shared_grid(fig, n, 3)
    col = colors(list(trajs))
    cols = [("sog", "t", "m/s", "SOG", "{:.3f}"), ("cog", "t_cog", "deg", "COG", "{:.2f}"),
            ("dcog", "t_dcog", "deg", "ΔCOG", "{:.2f}")]
    shade: list[Patch] = []
    span = _span(truth)
    for j, (key, tkey, unit, label, fmt) in enumerate(cols):
        vals = np.concatenate([np.abs(s[key][np.isfinite(s[key])]) for s in series.values()] or [np.zeros(0)])
        floor = 0.05 if key == "sog" else 0.2
        lim = max(float(np.percentile(vals, 98)) if len(vals) else floor, floor)
        px = _columns(axes[0, j])
        for i, (name, s) in enumerate(series.items()):
            ax = axes[i, j]
            v = s[key]
            ok = np.isfinite(v)
            ax.plot(*thin_minmax(s[tkey], v, px), "-", lw=0.8, color=col[name])
            rms = float(np.sqrt(np.mean(v[ok] ** 2))) if ok.any() else float("nan")
            shade = _shade_events(ax, events, span)
            ax.set_ylim(-1.1 * lim, 1.1 * lim)
            ax.axhline(0, color="k", lw=0.5)
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=7)
            ax.set_title(f"{name}: {label} RMS {fmt.format(rms)} {unit}", fontsize=8, color=col[name], loc="left",
                         y=1.0)
            if j == 0:
                ax.set_ylabel(f"[{unit}]", fontsize=8)
            if i == n - 1:
                ax.set_xlabel("time [s]", fontsize=8)
        moving = " (moving only)" if key != "sog" else ""
        axes[0, j].annotate(f"{label} estimate − truth{moving} [{unit}]", (0.5, 1.35), xycoords="axes fraction",
                            ha="center", fontsize=10, annotation_clip=False)
    _finish_grid(axes)
    if shade:
        fig.legend(handles=shade, loc="lower center", fontsize=8, frameon=False, ncols=len(shade))
    return fig


def plot_gnss_residuals(trajs: dict[str, Trajectory] | Trajectory, gnss: dict[str, np.ndarray],
                        windows: Sequence[tuple[float, float]] = (), *, fig: Figure | None = None) -> Figure | None:
    """For a log without truth: each estimator's distance to the GNSS fixes versus time, one panel per
    estimator (in its colour, one y-scale), the fixes' own 1σ dashed; ``windows``: hold-out windows
    (their fixes withheld from the estimators) shaded. ``gnss``: the fixes' columns ``t``, ``x``,
    ``y``, ``sigma``. ``None`` when no estimate meets a fix."""
    from .metrics import gnss_residuals

    trajs = _as_dict(trajs)
    xy = np.column_stack([gnss["x"], gnss["y"]])
    res = {n: gnss_residuals(tr, gnss["t"], xy, gnss["sigma"]) for n, tr in trajs.items()}
    res = {n: r for n, r in res.items() if len(r["t"])}
    if not res:
        return None
    n = len(res)
    if fig is None:
        fig = _panel_figure(11, 1.5 * n + 1.0, n, 1, left=0.6, right=0.2, top=0.3, bottom=0.75, hspace=0.3)
    grid = _shared_grid(fig, n, 1)
    axes = grid[:, 0]
    col = colors(list(trajs))
    top = max(float(np.percentile(np.concatenate([r["residual_m"] for r in res.values()]), 99)), 1.0)
    sig = float(np.nanmedian(gnss["sigma"])) if len(gnss["sigma"]) else None
    t0 = float(np.min(gnss["t"]))  # (NMEA logs count from 1970: time since the first fix reads better)
    for ax, (name, r) in zip(axes, res.items(), strict=True):
        for a, b in windows:
            ax.axvspan(a - t0, b - t0, color="#f2d64b", alpha=0.35, lw=0)
        ax.plot(r["t"] - t0, r["residual_m"], ".", ms=2, color=col[name])
        if sig is not None and np.isfinite(sig):
            ax.axhline(sig, color="0.3", lw=0.8, ls="--")
        rms = float(np.sqrt(np.mean(r["residual_m"] ** 2)))
        ax.set_title(f"{name}: RMS {rms:.2f} m over {len(r['t'])} fixes", fontsize=8, loc="left", color=col[name],
                     y=1.0)
        ax.set_ylim(0, 1.1 * top)
        ax.set_ylabel("[m]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    _finish_grid(grid)
    axes[-1].set_xlabel(f"time since the first fix (t = {t0:.1f} s) [s]")
    handles = [Line2D([], [], color="0.3", ls="--", label=f"fixes' 1σ (median {sig:.2g} m)")] if sig else []
    if windows:
        handles.append(Patch(facecolor="#f2d64b", alpha=0.35, label="hold-out windows (fixes withheld)"))
    if handles:
        fig.legend(handles=handles, loc="lower center", fontsize=8, frameon=False, ncols=len(handles))
    return fig


# -- consistency: ±3σ bounds and NEES --------------------------------------------------------------

def error_bound_panels(axes: Sequence[Axes], name: str, est: Trajectory, truth: Trajectory, *,
                       nsigma: float = 3.0, color: Any = "tab:blue", events: Sequence[dict] = ()) -> Figure:
    """Errors in x [m], y [m] and yaw [deg] versus time, each inside its ±``nsigma``·σ bound from the
    estimator's own covariance, on three given axes; each title gives the fraction inside (a
    consistent Gaussian estimator: 99.7 % for 3σ)."""
    e, r = paired(est, truth)
    if e.cov is None:
        raise ValueError(f"{name}: the trajectory has no covariance")
    err = [e.x - r.x, e.y - r.y, np.degrees(wrap_angle(e.yaw - r.yaw))]
    var = np.stack([e.cov[:, 0, 0], e.cov[:, 1, 1], e.cov[:, 2, 2]])
    sig = np.sqrt(np.clip(var, 0, None)) * np.array([1.0, 1.0, np.degrees(1.0)])[:, None]
    for ax, lab, unit, ei, si in zip(axes, ("x", "y", "yaw"), ("m", "m", "deg"), err, sig, strict=True):
        ok = np.isfinite(si)
        _shade_events(ax, events, _span(truth))
        px = _columns(ax)
        ts, ss = thin_minmax(e.t, si, px)
        ax.fill_between(ts, -nsigma * ss, nsigma * ss, where=np.isfinite(ss), color=color, alpha=0.18, lw=0,
                        label=f"±{nsigma:g}σ")
        ax.plot(*thin_minmax(e.t, ei, px), "-", color=color, lw=0.9, label="error")
        ax.axhline(0, color="k", lw=0.5)
        inside = float(np.mean(np.abs(ei[ok]) <= nsigma * si[ok])) if ok.any() else float("nan")
        ax.set_title(f"{name}: {lab} error, {100 * inside:.1f} % inside ±{nsigma:g}σ", fontsize=9, y=1.0)
        ax.set_ylabel(f"{lab} error [{unit}]")
        # the axis follows the errors and the typical bound, not the largest bound (an odometry
        # estimator's bound grows without limit)
        v = np.concatenate([np.abs(ei), nsigma * si[ok]]) if ok.any() else np.abs(ei)
        lim = float(np.percentile(v, 99)) if len(v) else 1.0
        ax.set_ylim(-1.15 * max(lim, 1e-6), 1.15 * max(lim, 1e-6))
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    return axes[0].figure


def plot_error_bounds(trajs: dict[str, Trajectory] | Trajectory, truth: Trajectory, events: Sequence[dict] = (),
                      *, nsigma: float = 3.0, fig: Figure | None = None) -> Figure | None:
    """One row per estimator with covariances: x, y and yaw error with ±3σ bounds
    (:func:`error_bound_panels`); ``None`` when no trajectory carries covariances."""
    trajs = _as_dict(trajs)
    col = colors(list(trajs))
    with_cov = {n: t for n, t in trajs.items() if t.cov is not None and len(t)}
    if not with_cov:
        return None
    if fig is None:
        fig = _panel_figure(13, 2.3 * len(with_cov) + 0.6, len(with_cov), 3, hspace=0.45, wspace=0.75)
    axes = _shared_grid(fig, len(with_cov), 3)
    for row, (name, tr) in zip(axes, with_cov.items(), strict=True):
        error_bound_panels(row, name, tr, truth, nsigma=nsigma, color=col[name], events=events)
    _finish_grid(axes)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    axes[0, -1].legend(fontsize=8, loc="upper right")
    return fig


def nees_panel(ax: Axes, name: str, est: Trajectory, truth: Trajectory, *, color: Any = "tab:blue",
               window: int | None = None, events: Sequence[dict] = ()) -> Figure:
    """Position NEES versus time (dots) with its running mean over ``window`` samples (line; default
    2 % of the samples), the two-sided 95 % chi-square(2) band of one sample and the expected 2."""
    r = position_nees(est, truth)
    if r is None:
        raise ValueError(f"{name}: the trajectory has no covariance")
    t, v = r["t"], r["nees"]
    _shade_events(ax, events, _span(truth))
    ax.axhspan(*NEES_BAND, color="0.85", zorder=0, label="95 % band, χ²(2)")
    ax.axhline(2.0, color="k", lw=0.8, ls="--", label="expected (2)")
    if len(v):
        floor = 1e-4
        ax.plot(t, np.maximum(v, floor), ".", ms=1.5, color=color, alpha=0.35, zorder=2)
        w = window or max(5, len(v) // 50)
        if len(v) >= w:
            run = np.convolve(v, np.ones(w) / w, mode="valid")
            ax.plot(t[w // 2: w // 2 + len(run)], np.maximum(run, floor), "-", color=color, lw=1.5, zorder=3,
                    label=f"running mean ({w} samples)")
        inside = float(np.mean((v >= NEES_BAND[0]) & (v <= NEES_BAND[1])))
        ax.set_title(f"{name}: NEES mean {np.mean(v):.3g}, {100 * inside:.1f} % of samples in the 95 % band"
                     + (f" ({r['dropped']} without a usable covariance)" if r["dropped"] else ""), fontsize=9,
                     y=1.0)
        hi = max(float(np.percentile(v, 99.5)), NEES_BAND[1]) * 2
        lo = max(min(float(np.percentile(v, 1)), NEES_BAND[0]) / 2, floor)
        ax.set_ylim(lo, hi)
    else:
        ax.set_title(f"{name}: no NEES samples", fontsize=9, y=1.0)
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(FuncFormatter(lambda y, _: f"{y:g}"))
    ax.set_ylabel("NEES (log)")
    ax.set_xlabel("time [s]")
    ax.grid(alpha=0.3, which="both")
    _ticks_in_view(ax)
    return ax.figure


def plot_nees(trajs: dict[str, Trajectory] | Trajectory, truth: Trajectory, events: Sequence[dict] = (), *,
              fig: Figure | None = None, ax: Axes | None = None) -> Figure | None:
    """Position NEES over time, one row per estimator with covariances (:func:`nees_panel`); with
    ``ax``, the first such estimator on that axes. ``None`` when none carries covariances."""
    trajs = _as_dict(trajs)
    col = colors(list(trajs))
    with_cov = {n: t for n, t in trajs.items() if t.cov is not None and len(t)}
    if not with_cov:
        return None
    if ax is not None:
        name, tr = next(iter(with_cov.items()))
        return nees_panel(ax, name, tr, truth, color=col[name], events=events)
    if fig is None:
        fig = _panel_figure(11, 2.3 * len(with_cov) + 0.6, len(with_cov), 1, hspace=0.45)
    grid = _shared_grid(fig, len(with_cov), 1)
    axes = grid.ravel()
    for a, (name, tr) in zip(axes, with_cov.items(), strict=True):
        nees_panel(a, name, tr, truth, color=col[name], events=events)
    _finish_grid(grid)
    axes[0].legend(fontsize=8, loc="upper right", ncol=3)
    return fig


# -- covariance ellipses ------------------------------------------------------------------------------

def _nice_magnification(m: float) -> float:
    """1 when ellipses are already visible, else the next 1/2/5 x 10^k at or below ``m``."""
    if m <= 1.0:
        return 1.0
    k = 10 ** np.floor(np.log10(m))
    return float(max(s * k for s in (1, 2, 5) if s * k <= m))


def ellipse_magnification(tr: Trajectory, extent: float, *, n_ellipses: int = 25, nsigma: float = 2.0) -> float:
    """The magnification of one panel's ellipses: the median one about 2 % of the track's ``extent``,
    the largest at most 25 % of it; 1 (true scale) when they are already visible or larger."""
    idx = np.unique(np.linspace(0, len(tr) - 1, n_ellipses).astype(int))
    semi = np.array([np.sqrt(max(np.linalg.eigvalsh(c[:2, :2]).max(), 0.0)) for c in tr.cov[idx]
                     if np.all(np.isfinite(c[:2, :2]))])
    semi = semi[semi > 0]
    if not len(semi):
        return 1.0
    m = 0.02 * extent / (nsigma * float(np.median(semi)))
    m = min(m, 0.25 * extent / (nsigma * float(semi.max())))
    return _nice_magnification(m)


def covariance_panel(ax: Axes, name: str, tr: Trajectory, truth: Trajectory | None, *, n_ellipses: int = 25,
                     nsigma: float = 2.0, color: Any = "tab:blue") -> Figure:
    """``nsigma`` position ellipses at ``n_ellipses`` points along one trajectory, with this panel's
    own magnification (stated in the title) and view (its track and the truth, not the ellipses:
    ellipses larger than the track are clipped)."""
    xy = np.column_stack([tr.x, tr.y])
    if truth is not None and len(truth):
        inside = (truth.t >= tr.t[0] - MAX_DT) & (truth.t <= tr.t[-1] + MAX_DT)
        xy = np.vstack([xy, np.column_stack([truth.x[inside], truth.y[inside]])])
    (x0, x1), (y0, y1) = _limits(xy)
    cell = _pixel(ax, ((x0, x1), (y0, y1)))  # the lines drawn thinned to this panel's pixels
    if truth is not None and len(truth):
        ax.plot(*thin_xy(truth.x, truth.y, cell), "-", color="k", lw=1.2, label="truth")
    ax.plot(*thin_xy(tr.x, tr.y, cell), "-", color=color, lw=1.0, label=name)
    extent = max(x1 - x0, y1 - y0)
    mag = ellipse_magnification(tr, extent, n_ellipses=n_ellipses, nsigma=nsigma)
    idx = np.unique(np.linspace(0, len(tr) - 1, n_ellipses).astype(int))
    largest = 0.0
    for i in idx:
        c = tr.cov[i, :2, :2]
        if not np.all(np.isfinite(c)):
            continue
        w, v = np.linalg.eigh(0.5 * (c + c.T))
        w = np.clip(w, 0, None)
        largest = max(largest, nsigma * float(np.sqrt(w[1])))
        ang = np.degrees(np.arctan2(v[1, 1], v[0, 1]))
        a, b = 2 * mag * nsigma * np.sqrt(w[1]), 2 * mag * nsigma * np.sqrt(w[0])
        # (add_artist: the limits are set below, so no patch needs to stretch the data limits)
        ax.add_artist(Ellipse((tr.x[i], tr.y[i]), a, b, angle=ang, fill=False, color=color, lw=1.0))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (east) [m]")
    ax.set_ylabel("y (north) [m]")
    scale = f"magnified ×{mag:g}" if mag != 1 else "true scale"
    ax.set_title(f"{name}: {nsigma:g}σ ellipses ({scale}; largest {largest:.3g} m)", fontsize=9, y=1.0)
    ax.grid(alpha=0.3)
    _ticks_in_view(ax)
    ax.legend(fontsize=8, loc="best")
    return ax.figure


def plot_covariance(trajs: dict[str, Trajectory] | Trajectory, truth: Trajectory | None, *,
                    n_ellipses: int = 25, nsigma: float = 2.0, fig: Figure | None = None) -> Figure | None:
    """Position covariance ellipses, one panel per estimator with covariances, each with its own
    magnification and view (:func:`covariance_panel`); ``None`` when no trajectory carries covariances."""
    trajs = _as_dict(trajs)
    col = colors(list(trajs))
    with_cov = {n: t for n, t in trajs.items() if t.cov is not None and len(t)}
    if not with_cov:
        return None
    fig, axes = _grid(fig, len(with_cov), 3, (5.5, 5.0))
    for ax, (name, tr) in zip(axes.ravel(), with_cov.items(), strict=False):
        covariance_panel(ax, name, tr, truth, n_ellipses=n_ellipses, nsigma=nsigma, color=col[name])
    return fig
