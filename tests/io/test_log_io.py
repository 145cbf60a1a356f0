import gzip
import json

import numpy as np
import pytest
from _logfactory import every_record_log, logs_equal
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from graphnav.errors import LogError
from graphnav.io import load_log, save_log
from graphnav.io.jsonl import read_jsonl
from graphnav.log import Gnss, NavLog, Scan


@pytest.mark.parametrize("name", ["log.jsonl", "log.jsonl.gz"])
def test_jsonl_roundtrip(tmp_path, name):
    log = every_record_log()
    save_log(log, tmp_path / name)
    back = load_log(tmp_path / name)
    logs_equal(log, back, scan_atol=5e-5)  # scans are written to 4 decimals
    assert back.meta["events"] == log.meta["events"]
    assert back.counts() == log.counts()


def test_jsonl_gz_is_deterministic(tmp_path):
    log = every_record_log()
    save_log(log, tmp_path / "a.jsonl.gz")
    save_log(log, tmp_path / "b.jsonl.gz")
    assert (tmp_path / "a.jsonl.gz").read_bytes() == (tmp_path / "b.jsonl.gz").read_bytes()


def test_npz_roundtrip(tmp_path):
    log = every_record_log()
    save_log(log, tmp_path / "log.npz")
    back = load_log(tmp_path / "log.npz")
    logs_equal(log, back, scan_atol=4e-6)  # float32 beams: ~1e-7 relative
    assert back.meta["name"] == "every-record"


def test_npz_then_jsonl_then_npz_is_stable(tmp_path):
    log = every_record_log(seed=3)
    save_log(log, tmp_path / "a.npz")
    save_log(load_log(tmp_path / "a.npz"), tmp_path / "b.jsonl")
    save_log(load_log(tmp_path / "b.jsonl"), tmp_path / "c.npz")
    logs_equal(load_log(tmp_path / "a.npz"), load_log(tmp_path / "c.npz"), scan_atol=1e-4)


def test_scan_angle_min_increment_form(tmp_path):
    p = tmp_path / "s.jsonl"
    p.write_text(json.dumps({"t": 0, "type": "scan", "ranges": [1, None, 0, 2.5],
                             "angle_min": -1.0, "angle_increment": 0.5}) + "\n")
    (s,) = read_jsonl(p).records
    assert isinstance(s, Scan)
    assert np.allclose(s.angles, [-1.0, -0.5, 0.0, 0.5])
    assert s.valid().tolist() == [True, False, False, True]


def test_gnss_lat_lon_uses_meta_origin(tmp_path):
    p = tmp_path / "g.jsonl"
    lines = [{"type": "meta", "origin": {"lat": 54.5, "lon": 18.55}},
             {"t": 0, "type": "gnss", "lat": 54.5, "lon": 18.55, "sigma": 2},
             {"t": 1, "type": "gnss", "lat": 54.5 + 1 / 60, "lon": 18.55, "sigma": 2}]
    p.write_text("\n".join(json.dumps(o) for o in lines))
    log = read_jsonl(p)
    a, b = log.records
    assert isinstance(a, Gnss) and abs(a.x) < 1e-6 and abs(a.y) < 1e-6
    assert 1850 < b.y < 1860 and abs(b.x) < 0.05
    assert log.meta["origin"]["lat"] == 54.5


def test_gnss_lat_lon_defaults_origin_to_first_fix(tmp_path):
    p = tmp_path / "g.jsonl"
    p.write_text(json.dumps({"t": 0, "type": "gnss", "lat": 10.0, "lon": 20.0, "sigma": 2}) + "\n")
    log = read_jsonl(p)
    assert log.meta["origin"] == {"lat": 10.0, "lon": 20.0, "h": 0.0}


BAD_LINES = [
    ('{"t": 0, "type": "gnss", "x": 1, "y": 2}', "sigma"),
    ('{"t": 0, "type": "warp", "x": 1}', "type"),
    ('{"t": "zero", "type": "heading", "yaw": 1, "sigma": 0.1}', "t"),
    ('{"t": 1e999, "type": "heading", "yaw": 1, "sigma": 0.1}', "t"),
    ('{"t": 0, "type": "heading", "yaw": 1, "sigma": -0.1}', "sigma"),
    ('{"t": 0, "type": "scan", "ranges": [1, 2], "angles": [0]}', "angles"),
    ('{"t": 0, "type": "scan", "ranges": [1, "a"], "angles": [0, 1]}', "ranges"),
    ('{"t": 0, "type": "beacon", "id": "", "range": 1, "bearing": 0}', "id"),
    ('{"t": 0, "type": "gnss", "lat": 95, "lon": 0, "sigma": 1}', "lat"),
    ('{"t": 0, "type": "odometry", "v": NaN, "w": 0}', "v"),
]


@pytest.mark.parametrize("line,field", BAD_LINES)
def test_bad_line_names_file_line_field(tmp_path, line, field):
    p = tmp_path / "bad.jsonl"
    p.write_text('{"t": 0, "type": "truth", "x": 0, "y": 0, "yaw": 0}\n# comment\n' + line + "\n")
    with pytest.raises(LogError) as ei:
        read_jsonl(p)
    err = ei.value
    assert err.file == str(p) and err.line == 3 and err.field == field
    assert f"{p}:3: field '{field}'" in str(err)


