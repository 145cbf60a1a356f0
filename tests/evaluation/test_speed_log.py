"""The speed log's calibration check (graphnav.evaluation.datacheck.speed_log_scale): known answers on a
synthetic boat whose log under-reads, whose compass is off and which sails in a current."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from graphnav.evaluation.datacheck import LOG_MIN_PAIRS, speed_log_scale
from graphnav.log import GnssVelocity, Heading, NavLog, WaterSpeed


def _boat(scale: float, offset_deg: float, current: tuple[float, float], *, turn: float = 2 * math.pi / 300,
          n: int = 1800, noise: float = 0.05, seed: int = 0) -> NavLog:
    """1 Hz: a boat at 2.5 m/s through the water turning ``turn`` rad/s; its log reads the speed / ``scale``, its
    compass the heading + ``offset_deg``; the GNSS velocity (``noise`` per axis) is the water velocity plus
    ``current``."""
    rng = np.random.default_rng(seed)
    recs = []
    for k in range(n):
        t, yaw = float(k), turn * k + 0.3
        u = 2.5 * np.array([math.cos(yaw), math.sin(yaw)]) + np.asarray(current)
        recs += [WaterSpeed(t, 2.5 / scale, 0.05), Heading(t + 0.2, yaw + math.radians(offset_deg), 0.01),
                 GnssVelocity(t + 0.4, *(u + rng.normal(0.0, noise, 2)), noise)]
    return NavLog(recs)


@pytest.mark.parametrize("scale,offset", [(1.08, 2.0), (0.95, -1.0), (1.0, 0.0)])
def test_the_scale_the_angle_and_the_current_are_recovered(scale, offset):
    sl = speed_log_scale(_boat(scale, offset, (0.2, -0.1)))
    assert len(sl["windows"]) == 3
    assert sl["scale"] == pytest.approx(scale, abs=0.003)
    assert sl["angle_deg"] == pytest.approx(-offset, abs=0.1)  # the bow back onto the track through the water
    for _, s, se, _, cx, cy, n in sl["windows"]:
        assert abs(s - scale) < 4 * se + 1e-3 and n >= LOG_MIN_PAIRS
        assert cx == pytest.approx(0.2, abs=0.01) and cy == pytest.approx(-0.1, abs=0.01)
    assert sl["scale_spread"] < 0.01
    json.dumps(sl)  # (the JSON of info and compare)


def test_a_straight_leg_cannot_tell_the_scale_from_a_current():
    """On one heading ``s v bow + c`` is one unknown along the bow: no window counts."""
    sl = speed_log_scale(_boat(1.08, 0.0, (0.2, -0.1), turn=0.0))
    assert sl == {"windows": [], "scale": None, "scale_se": None, "scale_spread": None, "angle_deg": None}


def test_without_the_three_kinds_there_is_no_check():
    log = _boat(1.08, 0.0, (0.0, 0.0), n=LOG_MIN_PAIRS - 1)
    assert speed_log_scale(log) is None
    assert speed_log_scale(NavLog([r for r in _boat(1.0, 0.0, (0.0, 0.0)).records
                                   if not isinstance(r, WaterSpeed)])) is None


def test_info_prints_it(tmp_path, capsys):
    from graphnav.cli import main

    path = tmp_path / "boat.jsonl"
    from graphnav.io import save_log

    save_log(_boat(1.08, 0.0, (0.1, 0.0)), path)
    assert main(["info", str(path), "--json"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert obj["speed_log"]["scale"] == pytest.approx(1.08, abs=0.005)
    assert main(["info", str(path)]) == 0
    assert "speed log: x1.08" in capsys.readouterr().out
