"""NMEA 2000 in (graphnav.io.n2k): the three text formats, fast-packet reassembly, each PGN's record
with known values, sources kept apart and chosen (``--drop gnss@SRC``), errors naming file/line/field,
a hypothesis fuzz (a result or a LogError, bounded memory), and the real logs of
../shared/data/marine (skipped when absent)."""

from __future__ import annotations

import gzip
import math
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from graphnav.errors import LogError
from graphnav.io import load_log
from graphnav.io.drop import drop_kinds, parse_kinds
from graphnav.io.n2k import can_id_split, parse_line, read_n2k

cb = pytest.importorskip("nmea2000._canboat", reason="the [marine] extra (nmea2000) is not installed")
DB = cb.Database("si")
REPO = Path(__file__).resolve().parents[2]
MARINE = next((p for p in (REPO.parent / "shared" / "data" / "marine",
                           REPO.parent.parent / "shared" / "data" / "marine") if p.is_dir()), None)


def _payload(pgn_id: str, **fields) -> bytes:
    return DB.encode(pgn_id, fields)


def _canboat(t: str, pgn: int, src: int, data: bytes, prio: int = 2) -> str:
    return f"{t},{prio},{pgn},{src},255,{len(data)}," + ",".join(f"{b:02x}" for b in data)


def _write(tmp_path: Path, lines: list[str], name: str = "bus.n2k") -> Path:
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


T0 = "2024-06-01T12:00:00.000Z"
POSIX0 = 1717243200.0  # 2024-06-01T12:00:00Z


def test_each_pgn_gives_its_record_with_known_values(tmp_path):
    lines = [
        _canboat(T0, 129029, 7, _payload("gnssPositionData", latitude=59.5, longitude=24.25, method=2, hdop=0.8)),
        _canboat("2024-06-01T12:00:00.100Z", 129026, 7, _payload("cogSogRapidUpdate", cogReference=0, cog=0.5,
                                                                 sog=2.0)),
        _canboat("2024-06-01T12:00:00.200Z", 127251, 9, _payload("rateOfTurn", rate=0.01)),
        _canboat("2024-06-01T12:00:00.300Z", 127257, 9, _payload("attitude", roll=0.1, pitch=0.05)),
        _canboat("2024-06-01T12:00:00.400Z", 128259, 11, _payload("speed", speedWaterReferenced=3.0)),
        _canboat("2024-06-01T12:00:00.500Z", 127250, 9, _payload("vesselHeading", heading=1.0, reference=0)),
        _canboat("2024-06-01T12:00:00.600Z", 127250, 9, _payload("vesselHeading", heading=1.0, reference=1,
                                                                 deviation=0.02, variation=0.1)),
        _canboat("2024-06-01T12:00:01.000Z", 129025, 7, _payload("positionRapidUpdate", latitude=59.5001,
                                                                 longitude=24.25)),
    ]
    log = read_n2k(_write(tmp_path, lines))
    g, vel, odo, att, ws, hd = (log.of(k) for k in ("gnss", "gnss_velocity", "odometry", "attitude", "water_speed",
                                                      "heading"))
    assert log.meta["origin"]["lat"] == pytest.approx(59.5) and log.meta["origin"]["lon"] == pytest.approx(24.25)
    assert g[0].t == pytest.approx(POSIX0) and (g[0].x, g[0].y) == pytest.approx((0.0, 0.0), abs=1e-6)
    assert g[0].sigma == pytest.approx(0.8 * 1.0)  # DGNSS: HDOP x 1 m
    assert g[0].source == "7"
    assert log.meta["odometry"] == "rate of turn + SOG"  # not an odometer (auto_motion)
    # 0.0001 deg of latitude north is 11.1 m; the rapid update inherits HDOP and method of 129029
    assert g[1].y == pytest.approx(11.13, abs=0.02) and abs(g[1].x) < 1e-3 and g[1].sigma == pytest.approx(0.8)
    assert (vel[0].vx, vel[0].vy) == pytest.approx((2.0 * math.sin(0.5), 2.0 * math.cos(0.5)), abs=1e-3)
    assert odo[0].v == pytest.approx(2.0) and odo[0].w == pytest.approx(-0.01, abs=1e-6)  # starboard -> CW
    assert (att[0].roll, att[0].pitch) == pytest.approx((0.1, -0.05), abs=1e-4)  # pitch bow-down positive
    assert ws[0].v == pytest.approx(3.0) and ws[0].source == "11"
    assert hd[0].yaw == pytest.approx(math.pi / 2 - 1.0, abs=1e-4)
    assert hd[1].yaw == pytest.approx(math.pi / 2 - 1.12, abs=1e-4)  # magnetic + deviation + variation
    assert hd[1].sigma > hd[0].sigma
    assert log.meta["pgns"]["read"]["129029"] == 1


