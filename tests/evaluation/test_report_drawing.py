"""The report's parallel paths give what the serial one gives: the figures drawn in forked processes (the
panel figures first) are the same PNGs in the same order, and ``graphnav compare``'s writer, which writes
the TUM and WGS84 files while the figures draw, writes the same files in the same order."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from _polyworld import synthetic_log

from graphnav.evaluation.comparison import Comparison, compare
from graphnav.evaluation.report import assemble, render
from graphnav.evaluation.report.figures import PANEL_FIGURES, PendingFigures, figure_jobs, render_figures
from graphnav.evaluation.report.writer import write, write_drawing
from graphnav.io.outputs import OutDir


@pytest.fixture(scope="module")
def comp() -> Comparison:
    log = synthetic_log(30)
    log.meta["origin"] = {"lat": 50.8, "lon": -1.1, "h": 0.0}  # so that the WGS84 files are written
    return compare(log, ["dead-reckoning", "ekf", "icp-dr"], log_name="synthetic")


@pytest.fixture
def fixed_header(monkeypatch):
    """The provenance without its clock (the two renders run seconds apart)."""
    monkeypatch.setattr(assemble, "provenance", lambda log_path, command=None: {"command": str(command)})


def test_figures_in_two_processes_are_the_serial_pngs_in_order(comp):
    jobs = figure_jobs(comp)
    assert PANEL_FIGURES & {j[3] for j in jobs} and len(jobs) >= 5
    serial = render_figures(jobs, 1)
    parallel = render_figures(jobs, 2)
    assert list(parallel) == list(serial) == [j[3] for j in jobs]
    assert all(parallel[f] == serial[f] for f in serial)  # caption and PNG bytes


def test_pending_figures_can_be_closed_unfinished_and_give_one_result(comp):
    jobs = figure_jobs(comp)
    PendingFigures(jobs, 2).close()  # nothing left running, no error
    pending = PendingFigures(jobs, 2)
    first = pending.result()
    assert pending.result() is first and len(first) == len(jobs)


def test_writing_while_drawing_writes_the_serial_files(comp, tmp_path, fixed_header):
    files = write(render(comp, command="c", workers=1), OutDir(tmp_path / "serial", command="t"))
    report, drawn = write_drawing(assemble.start(comp, command="c", workers=2), OutDir(tmp_path / "drawn", command="t"))
    assert list(drawn) == list(files)  # the same names in the same order
    assert {"ekf.tum", "truth.tum", "nees.png", "report.html", "trajectory.gpx", "map.html"} <= set(files)
    for name in files:
        assert (tmp_path / "drawn" / name).read_bytes() == (tmp_path / "serial" / name).read_bytes(), name
    manifest = [json.loads(Path(tmp_path / d / ".graphnav-outputs.json").read_text())["files"]
                for d in ("serial", "drawn")]
    assert manifest[0] == manifest[1] == list(files)
    assert report.wgs84 is not None and report.wgs84["wgs84"]["files"] == ["trajectory.geojson", "trajectory.gpx",
                                                                            "trajectory.kml"]
