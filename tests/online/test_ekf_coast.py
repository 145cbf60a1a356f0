"""The online EKF coasts through a gap without records as the navigator does (graphnav.graph.coast): a
straight line at constant velocity, fixes at 1 Hz, then 60 s without any record, then fixes again.
Known answers: the predictions lie on the output grid inside the gap, each the filter's own motion model
in closed form (the vessel model's constant velocity and white-noise acceleration; the unicycle with the
held control) applied to a copy of the filter; the filter's later estimates are bit-identical to a run
without coasting; the flag reaches GGA, Signal K (``navigation.gnss.methodQuality``), the trajectory CSV
and the live summary; ``coast_hz=0`` turns it off and ``coast_max_s`` stops it. ICP motion coasts on the last
scan increment's twist."""

from __future__ import annotations

import json
import math
import socket

import numpy as np
import pytest
from _live import fed_up_to_the_gap
from _logfactory import straight_line

from graphnav.estimators.ekf_online import EkfOnline
from graphnav.geodesy import LocalFrame
from graphnav.io.signalk import DR_MODE, solution_delta
from graphnav.io.trajectory_csv import read_trajectory_csv, write_trajectory_csv
from graphnav.log import NavLog
from graphnav.online.live_runner import LiveRunner
from graphnav.online.runner import run_online
from graphnav.online.sink import Sink
from graphnav.result import Estimate

V = np.array([1.5, 0.8])  # [m/s] the true velocity
SIGMA, SIGMA_V = 0.5, 0.05  # [m], [m/s] the fixes' and the GNSS velocities' sigmas
GAP = (60.0, 121.0)  # the last fix before the gap, the first after
YAW = math.atan2(V[1], V[0])
VESSEL = {"motion": "vessel", "vessel_accel": 0.05, "vessel_yaw_rate_deg": 1.0, "vessel_steerage_speed": 0.5,
          "vessel_position_walk": 0.01}  # stated (the walk given: not estimated from the stream)


def _line(kind: str, seed: int = 1) -> NavLog:
    """Fixes and a compass at 1 Hz on ``x = V t`` (+ noise), none in ``GAP``; ``kind`` "vessel": GNSS
    velocity with each fix, "odometry": the speed and a zero rate of turn."""
    return straight_line(V, SIGMA, GAP, heading=True, velocity_sigma=SIGMA_V if kind == "vessel" else None,
                         odometry=kind == "odometry", seed=seed)


def _options(kind: str) -> dict:
    return dict(VESSEL) if kind == "vessel" else {"motion": "odometry"}


def _closed_form(kind: str, x: np.ndarray, P: np.ndarray, T: float, est: EkfOnline):
    """The filter's motion model over ``T`` in closed form: the mean and covariance of (x, y, yaw)."""
    if kind == "vessel":
        n = len(x)
        F = np.eye(n)
        F[0, 3] = F[1, 4] = T
        qa, walk, qy = VESSEL["vessel_accel"] ** 2, VESSEL["vessel_position_walk"], math.radians(1.0) ** 2
        Q = np.zeros((n, n))
        for i in (0, 1):
            Q[i, i] = qa * T**3 / 3 + walk**2 * T
            Q[i, i + 3] = Q[i + 3, i] = qa * T**2 / 2
            Q[i + 3, i + 3] = qa * T
        Q[2, 2] = qy * T
        return (F @ x)[:3], (F @ P @ F.T + Q)[:3, :3]
    u = est.stepper.u  # the held control
    c, s = math.cos(x[2]), math.sin(x[2])
    G = np.array([[1, 0, -s * T * u.v], [0, 1, c * T * u.v], [0, 0, 1]])
    W = np.array([[c * T, 0], [s * T, 0], [0, T]])
    mean = x[:3] + [u.v * T * c, u.v * T * s, u.w * T]
    return mean, G @ P @ G.T + W @ np.diag([u.sigma_v**2, u.sigma_w**2]) @ W.T


