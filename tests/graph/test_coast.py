"""Coasting: the online output goes on through a gap without records (a straight line at constant
velocity, GNSS at 1 Hz, then 60 s without any record, then GNSS again). Known answers: the predictions
lie on the output grid inside the gap, at the constant-velocity position within what the noise allows,
with a covariance that grows monotonically; the graph itself is untouched (the estimates at the records
and the smoothed track are those of a run without coasting); live mode's clock tick gives the same."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _live import fed_up_to_the_gap
from _logfactory import straight_line

from graphnav.graph.log_runs import run_isam2
from graphnav.graph.navigator import Navigator
from graphnav.log import NavLog

V = np.array([1.5, 0.8])  # [m/s] the true velocity
SIGMA = 0.5  # [m] the fixes' sigma
SIGMA_V = 0.05  # [m/s] the GNSS velocity's sigma
GAP = (60.0, 121.0)  # the last fix before the gap, the first after


def _line(vessel: bool, seed: int = 1) -> NavLog:
    """Fixes at 1 Hz on ``x = V t`` (+ noise) with no record in ``GAP``; ``vessel``: a compass and GNSS
    velocity with each fix (the Pose3 vessel graph), else the fixes alone (the Pose2 graph)."""
    return straight_line(V, SIGMA, GAP, heading=vessel, velocity_sigma=SIGMA_V if vessel else None, seed=seed)


def _coasted(r):
    o = r.online
    return o, np.asarray(o.meta["coasted"], bool)


@pytest.mark.parametrize("vessel", [True, False])
def test_the_online_output_coasts_on_its_grid_through_a_gap_at_the_constant_velocity(vessel):
    r = run_isam2(_line(vessel))
    o, c = _coasted(r)
    period = r.info["coast_period_s"]
    assert period == pytest.approx(0.5)  # the estimates' median interval (the 0.5 s keyframe grid)
    tc = o.t[c]
    assert r.info["coasted_estimates"] == c.sum() == tc.size
    before, after = o.t[~c][o.t[~c] < tc[0]][-1], o.t[~c][o.t[~c] > tc[-1]][0]
    # on the grid from the last estimate before the gap, up to half a period before the next one
    np.testing.assert_allclose(tc, before + period * np.arange(1, tc.size + 1), atol=1e-9)
    assert tc[-1] < after - period / 2 + 1e-9 <= tc[-1] + period and tc.size >= 110
    assert np.all(np.diff(o.t) > 0)  # one time-ordered output
    err = o.poses[c, :2] - np.outer(tc, V)
    cov = o.cov[c]
    if vessel:  # GNSS velocity 0.05 m/s: the prediction within 3 sigma of the fixes and of that velocity
        dt = tc - GAP[0]
        tol = 3.0 * np.sqrt(SIGMA**2 + (SIGMA_V * dt) ** 2)
        assert np.all(np.hypot(err[:, 0], err[:, 1]) < tol)
    # and within its own covariance (chi-square, 2 dof, 99.9 %)
    m = np.einsum("ni,nij,nj->n", err, np.linalg.inv(cov[:, :2, :2]), err)
    assert np.all(m < 13.8)
    tr = cov[:, 0, 0] + cov[:, 1, 1]
    assert np.all(np.diff(tr) > 0) and np.all(np.diff(cov[:, 2, 2]) >= 0)  # growing with the time coasted
    assert tr[0] > o.cov[~c][o.t[~c] == before][0][:2, :2].trace()


def test_coasting_leaves_the_graph_untouched_and_coast_hz_sets_or_stops_it():
    log = _line(True)
    on, off, hz1 = (run_isam2(log, **kw) for kw in ({}, {"coast_hz": 0.0}, {"coast_hz": 1.0}))
    c = np.asarray(on.online.meta["coasted"], bool)
    assert off.info["coasted_estimates"] == 0 and not np.asarray(off.online.meta["coasted"]).any()
    np.testing.assert_array_equal(on.online.t[~c], off.online.t)
    np.testing.assert_allclose(on.online.poses[~c], off.online.poses, atol=1e-9)
    np.testing.assert_allclose(on.trajectory.poses, off.trajectory.poses, atol=1e-9)
    t1 = hz1.online.t[np.asarray(hz1.online.meta["coasted"], bool)]
    assert hz1.info["coast_period_s"] == 1.0 and np.allclose(np.diff(t1), 1.0) and 55 <= t1.size <= 60
    with pytest.raises(ValueError, match="coast_hz"):
        run_isam2(log, coast_hz=-1.0)


def test_live_clock_ticks_coast_once_the_stream_is_silent_and_never_twice():
    log = _line(True)
    nav = Navigator.for_log(log)
    for rec in log.records:
        if rec.t > GAP[0]:
            break
        nav.add(rec)
    assert nav.coast(GAP[0] + 1.5) == []  # one record period of silence is normal (the keyframe awaits a record)
    first = nav.coast(GAP[0] + 10.0)
    assert first and all(e.coasted for e in first)
    assert first[-1].t <= GAP[0] + 9.0 + 1e-9  # a period behind the stream's time
    assert nav.coast(GAP[0] + 10.0) == []  # nothing twice
    more = nav.coast(GAP[0] + 20.0)
    assert more[0].t > first[-1].t and np.allclose(np.diff([e.t for e in first + more]), first[1].t - first[0].t)
    e = more[-1]
    assert np.hypot(*(e.vec[:2] - V * e.t)) < 3.0 * math.hypot(SIGMA, SIGMA_V * (e.t - GAP[0]))
    assert e.sog == pytest.approx(np.hypot(*V), abs=0.1) and nav.info()["coasted_estimates"] == len(first + more)


def test_the_live_runner_publishes_the_predictions_while_the_stream_is_silent():
    from graphnav.online.live_runner import LiveRunner

    log = _line(True)
    runner = LiveRunner(["udp://127.0.0.1:9"], Navigator.for_log(log))
    real = fed_up_to_the_gap(runner, log, GAP[0])  # the last stamp came at wall time 100 s
    runner.tick(now=101.0)
    assert runner.sink.estimates == real  # one second of silence: nothing due yet
    runner.tick(now=110.0)
    assert runner.sink.coasted == runner.sink.estimates - real > 10 and runner.sink.last.coasted
    assert runner.sink.last.t <= GAP[0] + 9.0 + 1e-9


def test_the_keyframe_policys_spread_is_no_gap():
    """Estimates 0.4-1.0 s apart (one keyframe per metre, at least every second): a 1.0 s interval is the
    normal output, not a gap (twice the 90th percentile: 2.0 s); with an asked rate a gap is 1.5 periods."""
    from graphnav.graph.coast import Coaster

    c = Coaster(None)
    t = 0.0
    for k, dt in enumerate([0.4, 0.5, 0.8, 1.0, 0.4, 0.8, 0.8, 1.0, 0.8, 0.8]):
        t += dt
        c.estimated(k, t)
    assert c.period() == pytest.approx(0.8)
    assert not c.gap(t + 1.0) and not c.gap(t + 1.99) and c.gap(t + 2.01)
    assert c.grid(t + 2.0) == pytest.approx([t + 0.8, t + 1.6])  # what a gap's grid would be
    asked = Coaster(2.0)
    asked.estimated(0, 0.0)
    assert not asked.gap(0.75) and asked.gap(0.76) and Coaster(0.0).period() is None


def test_past_coast_max_s_the_live_output_says_no_fix_once_per_period_instead_of_falling_silent():
    """``coast_max_s``: predictions stop that long after the newest estimate; the output grid then carries
    "no solution" (GGA quality 0 with no position, RMC status V: what a receiver says when it loses its fix),
    each time once, until a record comes back."""
    import pynmea2

    from graphnav.geodesy import LocalFrame
    from graphnav.graph.smoother_config import SmootherConfig
    from graphnav.online.live_runner import LiveRunner

    class Sock:  # the NMEA socket: what was sent
        def __init__(self) -> None:
            self.sent: list[str] = []

        def sendto(self, data: bytes, addr: object) -> None:
            self.sent.extend(data.decode().split())

    log = _line(True)
    nav = Navigator.for_log(log, SmootherConfig.from_options({"coast_max_s": 5.0}))
    runner = LiveRunner(["udp://127.0.0.1:9"], nav)
    runner.sink.sock = sock = Sock()
    runner.nmea.decoder.frame = LocalFrame(43.5, 16.4, 0.0)
    fed_up_to_the_gap(runner, log, GAP[0])
    seed_t = runner.sink.last.t  # the newest real estimate
    sock.sent.clear()
    runner.tick(now=120.0)  # 20 s of silence: 5 s of predictions, then "no fix" up to a period behind
    period = nav.info()["coast_period_s"]
    n = runner.sink.no_fix_outputs
    assert runner.sink.last.coasted and runner.sink.last.t == pytest.approx(seed_t + 5.0)
    assert runner.sink.coasted == round(5.0 / period)
    lag = max(period, 1.0)  # the output runs a period (of the output or of the 1 Hz records) behind the stream
    assert n == round((GAP[0] + 20.0 - lag - (seed_t + 5.0)) / period) > 10
    gga = [pynmea2.parse(s) for s in sock.sent if s[3:6] == "GGA"]
    rmc = [pynmea2.parse(s) for s in sock.sent if s[3:6] == "RMC"]
    quality = [int(g.gps_qual) for g in gga]
    assert quality.count(6) == runner.sink.coasted and quality.count(0) == n == sum(r.status == "V" for r in rmc)
    assert all(g.lat == "" and g.lon == "" for g in gga if int(g.gps_qual) == 0)
    assert quality == sorted(quality, reverse=True)  # predictions first, then "no fix": never mixed
    runner.tick(now=120.0)
    assert runner.sink.no_fix_outputs == n  # nothing twice
    assert nav.info()["no_fix_outputs"] == n and nav.info()["coast_stopped"] == 1
    estimates = runner.sink.estimates
    for rec in log.records:
        if rec.t >= GAP[1]:
            runner._record(rec, None)
    assert runner.sink.estimates > estimates and runner.sink.no_fix_outputs == n
    assert runner.summary()["no_fix_outputs"] == n


@pytest.mark.parametrize("max_s", [math.inf, 1e308])
def test_an_unbounded_coast_max_s_coasts_on_and_never_says_no_fix(max_s):
    """``coast_max_s = inf`` (TOML ``inf``) or one too large to count periods in is no limit: the live tick
    coasts through the silence and says "no fix" at no time (it raised OverflowError)."""
    from graphnav.graph.coast import Coaster

    c = Coaster(10.0, max_s)
    for k in range(5):
        c.estimated(k, float(k))
    assert c.silent(1e6) == [] and c.grid(4.35) == pytest.approx([4.1, 4.2, 4.3])
    log = _line(True)
    nav = Navigator.for_log(log, coast_hz=10.0, coast_max_s=max_s)
    for rec in log.records:
        if rec.t > GAP[0]:
            break
        nav.add(rec)
    coasted = nav.coast(GAP[0] + 20.0)
    assert len(coasted) > 100 and nav.no_fix(GAP[0] + 20.0) == []
