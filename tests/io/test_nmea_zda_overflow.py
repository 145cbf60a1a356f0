"""A ZDA whose day has 40 digits is a bad field (LogError naming it), not an OverflowError (found by
tests/io/test_fuzz_readers.py's hypothesis search)."""

from __future__ import annotations

import pytest

from graphnav.errors import LogError
from graphnav.io.nmea import read_nmea
from graphnav.io.nmea_out import sentence


def test_zda_with_a_huge_day_is_a_log_error(tmp_path):
    p = tmp_path / "zda.nmea"
    p.write_text(sentence("GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,") + "\n"
                 + sentence("GPZDA,123521.00," + "9" * 40 + ",03,1994,00,00") + "\n")
    with pytest.raises(LogError) as err:
        read_nmea(p)
    assert err.value.line == 2 and err.value.field == "day"
    assert read_nmea(p, lenient=True) is not None