def test_out_of_order_time_is_an_error(tmp_path):
    p = tmp_path / "o.jsonl"
    p.write_text('{"t": 5, "type": "heading", "yaw": 0, "sigma": 0.1}\n'
                 '{"t": 4, "type": "heading", "yaw": 0, "sigma": 0.1}\n')
    with pytest.raises(LogError) as ei:
        read_jsonl(p)
    assert ei.value.line == 2 and ei.value.field == "t"


def test_lenient_skips_and_counts(tmp_path):
    p = tmp_path / "l.jsonl"
    p.write_text('{"t": 0, "type": "heading", "yaw": 0, "sigma": 0.1}\nnot json\n'
                 '{"t": 1, "type": "bogus"}\n{"t": 2, "type": "heading", "yaw": 0, "sigma": 0.1}\n')
    log = read_jsonl(p, lenient=True)
    assert len(log) == 2
    assert log.meta["skipped"] == 2
    assert ":2:" in log.meta["skipped_errors"][0] and ":3:" in log.meta["skipped_errors"][1]


def test_unreadable_gzip_is_a_log_error(tmp_path):
    p = tmp_path / "x.jsonl.gz"
    p.write_bytes(b"definitely not gzip")
    with pytest.raises(LogError):
        read_jsonl(p)


def test_npz_corrupt_and_inconsistent(tmp_path):
    p = tmp_path / "x.npz"
    p.write_bytes(b"PK\x03\x04 broken")
    with pytest.raises(LogError):
        load_log(p)
    log = every_record_log(n=3)
    save_log(log, tmp_path / "ok.npz")
    data = dict(np.load(tmp_path / "ok.npz"))
    data["gnss/x"] = data["gnss/x"][:-1]
    np.savez(tmp_path / "bad.npz", **data)
    with pytest.raises(LogError) as ei:
        load_log(tmp_path / "bad.npz")
    assert ei.value.field == "gnss/x"


def test_navlog_rejects_backwards_time():
    with pytest.raises(LogError):
        NavLog([Gnss(1.0, 0, 0, 1.0), Gnss(0.5, 0, 0, 1.0)])
    log = NavLog.from_unsorted([Gnss(1.0, 0.0, 0.0, 1.0), Gnss(0.5, 0.0, 0.0, 1.0)])
    assert [r.t for r in log] == [0.5, 1.0]


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True) | st.text(max_size=8),
    lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=8), c, max_size=5),
    max_leaves=12,
)
record_like = st.fixed_dictionaries(
    {"type": st.sampled_from(["scan", "gnss", "heading", "odometry", "imu", "beacon", "truth", "pose_prior",
                              "beacon_known", "meta", "x"])},
    optional={k: json_values for k in ["t", "x", "y", "sigma", "yaw", "v", "w", "ranges", "angles", "id",
                                       "range", "bearing", "lat", "lon", "origin", "sigma_xy", "sigma_yaw",
                                       "ax", "ay", "wz", "angle_min", "angle_increment"]},
)
garbage_line = st.one_of(st.text(max_size=80), record_like.map(lambda d: json.dumps(d)),
                         st.binary(max_size=40).map(lambda b: b.decode("latin-1")))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(garbage_line, min_size=1, max_size=6))
@example(lines=['{"type":"gnss","lat":0}'])  # found by hypothesis in CI: the frame's first fix without lon
def test_garbage_never_crashes_jsonl_reader(tmp_path, lines):
    p = tmp_path / "g.jsonl"
    p.write_text("\n".join(s.replace("\n", " ").replace("\r", " ") for s in lines), encoding="utf-8", errors="replace")
    try:
        read_jsonl(p)
    except LogError as err:
        assert err.file == str(p)
    lenient = read_jsonl(p, lenient=True)  # lenient never raises on record problems
    assert lenient.meta["skipped"] >= 0


def test_lat_without_lon_names_file_line_and_field(tmp_path):
    p = tmp_path / "fix.jsonl"
    p.write_text('{"type":"meta"}\n{"type":"gnss","t":0,"lat":50.1,"sigma":3}\n', encoding="utf-8")
    with pytest.raises(LogError) as exc:
        read_jsonl(p)
    assert (exc.value.file, exc.value.line, exc.value.field) == (str(p), 2, "lon")


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=200))
def test_garbage_bytes_in_gzip(tmp_path, payload):
    p = tmp_path / "g.jsonl.gz"
    p.write_bytes(gzip.compress(payload))
    try:
        read_jsonl(p)
    except LogError:
        pass


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=300), st.booleans())
def test_garbage_npz_is_a_log_error(tmp_path, payload, zip_header):
    p = tmp_path / "g.npz"
    p.write_bytes((b"PK\x03\x04" if zip_header else b"") + payload)
    with pytest.raises(LogError):
        load_log(p)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.dictionaries(st.sampled_from(["order", "meta", "gnss/t", "gnss/x", "gnss/y", "gnss/sigma", "scan/t",
                                        "scan/offsets", "scan/ranges", "scan/angles"]),
                       st.lists(st.floats(-5, 5), max_size=5), min_size=1))
def test_random_npz_arrays_never_crash(tmp_path, arrays):
    p = tmp_path / "r.npz"
    np.savez(p, **{k: np.array(v) for k, v in arrays.items()})
    try:
        load_log(p)
    except LogError:
        pass
