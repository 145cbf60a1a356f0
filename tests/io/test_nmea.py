"""NMEA 0183 reader and writer: known answers, round trip, errors with line numbers, garbage."""

from __future__ import annotations

import math
import string

import numpy as np
import pynmea2
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from graphnav.errors import LogError
from graphnav.geodesy import LocalFrame
from graphnav.geometry import heading_deg_to_yaw, wrap_angle
from graphnav.io import load_log
from graphnav.io.nmea import UERE_M, read_nmea
from graphnav.io.nmea_out import (
    checksum,
    gga,
    hdt,
    log_to_nmea,
    rmc,
    rot,
    sentence,
    trajectory_to_nmea,
    vtg,
    zda,
)
from graphnav.log import Gnss, Heading, NavLog, Odometry, Scan

GGA_SPEC = "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47"


def write(tmp_path, lines, name="x.nmea"):
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def synthetic_log(n=40, t0=1.7e9):
    recs = []
    rng = np.random.default_rng(3)
    for k in range(n):
        t = t0 + 0.1 * k
        recs.append(Gnss(t, 3.0 * k * 0.1 + rng.normal(), -2.0 * k * 0.1, float(1.0 + 0.5 * (k % 3))))
        recs.append(Heading(t, float(wrap_angle(0.13 * k)), 0.01))
        recs.append(Odometry(t, 2.0 + 0.01 * k, 0.05 - 0.003 * k))
        recs.append(Scan(t, np.ones(3), np.zeros(3)))  # not NMEA: ignored by the writer
    return NavLog.from_unsorted(recs, meta={"origin": {"lat": 59.9, "lon": 10.7}})


def test_checksum_matches_pynmea2():
    assert sentence("GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,") == GGA_SPEC
    for s in (zda(1.7e9), hdt(0.3), vtg(2.0, 1.0), rot(-0.02), gga(5.0, -33.9, -151.2),
              rmc(9.0, 1.0, 2.0, 3.0, 0.4)):
        msg = pynmea2.parse(s, check=True)  # raises on a wrong checksum
        assert s.endswith("*" + checksum(s[1:s.index("*")]))
        assert msg.render() == s


def test_gga_known_answer(tmp_path):
    log = read_nmea(write(tmp_path, [GGA_SPEC]), origin=(48.0, 11.5))
    (g,) = log.of("gnss")
    lat, lon = 48 + 7.038 / 60, 11 + 31.0 / 60
    x, y = LocalFrame(48.0, 11.5).to_local(lat, lon)
    assert g.x == pytest.approx(float(x), abs=1e-9) and g.y == pytest.approx(float(y), abs=1e-9)
    assert g.sigma == pytest.approx(0.9 * UERE_M[1])
    assert g.t == 12 * 3600 + 35 * 60 + 19  # no date: seconds since midnight
    assert log.meta["origin"] == {"lat": 48.0, "lon": 11.5, "h": 0.0}
    # default origin: the first fix
    log2 = read_nmea(write(tmp_path, [GGA_SPEC], "y.nmea"))
    assert log2.meta["origin"]["lat"] == pytest.approx(lat)
    assert log2.of("gnss")[0].x == pytest.approx(0, abs=1e-9)


def test_round_trip_within_format_precision(tmp_path):
    log = synthetic_log()
    lines = [s for _, s in log_to_nmea(log, with_rmc=True)]
    back = load_log(write(tmp_path, lines), origin=(59.9, 10.7))  # dispatch: .nmea -> read_nmea
    assert back.counts() == {"gnss": 40, "heading": 40, "odometry": 40}
    assert back.meta["time"] == "posix"
    for kind, names in (("gnss", ("t", "x", "y")), ("odometry", ("t", "v", "w"))):
        a, b = back.columns(kind), log.columns(kind)
        tol = {"t": 1e-3, "x": 1e-3, "y": 1e-3, "v": 0.0005 * 1852 / 3600, "w": math.radians(0.0005 / 60)}
        for n in names:
            np.testing.assert_allclose(a[n], b[n], atol=tol[n], rtol=0, err_msg=f"{kind}.{n}")
    sig = back.columns("gnss")["sigma"], log.columns("gnss")["sigma"]
    np.testing.assert_allclose(*sig, atol=0.005 * UERE_M[1])
    dyaw = wrap_angle(back.columns("heading")["yaw"] - log.columns("heading")["yaw"])
    assert np.max(np.abs(dyaw)) <= math.radians(0.005) + 1e-12


