"""Lenient NMEA at field level, and the GGA/RMC vs ZDA time rule (issue #14; docs/nmea.md).

With ``lenient`` a bad optional field (magnetic variation, SOG, COG, HDOP, RMC/ZDA date, HDG
deviation/variation) is dropped and counted in ``meta["dropped_fields"]``; the sentence is kept.
Strict mode still names the field. A fix time up to 2 s behind a ZDA-set clock is the fix's own
epoch; a ZDA behind the clock is ignored (counted).
"""

from __future__ import annotations

import calendar
from pathlib import Path

import pynmea2
import pytest
from hypothesis import given
from hypothesis import strategies as st

from graphnav.errors import LogError
from graphnav.io.nmea import parse_nmea, read_nmea
from graphnav.io.nmea_out import checksum

_REPO = Path(__file__).resolve().parents[2]
CORPUS = next((p for p in (_REPO.parent / "shared" / "data" / "nmea_corpus",
                           _REPO.parent.parent / "shared" / "data" / "nmea_corpus") if p.is_dir()), None)
T0 = calendar.timegm((2022, 11, 23, 11, 39, 38))


def s(body: str) -> str:
    return f"${body}*{checksum(body)}"


def hms(t: float) -> str:
    t = t % 86400
    return f"{int(t // 3600):02d}{int(t % 3600 // 60):02d}{t % 60:05.2f}"


def rmc(k: int, var: str = "999.9000,E", date: str = "231122", sog: str = "0.5") -> str:
    lat = f"3842.{86006 + k:05d}"
    return s(f"GPRMC,{hms(T0 + k)},A,{lat},N,11705.43645,W,{sog},46.4,{date},{var},D")


def gga(t: float, hdop: str = "0.9") -> str:
    return s(f"GPGGA,{hms(t)},3842.86006,N,11705.43645,W,1,08,{hdop},545.4,M,46.9,M,,")


def zda(t: float, day: str = "23,11,2022") -> str:
    return s(f"GPZDA,{hms(t)},{day},00,00")


def write(tmp_path: Path, lines: list[str], name: str = "f.nmea") -> Path:
    p = tmp_path / name
    p.write_text("\r\n".join(lines) + "\r\n")
    return p


def test_rmc_with_variation_sentinel_is_kept(tmp_path):
    """40 RMC with the 999.9 'no variation' sentinel (a real receiver's, GPSD corpus cat-ms352): all
    40 were lost with lenient; now the fixes, SOG/COG and dates are kept, the field counted."""
    p = write(tmp_path, [rmc(k) for k in range(40)])
    with pytest.raises(LogError) as ei:
        read_nmea(p)
    assert (ei.value.line, ei.value.field) == (1, "mag_variation")
    out, meta = parse_nmea(p, lenient=True)
    assert len(out.records) == 80 and len(out.sog_cog) == 40  # 40 fixes + 40 velocities
    assert meta["skipped"] == 0 and meta["dropped_fields"] == {"mag_variation": 40}
    assert meta["time"] == "posix" and out.records[0].t == pytest.approx(T0)


@pytest.mark.parametrize("kw,field", [({"var": "1.5,N"}, "mag_var_dir"), ({"date": "2208-1"}, "datestamp"),
                                      ({"sog": "abc"}, "spd_over_grnd"), ({"sog": "500"}, "spd_over_grnd")])
def test_bad_optional_rmc_field_drops_only_the_field(tmp_path, kw, field):
    p = write(tmp_path, [rmc(0, **{"var": "1.5,E", **kw}), rmc(1, var="1.5,E")])
    with pytest.raises(LogError) as ei:
        read_nmea(p)
    assert ei.value.field == field and ei.value.line == 1
    log = read_nmea(p, lenient=True)
    velocities = 1 if field == "spd_over_grnd" else 2  # a dropped SOG gives no velocity
    assert log.counts() == {"gnss": 2, "gnss_velocity": velocities}
    assert log.meta["dropped_fields"] == {field: 1} and log.meta["skipped"] == 0


