"""The NMEA reader's shortcuts against pynmea2 itself: the first pass's look at an RMC's variation field
without parsing it, and the kept time-of-day and date conversions."""

from __future__ import annotations

import datetime as dt

import pynmea2
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from graphnav.errors import LogError
from graphnav.io.nmea import _rmc_variation_text
from graphnav.io.nmea_fields import parse_date, parse_time_of_day, raw_field

FIELD = st.text(alphabet="0123456789.EWNSAV -+\t", max_size=8)


def _checksum(body: str) -> str:
    cs = 0
    for c in body:
        cs ^= ord(c)
    return f"{cs:02X}"


@settings(max_examples=400)
@given(st.lists(FIELD, min_size=0, max_size=14), st.sampled_from(["GP", "GN", "II"]), st.booleans())
def test_the_variation_field_is_empty_only_where_pynmea2_reads_none(fields, talker, with_checksum):
    body = ",".join([talker + "RMC", *fields])
    line = "$" + body + (f"*{_checksum(body)}" if with_checksum else "")
    try:
        msg = pynmea2.parse(line)
    except (pynmea2.ParseError, ValueError, TypeError, IndexError, AttributeError, KeyError):
        return  # (the first pass passes over a sentence pynmea2 cannot parse, as over one not parsed)
    text = str(msg.mag_variation or "").strip()
    fast = _rmc_variation_text(line.encode())
    assert (fast == b"") == (text == "")
    assert fast.decode() == text


def test_the_variation_field_of_real_sentences():
    assert _rmc_variation_text(b"$GNRMC,000000.200,A,5430.9,N,01833.1,E,2.9,90.00,010170,,,A*71") == b""
    assert _rmc_variation_text(b"$GPRMC,081836,A,3751.65,S,14507.36,E,000.0,360.0,130998,011.3,E*62") == b"011.3"
    assert _rmc_variation_text(b"$GPRMC,081836,A,3751.65,S") == b""


@given(st.integers(0, 23), st.integers(0, 59), st.integers(0, 59), st.sampled_from(["", ".5", ".25", ".125",
                                                                                     ".000001", ".9999999"]))
def test_time_of_day_is_pynmea2s(h, m, s, frac):
    raw = f"{h:02d}{m:02d}{s:02d}{frac}"
    ts = pynmea2.nmea_utils.timestamp(raw)
    want = ts.hour * 3600.0 + ts.minute * 60.0 + ts.second + ts.microsecond * 1e-6
    for _ in range(2):  # (the second answer is the kept one)
        assert parse_time_of_day(raw) == want


@given(st.dates(dt.date(1969, 1, 1), dt.date(2068, 12, 31)))
def test_date_is_pynmea2s(d):
    raw = d.strftime("%d%m%y")
    for _ in range(2):
        assert parse_date(raw) == pynmea2.nmea_utils.datestamp(raw) == d


def test_a_date_that_does_not_exist_is_an_error_every_time():
    for _ in range(2):
        with pytest.raises(LogError, match="does not exist"):
            parse_date("310299")


@given(st.dates(dt.date(1900, 1, 1), dt.date(2200, 12, 31)))
def test_posix_midnight_is_the_calendars(d):
    import calendar

    from graphnav.io.nmea_fields import posix_midnight

    for _ in range(2):
        assert posix_midnight(d) == float(calendar.timegm(d.timetuple())) == dt.datetime(
            d.year, d.month, d.day, tzinfo=dt.UTC).timestamp()


@pytest.mark.parametrize("line", [
    "$GPRMC,081836,A,3751.65,S,14507.36,E,000.0,360.0,130998,011.3,E*62",
    "$GPVTG,054.7,T,034.4,M,005.5,N,010.2,K*48", "$IIVHW,,T,,M,04.7,N,08.7,K*59",
    "$GPZDA,201530.00,04,07,2002,00,00*60",
    "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47"])
def test_raw_field_is_the_field_pynmea2s_attribute_reads(line):
    msg = pynmea2.parse(line)
    names = [f[1] for f in msg.fields]
    for i, name in enumerate(names):
        assert raw_field(msg, name) == (str(msg.data[i]) if i < len(msg.data) else "")
        if len(msg.fields[i]) < 3:  # an untyped field: pynmea2's attribute is the text itself
            assert raw_field(msg, name) == (getattr(msg, name) or "")
    assert raw_field(msg, "no_such_field") == ""
