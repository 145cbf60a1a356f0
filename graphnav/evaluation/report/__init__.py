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

from ...log import NavLog
from ..comparison import Comparison, Entry
from .provenance import provenance
from .rendered import Report
from .text import (
    COLUMNS,
    _config,
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
    from .assemble import finish, start

    return finish(start(comp, command=command, log_path=log_path, workers=workers, track_map=track_map, tiles=tiles))


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
