"""The CARMEN log reader on excerpts the tests write (every message kind, errors, lenient, gzip,
dispatch), a hypothesis fuzz of the line parser, and the real logs in ../shared/data/carmen
(skipped with the reason when absent)."""

from __future__ import annotations

import gzip
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from graphnav.errors import LogError
from graphnav.io import load_log
from graphnav.io.carmen import (
    LaserMessage,
    dead_beams,
    flaser_angles,
    is_carmen,
    parse_line,
    read_carmen,
    saturation_threshold,
)

REPO = Path(__file__).resolve().parents[2]
LOGS = ("acapulco", "belgioioso", "edmonton", "freiburg-079", "freiburg-101", "freiburg-campus",
        "infinite-corridor", "orebro", "seattle")


def carmen_dir() -> Path | None:
    for c in (REPO.parent / "shared" / "data" / "carmen", REPO.parent.parent / "shared" / "data" / "carmen"):
        if (c / "acapulco-corrected.log.gz").exists():
            return c
    return None


def flaser(ranges, pose=(1.0, 2.0, 0.5), t=10.0, odom=(0.0, 0.0, 0.0)) -> str:
    r = " ".join(f"{v:g}" for v in ranges)
    return f"FLASER {len(ranges)} {r} {pose[0]} {pose[1]} {pose[2]} {odom[0]} {odom[1]} {odom[2]} {t} host {t}"


def robotlaser(ranges, pose=(3.0, 4.0, -0.25), robot=(9.0, 9.0, 9.0), t=5.0, start=-1.0, res=0.5,
               max_range=20.0, rem=(7.0, 8.0)) -> str:
    r = " ".join(f"{v:g}" for v in ranges)
    e = " ".join(f"{v:g}" for v in rem)
    return (f"ROBOTLASER1 0 {start} {res * (len(ranges) - 1)} {res} {max_range} 0.01 0 {len(ranges)} {r} "
            f"{len(rem)} {e} {pose[0]} {pose[1]} {pose[2]} {robot[0]} {robot[1]} {robot[2]} 0.3 0.1 0.5 0.2 0.0 "
            f"{t} host {t}")


def rawlaser(ranges, t=5.0, start=-0.5, res=0.25, max_range=30.0) -> str:
    r = " ".join(f"{v:g}" for v in ranges)
    return f"RAWLASER1 0 {start} {res * (len(ranges) - 1)} {res} {max_range} 0.01 0 {len(ranges)} {r} 0 {t} host {t}"


def write(tmp_path: Path, lines: list[str], name: str = "x.log") -> Path:
    p = tmp_path / name
    text = "\n".join(lines) + "\n"
    if name.endswith(".gz"):
        with gzip.open(p, "wt") as fh:
            fh.write(text)
    else:
        p.write_text(text)
    return p


# ----------------------------------------------------------------------------- message kinds

def test_flaser_angles_follow_carmen():
    a181 = flaser_angles(181)
    assert a181[0] == pytest.approx(-math.pi / 2) and a181[-1] == pytest.approx(math.pi / 2)
    a180 = flaser_angles(180)  # 1 deg spacing, the last beam at +89 deg (CARMEN: last beam ignored)
    assert np.allclose(np.diff(a180), math.radians(1.0)) and a180[-1] == pytest.approx(math.radians(89.0))
    a361 = flaser_angles(361)
    assert np.allclose(np.diff(a361), math.radians(0.5)) and a361[-1] == pytest.approx(math.pi / 2)
    a5 = flaser_angles(5)  # other counts: 180 deg evenly spread
    assert np.allclose(a5, np.radians([-90, -45, 0, 45, 90]))


