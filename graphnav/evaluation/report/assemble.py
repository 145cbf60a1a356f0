"""A report rendered in two steps, so that its figures draw (in forked processes) while the caller does
other work: :func:`start` starts the figures and builds what does not show them (the trajectories to
write, the tracks and ``map.html``); :func:`finish` waits for the figures and renders the text.
:func:`~graphnav.evaluation.report.render` is the two in a row; ``graphnav compare`` writes the TUM
and WGS84 files between them (:func:`~.writer.write_drawing`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...trajectory import Trajectory
from ..comparison import Comparison
from .figures import PendingFigures, figure_jobs
from .provenance import provenance
from .render import render_html, render_markdown
from .rendered import Report
from .text import blocks, file_stem


@dataclass
class Draft:
    """A report whose figures are being drawn: everything else it needs, ready. ``header``: the
    provenance; ``tum``: file name ->
    trajectory; ``geo_tracks``: the tracks of the map and the WGS84 files (truth first); ``map_html``
    ``None`` when no map was asked."""

    comp: Comparison
    figures: PendingFigures
    header: dict[str, str]
    tum: dict[str, Trajectory]
    geo_tracks: dict[str, Trajectory] = field(default_factory=dict)
    map_html: str | None = None


def start(comp: Comparison, *, command: str | None = None, log_path: str | Path | None = None,
          workers: int = 1, track_map: bool = True, tiles: str | None = None) -> Draft:
    """Start drawing ``comp``'s figures (in ``workers`` processes; 0: one per core; 1: when
    :func:`finish` asks) and build the rest (arguments as :func:`~graphnav.evaluation.report.render`'s)."""
    from ..trackmap import track_map_html

    figures = PendingFigures(figure_jobs(comp), workers)
    if log_path is None and comp.log_name and Path(comp.log_name).exists():
        log_path = comp.log_name
    tum: dict[str, Trajectory] = {}
    for e in comp.ran:
        tum[f"{file_stem(e.name)}.tum"] = e.result.trajectory
        onl = e.result.online
        if onl is not None and onl is not e.result.trajectory and len(onl):
            tum[f"{file_stem(e.name)}.online.tum"] = onl
    draft = Draft(comp, figures, provenance(log_path, command), tum)
    if track_map:
        draft.geo_tracks = {**({"truth": comp.log.truth()} if comp.log.has_truth else {}), **comp.trajectories()}
        whole = comp.whole_log if comp.whole_log is not None else comp.log
        fixes = None
        if whole.of("gnss"):
            g = whole.columns("gnss")
            fixes = np.column_stack([g["x"], g["y"]])
        draft.map_html = track_map_html(draft.geo_tracks, comp.log.meta, title=f"Tracks: {comp.log_name}",
                                        tiles=tiles, gnss=fixes)
    return draft


def finish(draft: Draft) -> Report:
    """Wait for the figures and render the Markdown and HTML around them: the :class:`Report`."""
    comp = draft.comp
    images = draft.figures.result()
    b = blocks(comp, draft.header, [(cap, f) for f, (cap, _) in images.items()],
               "truth.tum" if comp.log.has_truth else None)
    return Report(comp.log, render_markdown(b), render_html(b, {f: png for f, (_, png) in images.items()}),
                  images, draft.tum, draft.map_html, draft.geo_tracks)
