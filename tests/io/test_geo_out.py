"""WGS84 track files (graphnav.io.geo_out): GeoJSON structure and coordinate order, GPX and KML read
back to the truth's positions, and `graphnav run/compare --out` writing them only with an origin."""

from __future__ import annotations

import json
import math
import re
import xml.etree.ElementTree as ET
from datetime import UTC, datetime
from pathlib import Path

import gpxpy
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from graphnav import cli
from graphnav.geodesy import LocalFrame, origin_frame
from graphnav.io.geo_out import GeoTrack, geojson, gpx_text, kml_text, render, write_wgs84
from graphnav.io.outputs import MANIFEST
from graphnav.io.tum import read_tum
from graphnav.trajectory import Trajectory

ORIGIN = {"lat": 54.52, "lon": 18.55, "h": 0.0}  # Gdynia: lat and lon far apart, so a swap shows
FRAME = LocalFrame(ORIGIN["lat"], ORIGIN["lon"])


def square_track(n: int = 41) -> Trajectory:
    """From the origin 400 m north, then east; yaw along the path; POSIX times."""
    s = np.linspace(0.0, 800.0, n)
    x, y = np.clip(s - 400.0, 0.0, None), np.minimum(s, 400.0)
    yaw = np.where(s < 400.0, np.pi / 2, 0.0)
    return Trajectory(1.7e9 + s / 2.0, np.column_stack([x, y, yaw]), name="est")


def test_origin_frame_never_invents_one():
    assert origin_frame({})[0] is None and "no geodetic origin" in origin_frame({})[1]
    assert origin_frame({"origin": {"lat": "x", "lon": 1}})[0] is None
    assert origin_frame({"origin": {"lat": 95.0, "lon": 1.0}})[0] is None
    f, why = origin_frame({"origin": ORIGIN})
    assert why is None and (f.lat0, f.lon0) == (ORIGIN["lat"], ORIGIN["lon"])


def test_geojson_structure_order_and_a_known_point():
    tr = square_track()
    obj = json.loads(json.dumps(geojson([GeoTrack.from_trajectory(tr, FRAME)]), allow_nan=False))
    assert obj["type"] == "FeatureCollection" and "crs" not in obj
    line = [f for f in obj["features"] if f["geometry"]["type"] == "LineString"]
    points = [f for f in obj["features"] if f["geometry"]["type"] == "Point"]
    assert len(line) == 1 and len(points) == len(tr)
    for f in obj["features"]:
        assert f["type"] == "Feature" and isinstance(f["properties"], dict)
    coords = np.array(line[0]["geometry"]["coordinates"])
    assert coords.shape == (len(tr), 2)
    # RFC 7946: [longitude, latitude]; the first pose is the origin itself
    assert abs(coords[0, 0] - ORIGIN["lon"]) < 1e-8 and abs(coords[0, 1] - ORIGIN["lat"]) < 1e-8
    # 400 m north: latitude up by ~400 / 111.3 km (deg), longitude unchanged
    i = len(tr) // 2
    assert abs(coords[i, 0] - ORIGIN["lon"]) < 1e-7
    assert abs(coords[i, 1] - ORIGIN["lat"] - 400.0 / 111_300.0) < 2e-5
    # then 400 m east: longitude up by ~400 / (111.3 km cos lat)
    assert abs(coords[-1, 0] - ORIGIN["lon"] - 400.0 / (111_320.0 * math.cos(math.radians(ORIGIN["lat"])))) < 3e-5
    lo, la, hi_lo, hi_la = obj["bbox"]
    assert lo <= coords[:, 0].min() and hi_la >= coords[:, 1].max()
    p = points[i - 1]["properties"]
    assert p["t"] == tr.t[i - 1] and abs(p["heading_deg"] - 0.0) < 1e-6  # north-going: heading 0
    assert abs(points[-1]["properties"]["heading_deg"] - 90.0) < 1e-6  # east-going: 90
    assert datetime.fromisoformat(p["time"].replace("Z", "+00:00")).timestamp() == pytest.approx(tr.t[i - 1], abs=1e-3)


@settings(max_examples=30, deadline=None)
@given(st.floats(-80, 80), st.floats(-179, 179), st.lists(st.tuples(st.floats(-3000, 3000), st.floats(-3000, 3000)),
                                                            min_size=2, max_size=6))
def test_geojson_coordinates_return_to_the_local_frame(lat0, lon0, xy):
    frame = LocalFrame(lat0, lon0)
    xy = np.array(xy)
    tr = Trajectory(np.arange(len(xy), dtype=float), np.column_stack([xy, np.zeros(len(xy))]))
    obj = geojson([GeoTrack.from_trajectory(tr, frame, "a")])
    coords = np.array(obj["features"][0]["geometry"]["coordinates"])
    assert np.all(np.abs(coords[:, 0]) <= 180.0) and np.all(np.abs(coords[:, 1]) <= 90.0)
    x, y = frame.to_local(coords[:, 1], coords[:, 0])
    assert np.allclose(x, xy[:, 0], atol=0.01) and np.allclose(y, xy[:, 1], atol=0.01)


