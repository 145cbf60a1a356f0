"""Records are checked once: a reader's checked records are not checked again by the navigator
(``NavLog.checked_records``), and every record that did not come from the reader still is."""

from __future__ import annotations

import json
import math

import pytest

from graphnav import estimators
from graphnav.errors import LogError
from graphnav.io import load_log
from graphnav.io.drop import drop_kinds
from graphnav.log import Gnss, Heading, Limits, NavLog


def _write(path, n=30):
    lines = [{"type": "pose_prior", "t": 0.0, "x": 0.0, "y": 0.0, "yaw": 0.0, "sigma_xy": 1.0, "sigma_yaw": 0.1}]
    for i in range(n):
        lines.append({"type": "gnss", "t": float(i), "x": 0.5 * i, "y": 0.0, "sigma": 1.0})
        lines.append({"type": "heading", "t": float(i), "yaw": 0.0, "sigma": 0.05})
    path.write_text("".join(json.dumps(o) + "\n" for o in lines))
    return path


def test_a_read_log_is_checked_and_its_copies_keep_it(tmp_path):
    log = load_log(_write(tmp_path / "a.jsonl"))
    assert all(ok for _, ok in log.checked_records())
    assert all(ok for _, ok in drop_kinds(log, ["heading"]).checked_records())
    assert all(ok for _, ok in log.sliced(3.0, 9.0).checked_records())
    assert not any(ok for _, ok in NavLog(list(log.records)).checked_records())  # built in Python: unchecked


def test_looser_reader_bounds_are_not_enough(tmp_path):
    log = load_log(_write(tmp_path / "a.jsonl"), limits=Limits(max_coord=1e12))
    assert not any(ok for _, ok in log.checked_records())
    assert all(ok for _, ok in log.checked_records(Limits(max_coord=1e12)))


def test_records_put_in_later_are_not_trusted(tmp_path):
    log = load_log(_write(tmp_path / "a.jsonl"))
    log.records[5] = Gnss(t=log.records[5].t, x=0.0, y=0.0, sigma=1.0)
    log.records.append(Heading(t=99.0, yaw=0.0, sigma=0.1))
    flags = [ok for _, ok in log.checked_records()]
    assert flags[5] is False and flags[-1] is False and sum(flags) == len(flags) - 2


@pytest.mark.parametrize("solver", ["isam2", "batch"])
def test_a_bad_record_slipped_into_a_read_log_is_still_an_error(tmp_path, solver):
    log = load_log(_write(tmp_path / "a.jsonl", n=8))
    i = next(i for i, r in enumerate(log.records) if r.kind == "gnss" and r.t == 4.0)
    log.records[i] = Gnss(t=4.0, x=math.nan, y=0.0, sigma=1.0)
    with pytest.raises(LogError, match=f"record {i + 1} .*finite"):
        estimators.run(solver, log)


def _nmea(path):
    """Two epochs of GGA + RMC + HDT + VTG (checksums computed), one GST re-sigma'ing the second fix."""
    def line(body: str) -> str:
        cs = 0
        for c in body:
            cs ^= ord(c)
        return f"${body}*{cs:02X}\n"

    rows = []
    for i in range(2):
        tod = f"1200{i:02d}.00"
        rows += [f"GPGGA,{tod},5430.9395,N,01833.1088,E,1,10,1.00,0.0,M,0.0,M,,",
                 f"GPRMC,{tod},A,5430.9395,N,01833.1088,E,2.9,90.0,010170,,,A", "HEHDT,90.0,T",
                 "GPVTG,90.0,T,,M,2.9,N,5.4,K,A"]
    rows.append("GPGST,120001.00,1.0,0.5,0.4,0.0,0.8,0.6,1.0")
    path.write_text("".join(line(r) for r in rows))
    return path


def test_an_nmea_log_is_checked_with_the_bounds_it_was_read_with(tmp_path):
    log = load_log(_nmea(tmp_path / "a.nmea"))
    assert len(log) > 0 and all(ok for _, ok in log.checked_records())
    assert any(r.kind == "gnss" and r.sigma == pytest.approx(math.sqrt(0.5 * (0.8**2 + 0.6**2)))
               for r in log.records)  # (the GST's re-sigma'd fix is the checked object)
    loose = load_log(_nmea(tmp_path / "b.nmea"), limits=Limits(max_coord=1e12))
    assert not any(ok for _, ok in loose.checked_records())