@pytest.mark.parametrize("kind", ["vessel", "odometry"])
def test_the_ekf_coasts_on_its_grid_with_the_models_closed_form(kind):
    log = _line(kind)
    est = EkfOnline(**_options(kind))
    before = [r for r in log.records if r.t <= GAP[0]]
    for r in before:
        est.add(r)
    x0, P0 = est.stepper.f.x.copy(), est.stepper.f.P.copy()  # the state at the last record before the gap
    out = []
    for r in log.records[len(before):]:
        e = est.add(r)
        out += est.coasted_out
        if e is not None:
            out.append(e)
    c = [e for e in out if e.coasted]
    assert all(GAP[0] < e.t < GAP[1] for e in c)
    # on the grid (the estimates' 1 s median interval) from the last estimate, up to half a period before the next
    np.testing.assert_allclose([e.t for e in c], GAP[0] + np.arange(1, 61), atol=1e-9)
    assert est.info()["coasted_estimates"] == 60 and est.info()["coast_period_s"] == pytest.approx(1.0)
    for e in c:
        mean, cov = _closed_form(kind, x0, P0, e.t - GAP[0], est)
        np.testing.assert_allclose(e.vec, mean, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(e.cov, cov, rtol=1e-9, atol=1e-12)
    # against the truth: within the stated covariance (chi-square 2 dof, 99.9 %), the uncertainty growing
    err = np.array([e.vec[:2] - V * e.t for e in c])
    nees = np.einsum("ni,nij,nj->n", err, np.linalg.inv([e.cov[:2, :2] for e in c]), err)
    assert np.all(nees < 13.8)
    assert np.all(np.diff([np.trace(e.cov[:2, :2]) for e in c]) > 0)


@pytest.mark.parametrize("kind", ["vessel", "odometry"])
def test_coasting_leaves_the_filter_untouched_and_coast_hz_0_turns_it_off(kind):
    log = _line(kind)
    on = run_online(log, EkfOnline(**_options(kind)))
    off_est = EkfOnline(**_options(kind), coast_hz=0)
    off = run_online(log, off_est)
    c = on.meta["coasted"]
    assert c.sum() == 60 and not off.meta["coasted"].any() and off_est.info()["coasted_estimates"] == 0
    np.testing.assert_array_equal(on.t[~c], off.t)  # bit-identical: coasting predicts a copy
    np.testing.assert_array_equal(on.poses[~c], off.poses)
    hz2 = run_online(log, EkfOnline(**_options(kind), coast_hz=2.0))
    t2 = hz2.t[hz2.meta["coasted"]]
    np.testing.assert_allclose(np.diff(t2), 0.5)
    assert len(t2) == 121 and t2[0] == 60.5 and t2[-1] == 120.5  # up to half a period before the fix at 121 s
    with pytest.raises(ValueError, match="coast_hz"):
        EkfOnline(coast_hz=-1.0)


def test_coast_max_s_stops_coasting_and_says_so():
    log = _line("vessel")
    est = EkfOnline(**VESSEL, coast_max_s=10.0)
    tr = run_online(log, est)
    tc = tr.t[tr.meta["coasted"]]
    np.testing.assert_allclose(tc, GAP[0] + np.arange(1, 11))  # 10 s after the last estimate, then nothing
    info = est.info()
    assert info["coast_stopped"] == 1 and info["coast_max_s"] == 10.0 and info["coasted_estimates"] == 10


def _signalk_runner(sk: socket.socket, est: EkfOnline, **kw) -> LiveRunner:
    """A ``LiveRunner`` of ``est`` publishing Signal K deltas to ``sk`` (its sink open, its frame set)."""
    runner = LiveRunner(["udp://127.0.0.1:9"], est, publish_signalk=f"udp://127.0.0.1:{sk.getsockname()[1]}", **kw)
    runner.sink.open()
    runner.nmea.decoder.frame = LocalFrame(43.5, 16.4, 0.0)
    return runner


def _received(sk: socket.socket) -> list[dict]:
    """The deltas ``sk`` received (until it has been silent for its timeout)."""
    deltas = []
    while True:
        try:
            deltas.append(json.loads(sk.recv(65536)))
        except TimeoutError:
            return deltas


def test_live_ticks_coast_the_ekf_and_every_output_carries_the_flag(tmp_path):
    log = _line("vessel")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sk:
        sk.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)  # 180 datagrams read after they were sent
        sk.bind(("127.0.0.1", 0))
        sk.settimeout(0.5)
        runner = _signalk_runner(sk, EkfOnline(**VESSEL), out_dir=tmp_path)
        real = fed_up_to_the_gap(runner, log, GAP[0])  # the last stamp came at wall time 100 s
        runner.tick(now=101.5)
        assert runner.sink.estimates == real  # 1.5 s of silence at 1 Hz: nothing due yet
        runner.tick(now=110.0)
        n = runner.sink.coasted
        assert n == runner.sink.estimates - real == 9 and runner.sink.last.coasted  # 61..69: a period behind
        runner.tick(now=110.0)
        assert runner.sink.coasted == n  # nothing twice
        for rec in log.records:
            if rec.t >= GAP[1]:
                runner._record(rec, None)
        runner.sink.close()
        deltas = _received(sk)
    q = [next(v["value"] for v in d["updates"][0]["values"] if v["path"] == "navigation.gnss.methodQuality")
         for d in deltas]
    assert len(q) == runner.sink.estimates and q.count(DR_MODE) == runner.sink.coasted > n  # the rest of the gap
    assert set(q) == {DR_MODE, "GNSS Fix"}
    s = runner.summary()
    assert s["coasted_estimates"] == runner.sink.coasted and s["coasted_spans_total"] == 1
    (t0, t1, count), = s["coasted_spans"]
    assert (t0, t1, count) == (GAP[0] + 1, GAP[0] + 60, 60)