def test_gpx_reads_back_within_1e_6_deg_with_times():
    tr = square_track()
    truth_lat, truth_lon = FRAME.to_geodetic(tr.x, tr.y)
    g = gpxpy.parse(gpx_text([GeoTrack.from_trajectory(tr, FRAME, "isam2")]))
    assert [t.name for t in g.tracks] == ["isam2"]
    pts = g.tracks[0].segments[0].points
    assert len(pts) == len(tr)
    assert np.max(np.abs(np.array([p.latitude for p in pts]) - truth_lat)) < 1e-6
    assert np.max(np.abs(np.array([p.longitude for p in pts]) - truth_lon)) < 1e-6
    assert pts[3].time == datetime.fromtimestamp(tr.t[3], UTC)


def test_kml_reads_back_within_1e_6_deg():
    tr = square_track()
    truth_lat, truth_lon = FRAME.to_geodetic(tr.x, tr.y)
    root = ET.fromstring(kml_text([GeoTrack.from_trajectory(tr, FRAME, "isam2")]))
    ns = {"k": "http://www.opengis.net/kml/2.2"}
    pm = root.findall(".//k:Placemark", ns)
    assert len(pm) == 1 and pm[0].find("k:name", ns).text == "isam2"
    text = pm[0].find(".//k:LineString/k:coordinates", ns).text.split()
    c = np.array([[float(v) for v in p.split(",")] for p in text])
    assert c.shape == (len(tr), 3)
    assert np.max(np.abs(c[:, 0] - truth_lon)) < 1e-6 and np.max(np.abs(c[:, 1] - truth_lat)) < 1e-6
    assert pm[0].find(".//k:TimeSpan/k:begin", ns).text.startswith("2023-11-14T22:13:20")


def test_write_wgs84_without_origin_writes_nothing(tmp_path):
    out = write_wgs84(tmp_path, {"a": square_track()}, {"name": "no origin"})
    assert out["wgs84"] is None and "no geodetic origin" in out["wgs84_reason"]
    assert list(tmp_path.iterdir()) == []
    out = write_wgs84(tmp_path, {"a": square_track()}, {"origin": ORIGIN})
    assert out["wgs84"]["files"] == ["trajectory.geojson", "trajectory.gpx", "trajectory.kml"]
    assert out["wgs84"]["origin"] == ORIGIN


# -- the CLI
def tiny_log(tmp_path: Path, origin: dict | None, n: int = 40) -> Path:
    """Odometry, GNSS and truth along a line heading north-east; a meta line with ``origin`` if given."""
    p = tmp_path / ("with-origin.jsonl" if origin else "no-origin.jsonl")
    recs = [{"type": "meta", "name": "tiny", **({"origin": origin} if origin else {})},
            {"t": 0.0, "type": "pose_prior", "x": 0, "y": 0, "yaw": 0.7, "sigma_xy": 1, "sigma_yaw": 0.1}]
    for k in range(1, n):
        t = 0.5 * k
        recs += [{"t": t, "type": "odometry", "v": 2.0, "w": 0.0, "sigma_v": 0.1, "sigma_w": 0.01},
                 {"t": t, "type": "truth", "x": 2 * t * math.cos(0.7), "y": 2 * t * math.sin(0.7), "yaw": 0.7}]
        if k % 5 == 0:
            recs.append({"t": t, "type": "gnss", "x": 2 * t * math.cos(0.7), "y": 2 * t * math.sin(0.7),
                         "sigma": 0.5})
    p.write_text("".join(json.dumps(r) + "\n" for r in recs))
    return p


def graphnav_json(capsys, *argv: str) -> tuple[int, dict]:
    rc = cli.main([*argv, "--json"])
    return rc, json.loads(capsys.readouterr().out)