def _ydraw_frames(t: str, pgn: int, src: int, data: bytes, prio: int = 3) -> list[str]:
    can_id = cb.can_id_compose(prio, pgn, src, 255)
    frames = cb.fast_packet_fragment(2, data) if len(data) > 8 else [data]
    return [f"{t} R {can_id:08X} " + " ".join(f"{b:02X}" for b in f) for f in frames]


def test_yacht_devices_raw_reassembles_fast_packets_and_takes_the_date(tmp_path):
    fix = _payload("gnssPositionData", latitude=-33.9, longitude=151.2, method=1, hdop=1.2)
    lines = (_ydraw_frames("23:59:59.500", 129029, 3, fix)
             + _ydraw_frames("00:00:00.500", 129026, 3, _payload("cogSogRapidUpdate", cogReference=0, cog=3.0,
                                                                 sog=1.0)))
    assert len(lines) > 2  # 129029 came in several CAN frames
    log = read_n2k(_write(tmp_path, lines, "yd.log"), date="2024-06-01")
    g, v = log.of("gnss"), log.of("gnss_velocity")
    assert len(g) == 1 and g[0].sigma == pytest.approx(1.2 * 3.0) and g[0].source == "3"
    assert g[0].t == pytest.approx(1717286399.5)  # 2024-06-01 23:59:59.5 UTC
    assert v[0].t - g[0].t == pytest.approx(1.0)  # past midnight: the next day
    assert load_log(_write(tmp_path, lines, "yd.log")).counts() == log.counts()  # sniffed as N2K
    undated = read_n2k(_write(tmp_path, lines, "yd.log"))
    assert undated.meta["date"]["source"] == "none" and undated.t0 == pytest.approx(86399.5)


def test_actisense_n2k_ascii_and_can_id():
    data = _payload("vesselHeading", heading=0.5, reference=0)
    fr = parse_line(f"A173321.107 09FF2 1F112 {data.hex().upper()}")
    assert (fr.src, fr.dst, fr.prio, fr.pgn, fr.data, fr.whole) == (9, 255, 2, 127250, data, True)
    assert fr.tod and fr.t == pytest.approx(17 * 3600 + 33 * 60 + 21.107)
    assert can_id_split(0x09F80123) == (2, 129025, 0x23, 255)
    assert can_id_split(0x18EA2301) == (6, 0xEA00, 1, 0x23)  # PDU1: the destination in the identifier


def test_canboat_plain_frames_are_reassembled(tmp_path):
    fix = _payload("gnssPositionData", latitude=10.0, longitude=20.0, method=1, hdop=1.0)
    frames = cb.fast_packet_fragment(5, fix)
    lines = [_canboat(T0, 129029, 4, f) for f in frames]
    log = read_n2k(_write(tmp_path, lines))
    assert len(log.of("gnss")) == 1 and log.meta["pgns"]["read"] == {"129029": 1}


def test_two_sources_kept_apart_chosen_and_fused(tmp_path):
    lines = []
    for i in range(10):
        t = f"2024-06-01T12:00:{i:02d}.000Z"
        lines.append(_canboat(t, 129025, 25, _payload("positionRapidUpdate", latitude=1.0, longitude=2.0)))
        lines.append(_canboat(t, 129025, 52, _payload("positionRapidUpdate", latitude=1.00001, longitude=2.0)))
    log = read_n2k(_write(tmp_path, lines))
    assert [r.source for r in log.of("gnss")[:2]] == ["25", "52"]
    only25 = drop_kinds(log, parse_kinds("gnss@52"))
    assert {r.source for r in only25.of("gnss")} == {"25"} and len(only25.of("gnss")) == 10
    assert len(drop_kinds(log, ["gnss@99"]).of("gnss")) == 20  # fused: both
    with pytest.raises(ValueError, match="KIND@SOURCE"):
        parse_kinds("scan@1")