def test_trajectory_sentences_parse_and_give_rates(tmp_path):
    t = np.arange(5) * 1.0 + 100.0
    poses = np.column_stack([np.arange(5) * 2.0, np.zeros(5), 0.1 * np.arange(5)])
    lines = [s for _, s in trajectory_to_nmea(t, poses, LocalFrame(10.0, 20.0))]
    kinds = [pynmea2.parse(s, check=True).sentence_type for s in lines]
    assert kinds.count("GGA") == 5 and kinds.count("HDT") == 5 and kinds.count("ROT") == 5
    log = read_nmea(write(tmp_path, lines), origin=(10.0, 20.0))
    odo = log.columns("odometry")
    np.testing.assert_allclose(odo["v"], 2.0, atol=1e-3)
    np.testing.assert_allclose(odo["w"], 0.1, atol=1e-6)
    np.testing.assert_allclose(log.columns("gnss")["x"], poses[:, 0], atol=1e-3)


def test_checksum_error_names_line_and_field(tmp_path):
    bad = GGA_SPEC[:-2] + "48"
    p = write(tmp_path, ["# a comment", GGA_SPEC, bad, "$HEHDT,10.0,T*" + checksum("HEHDT,10.0,T")])
    with pytest.raises(LogError) as ei:
        read_nmea(p)
    assert ei.value.line == 3 and ei.value.field == "checksum" and ei.value.file == str(p)
    assert f"{p}:3" in str(ei.value)
    log = read_nmea(p, lenient=True)
    assert log.meta["skipped"] == 1 and "checksum" in log.meta["skipped_errors"][0]
    assert log.counts() == {"gnss": 1, "heading": 1}


def test_malformed_field_is_named(tmp_path):
    body = "GPGGA,123519,48x7.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"
    with pytest.raises(LogError) as ei:
        read_nmea(write(tmp_path, [GGA_SPEC, sentence(body)]))
    assert ei.value.line == 2 and ei.value.field == "lat"
    body = "GPGGA,126519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"
    with pytest.raises(LogError) as ei:
        read_nmea(write(tmp_path, [sentence(body)]))
    assert ei.value.field == "timestamp"


def test_midnight_rollover_and_date(tmp_path):
    f = [sentence("GPGGA,235959.5,4807.038,N,01131.000,E,1,08,0.9,0,M,0,M,,"),
         sentence("GPGGA,000000.5,4807.038,N,01131.000,E,1,08,0.9,0,M,0,M,,")]
    t = read_nmea(write(tmp_path, f)).columns("gnss")["t"]
    assert t[1] - t[0] == pytest.approx(1.0)
    # the date arrives after the first fix: earlier fixes are placed on it too
    f.append(sentence("GPRMC,000001.5,A,4807.038,N,01131.000,E,,,010124,,,A"))
    log = read_nmea(write(tmp_path, f, "d.nmea"))
    t = log.columns("gnss")["t"]
    assert log.meta["time"] == "posix"
    assert t[1] == pytest.approx(1704067200.5)  # 2024-01-01T00:00:00.5Z
    assert t[0] == pytest.approx(1704067199.5)


def test_heading_sentences(tmp_path):
    lines = [sentence("GPZDA,120000.00,01,06,2025,00,00"),
             sentence("HEHDT,45.0,T"),
             sentence("HCHDG,100.0,2.0,E,3.0,W"),  # magnetic 100 + dev 2E - var 3W = 99 true
             sentence("HCHDG,100.0,,,,"),  # before any RMC: the file's first RMC variation (1.5 E)
             sentence("GPRMC,120001,A,4807.038,N,01131.000,E,,,010625,1.5,E,A"),
             sentence("HCHDG,100.0,,,,"),  # the RMC's 1.5 E variation applies
             sentence("GPRMC,120002,A,4807.038,N,01131.000,E,,,010625,2.5,W,A"),
             sentence("HCHDM,100.0,M"),  # the last RMC's: 2.5 W
             sentence("HETHS,270.0,A"),
             sentence("HETHS,271.0,V")]  # invalid: skipped
    log = read_nmea(write(tmp_path, lines))
    yaw = log.columns("heading")["yaw"]
    expect = heading_deg_to_yaw(np.array([45.0, 99.0, 101.5, 101.5, 97.5, 270.0]))
    np.testing.assert_allclose(wrap_angle(yaw - expect), 0, atol=1e-12)
    assert "hdg_without_variation" not in log.meta
    assert log.of("heading")[0].t == pytest.approx(1748779200.0)


