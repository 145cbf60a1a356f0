"""A comparison as a report, in memory: :func:`render` turns a
:class:`~graphnav.evaluation.comparison.Comparison` into a :class:`Report` (Markdown, one self-contained
HTML page, the PNG figures, the track map, the trajectories to write), and
:func:`~.writer.write` persists it through an :class:`~graphnav.io.outputs.OutDir` — the only step
that touches the disk (evo's core/tools split: metrics -> comparison -> report -> writer).

``report.html`` is self-contained, to send to a colleague: the figures are inlined as base64 PNG,
the style sheet is inline, there is no script, and its Content-Security-Policy forbids any network
load. Both reports are rendered from one list of blocks, so they say the same thing.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ...log import NavLog
from ...trajectory import Trajectory
from ..comparison import Comparison, Entry
from .provenance import provenance
from .render import render_html, render_markdown
from .rendered import Report
from .text import (
    COLUMNS,
    _config,
    blocks,
    event_table,
    file_stem,
    markdown_table,
    results_table,
    summary_lines,
    to_json,
    warnings,
)

__all__ = ["COLUMNS", "Report", "_config", "event_table", "file_stem", "markdown_table", "provenance", "render",
           "results_table", "summary_lines", "to_json", "warnings", "write_report"]


def render(comp: Comparison, *, command: str | None = None, log_path: str | Path | None = None,
           workers: int = 1, track_map: bool = True, tiles: str | None = None) -> Report:
    """Render ``comp``: figures (in ``workers`` processes; 0: one per core), the blocks of the text,
    Markdown, HTML and, with ``track_map``, map.html (``tiles``: a {z}/{x}/{y} URL template drawn
    under the tracks). ``command`` and ``log_path`` (default: the log's name when it names a file)
    go into the provenance header."""
    from ..trackmap import track_map_html
    from .figures import figure_jobs, render_figures

    images = render_figures(figure_jobs(comp), workers)
    if log_path is None and comp.log_name and Path(comp.log_name).exists():
        log_path = comp.log_name
    has_truth = comp.log.has_truth
    b = blocks(comp, provenance(log_path, command), [(cap, f) for f, (cap, _) in images.items()],
               "truth.tum" if has_truth else None)
    tum: dict[str, Trajectory] = {}
    for e in comp.ran:
        tum[f"{file_stem(e.name)}.tum"] = e.result.trajectory
        onl = e.result.online
        if onl is not None and onl is not e.result.trajectory and len(onl):
            tum[f"{file_stem(e.name)}.online.tum"] = onl
    rep = Report(comp.log, render_markdown(b), render_html(b, {f: png for f, (_, png) in images.items()}),
                 images, tum)
    if track_map:
        rep.geo_tracks = {**({"truth": comp.log.truth()} if has_truth else {}), **comp.trajectories()}
        whole = comp.whole_log if comp.whole_log is not None else comp.log
        fixes = None
        if whole.of("gnss"):
            g = whole.columns("gnss")
            fixes = np.column_stack([g["x"], g["y"]])
        rep.map_html = track_map_html(rep.geo_tracks, comp.log.meta, title=f"Tracks: {comp.log_name}", tiles=tiles,
                                      gnss=fixes)
    return rep


def write_report(entries: Sequence[Entry] | Comparison, log: NavLog, out: Any, *, log_name: str = "",
                 command: str | None = None, log_path: str | Path | None = None, workers: int = 1) -> dict[str, Path]:
    """Render and write report.md, report.html, the PNGs, one TUM file per estimator and truth.tum into
    ``out`` (no map); returns the paths. ``entries`` may be a plain list (as :func:`compare` gave before
    it returned a :class:`Comparison`)."""
    from .writer import write

    comp = entries if isinstance(entries, Comparison) else Comparison(
        list(entries), log, log_name=log_name or str(log.meta.get("name", "log")))
    if log_name:
        comp.log_name = log_name
    return write(render(comp, command=command, log_path=log_path, workers=workers, track_map=False), out)
