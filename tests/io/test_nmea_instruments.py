"""The records a boat's instruments give, from NMEA 0183 (issues #21, #23; docs/nmea.md): known answers
per sentence (RMC/VTG -> gnss_velocity, VHW -> water_speed, HDG/HDM + variation -> heading, GLL, GNS,
GST sigmas, XDR/PASHR -> attitude), the date rule of dateless logs (``--date``), the per-sentence
counts and gaps of ``info``, and the real boats' logs of ../shared/data/marine (skipped when absent)."""

from __future__ import annotations

import calendar
import json
import math
from pathlib import Path

import numpy as np
import pytest

from graphnav.cli import main
from graphnav.errors import LogError
from graphnav.geometry import heading_deg_to_yaw
from graphnav.io import load_log
from graphnav.io.nmea import (
    HEADING_SIGMA_DEG,
    KNOT,
    UERE_M,
    UNKNOWN_VARIATION_SIGMA_DEG,
    read_nmea,
    velocity_sigma,
    water_speed_sigma,
)
from graphnav.io.nmea_out import checksum

REPO = Path(__file__).resolve().parents[2]
MARINE = next((p for p in (REPO.parent / "shared" / "data" / "marine",
                           REPO.parent.parent / "shared" / "data" / "marine") if p.is_dir()), None)


def s(body: str) -> str:
    return f"${body}*{checksum(body)}"


def write(tmp_path: Path, bodies: list[str], name: str = "x.nmea") -> Path:
    p = tmp_path / name
    p.write_text("\r\n".join(s(b) for b in bodies) + "\r\n")
    return p


ZDA = "GPZDA,120000.00,01,06,2025,00,00"
T0 = calendar.timegm((2025, 6, 1, 12, 0, 0))


# ----------------------------------------------------------------------------- velocity over ground

def test_vtg_known_answer(tmp_path):
    """10 kn at 090 deg true -> vx = 5.144 m/s east, vy = 0; sigma from the stated rule."""
    log = read_nmea(write(tmp_path, [ZDA, "GPVTG,090.0,T,,M,10.0,N,18.5,K,A"]))
    (v,) = log.of("gnss_velocity")
    assert v.t == T0
    assert v.vx == pytest.approx(5.144, abs=5e-4) and v.vx == pytest.approx(10 * 1852 / 3600)
    assert v.vy == pytest.approx(0.0, abs=1e-12)
    assert v.sigma == pytest.approx(velocity_sigma(10 * KNOT, 0.1 * KNOT, math.radians(0.1)))
    assert 0.1 <= v.sigma < 0.102


def test_rmc_velocity_and_one_per_epoch(tmp_path):
    """RMC 4.7 kn at 310 deg: vx = sog sin(cog) < 0 (west), vy > 0 (north); the VTG of the same epoch
    repeats it and is counted, not added; mode N and E give no velocity."""
    log = read_nmea(write(tmp_path, [
        "GPRMC,120000,A,4612.888,N,00610.030,E,04.7,310,010625,,,A",
        "GPVTG,310,T,,M,4.7,N,,,A",  # same epoch: a duplicate
        "GPRMC,120001,A,4612.889,N,00610.029,E,00.0,,010625,,,A",  # at rest, no course: (0, 0)
        "GPRMC,120002,A,4612.889,N,00610.029,E,01.0,,010625,,,A",  # moving, no course: none
        "GPRMC,120003,A,4612.889,N,00610.029,E,01.0,100,010625,,,E",  # dead reckoning: none
        "GPVTG,100,T,,M,1.0,N,,,N"]))  # no fix: none
    v = log.of("gnss_velocity")
    sog = 4.7 * KNOT
    assert len(v) == 2
    assert v[0].vx == pytest.approx(sog * math.sin(math.radians(310))) and v[0].vx < 0
    assert v[0].vy == pytest.approx(sog * math.cos(math.radians(310))) and v[0].vy > 0
    assert v[0].sigma == pytest.approx(velocity_sigma(sog, 0.1 * KNOT, math.radians(1.0)))
    assert (v[1].vx, v[1].vy, v[1].t) == (0.0, 0.0, T0 + 1)
    assert log.meta["duplicate_velocity"] == 1 and log.meta["sog_without_cog"] == 1
    sent = log.meta["sentences"]
    assert sent["GPVTG"] == {"read": 0, "skipped": {"duplicate velocity (same time stamp)": 1, "no speed": 1}}


# ----------------------------------------------------------------------------- water speed