def test_flaser_scan_and_truth(tmp_path):
    p = write(tmp_path, ["# a comment", "PARAM robot_frontlaser_offset 0.0 nohost 0",
                         flaser([1.0, 2.0, 0.0, 3.0, 4.0], pose=(1.0, 2.0, 0.5), t=10.0),
                         "ODOM 1 2 0.5 0 0 0 10.0 host 10.0", "NEFF 30",
                         flaser([1.5, 2.5, 3.5, 4.5, 5.5], pose=(1.5, 2.0, 4.0), t=11.0)])
    log = read_carmen(p)
    assert log.counts() == {"scan": 2, "truth": 2}
    s0, s1 = log.of("scan")
    assert s0.t == 10.0 and s1.t == 11.0
    assert np.allclose(s0.angles, np.radians([-90, -45, 0, 45, 90]))
    assert s0.valid().tolist() == [True, True, False, True, True]  # a zero range is a missing return
    tr = log.truth()
    assert np.allclose(tr.poses[0], [1.0, 2.0, 0.5])
    assert tr.poses[1, 2] == pytest.approx(4.0 - 2 * math.pi)  # yaw wrapped
    assert log.meta["ignored"] == {"NEFF": 1, "ODOM": 1, "PARAM": 1}
    assert log.meta["messages"] == {"FLASER": 2}
    assert log.meta["time"].startswith("log")


def test_robotlaser1_uses_its_config_and_laser_pose(tmp_path):
    p = write(tmp_path, [robotlaser([1.0, 20.0, 25.0, 2.0], pose=(3.0, 4.0, -0.25), t=5.0, start=-1.0, res=0.5,
                                    max_range=20.0),
                         robotlaser([1.0, 2.0, 3.0, 4.0], pose=(3.5, 4.0, -0.2), t=6.0)])
    log = read_carmen(p)
    s = log.of("scan")[0]
    assert np.allclose(s.angles, [-1.0, -0.5, 0.0, 0.5])
    assert s.ranges[0] == 1.0 and np.isnan(s.ranges[1]) and np.isnan(s.ranges[2])  # >= max_range: missing
    assert np.allclose(log.truth().poses[0], [3.0, 4.0, -0.25])  # the laser pose, not the robot pose
    assert log.meta["max_range"] == {"ROBOTLASER1": [20.0]}
    assert log.meta["missing_returns"]["max_range"] == 2


def test_rawlaser1_alone_gives_scans_without_truth(tmp_path):
    p = write(tmp_path, [rawlaser([1.0, 2.0, 31.0], t=1.0), rawlaser([1.0, 2.0, 3.0], t=2.0)])
    log = read_carmen(p)
    assert log.counts() == {"scan": 2}
    s = log.of("scan")[0]
    assert np.allclose(s.angles, [-0.5, -0.25, 0.0]) and np.isnan(s.ranges[2])


def test_rawlaser1_beside_robotlaser1_is_counted_not_doubled(tmp_path):
    p = write(tmp_path, [rawlaser([1.0, 2.0, 3.0], t=1.0), robotlaser([1.0, 2.0, 3.0, 4.0], t=1.0),
                         rawlaser([1.0, 2.0, 3.0], t=2.0), robotlaser([1.0, 2.0, 3.0, 4.0], t=2.0)])
    log = read_carmen(p)
    assert log.counts() == {"scan": 2, "truth": 2}
    assert log.meta["unused"] == {"RAWLASER1": 2}


def test_unknown_messages_are_counted_not_errors(tmp_path):
    p = write(tmp_path, ["TRUEPOS 1 2 3 4 5 6 1.0 h 1.0", "ROBOTLASER2 whatever", "RLASER 3 1 2 3",
                         flaser([1.0, 2.0, 3.0])])
    log = read_carmen(p)
    assert log.meta["ignored"] == {"RLASER": 1, "ROBOTLASER2": 1, "TRUEPOS": 1}
    assert log.counts() == {"scan": 1, "truth": 1}


def test_truth_can_be_left_out(tmp_path):
    p = write(tmp_path, [flaser([1.0, 2.0, 3.0])])
    assert read_carmen(p, truth=False).counts() == {"scan": 1}


# ----------------------------------------------------------------------------- time