def test_run_writes_wgs84_tracks_only_with_an_origin(tmp_path, capsys):
    out = tmp_path / "o"
    rc, s = graphnav_json(capsys, "run", str(tiny_log(tmp_path, ORIGIN)), "-e", "dead-reckoning", "--out", str(out))
    assert rc == 0 and s["origin"] == ORIGIN and s["wgs84"]["origin"] == ORIGIN
    names = {"trajectory.geojson", "trajectory.gpx", "trajectory.kml"}
    assert names <= {p.name for p in out.iterdir()}
    assert names <= set(json.loads((out / MANIFEST).read_text())["files"])
    assert json.loads((out / "summary.json").read_text())["origin"] == ORIGIN
    g = gpxpy.parse((out / "trajectory.gpx").read_text())
    assert [t.name for t in g.tracks] == ["dead-reckoning", "truth"]
    est = read_tum(out / "trajectory.tum")
    lat, lon = FRAME.to_geodetic(est.x, est.y)
    pts = g.tracks[0].segments[0].points
    assert np.max(np.abs(np.array([p.latitude for p in pts]) - lat)) < 1e-6
    assert np.max(np.abs(np.array([p.longitude for p in pts]) - lon)) < 1e-6

    out2 = tmp_path / "o2"
    rc, s = graphnav_json(capsys, "run", str(tiny_log(tmp_path, None)), "-e", "dead-reckoning", "--out", str(out2))
    assert rc == 0 and s["origin"] is None and s["wgs84"] is None and "no geodetic origin" in s["wgs84_reason"]
    assert not any(p.suffix in (".geojson", ".gpx", ".kml") for p in out2.iterdir())


def test_compare_writes_every_track_and_a_self_contained_map(tmp_path, capsys):
    out = tmp_path / "c"
    rc, s = graphnav_json(capsys, "compare", str(tiny_log(tmp_path, ORIGIN)), "-e", "ekf,dead-reckoning",
                          "--out", str(out))
    assert rc == 0 and s["map"] == "map.html" and set(s["wgs84"]["tracks"]) == {"truth", "ekf", "dead-reckoning"}
    obj = json.loads((out / "trajectory.geojson").read_text())
    names = {f["properties"]["name"] for f in obj["features"] if f["geometry"]["type"] == "LineString"}
    assert names == {"truth", "ekf", "dead-reckoning"}
    html = (out / "map.html").read_text()
    assert "<svg" in html and "°" in html  # a graticule with degree labels
    assert not re.search(r"https?://|\bsrc=|\bhref=|url\(|@import|<link|<script", html)  # loads nothing
    out2 = tmp_path / "c2"
    rc, s = graphnav_json(capsys, "compare", str(tiny_log(tmp_path, None)), "-e", "dead-reckoning", "--out", str(out2))
    assert rc == 0 and s["wgs84"] is None and (out2 / "map.html").exists()
    assert not (out2 / "trajectory.geojson").exists()


def _geojson_spec(tracks: list[GeoTrack]) -> dict:
    """The FeatureCollection as the module docstring states it, built plainly from ``GeoTrack.times``
    (``datetime``), ``round`` and dicts: the oracle of the directly written text."""
    def iso(d: datetime) -> str:
        return d.isoformat(timespec="milliseconds").replace("+00:00", "Z")

    features = []
    for tr in tracks:
        times = [iso(d) for d in tr.times()]
        coords = [[round(float(lo), 8), round(float(la), 8)] for la, lo in zip(tr.lat, tr.lon, strict=True)]
        if len(coords) >= 2:
            features.append({"type": "Feature", "geometry": {"type": "LineString", "coordinates": coords},
                             "properties": {"name": tr.name, "kind": "track", "poses": len(coords),
                                            "start": times[0], "end": times[-1]}})
        for i, c in enumerate(coords):
            props = {"name": tr.name, "kind": "pose", "t": float(tr.t[i]), "time": times[i]}
            if math.isfinite(tr.heading_deg[i]):
                props["heading_deg"] = round(float(tr.heading_deg[i]), 3)
            features.append({"type": "Feature", "geometry": {"type": "Point", "coordinates": c}, "properties": props})
    lat, lon = np.concatenate([t.lat for t in tracks]), np.concatenate([t.lon for t in tracks])
    bbox = [round(float(v), 8) for v in (lon.min(), lat.min(), lon.max(), lat.max())]
    return {"type": "FeatureCollection", "features": features, "bbox": bbox}


_times = st.lists(st.floats(-1e9, 1e10, allow_nan=False), min_size=1, max_size=40)


@settings(max_examples=60, deadline=None)
@given(_times, st.integers(0, 2**32 - 1), st.text(max_size=8))
def test_the_directly_written_geojson_and_gpx_equal_the_libraries_reading(ts, seed, name):
    """GeoJSON and GPX are written as text directly (fast for 100 Hz tracks): the GeoJSON parses to the
    plainly built document exactly, and gpxpy reads the GPX back to the very floats, ``datetime`` times
    (``datetime.fromtimestamp`` of the time rounded to the microsecond) and name."""
    rng = np.random.default_rng(seed)
    n = len(ts)
    poses = np.column_stack([rng.normal(0, 5e3, n), rng.normal(0, 5e3, n), rng.uniform(-4, 4, n)])
    poses[rng.random(n) < 0.2, 2] = np.nan  # no heading there
    tracks = [GeoTrack.from_trajectory(Trajectory(np.sort(ts), poses, name=name), FRAME),
              GeoTrack.from_trajectory(square_track(5), FRAME, "second <&>")]
    assert json.loads(render(tracks, "geojson")) == _geojson_spec(tracks)
    g = gpxpy.parse(gpx_text(tracks))
    for tr, trk in zip(tracks, g.tracks, strict=True):
        pts = trk.segments[0].points
        assert trk.name == (tr.name or None)
        assert [p.latitude for p in pts] == tr.lat.tolist() and [p.longitude for p in pts] == tr.lon.tolist()
        assert [p.time for p in pts] == tr.times()