def test_vhw_water_speed(tmp_path):
    log = read_nmea(write(tmp_path, [ZDA, "IIVHW,,T,,M,06.11,N,11.31,K", "IIVHW,,T,,M,,N,18.0,K",
                                     "IIVHW,,T,,M,,N,,K"]))
    w = log.of("water_speed")
    assert [r.v for r in w] == pytest.approx([6.11 * KNOT, 5.0])
    assert w[0].sigma_v == pytest.approx(water_speed_sigma(6.11 * KNOT, 0.01 * KNOT))
    assert w[0].sigma_v == pytest.approx(math.hypot(0.1, 0.05 * 6.11 * KNOT), rel=1e-4)
    assert log.meta["sentences"]["IIVHW"] == {"read": 2, "skipped": {"no speed": 1}}


# ----------------------------------------------------------------------------- heading

def test_hdg_variation_known_answer(tmp_path):
    """HDG 100 deg magnetic with variation 3 E -> 103 deg true -> yaw = pi/2 - 103 deg, CCW from east."""
    log = read_nmea(write(tmp_path, [ZDA, "HCHDG,100.0,,,3.0,E", "HCHDG,100.0,1.0,W,3.0,W"]))
    h = log.of("heading")
    assert h[0].yaw == pytest.approx(math.radians(90.0 - 103.0))
    assert h[0].yaw == pytest.approx(float(heading_deg_to_yaw(103.0)))
    assert h[1].yaw == pytest.approx(math.radians(90.0 - 96.0))  # 100 - 1 (deviation W) - 3 (variation W)
    assert h[0].sigma == pytest.approx(math.radians(HEADING_SIGMA_DEG["HDG"]))


def test_magnetic_heading_without_any_variation(tmp_path):
    """No variation in the sentence, no RMC with one, none stated: the magnetic heading stands for the
    true one, its sigma widened and the sentences counted; ``variation_deg`` states one."""
    p = write(tmp_path, [ZDA, "HCHDG,100.0,,,,", "HCHDM,200.0,M"])
    log = read_nmea(p)
    h = log.of("heading")
    assert [r.yaw for r in h] == pytest.approx([math.radians(-10.0), math.radians(-110.0)])
    assert h[0].sigma == pytest.approx(math.radians(math.hypot(HEADING_SIGMA_DEG["HDG"], UNKNOWN_VARIATION_SIGMA_DEG)))
    assert log.meta["hdg_without_variation"] == 2
    stated = read_nmea(p, variation_deg=-4.0)
    assert [r.yaw for r in stated.of("heading")] == pytest.approx([math.radians(-6.0), math.radians(-106.0)])
    assert "hdg_without_variation" not in stated.meta


def test_hdm_with_rmc_variation(tmp_path):
    log = read_nmea(write(tmp_path, ["GPRMC,120000,A,4612.888,N,00610.030,E,,,010625,2.0,E,A", "IIHDM,31.0,M",
                                     "IIHDM,,M"]))
    (h,) = log.of("heading")
    assert h.yaw == pytest.approx(math.radians(90.0 - 33.0))
    assert log.meta["sentences"]["IIHDM"] == {"read": 1, "skipped": {"empty": 1}}


# ----------------------------------------------------------------------------- positions

def test_gll_gns_and_gst(tmp_path):
    """GNS (mode RR: RTK fixed) gives the fix with HDOP x UERE(4); its GST (after it, same time
    stamp) replaces the sigma; a GLL of the same epoch is not a second fix."""
    log = read_nmea(write(tmp_path, [
        ZDA,
        "GNGNS,120000.00,4332.69262,S,17235.48549,E,RR,13,0.9,25.63,11.24,,",
        "GPGLL,4332.69262,S,17235.48549,E,120000.00,A,D",
        "GNGST,120000.00,0.006,0.023,0.020,273.6,0.030,0.040,0.031",
        "GNGNS,120001.00,4332.69262,S,17235.48549,E,AN,13,1.2,25.63,11.24,,",  # GST 1 s old: used
        "GNGNS,120004.00,4332.69262,S,17235.48549,E,AN,13,1.2,25.63,11.24,,",  # 4 s: HDOP x UERE
        "GNGNS,120005.00,,,,,NN,0,,,,,"]))
    g = log.of("gnss")
    rms = math.sqrt((0.03 ** 2 + 0.04 ** 2) / 2)
    assert [r.sigma for r in g] == pytest.approx([rms, rms, 1.2 * UERE_M[1]])
    assert log.meta["no_fix"] == 1 and log.meta["fix_sigma_from_gst"] == 2
    assert log.meta["sentences"]["GPGLL"] == {"read": 0, "skipped": {"position from GGA/GNS": 1}}