def test_constant_timestamps_fall_back_to_the_scan_index(tmp_path):
    p = write(tmp_path, [flaser([1.0, 2.0, 3.0], t=0.0) for _ in range(4)])
    log = read_carmen(p, scan_dt=0.5)
    assert [s.t for s in log.of("scan")] == [0.0, 0.5, 1.0, 1.5]
    assert log.truth().t.tolist() == [0.0, 0.5, 1.0, 1.5]
    assert "scan index x 0.5 s" in log.meta["time"] and "3 of 3 steps" in log.meta["time"]


def test_time_log_mode_names_the_backwards_line(tmp_path):
    p = write(tmp_path, [flaser([1.0], t=5.0), flaser([1.0], t=6.0), flaser([1.0], t=4.0)])
    with pytest.raises(LogError) as ei:
        read_carmen(p, time="log")
    assert ei.value.line == 3 and ei.value.field == "timestamp" and str(p) in str(ei.value)
    assert [s.t for s in read_carmen(p, time="index").of("scan")] == [0.0, 1.0, 2.0]
    lenient = read_carmen(p, time="log", lenient=True)
    assert lenient.meta["skipped"] == 1 and len(lenient.of("scan")) == 2


# ----------------------------------------------------------------------------- missing returns

def test_saturation_threshold_detects_a_cluster_at_the_maximum():
    rng = np.random.default_rng(0)
    r = np.concatenate([rng.uniform(0.5, 30.0, 5000), np.full(50, 81.91), [81.5]])
    assert saturation_threshold(r) == pytest.approx(0.99 * 81.91)
    assert saturation_threshold(rng.uniform(0.5, 30.0, 5000)) is None  # no cluster: no cut
    assert saturation_threshold(np.array([np.nan, 0.0])) is None
    assert saturation_threshold(np.array([1.0, 2.0, 9.0, 9.0])) is None  # too few to be a sensor's cut-off


def test_flaser_saturation_and_explicit_max_range(tmp_path):
    lines = [flaser([1.0 + k * 0.01, 2.0 - k * 0.01, 81.91, 3.0 + k * 0.01], t=float(k)) for k in range(30)]
    log = read_carmen(write(tmp_path, lines))
    assert all(np.isnan(s.ranges[2]) and s.valid().sum() == 3 for s in log.of("scan"))
    assert log.meta["missing_returns"]["max_range"] == 30
    log = read_carmen(write(tmp_path, lines), max_range=2.5)  # the caller's cut wins
    assert all(s.valid().tolist() == [True, True, False, False] for s in log.of("scan")[:10])


def test_a_beam_constant_over_the_whole_log_is_dead(tmp_path):
    # as in acapulco: the last beam reads 50.0 m in every scan, below the 81.91 m saturation
    lines = [flaser([1.0 + 0.01 * k, 81.91, 50.0], t=float(k)) for k in range(25)]
    log = read_carmen(write(tmp_path, lines))
    assert log.meta["dead_beams"] == {"FLASER/3": [2]}
    assert all(s.valid().tolist() == [True, False, False] for s in log.of("scan"))
    assert log.meta["missing_returns"] == {"max_range": 25, "dead_beam": 25}
    assert dead_beams([np.array([1.0, 2.0])] * 5).size == 0  # too few scans to judge


# ----------------------------------------------------------------------------- errors

