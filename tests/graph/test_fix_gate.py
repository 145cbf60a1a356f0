"""The graph's online GNSS gate (graphnav.graph.fix_gate): known answers on innovations, then the navigator
on a cold start whose first fixes are 40 m off (the online track re-acquires the good fixes once they
outnumber the bad) and on a 20 m jump after minutes of tracking (refused for as long as it lasts)."""

from __future__ import annotations

import numpy as np
import pytest
from _logfactory import straight_line

from graphnav import estimators
from graphnav.graph.fix_gate import FixGate
from graphnav.log import Gnss, NavLog

S = np.eye(2) * 2.0  # the innovation covariance: sigma^2 = 1 m^2 plus the prediction's 1 m^2
VAR = 1.0


def _feed(gate: FixGate, ds) -> list[bool]:
    return [gate.accept(np.asarray(d, float), S, VAR) for d in ds]


def test_a_run_that_outnumbers_the_fixes_behind_the_estimate_is_reacquired():
    g = FixGate(4.0, 15)
    assert _feed(g, [(0.5, 0.0), (-0.3, 0.2), (0.1, -0.4)]) == [True] * 3
    # 40 m off, agreeing with each other within the gate: rejected while they are not more than the 3 accepted
    out = _feed(g, [(40.0, 0.0), (40.8, 0.5), (39.5, -0.3), (40.2, 0.1)])
    assert out == [False, False, False, True] and g.reacquired == 1 and g.taken_back == 3
    assert g.rejected == 0  # the run's rejections are taken back
    assert g.tracked == 4 and g.reacquiring
    assert _feed(g, [(35.0, 0.0)]) == [True]  # ungated while the estimate moves to them ...
    assert _feed(g, [(0.2, 0.1), (9.0, 0.0)]) == [True, False]  # ... until one passes; then gated again


def test_scattered_rejections_and_a_jump_after_long_tracking_are_not_reacquired():
    g = FixGate(4.0, 15)
    _feed(g, [(0.0, 0.0)] * 3)
    # outliers that do not agree with each other (20 m apart) never form a run
    assert _feed(g, [(30.0, 0.0), (0.0, 30.0), (-30.0, 0.0), (0.0, -30.0), (30.0, 30.0)]) == [False] * 5
    assert g.reacquired == 0
    g = FixGate(4.0, 15)
    _feed(g, [(0.0, 0.0)] * 300)
    assert _feed(g, [(20.0, 0.0)] * 10) == [False] * 10 and g.reacquired == 0 and g.rejected == 10
    assert _feed(g, [(20.0, 0.0)] * 6) == [False] * 5 + [True]  # the 16th in a row: gate_max_rejects (rule 1)


@pytest.mark.parametrize("bad", [3, 6])
def test_the_online_track_leaves_a_cold_starts_wrong_first_fixes(bad):
    """A boat at 1.5 m/s with a compass and GNSS velocity (the vessel graph); its first ``bad`` fixes are
    40 m off. Online, the estimate follows them, then re-acquires the good fixes after ``bad + 1`` of them
    (the bad fixes are taken out of iSAM2's online problem) and stays on them."""
    log = straight_line(np.array([1.5, 0.0]), 0.5, (1e6, 1e6 + 1), heading=True, velocity_sigma=0.05, n=41, seed=2)
    recs, n = [], 0
    for r in log.records:
        if isinstance(r, Gnss) and n < bad:
            r = Gnss(r.t, r.x, r.y + 40.0, r.sigma)
            n += 1
        recs.append(r)
    bent = NavLog(recs)
    r = estimators.run("isam2", bent)
    assert r.info["gnss_reacquired"] == 1
    fixes = bent.columns("gnss")
    t_back = fixes["t"][2 * bad]  # the re-acquiring fix: the (bad + 1)-th good one
    on = r.online
    truth = np.c_[1.5 * on.t, np.zeros_like(on.t)]
    err = np.hypot(*(on.poses[:, :2] - truth).T)
    assert np.all(err[on.t >= t_back] < 2.0)  # on the good fixes from the re-acquisition on
    assert np.median(err[on.t < fixes["t"][bad]]) > 10.0  # (on the bad ones before: nothing told them apart)
    ungated = estimators.run("isam2", bent, gnss_gate_online=False).online
    assert np.median(np.hypot(*(ungated.poses[:, :2] - np.c_[1.5 * ungated.t, 0 * ungated.t]).T)) > 5.0
