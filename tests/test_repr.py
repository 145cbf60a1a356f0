"""Short reprs: a log, a trajectory or a result prints in one line, and as a small table in a notebook."""

from __future__ import annotations

import numpy as np
from _polyworld import synthetic_log

from graphnav import estimators
from graphnav.trajectory import Trajectory


def test_reprs_are_short_whatever_the_size():
    log = synthetic_log(120)  # 120 scans of 360 beams: the dataclass repr was megabytes
    log.meta["name"] = "poly"
    res = estimators.run("dead-reckoning", log)
    big = Trajectory(np.arange(100_000.0), np.zeros((100_000, 3)), np.zeros((100_000, 3, 3)), name="big")
    for obj in (log, res, res.trajectory, big):
        r = repr(obj)
        assert len(r) < 300 and "\n" not in r, r
        h = obj._repr_html_()
        assert len(h) < 4000 and "<table>" in h and h.count("<tr>") >= 2, h
    assert repr(log).startswith("<NavLog 'poly': ") and "scan 120" in repr(log)
    assert "scan</td><td>120</td>" in log._repr_html_()
    assert repr(big) == "<Trajectory 'big': 100000 poses, 0.00–99999.00 s, 0.0 m, with covariance>"
    assert repr(res).startswith(f"<RunResult: {len(res.trajectory)} poses")


def test_reprs_of_empty_objects():
    from graphnav.log import NavLog
    from graphnav.result import RunResult

    empty = Trajectory(np.zeros(0), np.zeros((0, 3)))
    assert repr(empty) == "<Trajectory: 0 poses, empty>"
    assert repr(NavLog([])) == "<NavLog: 0 records, empty; no records>"
    assert "online: none" in repr(RunResult(empty)) and "<table>" in RunResult(empty)._repr_html_()