def test_rot_sign_sog_and_untimed(tmp_path):
    lines = [sentence("TIROT,60.0,A"),  # before any time: gets the first time; no SOG yet
             sentence("GPVTG,90.0,T,,M,,N,36.0,K,A"),  # km/h only -> 10 m/s (no time yet)
             sentence("GPGGA,000010,0000.000,N,00000.000,E,1,08,1.0,0,M,0,M,,"),
             sentence("TIROT,60.0,A"),  # 60 deg/min to starboard -> w = -1 deg/s
             sentence("TIROT,,V"),
             sentence("GPGGA,000015,0000.000,N,00000.000,E,1,08,1.0,0,M,0,M,,"),
             sentence("TIROT,-30.0,A")]  # SOG now 5 s old: no odometry
    log = read_nmea(write(tmp_path, lines))
    odo = log.of("odometry")
    assert len(odo) == 1  # the first ROT is stamped t = 10 but precedes any SOG (order kept)
    assert odo[0].t == 10.0 and odo[0].v == pytest.approx(10.0)
    assert odo[0].w == pytest.approx(-math.radians(1.0))
    assert log.meta["rot_without_sog"] == 2


def test_no_fix_and_ignored_types(tmp_path):
    lines = [sentence("GPGGA,000010,,,,,0,00,,,M,,M,,"),
             sentence("GPGSV,1,1,00"),
             "!AIVDM,1,1,,A,13aG?P0P00PD;88MD5MTDww@2<0L,0*30",
             sentence("GPRMC,000011,V,,,,,,,010124,,,N")]
    log = read_nmea(write(tmp_path, lines))
    assert len(log) == 0 and log.meta["no_fix"] == 2
    assert log.meta["ignored"]["GSV"] == 1


def test_gzip(tmp_path):
    import gzip

    p = tmp_path / "x.nmea.gz"
    p.write_bytes(gzip.compress((GGA_SPEC + "\n").encode()))
    assert load_log(p).counts() == {"gnss": 1}


VALID = [GGA_SPEC, sentence("GPRMC,000011,A,4807.038,N,01131.000,E,1.0,2.0,010124,,,A"),
         sentence("HEHDT,45.0,T"), sentence("HCHDG,100.0,2.0,E,3.0,W"), sentence("TIROT,60.0,A"),
         sentence("GPVTG,90.0,T,,M,1.0,N,1.8,K,A"), sentence("GPZDA,120000.00,01,06,2025,00,00"),
         sentence("HETHS,270.0,A")]
printable = st.text(alphabet=string.printable.replace("\n", "").replace("\r", "").replace("\x0b", "")
                    .replace("\x0c", ""), max_size=80)


@st.composite
def garbage_line(draw):
    kind = draw(st.integers(0, 3))
    if kind == 0:
        return draw(printable)
    base = draw(st.sampled_from(VALID))
    if kind == 1:  # mutate characters of a valid sentence, checksum left as is
        chars = list(base)
        for _ in range(draw(st.integers(1, 4))):
            chars[draw(st.integers(0, len(chars) - 1))] = draw(st.sampled_from(string.printable[:94]))
        return "".join(chars)
    body = base[1:base.index("*")]
    fields = body.split(",")
    i = draw(st.integers(1, len(fields) - 1)) if len(fields) > 1 else 0
    fields[i] = draw(st.text(alphabet=string.ascii_letters + string.digits + ".-+ ", max_size=12))
    if kind == 3:
        fields = fields[: draw(st.integers(1, len(fields)))]  # truncated
    return sentence(",".join(fields))  # valid checksum around garbage fields


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(garbage_line(), min_size=1, max_size=8))
def test_garbage_only_raises_logerror(tmp_path, lines):
    p = tmp_path / "g.nmea"
    p.write_text("\n".join(VALID[:1] + lines) + "\n")
    try:
        read_nmea(p)
    except LogError as err:
        assert err.line is not None and err.file == str(p)
    log = read_nmea(p, lenient=True)  # never raises
    assert log.meta["skipped"] >= 0


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=200))
def test_binary_garbage(tmp_path, data):
    p = tmp_path / "b.nmea"
    p.write_bytes(data)
    try:
        read_nmea(p)
    except LogError:
        pass
    read_nmea(p, lenient=True)


def test_first_error_in_line_order(tmp_path):
    lines = [GGA_SPEC, sentence("GPGGA,123520,48x7.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"),
             GGA_SPEC[:-2] + "00"]
    with pytest.raises(LogError) as ei:
        read_nmea(write(tmp_path, lines))
    assert ei.value.line == 2 and ei.value.field == "lat"
    log = read_nmea(write(tmp_path, lines), lenient=True)
    assert log.meta["skipped"] == 2 and ":2:" in log.meta["skipped_errors"][0]
