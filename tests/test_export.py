"""`graphnav export`: a run directory or a log's truth/GNSS as NMEA (parsed back with pynmea2 against
the trajectory), GeoJSON, GPX; never without a geodetic origin."""

from __future__ import annotations

import json
import math
from datetime import UTC, datetime
from pathlib import Path

import gpxpy
import numpy as np
import pynmea2

from graphnav import cli
from graphnav.geodesy import LocalFrame
from graphnav.geometry import yaw_to_heading_deg
from graphnav.io import load_log
from graphnav.io.nmea import KNOT
from graphnav.io.tum import read_tum

ORIGIN = {"lat": 59.91, "lon": 10.73, "h": 0.0}
FRAME = LocalFrame(ORIGIN["lat"], ORIGIN["lon"])
T0 = 1.7e9


def turning_log(tmp_path: Path, origin: dict | None = ORIGIN, n: int = 60) -> Path:
    """Truth on a circle of radius 200 m at 3 m/s (POSIX times), odometry and GNSS along it."""
    p = tmp_path / ("turn.jsonl" if origin else "turn-no-origin.jsonl")
    w = 3.0 / 200.0
    recs = [{"type": "meta", "name": "turn", **({"origin": origin} if origin else {})}]
    for k in range(n):
        t = T0 + 1.0 * k
        a = w * (t - T0)
        x, y, yaw = 200.0 * math.sin(a), 200.0 * (1 - math.cos(a)), a
        recs += [{"t": t, "type": "truth", "x": x, "y": y, "yaw": yaw},
                 {"t": t, "type": "odometry", "v": 3.0, "w": w, "sigma_v": 0.1, "sigma_w": 0.01},
                 {"t": t, "type": "gnss", "x": x + 0.3, "y": y - 0.2, "sigma": 1.0}]
    p.write_text("".join(json.dumps(r) + "\n" for r in recs))
    return p


def export(capsys, *argv: str) -> tuple[int, dict]:
    rc = cli.main(["export", *argv, "--json"])
    out = capsys.readouterr().out
    return rc, json.loads(out)


def test_nmea_from_a_log_truth_parses_back_to_the_trajectory(tmp_path, capsys):
    log = turning_log(tmp_path)
    out = tmp_path / "truth.nmea"
    rc, obj = export(capsys, str(log), "--to", "nmea", "--out", str(out))
    assert rc == 0 and obj["source"] == "truth" and obj["kind"] == "log" and obj["origin"] == ORIGIN
    truth = load_log(log).truth()
    raw = out.read_bytes().decode("ascii")
    assert raw.endswith("\r\n")
    msgs = [pynmea2.parse(s, check=True) for s in raw.split("\r\n") if s]
    kinds = [m.sentence_type for m in msgs]
    assert obj["sentences"] == len(msgs) and {k: kinds.count(k) for k in set(kinds)} == {
        "GGA": len(truth), "RMC": len(truth), "HDT": len(truth), "VTG": len(truth)}
    lat, lon = FRAME.to_geodetic(truth.x, truth.y)
    gga = [m for m in msgs if m.sentence_type == "GGA"]
    assert np.max(np.abs(np.array([m.latitude for m in gga]) - lat)) < 1e-6
    assert np.max(np.abs(np.array([m.longitude for m in gga]) - lon)) < 1e-6
    hdt = np.array([float(m.heading) for m in msgs if m.sentence_type == "HDT"])
    dh = (hdt - yaw_to_heading_deg(truth.yaw) + 180.0) % 360.0 - 180.0
    assert np.max(np.abs(dh)) <= 0.005 + 1e-9
    # SOG/COG from the trajectory's steps: a chord of the circle, 3 m/s * sinc(w/2)
    w = 3.0 / 200.0
    chord = 3.0 * math.sin(w / 2) / (w / 2)
    rmc = [m for m in msgs if m.sentence_type == "RMC"]
    vtg = [m for m in msgs if m.sentence_type == "VTG"]
    np.testing.assert_allclose([float(m.spd_over_grnd) * KNOT for m in rmc], chord, atol=0.0005 * KNOT)
    np.testing.assert_allclose([float(m.spd_over_grnd_kts) * KNOT for m in vtg], chord, atol=0.0005 * KNOT)
    d = np.diff(truth.poses[:, :2], axis=0)
    cog = yaw_to_heading_deg(np.arctan2(d[:, 1], d[:, 0]))
    dc = (np.array([float(m.true_track) for m in vtg])[:-1] - cog + 180.0) % 360.0 - 180.0
    assert np.max(np.abs(dc)) <= 0.005 + 1e-9
    # time and date (RMC) give the trajectory's POSIX times back
    ts = [datetime.combine(m.datestamp, m.timestamp).replace(tzinfo=UTC).timestamp() for m in rmc]
    np.testing.assert_allclose(ts, truth.t, atol=1e-3)