def test_bad_hdop_uses_the_default(tmp_path):
    log = read_nmea(write(tmp_path, [gga(T0, hdop="x.y"), gga(T0 + 1)]), lenient=True)
    sig = [r.sigma for r in log.of("gnss")]
    assert sig == [pytest.approx(1.5 * 3.0), pytest.approx(0.9 * 3.0)]
    assert log.meta["dropped_fields"] == {"horizontal_dil": 1}


def test_speed_beyond_the_vessel_limit_is_dropped(tmp_path):
    lines = [gga(T0), s("GPVTG,90.0,T,,M,200.0,N,370.4,K,A"), s("TIROT,10.0,A"),
             s("GPVTG,90.0,T,,M,5.0,N,9.26,K,A"), s("TIROT,10.0,A")]
    log = read_nmea(write(tmp_path, lines), lenient=True)
    odo = log.of("odometry")
    assert len(odo) == 1 and odo[0].v == pytest.approx(5.0 * 1852 / 3600)
    assert log.meta["dropped_fields"] == {"spd_over_grnd_kts": 1, "spd_over_grnd_kmph": 1}
    assert log.meta["rot_without_sog"] == 1


def test_hdg_bad_variation_falls_back_to_rmc(tmp_path):
    lines = [rmc(0, var="2.0,E"), s("HCHDG,100.0,,,3.0,Q")]
    log = read_nmea(write(tmp_path, lines), lenient=True)
    from graphnav.geometry import heading_deg_to_yaw

    assert log.of("heading")[0].yaw == pytest.approx(float(heading_deg_to_yaw(102.0)))
    assert log.meta["dropped_fields"] == {"var_dir": 1}


def test_zda_one_second_ahead_of_gga_keeps_every_fix(tmp_path):
    """Each epoch: ZDA of the next second, then the GGA and HDT of this one. Before: all 40 fixes and
    40 headings (lenient) were dropped as 'time goes backwards', strict mode failed at line 2."""
    lines = []
    for k in range(40):
        lines += [zda(T0 + k + 1), gga(T0 + k), s("HEHDT,45.0,T")]
    log = read_nmea(write(tmp_path, lines))  # strict: no error
    fixes = log.of("gnss")
    assert [r.t for r in fixes] == pytest.approx([T0 + k for k in range(40)])
    assert log.meta["zda_ahead"] == 40
    heads = log.of("heading")  # untimed sentences after the GGA take the fix's time
    assert [r.t for r in heads] == pytest.approx([T0 + k for k in range(40)])


def test_zda_two_seconds_ahead_and_across_midnight(tmp_path):
    t_mid = calendar.timegm((2022, 11, 24, 0, 0, 0))
    lines = []
    for k in range(-3, 3):  # ZDA 2 s ahead of the GGA that follows, the ZDA crossing midnight first
        day = "24,11,2022" if k + 2 >= 0 else "23,11,2022"
        lines += [zda(t_mid + k + 2, day), gga(t_mid + k)]
    log = read_nmea(write(tmp_path, lines))
    assert [r.t for r in log.of("gnss")] == pytest.approx([t_mid + k for k in range(-3, 3)])


def test_fix_far_behind_a_zda_is_still_an_error(tmp_path):
    p = write(tmp_path, [zda(T0 + 10), gga(T0)])
    with pytest.raises(LogError) as ei:
        read_nmea(p)
    assert ei.value.field == "timestamp" and ei.value.line == 2


def test_zda_behind_the_clock_and_empty_zda_are_counted(tmp_path):
    p = write(tmp_path, [gga(T0 + 55), zda(T0), s("GPZDA,,,,,,"), gga(T0 + 56)])
    log = read_nmea(p)
    assert len(log.of("gnss")) == 2
    assert log.meta["zda_behind"] == 1 and log.meta["zda_without_time"] == 1


@pytest.mark.skipif(CORPUS is None, reason="nmea_corpus not found at ../shared/data/nmea_corpus")
def test_real_receivers():
    """cat-ms352: every RMC kept (mag. variation 999.9 dropped); AC12: ZDA 2 s ahead, strict reads."""
    out, meta = parse_nmea(CORPUS / "cat-ms352.log", lenient=True)
    assert meta["skipped"] == 0 and meta["dropped_fields"]["mag_variation"] >= 40 and len(out.sog_cog) >= 40
    log = read_nmea(CORPUS / "ac12.log")
    t = [r.t for r in log.of("gnss")]
    assert len(t) >= 7 and all(b - a == pytest.approx(1.0) for a, b in zip(t, t[1:], strict=False))


