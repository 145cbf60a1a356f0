"""The report's figures, drawn to PNG bytes in memory (in forked processes when asked): which figures a
comparison gets, their captions, and the drawing."""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .. import plots
from ..comparison import Comparison

#: (plot function, args, kwargs, file name, caption)
Job = tuple[Any, tuple, dict, str, str]


def figure_jobs(comp: Comparison) -> list[Job]:
    """The figures of a comparison (nothing drawn yet): with truth, the error figures; without,
    the tracks over the GNSS fixes and the GNSS residuals."""
    log = comp.log
    ok = comp.ran
    trajs = comp.trajectories()
    truth = log.truth() if log.has_truth else None
    events = log.meta.get("events", []) or []
    gnss = None
    if log.of("gnss"):
        c = log.columns("gnss")
        gnss = np.column_stack([c["x"], c["y"]])
    jobs: list[Job] = []

    def put(fn: Any, args: tuple, fname: str, caption: str, **kw: Any) -> None:
        jobs.append((fn, args, kw, fname, caption))

    if trajs:
        name = Path(comp.log_name).name or comp.log_name
        title = (f"Trajectories over the truth — {name}" if truth is not None else
                 f"Trajectories (no truth) over the GNSS fixes — {name}")
        put(plots.plot_trajectories, (trajs, truth, gnss), "trajectories.png",
            "Trajectories" if truth is not None else "Trajectories (no truth)", title=title)
        loops = {e.name: e.result.info["loop_edge_times"] for e in ok if e.result.info.get("loop_edge_times")}
        put(plots.plot_trajectory_panels, (trajs, truth), "trajectory_panels.png",
            ("Each estimator over the truth (coloured by position error) and its largest error close up"
             if truth is not None else "Each estimator on its own (no truth: no error to colour by)")
            + (" (orange: accepted loop closures)" if loops else ""), loops=loops)
        if truth is not None:
            online = {e.name: e.result.online for e in ok
                      if e.result.online is not None and e.result.online is not e.result.trajectory}
            put(plots.plot_position_error, (trajs, truth, events, online), "position_error.png",
                "Position error versus time (smoothers: online estimate dashed)")
            put(plots.plot_heading_error, (trajs, truth, events), "heading_error.png", "Heading error versus time")
            put(plots.plot_error_cdf, (trajs, truth), "error_cdf.png", "Error CDF")
            put(plots.plot_sog_cog, (trajs, truth, events), "sog_cog.png",
                "SOG, COG and ΔCOG errors (weighted-ICP paper, Figs. 12-15 style)")
            put(plots.plot_error_bounds, (trajs, truth, events), "error_bounds.png",
                "Errors in x, y and yaw with the estimators' own ±3σ bounds")
            put(plots.plot_nees, (trajs, truth, events), "nees.png",
                "Position NEES over time with its 95 % chi-square band (2 dof)")
        else:
            whole = comp.whole_log if comp.whole_log is not None else log
            if whole.of("gnss"):
                wins = comp.holdout.windows if comp.holdout is not None else []
                put(plots.plot_gnss_residuals, (trajs, whole.columns("gnss"), wins), "gnss_residuals.png",
                    "No truth: each estimate's distance to the GNSS fixes"
                    + (" (shaded: hold-out windows, whose fixes the estimators did not see)" if wins else ""))
        put(plots.plot_covariance, (trajs, truth), "covariance.png",
            "Covariance ellipses (2σ, each panel its own scale)")
    return jobs


def png_bytes(fig: Any, dpi: int = 110) -> bytes:
    """``fig`` as PNG bytes (what :func:`graphnav.evaluation.plots.save` writes to a file)."""
    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png")
    return buf.getvalue()


_FIG_JOBS: list[Job] = []  # what forked figure workers render (set before forking)

#: the figures with a panel per estimator: several times the others' CPU (drawn first in parallel)
PANEL_FIGURES = frozenset({"trajectory_panels.png", "sog_cog.png", "error_bounds.png", "nees.png",
                           "covariance.png"})


def _render(i: int) -> bytes | None:
    """Draw figure ``i`` of :data:`_FIG_JOBS`: its PNG, or ``None`` when there was nothing to draw."""
    fn, args, kw, _, _ = _FIG_JOBS[i]
    fig = fn(*args, **kw)
    return None if fig is None else png_bytes(fig)


class PendingFigures:
    """Figures being drawn in ``workers`` forked processes (those with a panel per estimator first),
    while the caller goes on with other work; :meth:`result` waits for them. With one worker (or one
    figure) they are drawn in this process when :meth:`result` asks; 0 workers: one per core."""

    def __init__(self, jobs: Sequence[Job], workers: int = 1) -> None:
        global _FIG_JOBS
        self.jobs = list(jobs)
        self._pool: Any = None
        self._futures: dict[int, Any] = {}
        self._done: dict[str, tuple[str, bytes]] | None = None
        if workers <= 0:
            workers = os.cpu_count() or 1
        if workers > 1 and len(self.jobs) > 1:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            _FIG_JOBS = self.jobs  # the workers fork at the first submit and inherit it
            self._pool = ProcessPoolExecutor(max_workers=min(workers, len(self.jobs)),
                                             mp_context=multiprocessing.get_context("fork"))
            order = sorted(range(len(self.jobs)), key=lambda i: self.jobs[i][3] not in PANEL_FIGURES)
            self._futures = {i: self._pool.submit(_render, i) for i in order}

    def result(self) -> dict[str, tuple[str, bytes]]:
        """``{file name: (caption, PNG bytes)}`` in the jobs' order, without the jobs that drew nothing."""
        global _FIG_JOBS
        if self._done is None:
            try:
                if self._pool is not None:
                    pngs = [self._futures[i].result() for i in range(len(self.jobs))]
                else:
                    _FIG_JOBS = self.jobs
                    pngs = [_render(i) for i in range(len(self.jobs))]
            finally:
                self.close()
            self._done = {job[3]: (job[4], png) for job, png in zip(self.jobs, pngs, strict=True)
                          if png is not None}
        return self._done

    def close(self) -> None:
        """Stop the workers: the figures being drawn are finished, the others not started."""
        global _FIG_JOBS
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None
        _FIG_JOBS = []


def render_figures(jobs: Sequence[Job], workers: int = 1) -> dict[str, tuple[str, bytes]]:
    """Draw each job: ``{file name: (caption, PNG bytes)}`` in the jobs' order, without the jobs that
    drew nothing. ``workers > 1`` draws them in that many forked processes (the figures are
    independent; the PNGs are the same), those with a panel per estimator first; 0: one per core."""
    return PendingFigures(jobs, workers).result()