@pytest.mark.parametrize(("line", "field"), [
    ("2024-06-01T12:00:00.000Z,2,129025,7,255,8,00,00,00,00,00,00,00", "len"),
    ("2024-06-01T12:00:00.000Z,2,129025,7,255,8,zz,00,00,00,00,00,00,00", "data"),
    ("2024-13-01T12:00:00.000Z,2,129025,7,255,8,00,00,00,00,00,00,00,00", "timestamp"),
    ("2024-06-01T12:00:00.000Z,9,129025,7,255,8,00,00,00,00,00,00,00,00", "prio"),
    ("2024-06-01T12:00:00.000Z,2,129025,300,255,8,00,00,00,00,00,00,00,00", "src"),
    ("2024-06-01T12:00:00.000Z,2,129025,7,255,8,00,00,00,40,00,00,00,00", "latitude"),
    ("hello world", "line"),
    ("12:00:00.000 R 1FFFFFFFF 00", "can_id"),
])
def test_bad_lines_name_file_line_and_field(tmp_path, line, field):
    good = _canboat(T0, 128259, 1, _payload("speed", speedWaterReferenced=1.0))
    p = _write(tmp_path, [good, line])
    with pytest.raises(LogError) as ei:
        read_n2k(p)
    assert ei.value.file == str(p) and ei.value.line == 2 and ei.value.field == field
    lenient = read_n2k(p, lenient=True)
    assert lenient.meta["skipped"] == 1 and len(lenient.of("water_speed")) == 1


def test_sources_round_trip_through_jsonl_and_npz(tmp_path):
    from graphnav.io import save_log

    lines = [_canboat(T0, 129025, 25, _payload("positionRapidUpdate", latitude=1.0, longitude=2.0)),
             _canboat(T0, 128259, 35, _payload("speed", speedWaterReferenced=1.5))]
    log = read_n2k(_write(tmp_path, lines))
    for name in ("a.jsonl", "a.npz"):
        save_log(log, tmp_path / name)
        back = load_log(tmp_path / name)
        assert [r.source for r in back.records] == ["25", "35"]


FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
_GOOD = [_canboat(T0, 129029, 7, _payload("gnssPositionData", latitude=59.5, longitude=24.25, method=2, hdop=0.8)),
         _canboat(T0, 127250, 9, _payload("vesselHeading", heading=1.0, reference=0)),
         *_ydraw_frames("12:00:00.000", 129029, 3, _payload("gnssPositionData", latitude=1.0, longitude=2.0,
                                                            method=1))]


@FUZZ
@given(base=st.lists(st.sampled_from(_GOOD), min_size=1, max_size=6),
       cuts=st.lists(st.tuples(st.integers(0, 400), st.text(",0123456789abcdefRTA:.- xZ\x00é", max_size=6)),
                     max_size=4),
       lenient=st.booleans())
def test_fuzz_result_or_logerror_bounded(tmp_path, base, cuts, lenient):
    text = "\n".join(base)
    for pos, ins in cuts:
        pos = min(pos, len(text))
        text = text[:pos] + ins + text[pos + len(ins):]
    p = tmp_path / "fuzz.n2k"
    p.write_text(text, encoding="utf-8")
    tracemalloc.start()
    try:
        try:
            out = read_n2k(p, lenient=lenient)
        except LogError as err:
            assert not lenient and err.file == str(p) and err.line is not None and err.field
            out = None
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 32 << 20
    if out is not None:
        assert all(math.isfinite(r.t) for r in out.records)


def test_a_line_without_end_is_bounded(tmp_path):
    p = tmp_path / "long.n2k"
    p.write_bytes(b"2024-06-01T12:00:00.000Z,2,129025,7,255,8," + b"00," * 200_000)
    with pytest.raises(LogError, match="longer than"):
        read_n2k(p)


def _marine(rel: str) -> Path:
    if MARINE is None or not (MARINE / rel).is_file():
        pytest.skip(f"../shared/data/marine/{rel} not found (real logs, not in the repository)")
    return MARINE / rel