# -- the field parsers: pynmea2's conversions behind graphnav's checks, against the closed form
@given(st.integers(0, 89), st.integers(0, 59), st.integers(0, 9999), st.sampled_from("NS"))
def test_latitude_is_pynmea2s_and_the_closed_form(deg, minute, frac, hemi):
    from graphnav.io.nmea import parse_latlon

    raw = f"{deg:02d}{minute:02d}.{frac:04d}"
    v = parse_latlon(raw, hemi, lat=True)
    expected = (deg + (minute + frac / 1e4) / 60.0) * (1 if hemi == "N" else -1)
    assert abs(v - expected) < 1e-12
    msg = pynmea2.parse(s(f"GPGGA,123519,{raw},{hemi},01131.000,E,1,08,0.9,0,M,0,M,,"))
    assert v == msg.latitude


@given(st.integers(0, 179), st.integers(0, 59), st.integers(0, 99999), st.sampled_from("EW"))
def test_longitude_is_pynmea2s_and_the_closed_form(deg, minute, frac, hemi):
    from graphnav.io.nmea import parse_latlon

    raw = f"{deg:03d}{minute:02d}.{frac:05d}"
    v = parse_latlon(raw, hemi, lat=False)
    assert abs(v - (deg + (minute + frac / 1e5) / 60.0) * (1 if hemi == "E" else -1)) < 1e-12
    assert parse_latlon(raw.split(".")[0], hemi, lat=False) == pytest.approx(
        (deg + minute / 60.0) * (1 if hemi == "E" else -1), abs=1e-12)  # no decimals: accepted


@given(st.integers(0, 23), st.integers(0, 59), st.integers(0, 59), st.integers(0, 999))
def test_time_of_day_is_pynmea2s_and_the_closed_form(hh, mm, ss, ms):
    from graphnav.io.nmea import parse_time_of_day

    raw = f"{hh:02d}{mm:02d}{ss:02d}.{ms:03d}"
    assert abs(parse_time_of_day(raw) - (hh * 3600 + mm * 60 + ss + ms / 1000)) < 1e-6
    msg = pynmea2.parse(s(f"GPGGA,{raw},4807.038,N,01131.000,E,1,08,0.9,0,M,0,M,,"))
    ts = msg.timestamp
    assert parse_time_of_day(raw) == ts.hour * 3600.0 + ts.minute * 60.0 + ts.second + ts.microsecond * 1e-6


@pytest.mark.parametrize(("parse", "raw", "field"), [
    ("time", " 9", "timestamp"), ("time", "+12345", "timestamp"), ("time", "246000", "timestamp"),
    ("time", "123561", "timestamp"), ("lat", "4860.0", "lat"), ("lat", "9100.0", "lat"), ("lat", "48007.5", "lat"),
    ("lat", "", "lat"), ("lon", "18100.0", "lon"), ("lon", "1131.000", "lon"), ("date", "1199", "datestamp"),
    ("date", "310299", "datestamp"),
])
def test_what_pynmea2_would_accept_is_still_a_named_error(parse, raw, field):
    """pynmea2 alone reads these (" 9" s, minutes >= 60, an empty latitude as 0 deg, a 4-digit longitude,
    strptime's "1199"); graphnav names the field instead."""
    from graphnav.io.nmea import parse_date, parse_latlon, parse_time_of_day

    f = {"time": parse_time_of_day, "date": parse_date,
         "lat": lambda r: parse_latlon(r, "N", lat=True), "lon": lambda r: parse_latlon(r, "E", lat=False)}[parse]
    with pytest.raises(LogError) as ei:
        f(raw)
    assert ei.value.field == field


def test_leap_second_and_the_date_pivot():
    from graphnav.io.nmea import parse_date, parse_time_of_day

    assert parse_time_of_day("235960.5") == 86400.5  # datetime.time has no 60th second: graphnav keeps it
    assert str(parse_date("010170")) == "1970-01-01" and str(parse_date("010168")) == "2068-01-01"