@pytest.mark.parametrize(("line", "field"), [
    ("FLASER 3 1.0 x 3.0 1 2 3 4 5 6 7 h 7", "range[1]"),
    ("FLASER 3 1.0 2.0 3.0 1 2", "laser_theta"),  # the line ends inside the pose
    ("FLASER 3 1.0 2.0", "num_readings"),  # says 3 values, 2 follow
    ("FLASER 3 1.0 2.0 3.0 1 2 3 4 5 6", "timestamp"),
    ("FLASER 3 1.0 2.0 3.0 1 nan 3 4 5 6 7 h 7", "laser_y"),
    ("FLASER -3 1.0", "num_readings"),
    ("FLASER 300 1.0", "num_readings"),
    ("FLASER 1 1.0 1 2 3 4 5 6 7 h 7 8", "logger_timestamp"),
    ("FLASER 1 1.0 1 2 3 4 5 6 7 h x", "logger_timestamp"),
    ("ROBOTLASER1 0 -1 3 0 20 0.01 0 1 1.0 0 1 2 3 4 5 6 0 0 0 0 0 7 h 7", "angular_res"),
    ("ROBOTLASER1 0 -1 3 0.5 20 0.01 0 1 1.0 2 5", "num_remissions"),
    ("RAWLASER1 0 -1 3 0.5 20 0.01 q 1 1.0 0 7 h 7", "remission_mode"),
    ("flaser 1 2 3", "message"),
    ("12 3 4", "message"),
])
def test_malformed_lines_name_line_and_field(tmp_path, line, field):
    p = write(tmp_path, [flaser([1.0, 2.0]), line])
    with pytest.raises(LogError) as ei:
        read_carmen(p)
    err = ei.value
    assert (err.file, err.line) == (str(p), 2)
    assert err.field == field, str(err)
    assert f"{p}:2: field '{err.field}'" in str(err)


def test_lenient_skips_and_counts(tmp_path):
    p = write(tmp_path, [flaser([1.0, 2.0], t=1.0), "FLASER 2 1.0 oops 1 2 3 4 5 6 7 h 7", "bad line",
                         flaser([1.0, 2.0], t=2.0)])
    log = read_carmen(p, lenient=True)
    assert log.counts() == {"scan": 2, "truth": 2}
    assert log.meta["skipped"] == 2
    assert ":2:" in log.meta["skipped_errors"][0] and ":3:" in log.meta["skipped_errors"][1]


def test_non_ascii_and_overlong_lines(tmp_path, monkeypatch):
    from graphnav.io import carmen

    p = tmp_path / "x.log"
    p.write_bytes(flaser([1.0]).encode() + b"\nFLASER \xff\n" + b"NEFF " + b"9" * 300 + b"\n"
                  + flaser([1.0], t=11.0).encode() + b"\n")
    monkeypatch.setattr(carmen, "MAX_LINE_BYTES", 100)
    log = read_carmen(p, lenient=True)
    assert log.meta["skipped"] == 2 and len(log.of("scan")) == 2
    assert "non-ASCII" in log.meta["skipped_errors"][0] and "longer than 100" in log.meta["skipped_errors"][1]


def test_truncated_gzip_is_a_log_error(tmp_path):
    p = write(tmp_path, [flaser([1.0, 2.0], t=float(k)) for k in range(200)], name="x.log.gz")
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(LogError) as ei:
        read_carmen(p)
    assert str(p) in str(ei.value) and "cannot read" in str(ei.value)


# ----------------------------------------------------------------------------- gzip, dispatch, CLI

def test_gzip_equals_plain(tmp_path):
    lines = [flaser([1.0, 2.0, 3.0], t=1.0), robotlaser([1.0, 2.0], t=2.0)]
    a = read_carmen(write(tmp_path, lines, "a.log"))
    b = read_carmen(write(tmp_path, lines, "b.log.gz"))
    assert a.counts() == b.counts()
    for ra, rb in zip(a.records, b.records, strict=True):
        assert ra.t == rb.t and type(ra) is type(rb)


def test_dispatch_tells_carmen_from_nmea(tmp_path):
    c = write(tmp_path, ["# CARMEN Logfile", flaser([1.0, 2.0])], "c.log.gz")
    assert is_carmen(c) and load_log(c).counts() == {"scan": 1, "truth": 1}
    clf = write(tmp_path, [flaser([1.0, 2.0])], "c.clf")
    assert load_log(clf).meta["format"] == "carmen"
    n = write(tmp_path, ["$GPGGA,120000.00,4330.0000,N,01624.0000,E,1,08,0.9,10.0,M,0.0,M,,"], "n.log")
    assert not is_carmen(n)
    assert load_log(n).meta["format"] == "nmea0183"