def test_signalk_delta_and_csv_carry_the_flag(tmp_path):
    frame = LocalFrame(43.5, 16.4, 0.0)
    quality = lambda d: [v["value"] for v in d["updates"][0]["values"]  # noqa: E731
                         if v["path"] == "navigation.gnss.methodQuality"]
    assert quality(solution_delta(1.0, [0, 0, 0], frame, coasted=True)) == ["Estimated (DR) mode"]
    assert quality(solution_delta(1.0, [0, 0, 0], frame, coasted=False)) == ["GNSS Fix"]
    assert quality(solution_delta(1.0, [0, 0, 0], frame)) == []
    tr = run_online(_line("odometry"), EkfOnline(motion="odometry"))
    write_trajectory_csv(tr, tmp_path / "online.csv")
    back = read_trajectory_csv(tmp_path / "online.csv")
    np.testing.assert_array_equal(back.meta["coasted"], tr.meta["coasted"])
    np.testing.assert_array_equal(back.t, tr.t)
    assert back.meta["coasted"].sum() == 60


def test_the_sink_counts_coasted_spans():
    sink = Sink()
    for t, c in ((1.0, False), (2.0, True), (3.0, True), (4.0, False), (5.0, True), (6.0, False)):
        sink.emit(Estimate(t, np.array([t, 0.0, 0.0]), np.eye(3), coasted=c), None, None)
    s = sink.summary()
    assert s["coasted_spans"] == [[2.0, 3.0, 2], [5.0, 5.0, 1]] and s["coasted_spans_total"] == 2


