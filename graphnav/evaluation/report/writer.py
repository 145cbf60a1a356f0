"""The one place a report touches the disk: every file of a rendered :class:`~.Report` through an
:class:`~graphnav.io.outputs.OutDir` (each atomically, its name in the manifest first).
:func:`write_drawing` writes a :class:`~.assemble.Draft` whose figures are still being drawn: the same
files in the same order, those that do not show the figures written (or prepared) while they draw."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ...io.geo_out import wgs84_texts, write_texts
from ...io.outputs import OutDir, atomic_path, write_text_atomic
from ...io.tum import write_truth, write_tum
from ...log import NavLog
from ...trajectory import Trajectory
from .assemble import Draft, finish
from .rendered import Report

#: the WGS84 files of a report, rendered and not yet written: (summary entry, {file name: text})
Wgs84 = tuple[dict[str, Any], dict[str, str]]


def write(report: Report, out: OutDir | str | Path) -> dict[str, Path]:
    """Write ``report`` into ``out``: one TUM per estimator (``.online.tum`` beside a smoother's),
    ``truth.tum``, the PNGs, ``report.md``, ``report.html``, the WGS84 tracks when the log has an
    origin, and ``map.html``. Returns ``{file name: path}``; ``report.wgs84`` is set to what
    :func:`~graphnav.io.geo_out.write_wgs84` says."""
    out = _directory(out)
    files = _write_tracks(report.tum, report.log, out)
    geo = wgs84_texts(report.geo_tracks, report.log.meta) if report.map_html is not None else None
    files.update(_write_pages(report, geo, out))
    return files


def write_drawing(draft: Draft, out: OutDir | str | Path) -> tuple[Report, dict[str, Path]]:
    """:func:`write` of ``finish(draft)``, the TUM files written and the WGS84 files rendered while the
    figures draw: the finished :class:`Report` and the files."""
    out = _directory(out)
    try:
        files = _write_tracks(draft.tum, draft.comp.log, out)
        geo = wgs84_texts(draft.geo_tracks, draft.comp.log.meta) if draft.map_html is not None else None
        report = finish(draft)
    finally:
        draft.figures.close()
    files.update(_write_pages(report, geo, out))
    return report, files


def _directory(out: OutDir | str | Path) -> OutDir | Path:
    if isinstance(out, OutDir):
        return out
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    return out


def _write_tracks(tum: dict[str, Trajectory], log: NavLog, out: OutDir | Path) -> dict[str, Path]:
    """The TUM files, then ``truth.tum``."""
    files: dict[str, Path] = {}
    for name, tr in tum.items():
        p = out / name
        write_tum(tr, p)
        files[name] = p
    truth_path = write_truth(log, out)
    if truth_path is not None:
        files[truth_path.name] = truth_path
    return files


def _write_pages(report: Report, geo: Wgs84 | None, out: OutDir | Path) -> dict[str, Path]:
    """The PNGs, ``report.md``, ``report.html``, then (with a map) the WGS84 files ``geo`` and ``map.html``."""
    files: dict[str, Path] = {}
    for name, (_, png) in report.images.items():
        with atomic_path(out / name) as tmp:
            tmp.write_bytes(png)
        files[name] = out / name
    files["report.md"] = write_text_atomic(out / "report.md", report.markdown)
    files["report.html"] = write_text_atomic(out / "report.html", report.html)
    if report.map_html is not None and geo is not None:
        report.wgs84 = write_texts(out, *geo)
        files.update({n: Path(str(out)) / n for n in (report.wgs84["wgs84"] or {}).get("files", [])})
        files["map.html"] = write_text_atomic(out / "map.html", report.map_html)
    return files
