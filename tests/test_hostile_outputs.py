"""Issue #27 (4, 5, 7): one owner per output. ``--out`` directories are locked for the run (a second
run gets exit 2 naming the holder); logs written by ``simulate``/``convert`` go through the atomic
writer and are not replaced without ``--overwrite``; nothing but a regular file is ever replaced
(no FIFO, symlink or device); ``export`` refuses times and positions that are no date or place, and
a ``summary.json`` nested without bound."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np
import pytest

from graphnav.cli import main
from graphnav.errors import GraphnavError
from graphnav.io import load_log, save_log
from graphnav.io.geo_out import GeoTrack, render
from graphnav.io.outputs import OutDir, check_replaceable, file_kind
from graphnav.io.tum import write_tum
from graphnav.log import Gnss, NavLog
from graphnav.trajectory import Trajectory

REPO = Path(__file__).resolve().parents[1]


def cli(*argv: str) -> tuple[int, dict | None]:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = main([*argv, "--json"])
    text = out.getvalue().strip()
    return code, (json.loads(text) if text else None)


def small_log() -> NavLog:
    return NavLog([Gnss(t=float(k), x=float(k), y=0.0, sigma=1.0) for k in range(5)], [], {})


# -- (4) --out locked --------------------------------------------------------------------------------------

def test_a_second_process_on_the_same_out_gets_exit_2_naming_the_holder(tmp_path):
    out = tmp_path / "out"
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from graphnav.io.outputs import OutDir; "
                               f"d = OutDir({str(out)!r}, command='run'); print('held', flush=True); "
                               "sys.stdin.readline()"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=REPO)
    try:
        assert holder.stdout.readline().strip() == "held"
        log = tmp_path / "l.jsonl"
        save_log(small_log(), log)
        r = subprocess.run([sys.executable, "-m", "graphnav", "run", str(log), "-e", "dead-reckoning", "--out",
                            str(out), "--overwrite", "--json"], capture_output=True, text=True, cwd=REPO, timeout=120)
        assert r.returncode == 2, r.stderr
        obj = json.loads(r.stdout)
        assert obj["where"] == str(out) and f"process {holder.pid}" in obj["error"] and "graphnav run" in obj["error"]
    finally:
        holder.communicate("\n", timeout=30)
    d = OutDir(out, command="run", overwrite=True)  # released when the holder ended
    d.close()


def test_the_same_process_may_open_its_out_again(tmp_path):
    a = OutDir(tmp_path / "o", command="run")
    a.write_text("x.txt", "1")
    b = OutDir(tmp_path / "o", command="run", overwrite=True)
    b.close()
    a.close()


# -- (5) atomic logs, --overwrite, only regular files replaced ---------------------------------------------

@pytest.mark.parametrize("name", ["l.jsonl", "l.jsonl.gz", "l.npz"])
def test_save_log_refuses_to_replace_without_overwrite_and_is_atomic(tmp_path, name):
    p = tmp_path / name
    save_log(small_log(), p)
    before = p.read_bytes()
    with pytest.raises(GraphnavError, match="--overwrite"):
        save_log(small_log(), p, overwrite=False)
    assert p.read_bytes() == before
    save_log(NavLog([Gnss(t=9.0, x=1.0, y=1.0, sigma=2.0)], [], {}), p, overwrite=True)
    assert len(load_log(p)) == 1
    assert [e.name for e in tmp_path.iterdir()] == [name]  # no temporary file left


def test_a_failed_write_keeps_the_earlier_log(tmp_path, monkeypatch):
    p = tmp_path / "l.jsonl.gz"
    save_log(small_log(), p)
    before = p.read_bytes()
    import graphnav.io.jsonl as jsonl

    def boom(*_a, **_k):
        raise KeyboardInterrupt  # a kill in the middle of the write

    monkeypatch.setattr(jsonl, "_write", boom)
    with pytest.raises(KeyboardInterrupt):
        save_log(small_log(), p, overwrite=True)
    assert p.read_bytes() == before and [e.name for e in tmp_path.iterdir()] == ["l.jsonl.gz"]


def _specials(tmp_path: Path) -> dict[str, Path]:
    target = tmp_path / "target.txt"
    target.write_text("keep me")
    link = tmp_path / "link.jsonl"
    link.symlink_to(target)
    fifo = tmp_path / "fifo.jsonl"
    os.mkfifo(fifo)
    return {"symbolic link": link, "FIFO": fifo, "directory": tmp_path / "dir.jsonl"}


def test_nothing_but_a_regular_file_is_replaced(tmp_path):
    paths = _specials(tmp_path)
    paths["directory"].mkdir()
    for kind, p in paths.items():
        assert file_kind(p) == kind
        with pytest.raises(GraphnavError, match=f"is a {kind}"):
            save_log(small_log(), p, overwrite=True)
        with pytest.raises(GraphnavError, match=f"is a {kind}"):
            check_replaceable(p, overwrite=True)
    assert (tmp_path / "target.txt").read_text() == "keep me"
    assert file_kind("/dev/null") == "device"


def test_simulate_and_convert_refuse_an_existing_log(tmp_path):
    out = tmp_path / "s.jsonl"
    args = ["simulate", "harbour", "--duration", "5", "--lidar-hz", "0", "--out", str(out)]
    assert cli(*args)[0] == 0
    before = out.read_bytes()
    code, obj = cli(*args)
    assert code == 2 and "--overwrite" in obj["error"] and obj["where"] == str(out)
    assert out.read_bytes() == before
    assert cli(*args, "--overwrite")[0] == 0
    fifo = tmp_path / "f.jsonl"
    os.mkfifo(fifo)
    code, obj = cli("simulate", "harbour", "--duration", "5", "--out", str(fifo), "--overwrite")
    assert code == 2 and "FIFO" in obj["error"]
    carmen = tmp_path / "c.log"
    carmen.write_text("FLASER 3 1.0 2.0 3.0 0 0 0 0 0 0 1.0 host 1.0\n")
    code, obj = cli("convert", "carmen", str(carmen), "--out", str(out))
    assert code == 2 and "--overwrite" in obj["error"] and out.read_bytes() != b""


def test_export_onto_a_fifo_or_symlink_is_refused(tmp_path):
    log = tmp_path / "l.jsonl"
    save_log(NavLog([Gnss(t=float(k), x=float(k), y=0.0, sigma=1.0) for k in range(5)], [],
                    {"origin": {"lat": 54.5, "lon": 18.5, "h": 0.0}}), log)
    for kind, p in _specials(tmp_path).items():
        if kind == "directory":
            continue
        code, obj = cli("export", str(log), "--out", str(p), "--to", "gpx", "--overwrite")
        assert code == 2 and kind in obj["error"], obj
    assert (tmp_path / "target.txt").read_text() == "keep me"


# -- (6, 7) export: no NaN, no 1e300 dates, no NUL in XML, bounded summary.json -------------------------

def _run_dir(tmp_path: Path, t: np.ndarray, x: np.ndarray, name: str = "ekf") -> Path:
    d = tmp_path / "run"
    d.mkdir()
    write_tum(Trajectory(t, np.column_stack([x, np.zeros_like(x), np.zeros_like(x)]), name=name), d / "trajectory.tum")
    (d / "summary.json").write_text(json.dumps({"estimator": name, "origin": {"lat": 54.5, "lon": 18.5, "h": 0.0}}))
    return d


@pytest.mark.parametrize("fmt", ["gpx", "kml", "geojson", "nmea"])
def test_export_time_beyond_a_date_is_exit_2(tmp_path, fmt):
    d = _run_dir(tmp_path, np.array([0.0, 1e300]), np.array([0.0, 1.0]))
    code, obj = cli("export", str(d), "--out", str(tmp_path / f"x.{fmt}"), "--to", fmt)
    assert code == 2 and "not a date" in obj["error"] and not (tmp_path / f"x.{fmt}").exists()


def test_export_position_off_the_earth_is_exit_2(tmp_path):
    d = _run_dir(tmp_path, np.array([0.0, 1.0]), np.array([0.0, 1e300]))
    code, obj = cli("export", str(d), "--out", str(tmp_path / "x.gpx"))
    assert code == 2 and "not a place on Earth" in obj["error"]


def test_export_summary_nested_without_bound(tmp_path):
    d = _run_dir(tmp_path, np.array([0.0, 1.0]), np.array([0.0, 1.0]))
    (d / "summary.json").write_text("[" * 100_000 + "]" * 100_000)
    code, obj = cli("export", str(d), "--out", str(tmp_path / "x.kml"))
    assert code == 2 and obj["where"] == str(d / "summary.json")


def test_gpx_and_kml_never_hold_nan_or_nul(tmp_path):
    from graphnav.geodesy import LocalFrame

    frame = LocalFrame(54.5, 18.5, 0.0)
    traj = Trajectory(np.array([0.0, 1.0, 2.0, 3.0]), np.array([[0, 0, 0], [1e300, 0, 0], [np.nan, 0, 0], [1, 1, 0]],
                                                               dtype=float), name="ekf\x00bad")
    tr = GeoTrack.from_trajectory(traj, frame)
    assert len(tr.t) == 2 and tr.name == "ekfbad"
    for fmt in ("gpx", "kml"):
        text = render([tr], fmt)
        assert "nan" not in text.lower() and "\x00" not in text
    import xml.etree.ElementTree as ET

    ET.fromstring(render([tr], "gpx").encode())  # well-formed XML