def test_real_aava_reads_its_kinds():
    log = load_log(_marine("signalk/aava-n2k.data.gz"))
    c = log.counts()
    assert c["gnss"] == 1194 and c["heading"] == 596 and c["gnss_velocity"] == 596 and c["water_speed"] > 1000
    assert log.meta["pgns"]["ignored"]["129038"] == 1981  # AIS: counted, not decoded
    g = log.of("gnss")
    assert max(abs(r.x) for r in g) < 5000 and all(r.source == "160" for r in g)


def test_real_furuno_two_gnss_sources(tmp_path):
    src = _marine("canboat/furuno-130842-figure8-fast.raw.gz")
    part = tmp_path / "head.raw.gz"  # the first ~30 s: fast
    with gzip.open(src, "rt") as fh, gzip.open(part, "wt") as out:
        for i, line in enumerate(fh):
            if i > 3000:
                break
            out.write(line)
    log = load_log(part)
    srcs = {r.source for r in log.of("gnss")}
    assert srcs == {"25", "52"}
    a = np.array([[r.t, r.x, r.y] for r in log.of("gnss") if r.source == "25"])
    b = np.array([[r.t, r.x, r.y] for r in log.of("gnss") if r.source == "52"])
    d = np.hypot(np.interp(b[:, 0], a[:, 0], a[:, 1]) - b[:, 1], np.interp(b[:, 0], a[:, 0], a[:, 2]) - b[:, 2])
    assert np.median(d) < 10.0  # one boat: its two receivers within metres of each other
    assert {"odometry", "gnss_velocity", "attitude", "water_speed", "heading"} <= set(log.counts())
    # the SCX-20's heading comes in 127257's yaw (it sends no 127250): within the turns' sideslip of the course
    hd = np.array([[r.t, r.yaw] for r in log.of("heading")])
    assert {r.source for r in log.of("heading")} == {"52"}
    v = np.array([[r.t, r.vx, r.vy] for r in log.of("gnss_velocity") if math.hypot(r.vx, r.vy) > 1.0])
    course = np.arctan2(v[:, 2], v[:, 1])
    slip = np.degrees(np.angle(np.exp(1j * (course - np.interp(v[:, 0], hd[:, 0], np.unwrap(hd[:, 1]))))))
    assert abs(np.median(slip)) < 5.0


def test_attitude_yaw_is_a_true_heading_unless_the_source_sends_127250(tmp_path):
    lines = [
        _canboat(T0, 127257, 12, _payload("attitude", yaw=1.0, roll=0.1, pitch=0.05)),
        _canboat("2024-06-01T12:00:00.100Z", 127250, 9, _payload("vesselHeading", heading=2.0, reference=0)),
        _canboat("2024-06-01T12:00:00.200Z", 127257, 9, _payload("attitude", yaw=2.1, roll=0.1, pitch=0.05)),
        _canboat("2024-06-01T12:00:00.300Z", 127257, 12, _payload("attitude", yaw=-1.0)),
    ]
    log = read_n2k(_write(tmp_path, lines), lenient=True)
    hd = log.of("heading")
    assert [(r.source, round(r.yaw, 4)) for r in hd] == [
        ("12", round(math.pi / 2 - 1.0, 4)), ("9", round(math.pi / 2 - 2.0, 4)), ("12", round(math.pi / 2 + 1.0, 4))]
    assert hd[0].sigma == pytest.approx(hd[1].sigma)  # as a true 127250
    assert len(log.of("attitude")) == 2  # the last 127257 has no roll or pitch


def test_real_aava_head_isam2_follows_its_fixes(tmp_path):
    """``graphnav run LOG -e isam2`` on the first ~40 s of aava-n2k: the track within 2 m (median)
    of the log's own fixes (the whole log: 0.88 m, benchmarks/marine_n2k.py)."""
    from graphnav import estimators

    src = _marine("signalk/aava-n2k.data.gz")
    part = tmp_path / "head.data"
    with gzip.open(src, "rt") as fh:
        part.write_text("".join(next(fh) for _ in range(1500)))
    log = load_log(part)
    tr = estimators.run("isam2", log).trajectory
    g = np.array([[r.t, r.x, r.y] for r in log.of("gnss") if tr.t[0] <= r.t <= tr.t[-1]])
    d = np.hypot(np.interp(g[:, 0], tr.t, tr.poses[:, 0]) - g[:, 1], np.interp(g[:, 0], tr.t, tr.poses[:, 1]) - g[:, 2])
    assert len(g) > 60 and np.median(d) < 2.0