def test_gll_only_log_needs_a_date(tmp_path, capsys):
    """GLL + VTG + VHW + ZDA without a date (plaka's layout): without --date, t is seconds since UTC
    midnight and meta says so; with --date, POSIX time; midnight rolls over to the next day."""
    bodies = ["IIVTG,224.44,T,224.44,M,5.81,N,,,D", "GPZDA,235959,,,,00,", "GPGLL,6005.071,N,02332.346,E,235959,A,D",
              "IIVHW,,T,,M,06.11,N,11.31,K", "GPZDA,000001,,,,00,", "GPGLL,6005.068,N,02332.341,E,000001,A,D"]
    p = write(tmp_path, bodies)
    log = read_nmea(p)
    assert log.counts() == {"gnss": 2, "gnss_velocity": 1, "water_speed": 1}
    assert [r.t for r in log.of("gnss")] == [86399.0, 86401.0]
    assert log.meta["date"]["source"] == "none" and "--date" in log.meta["date"]["note"]
    day = calendar.timegm((2016, 5, 1, 0, 0, 0))
    dated = load_log(p, date="2016-05-01")
    assert [r.t for r in dated.of("gnss")] == [day + 86399.0, day + 86401.0]
    assert dated.meta["date"] == {"source": "--date", "day0": "2016-05-01"} and dated.meta["time"] == "posix"
    assert main(["info", str(p), "--date", "2016-05-01", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["t0"] == day + 86399.0 and out["records"]["gnss"] == 2
    assert out["sentences"]["GPGLL"] == {"read": 2} and out["sentences"]["GPZDA"] == {"read": 2}
    with pytest.raises(SystemExit) as ei:
        main(["info", str(p), "--date", "2016-13-01", "--json"])
    assert ei.value.code == 2
    assert "--date" in capsys.readouterr().err


def test_log_date_wins_over_flag(tmp_path):
    p = write(tmp_path, [ZDA, "GPGLL,6005.071,N,02332.346,E,120000,A,A"])
    log = load_log(p, date="2016-05-01")
    assert log.of("gnss")[0].t == T0 and log.meta["date"]["source"] == "log"
    assert "not used" in log.meta["date"]["note"]


def test_two_digit_zda_year(tmp_path):
    """Navico GoFree sends ZDA years as two digits: read as RMC's (14 -> 2014)."""
    log = read_nmea(write(tmp_path, ["GPZDA,195719,16,04,14,-02,00", "HEHDT,10.0,T"]))
    assert log.of("heading")[0].t == calendar.timegm((2014, 4, 16, 19, 57, 19))
    assert log.meta["zda_two_digit_year"] == 1


# ----------------------------------------------------------------------------- attitude

def test_xdr_and_pashr_attitude(tmp_path):
    """XDR PTCH 2 deg (bow up) and ROLL -3 deg (port down) -> pitch = -2 deg (REP-103: bow down
    positive), roll = -3 deg; PASHR likewise with its own time and accuracy as sigma."""
    log = read_nmea(write(tmp_path, [
        ZDA, "YXXDR,A,2.0,D,PTCH,A,-3.0,D,ROLL", "IIXDR,C,10.7,C,AIRTEMP,A,0.5,D,HEEL",  # heel only: none
        "PASHR,120000.500,224.19,T,-01.26,+00.83,+00.00,0.101,0.113,0.267,1,0"]))
    a = log.of("attitude")
    assert len(a) == 2
    assert (a[0].t, a[0].roll, a[0].pitch) == (T0, pytest.approx(math.radians(-3.0)), pytest.approx(math.radians(-2.0)))
    assert math.isnan(a[0].sigma)
    assert a[1].t == T0 + 0.5
    assert (a[1].roll, a[1].pitch) == (pytest.approx(math.radians(-1.26)), pytest.approx(math.radians(-0.83)))
    assert a[1].sigma == pytest.approx(math.radians(0.113))
    assert log.meta["sentences"]["IIXDR"] == {"read": 0, "skipped": {"no roll and pitch": 1}}


def test_bad_attitude_field_is_named(tmp_path):
    p = write(tmp_path, [ZDA, "YXXDR,A,2.x,D,PTCH,A,-3.0,D,ROLL"])
    with pytest.raises(LogError) as ei:
        read_nmea(p)
    assert (ei.value.line, ei.value.field) == (2, "PTCH")
    log = read_nmea(p, lenient=True)
    assert log.meta["dropped_fields"] == {"PTCH": 1} and not log.of("attitude")


# ----------------------------------------------------------------------------- info: sentences and gaps

def test_info_lists_sentences_and_gaps(tmp_path, capsys):
    bodies = []
    for k in list(range(10)) + list(range(40, 50)):  # a 30 s hole in the fixes
        bodies += [f"GPGGA,1200{k:02d},4612.888,N,00610.030,E,1,08,1.0,0,M,0,M,,", "GPGSV,1,1,00",
                   "IIMWV,280,R,8.5,N,A"]
    p = write(tmp_path, ["GPZDA,115959,01,06,2025,00,00"] + bodies + ["GPGGA,xx"], "g.nmea")
    assert main(["info", str(p), "--json", "--lenient"]) == 0
    out = json.loads(capsys.readouterr().out)
    sent = out["sentences"]
    assert sent["GPGGA"] == {"read": 20, "skipped": {"bad field timestamp": 1}}
    assert sent["GPGSV"] == {"read": 0, "skipped": {"not read by graphnav": 20}}
    assert sent["IIMWV"]["skipped"] == {"not read by graphnav": 20}
    gaps = out["gaps"]["gnss"]
    assert gaps["count"] == 1 and gaps["total_s"] == 31.0 and gaps["longest"] == [[T0 + 9, T0 + 40]]
    assert gaps["threshold_s"] == 5.0


# ----------------------------------------------------------------------------- real boats' logs

def _marine(rel: str) -> Path:
    if MARINE is None or not (MARINE / rel).is_file():
        pytest.skip(f"../shared/data/marine/{rel} not found (real logs, not in the repository)")
    return MARINE / rel


@pytest.mark.parametrize("name,lenient", [("psaros33-20140627-0004.nmea.gz", True),
                                          ("psaros33-20140627-0006.nmea.gz", False),
                                          ("psaros33-20140805-0020.nmea.gz", False)])
def test_psaros33_reads_gnss_heading_velocity_water_speed(name, lenient):
    """The catamaran's RMC + GLL + HDG + VHW: every kind, the HDG variation of the sentence (0004,
    0006: 1 deg E) or, where neither HDG nor RMC has one (0020), counted. 0004 has a real time glitch
    (two epochs stamped a minute early): strict mode names it, lenient skips those lines."""
    p = _marine("anemomind/" + name)
    if lenient:
        with pytest.raises(LogError, match="time goes backwards"):
            load_log(p)
    log = load_log(p, lenient=lenient)
    c = log.counts()
    assert set(c) == {"gnss", "heading", "gnss_velocity", "water_speed"}
    assert min(c.values()) > 5000
    assert log.meta["date"]["source"] == "log"
    v = log.columns("gnss_velocity")
    sog = np.hypot(v["vx"], v["vy"])
    assert 1.0 < float(np.percentile(sog, 90)) < 6.0  # a sailing catamaran: 2-12 kn
    w = log.columns("water_speed")["v"]
    assert 1.0 < float(np.percentile(w, 90)) < 6.0
    if name.endswith("0020.nmea.gz"):
        assert log.meta["hdg_without_variation"] == c["heading"]
    else:
        assert "hdg_without_variation" not in log.meta


def test_plaka_reads_without_a_date():
    """GLL + VTG + VHW with ZDA without a date: records (never 0 in silence), times of day on the day
    --date names; HDT/HDM are present but empty (counted as such)."""
    p = _marine("signalk/plaka.nmea.gz")
    log = load_log(p)
    assert set(log.counts()) == {"gnss", "gnss_velocity", "water_speed"} and min(log.counts().values()) > 7000
    assert log.meta["date"]["source"] == "none" and log.t0 < 86400.0
    sent = log.meta["sentences"]
    assert sent["IIHDT"] == {"read": 0, "skipped": {"empty": 14500}}
    dated = load_log(p, date="2016-05-01")
    assert dated.t0 == calendar.timegm((2016, 5, 1, 0, 0, 0)) + log.t0


def test_gofree_merrimac_reads():
    p = _marine("signalk/gofree-merrimac.nmea.gz")
    log = load_log(p)
    assert set(log.counts()) == {"gnss", "heading", "gnss_velocity", "water_speed"}
    assert log.meta["date"] == {"source": "log", "day0": "2014-04-16"}
    assert log.meta["sentences"]["!AIVDM"]["skipped"] == {"encapsulated (AIS): not navigation input": 1507}