def test_run_out_writes_the_online_track_with_its_coasted_column(tmp_path):
    """``graphnav run -e isam2 --out``: ``online_final.csv`` flags the navigator's coasted estimates."""
    import subprocess
    import sys

    from graphnav.io import save_log

    save_log(_line("vessel"), tmp_path / "line.jsonl")
    p = subprocess.run([sys.executable, "-m", "graphnav", "run", str(tmp_path / "line.jsonl"), "-e", "isam2",
                        "--out", str(tmp_path / "o"), "--json"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    tr = read_trajectory_csv(tmp_path / "o" / "online_final.csv")
    c = tr.meta["coasted"]
    assert c.sum() == json.loads(p.stdout)["coasted_estimates"] > 100  # the 0.5 s grid through the 60 s gap
    assert np.all((tr.t[c] > GAP[0]) & (tr.t[c] < GAP[1])) and tr.cov is not None


def test_icp_motion_coasts_on_the_last_increments_twist():
    """``motion="icp"``: a prediction is the last scan increment's constant twist for the time since that
    scan (``Pose2.Expmap(Logmap(inc) * dt / scan interval)`` composed on the state), its covariance grown by the
    failed-match bridge's per scan interval; nothing before the first increment; the filter untouched."""
    import gtsam
    from _harbour import harbour_trial

    from graphnav.scan.motion_guess import CV_BRIDGE_SIGMA

    log = harbour_trial(duration=6.0, rate=5.0, scans=True, scan_hz=1.0)
    est = EkfOnline(motion="icp", emit="all")
    scans = [r for r in log.records if r.kind == "scan"]
    for r in log.records:
        if r is scans[1]:
            break
        est.add(r)
    st = est.stepper
    assert st is not None and st.coast(st.t + 0.5) is None  # one scan so far: no increment to coast on
    for r in log.records:
        if r.t >= scans[1].t:
            est.add(r)
    x0, P0 = st.f.x.copy(), st.f.P.copy()
    last = st.prev_scan
    assert last is not None and st.inc_dt is not None
    t = last.t + 1.7 * st.inc_dt
    g = st.coast(t)
    assert g is not None
    inc = gtsam.Pose2.Expmap(np.asarray(gtsam.Pose2.Logmap(gtsam.Pose2(*st.last_inc))) * 1.7)
    want = gtsam.Pose2(*x0[:3]).compose(inc)
    assert np.allclose(g.x[:2], [want.x(), want.y()], atol=1e-9)
    assert math.isclose(math.remainder(g.x[2] - want.theta(), 2 * math.pi), 0.0, abs_tol=1e-9)
    grown = np.linalg.eigvalsh(g.P[:3, :3] - P0[:3, :3])
    assert grown.min() > -1e-12 and np.trace(g.P[:3, :3]) - np.trace(P0[:3, :3]) >= 1.7 * min(
        np.square(CV_BRIDGE_SIGMA)) * 0.99
    assert np.array_equal(st.f.x, x0) and np.array_equal(st.f.P, P0)  # the filter itself untouched


def test_past_coast_max_s_the_ekf_says_no_gps_on_signalk_and_the_nmea_reader_reads_no_fix(tmp_path):
    """Coasting stops at ``coast_max_s``; then each output time carries Signal K ``methodQuality`` "no GPS"
    with no position, and the NMEA pair (GGA quality 0, RMC status V) is what our own reader takes as no fix."""
    from graphnav.io.nmea import read_nmea
    from graphnav.io.nmea_out import no_fix_sentences
    from graphnav.io.signalk import NO_FIX

    log = _line("vessel")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sk:
        sk.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        sk.bind(("127.0.0.1", 0))
        sk.settimeout(0.5)
        runner = _signalk_runner(sk, EkfOnline(**VESSEL, coast_max_s=10.0))
        fed_up_to_the_gap(runner, log, GAP[0])
        runner.tick(now=130.0)  # 30 s of silence: 10 s coasted, then "no GPS" up to a period behind (89 s)
        runner.tick(now=130.0)
        runner.sink.close()
        deltas = _received(sk)
    values = [{v["path"]: v["value"] for v in d["updates"][0]["values"]} for d in deltas]
    no_fix = [v for v in values if v.get("navigation.gnss.methodQuality") == NO_FIX]
    assert len(no_fix) == runner.sink.no_fix_outputs == 19  # 71 .. 89 s at 1 Hz, each once
    assert all("navigation.position" not in v for v in no_fix)
    assert sum(v.get("navigation.gnss.methodQuality") == DR_MODE for v in values) == runner.sink.coasted == 10
    assert runner.estimator.info()["no_fix_outputs"] == 19
    p = tmp_path / "nofix.nmea"
    p.write_text("\r\n".join(s for k in range(3) for s in no_fix_sentences(1_700_000_000.0 + k)) + "\r\n")
    assert not any(r.kind == "gnss" for r in read_nmea(p, date="2023-11-14").records)
