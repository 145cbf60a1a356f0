"""CSV/TSV logs with a column mapping (graphnav.io.csv_table, docs/csv.md): known answers for each
field and unit, errors naming the file, line and column, the CLI's --columns, and a fuzz (a result or
a LogError)."""

from __future__ import annotations

import io
import json
import math
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from graphnav.cli import main
from graphnav.errors import LogError
from graphnav.geodesy import LocalFrame
from graphnav.io import load_log
from graphnav.io.csv_table import read_csv_log

TABLE = """time,Latitude,Longitude,HDG,SOG,COG,STW,hdop
2024-06-01T10:00:00Z,54.5200,18.5500,90.0,5.0,90.0,4.8,1.2
2024-06-01T10:00:01Z,54.5200,18.5501,0.0,5.0,180.0,4.8,1.5
2024-06-01T10:00:02Z,54.5201,18.5501,270.0,5.1,0.0,,2.0
2024-06-01T10:00:03Z,,,,5.1,45.0,4.9,
"""
MAPPING = "t=time,lat=Latitude,lon=Longitude,sigma=hdop:m,heading=HDG,heading_sigma=0.5,sog=SOG:kn,cog=COG,stw=STW:kn"
KN = 1852.0 / 3600.0


def write(tmp_path, text, name="boat.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_fields_and_units_known_answers(tmp_path):
    log = load_log(write(tmp_path, TABLE), columns=MAPPING)
    assert log.counts() == {"gnss": 3, "heading": 3, "gnss_velocity": 4, "water_speed": 3}
    assert log.t0 == 1717236000.0 and log.t1 == 1717236003.0  # ISO 8601, UTC
    g = log.of("gnss")
    x, y = LocalFrame(54.52, 18.55).to_local(54.5200, 18.5501)
    assert (g[0].x, g[0].y) == (0.0, 0.0) and g[1].x == pytest.approx(float(x)) and abs(g[1].y - float(y)) < 1e-9
    assert 6.4 < g[1].x < 6.5  # 0.0001 deg of longitude at 54.52 N
    assert [r.sigma for r in g] == [1.2, 1.5, 2.0]
    h = log.of("heading")  # nautical degrees -> yaw CCW from east, rad
    np.testing.assert_allclose([r.yaw for r in h], [0.0, math.pi / 2, -math.pi], atol=1e-12)  # wrapped to [-pi, pi)
    assert h[0].sigma == pytest.approx(math.radians(0.5))
    v = log.of("gnss_velocity")  # SOG kn, COG true -> (east, north) m/s
    np.testing.assert_allclose([v[0].vx, v[0].vy], [5.0 * KN, 0.0], atol=1e-12)
    np.testing.assert_allclose([v[1].vx, v[1].vy], [0.0, -5.0 * KN], atol=1e-12)
    np.testing.assert_allclose([v[3].vx, v[3].vy], [5.1 * KN / math.sqrt(2)] * 2, atol=1e-12)
    assert log.of("water_speed")[0].v == pytest.approx(4.8 * KN)
    assert log.meta["columns"]["sigma"] == "hdop" and log.meta["columns"]["heading_sigma"] == "constant 0.5"
    assert log.meta["units"]["sog"] == "kn" and log.meta["units"]["cog"] == "deg" and log.meta["origin"]["lat"] == 54.52


def test_header_names_are_fields_semicolons_and_time_units(tmp_path):
    p = write(tmp_path, "t;x;y;sigma;yaw;heading_sigma;v;w\n1500;1;2;0.5;0.1;2;1.5;0.01\n2500;2;2;0.5;0.2;2;1.5;0.02\n")
    log = load_log(p)  # the header's names are the fields
    assert log.counts() == {"gnss": 2, "heading": 2, "odometry": 2}
    assert log.of("heading")[1].yaw == 0.2 and log.of("odometry")[0].w == 0.01
    log = load_log(p, columns="t=t:ms,x=x:km,y=y,sigma=sigma,yaw=yaw:deg,heading_sigma=heading_sigma,w=w:deg/s,v=v")
    assert [r.t for r in log.of("gnss")] == [1.5, 2.5] and log.of("gnss")[0].x == 1000.0
    assert log.of("heading")[0].yaw == pytest.approx(math.radians(0.1))
    assert log.of("odometry")[0].w == pytest.approx(math.radians(0.01))


@pytest.mark.parametrize("text,mapping,words", [
    (TABLE.replace("54.5201", "54.5x01"), MAPPING, ["boat.csv:4", "column 'Latitude' (lat)", "not a number"]),
    (TABLE.replace("2024-06-01T10:00:02Z", "2024-06-01T09:00:02Z"), MAPPING,
     ["boat.csv:4", "column 'time' (t)", "time order"]),
    (TABLE.replace("2024-06-01T10:00:01Z", "yesterday"), MAPPING, ["boat.csv:3", "column 'time' (t)", "ISO 8601"]),
    (TABLE.replace("54.5201", "95.0"), MAPPING, ["boat.csv:4", "(lat)", "outside [-90, 90]"]),
    (TABLE.replace("5.1,0.0", "500,0.0"), MAPPING.replace("SOG:kn", "SOG"), ["boat.csv:4"]),
    (TABLE, MAPPING.replace("sigma=hdop:m,", ""), ["boat.csv:2", "sigma", "--columns sigma=3"]),
    (TABLE, MAPPING + ",depth=Depth", ["--columns", "unknown field(s) depth"]),
    (TABLE, MAPPING.replace("SOG:kn", "SOG:knots"), ["unknown unit 'knots'", "kn, km/h"]),
    (TABLE, MAPPING.replace("Latitude", "Lat"), ["boat.csv:1", "no column 'Lat'", "Latitude"]),
    (TABLE, "lat=Latitude", ["boat.csv:1", "no time column"]),
    (TABLE, "t=time,lat", ["expected FIELD=COLUMN"]),
    ("", MAPPING, ["boat.csv", "no header"]),
    ("time,lat\n0,5\r4\n", "t=time,lat=lat", ["boat.csv:2", "not a CSV line"]),  # a lone CR (found by the fuzz)
    (TABLE.replace("1.2", "nan"), MAPPING, ["boat.csv:2", "column 'hdop' (sigma)", "not finite"]),
])
def test_errors_name_file_line_and_column(tmp_path, text, mapping, words):
    with pytest.raises(LogError) as exc:
        load_log(write(tmp_path, text), columns=mapping)
    for w in words:
        assert w in str(exc.value), (w, str(exc.value))


def test_lenient_skips_and_counts_bad_rows(tmp_path):
    log = load_log(write(tmp_path, TABLE.replace("54.5201", "54.5x01")), columns=MAPPING, lenient=True)
    assert log.meta["skipped"] == 1 and "Latitude" in log.meta["skipped_errors"][0]
    assert log.counts()["gnss"] == 2


def test_columns_on_a_log_that_is_not_csv_is_an_error(tmp_path):
    p = tmp_path / "a.jsonl"
    p.write_text('{"t": 0, "type": "gnss", "x": 0, "y": 0, "sigma": 1}\n')
    with pytest.raises(LogError, match="--columns"):
        load_log(p, columns="t=t")


def cli(*argv: str) -> tuple[int, dict]:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = main([*argv, "--json"])
    assert "Traceback" not in err.getvalue()
    return code, json.loads(out.getvalue())


def test_cli_columns_info_and_run(tmp_path):
    rows = ["time,lat,lon,hdg"]
    for k in range(60):
        lat, lon = 54.52, 18.55 + 2e-5 * k  # ~1.3 m/s east
        rows.append(f"{1.7e9 + k:.1f},{lat:.7f},{lon:.7f},90")
    p = write(tmp_path, "\n".join(rows) + "\n", "track.csv")
    cols = "t=time,lat=lat,lon=lon,sigma=1.5,heading=hdg,heading_sigma=2"
    code, out = cli("info", str(p), "--columns", cols)
    assert code == 0 and out["records"] == {"gnss": 60, "heading": 60} and out["units"]["heading"] == "deg"
    code, out = cli("run", str(p), "--columns", cols, "-e", "isam2", "--out", str(tmp_path / "o"))
    assert code == 0
    code, out = cli("info", str(p), "--columns", "t=time,lat=lat,lon=lon,sigma=-1")
    assert code == 2 and "sigma" in out["error"]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cells=st.lists(st.lists(st.one_of(st.text(max_size=8), st.floats(allow_nan=True), st.integers(),
                                         st.sampled_from(["", "1e400", "-0", "2024-13-01T00:00:00", "1" * 400])),
                               min_size=1, max_size=6), max_size=5))
def test_fuzz_a_result_or_a_log_error(tmp_path, cells):
    text = "time,Latitude,Longitude,HDG,SOG,COG\n" + "\n".join(",".join(str(c) for c in row) for row in cells)
    p = tmp_path / "fuzz.csv"
    p.write_bytes(text.encode("utf-8", "replace"))
    try:
        read_csv_log(p, columns="t=time,lat=Latitude,lon=Longitude,sigma=3,heading=HDG,heading_sigma=1,sog=SOG,"
                                "cog=COG")
    except LogError:
        pass