def test_nmea_reads_back_through_graphnav(tmp_path, capsys):
    log = turning_log(tmp_path)
    out = tmp_path / "t.nmea"
    assert export(capsys, str(log), "--out", str(out))[0] == 0  # format from the suffix
    back = load_log(out, origin=(ORIGIN["lat"], ORIGIN["lon"]))
    truth = load_log(log).truth()
    g = back.columns("gnss")
    assert np.max(np.abs(g["x"] - truth.x)) < 1e-3 and np.max(np.abs(g["y"] - truth.y)) < 1e-3
    np.testing.assert_allclose(g["t"], truth.t, atol=1e-3)


def test_gnss_source_has_no_heading(tmp_path, capsys):
    log = turning_log(tmp_path)
    out = tmp_path / "g.nmea"
    rc, obj = export(capsys, str(log), "--source", "gnss", "--to", "nmea", "--out", str(out))
    assert rc == 0 and obj["source"] == "gnss" and "no heading" in obj["heading"]
    kinds = [pynmea2.parse(s).sentence_type for s in out.read_text().split()]
    assert "HDT" not in kinds and kinds.count("GGA") == 60
    gj = tmp_path / "g.geojson"
    rc, obj = export(capsys, str(log), "--source", "gnss", "--out", str(gj))
    pts = [f for f in json.loads(gj.read_text())["features"] if f["geometry"]["type"] == "Point"]
    assert len(pts) == 60 and all("heading_deg" not in f["properties"] for f in pts)


def test_run_dir_exports_the_estimate_with_the_recorded_origin(tmp_path, capsys):
    log, run_dir = turning_log(tmp_path), tmp_path / "run"
    assert cli.main(["run", str(log), "-e", "dead-reckoning", "--out", str(run_dir), "--json"]) == 0
    capsys.readouterr()
    out = tmp_path / "run.gpx"
    rc, obj = export(capsys, str(run_dir), "--to", "gpx", "--out", str(out))
    assert rc == 0 and obj["kind"] == "run" and obj["track"] == "dead-reckoning" and obj["origin"] == ORIGIN
    est = read_tum(run_dir / "trajectory.tum")
    lat, lon = FRAME.to_geodetic(est.x, est.y)
    pts = gpxpy.parse(out.read_text()).tracks[0].segments[0].points
    assert np.max(np.abs(np.array([p.latitude for p in pts]) - lat)) < 1e-6
    assert np.max(np.abs(np.array([p.longitude for p in pts]) - lon)) < 1e-6
    rc, _ = export(capsys, str(run_dir), "--to", "gpx", "--out", str(out))
    assert rc == 2  # exists: --overwrite needed
    assert export(capsys, str(run_dir), "--to", "kml", "--out", str(out), "--overwrite")[0] == 0


def test_no_origin_is_a_clean_error_and_writes_nothing(tmp_path, capsys):
    log, run_dir = turning_log(tmp_path, origin=None), tmp_path / "run"
    rc, obj = export(capsys, str(log), "--to", "nmea", "--out", str(tmp_path / "x.nmea"))
    assert rc == 2 and "no geodetic origin" in obj["error"] and not (tmp_path / "x.nmea").exists()
    assert cli.main(["run", str(log), "-e", "dead-reckoning", "--out", str(run_dir), "--json"]) == 0
    capsys.readouterr()
    rc, obj = export(capsys, str(run_dir), "--to", "geojson", "--out", str(tmp_path / "x.geojson"))
    assert rc == 2 and "no geodetic origin" in obj["error"] and obj["where"].endswith("summary.json")
    assert not (tmp_path / "x.geojson").exists()


def test_bad_out_is_a_clean_error(tmp_path, capsys):
    log = turning_log(tmp_path)
    rc, obj = export(capsys, str(log), "--to", "nmea", "--out", str(tmp_path / "no" / "x.nmea"))
    assert rc == 2 and "does not exist" in obj["error"]
    rc, obj = export(capsys, str(log), "--out", str(tmp_path / "x.unknown"))
    assert rc == 2 and "--to" in obj["error"]