def _kml_read(text: str) -> list[tuple]:
    """Per placemark: name, its style's colour and width, time span, coordinates (floats)."""
    ns = {"k": "http://www.opengis.net/kml/2.2"}
    root = ET.fromstring(text)
    styles = {s.get("id"): (s.find(".//k:color", ns).text, s.find(".//k:width", ns).text)
              for s in root.iter("{http://www.opengis.net/kml/2.2}Style")}
    out = []
    for pm in root.iter("{http://www.opengis.net/kml/2.2}Placemark"):
        span = pm.find("k:TimeSpan", ns)
        coords = [tuple(float(v) for v in c.split(",")) for c in pm.find(".//k:coordinates", ns).text.split()]
        out.append((pm.find("k:name", ns).text, styles[pm.find("k:styleUrl", ns).text[1:]],
                    None if span is None else (span.find("k:begin", ns).text, span.find("k:end", ns).text), coords))
    return out


def _simplekml_text(tracks: list[GeoTrack]) -> str:
    """The KML as simplekml writes it (the oracle of the directly written text)."""
    import simplekml

    from graphnav.io.geo_out import _KML_COLOURS
    k = simplekml.Kml(name="graphnav")
    for i, tr in enumerate(tracks):
        coords = [(float(lo), float(la)) for la, lo in zip(tr.lat, tr.lon, strict=True)]
        ls = k.newlinestring(name=tr.name, coords=coords)
        ls.style.linestyle.color = "ff000000" if tr.name == "truth" else _KML_COLOURS[i % len(_KML_COLOURS)]
        ls.style.linestyle.width = 2
        if len(tr.t):
            times = [d.isoformat(timespec="milliseconds").replace("+00:00", "Z") for d in tr.times()]
            ls.timespan.begin, ls.timespan.end = times[0], times[-1]
    return k.kml()


@settings(max_examples=40, deadline=None)
@given(_times, st.integers(0, 2**32 - 1), st.sampled_from(["truth", "isam2", "a<&>b"]))
def test_the_directly_written_kml_reads_as_simplekml_s(ts, seed, name):
    """KML is written as text directly: read back, the same placemarks (names, colours, widths, time
    spans, the very coordinates) as simplekml's document."""
    rng = np.random.default_rng(seed)
    n = len(ts)
    poses = np.column_stack([rng.normal(0, 5e3, n), rng.normal(0, 5e3, n), rng.uniform(-4, 4, n)])
    tracks = [GeoTrack.from_trajectory(square_track(5), FRAME, "truth"),
              GeoTrack.from_trajectory(Trajectory(np.sort(ts), poses), FRAME, name)]
    assert _kml_read(kml_text(tracks)) == _kml_read(_simplekml_text(tracks))


def test_wgs84_tracks_are_thinned_to_the_rate_and_keep_their_ends(tmp_path):
    """A 100 Hz track goes into the WGS84 files at 10 Hz (first and last pose kept, consecutive poses at
    least 0.1 s apart); a 1 Hz track whole; ``max_rate_hz=None``: every pose."""
    from graphnav.io.geo_out import MAX_RATE_HZ, thinned

    t = 1.7e9 + np.arange(0.0, 60.005, 0.01)
    fast = Trajectory(t, np.column_stack([t - t[0], np.zeros_like(t), np.zeros_like(t)]), name="ukf")
    th = thinned(fast, MAX_RATE_HZ)
    assert th.t[0] == t[0] and th.t[-1] == t[-1]
    assert np.all(np.diff(th.t[:-1]) >= 0.1 - 1e-4) and len(th) == 601
    slow = square_track()
    assert thinned(slow, MAX_RATE_HZ) is slow and thinned(fast, None) is fast
    entry = write_wgs84(tmp_path, {"ukf": fast, "truth": slow}, {"origin": ORIGIN})
    assert entry["wgs84"]["max_rate_hz"] == MAX_RATE_HZ
    g = gpxpy.parse((tmp_path / "trajectory.gpx").read_text())
    assert [len(trk.segments[0].points) for trk in g.tracks] == [601, len(slow)]
    write_wgs84(tmp_path, {"ukf": fast}, {"origin": ORIGIN}, max_rate_hz=None)
    assert len(gpxpy.parse((tmp_path / "trajectory.gpx").read_text()).tracks[0].segments[0].points) == len(t)
