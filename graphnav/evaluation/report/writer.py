"""The one place a report touches the disk: every file of a rendered :class:`~.Report` through an
:class:`~graphnav.io.outputs.OutDir` (each atomically, its name in the manifest first)."""

from __future__ import annotations

from pathlib import Path

from ...io.geo_out import write_wgs84
from ...io.outputs import OutDir, atomic_path, write_text_atomic
from ...io.tum import write_truth, write_tum
from .rendered import Report


def write(report: Report, out: OutDir | str | Path) -> dict[str, Path]:
    """Write ``report`` into ``out``: one TUM per estimator (``.online.tum`` beside a smoother's),
    ``truth.tum``, the PNGs, ``report.md``, ``report.html``, the WGS84 tracks when the log has an
    origin, and ``map.html``. Returns ``{file name: path}``; ``report.wgs84`` is set to what
    :func:`~graphnav.io.geo_out.write_wgs84` says."""
    if not isinstance(out, OutDir):
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
    files: dict[str, Path] = {}
    for name, tr in report.tum.items():
        p = out / name
        write_tum(tr, p)
        files[name] = p
    truth_path = write_truth(report.log, out)
    if truth_path is not None:
        files[truth_path.name] = truth_path
    for name, (_, png) in report.images.items():
        with atomic_path(out / name) as tmp:
            tmp.write_bytes(png)
        files[name] = out / name
    files["report.md"] = write_text_atomic(out / "report.md", report.markdown)
    files["report.html"] = write_text_atomic(out / "report.html", report.html)
    if report.map_html is not None:
        report.wgs84 = write_wgs84(out, report.geo_tracks, report.log.meta)
        files.update({n: Path(str(out)) / n for n in (report.wgs84["wgs84"] or {}).get("files", [])})
        files["map.html"] = write_text_atomic(out / "map.html", report.map_html)
    return files