def test_convert_and_info_cli(tmp_path):
    p = write(tmp_path, [flaser([1.0, 2.0, 3.0], t=float(k)) for k in range(3)] + ["NEFF 3"], "c.log.gz")
    out = tmp_path / "c.jsonl.gz"
    r = subprocess.run([sys.executable, "-m", "graphnav", "convert", "carmen", str(p), "--out", str(out), "--json"],
                       capture_output=True, text=True, check=True, cwd=REPO)
    obj = json.loads(r.stdout)
    assert obj["records"] == {"scan": 3, "truth": 3} and obj["ignored"] == {"NEFF": 1}
    assert load_log(out).counts() == {"scan": 3, "truth": 3}
    r = subprocess.run([sys.executable, "-m", "graphnav", "info", str(p), "--json"],
                       capture_output=True, text=True, check=True, cwd=REPO)
    assert json.loads(r.stdout)["records"] == {"scan": 3, "truth": 3}
    bad = write(tmp_path, ["FLASER 2 1.0"], "bad.log")
    r = subprocess.run([sys.executable, "-m", "graphnav", "convert", "carmen", str(bad), "--out", str(out),
                        "--overwrite"], capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 2 and f"{bad}:1: field 'num_readings'" in r.stderr and "Traceback" not in r.stderr


# ----------------------------------------------------------------------------- fuzz

_TOKENS = st.one_of(
    st.sampled_from(["FLASER", "ROBOTLASER1", "RAWLASER1", "ODOM", "PARAM", "#", "nan", "inf", "-inf", "1e999",
                     "0", "1", "2", "3", "-1", "0.5", "x", "host", "1e-300", "00", "1.0.0", "\x00"]),
    st.integers(-5, 400).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.text(max_size=6),
)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_TOKENS, max_size=40))
def test_parse_line_returns_or_raises_log_error(tokens):
    line = " ".join(tokens)
    try:
        out = parse_line(line)
    except LogError as err:
        assert err.field
        return
    assert out is None or isinstance(out, str | LaserMessage)
    if isinstance(out, LaserMessage):
        assert out.ranges.shape == out.angles.shape
        assert math.isfinite(out.timestamp)
        assert np.all(np.isfinite(out.angles))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=400))
def test_read_never_fails_other_than_log_error(tmp_path, data):
    p = tmp_path / "f.log"
    p.write_bytes(b"FLASER 2 1 2 0 0 0 0 0 0 1 h 1\n" + data)
    for lenient in (False, True):
        try:
            log = read_carmen(p, lenient=lenient)
        except LogError:
            assert not lenient
            continue
        assert len(log.of("scan")) >= 1


# ----------------------------------------------------------------------------- the real logs

@pytest.fixture(scope="module")
def carmen_logs() -> Path:
    d = carmen_dir()
    if d is None:
        pytest.skip("CARMEN logs not found at ../shared/data/carmen (research data, not in the repository)")
    return d


@pytest.mark.parametrize("name", LOGS)
def test_real_logs_read_strictly(carmen_logs, name):
    log = read_carmen(carmen_logs / f"{name}-corrected.log.gz")
    c = log.counts()
    assert c["scan"] > 0 and c["truth"] == c["scan"]
    assert log.meta["messages"] == {"FLASER": c["scan"]}
    scans = log.of("scan")
    valid = np.array([s.valid().sum() for s in scans])
    assert np.median(valid) > 0.5 * scans[0].ranges.size  # most beams hit something
    assert log.meta["max_range"]["FLASER"], "every log saturates at its sensor's maximum"
    assert max(float(np.nanmax(s.ranges)) for s in scans) < log.meta["max_range"]["FLASER"][0]
    t = np.array([s.t for s in scans])
    assert np.all(np.diff(t) > 0)
    steps = np.hypot(*np.diff(log.truth().poses[:, :2], axis=0).T)
    assert np.median(steps) < 2.0  # consecutive corrected poses are close (truth is the laser track)
