"""The ``ekf`` estimator online (graphnav.estimators.ekf_online.EkfOnline): the batch filter step for step,
estimates per fix and through outages, and ``graphnav live --estimator ekf`` on loopback."""

from __future__ import annotations

import json
import socket
import sys
import time
from pathlib import Path

import numpy as np
import pynmea2
import pytest
from _harbour import harbour_trial
from _live import start_live

from graphnav.estimators.ekf import run_ekf
from graphnav.estimators.ekf_online import EkfOnline
from graphnav.evaluation.metrics import ate
from graphnav.geodesy import LocalFrame
from graphnav.io import load_log
from graphnav.log import Gnss, Heading, NavLog
from graphnav.online.nmea_replay import replay
from graphnav.online.runner import make_online, run_online

REPO = Path(__file__).resolve().parents[2]


def last_per_time(tr):
    """The last estimate of every time (the batch filter reports the state after a time's last
    record). The online filter starts once the first epoch is complete, so its first estimate is
    the second epoch's: the batch's first one is dropped for the comparison."""
    keep = np.append(tr.t[1:] != tr.t[:-1], True)
    return tr.t[keep], tr.poses[keep]


@pytest.mark.parametrize("speed", [False, True])
def test_online_is_the_batch_filter_on_the_harbour_log(speed, legacy_harbour):
    log = legacy_harbour.sliced(None, 120.0)  # odometry-driven; anchored by its pose prior
    batch = run_ekf(log, speed=speed).trajectory
    est = EkfOnline(motion="odometry", emit="all", speed=speed)
    t, poses = last_per_time(run_online(log, est))
    np.testing.assert_array_equal(t, batch.t[1:])
    np.testing.assert_array_equal(poses, batch.poses[1:])  # bit-identical: the same EkfStepper
    assert est.info()["anchor"] == "pose_prior"


def test_online_is_the_batch_filter_when_anchored_by_the_first_fix():
    log = harbour_trial(duration=30.0, rate=5.0, seed=4)  # no prior: first fix + first heading
    batch = run_ekf(log, gate=0.99)
    est = make_online("ekf", emit="all", gate=0.99)  # motion "auto": the batch's choice, from the first epoch
    t, poses = last_per_time(run_online(log, est))
    assert est.motion == batch.info["motion"] == "odometry"
    np.testing.assert_array_equal(t, batch.trajectory.t[1:])
    np.testing.assert_array_equal(poses, batch.trajectory.poses[1:])
    assert est.info()["anchor"] == batch.info["anchor"] == "gnss"


def test_online_is_the_batch_filter_with_icp_motion():
    """``motion="icp"``: the state moves at scans only, but each estimate carries its record's time
    (it carried the last scan's)."""
    log = harbour_trial(duration=6.0, rate=5.0, scans=True, scan_hz=1.0)
    batch = run_ekf(log, motion="icp")
    est = EkfOnline(motion="icp", emit="all")
    t, poses = last_per_time(run_online(log, est))
    np.testing.assert_array_equal(t, batch.trajectory.t[1:])
    np.testing.assert_array_equal(poses, batch.trajectory.poses[1:])


def test_one_estimate_per_fix_and_dead_reckoning_in_an_outage():
    log = harbour_trial(duration=40.0, rate=5.0, seed=1)
    t0 = log.t0
    gap = log.without(lambda r: r.kind == "gnss" and 10.0 <= r.t - t0 < 25.0)
    est = EkfOnline(motion="odometry")
    estimates = [e for r in gap.records if (e := est.add(r)) is not None]
    t = np.array([e.t for e in estimates])
    fixes = np.array([r.t for r in gap.of("gnss")])
    assert np.all(np.diff(t) >= 0)  # (the fix that ends an outage re-reports its epoch, updated)
    assert set(fixes[1:]) <= set(t)  # every fix yields an estimate (the first epoch starts the filter)
    outage = t[(t > t0 + 10.0) & (t < t0 + 25.0)]
    assert len(outage) >= 10 * 12  # 10 Hz odometry keeps the output going after 1.5 s without a fix
    assert not np.any((t > t0 + 2.0) & (t < t0 + 10.0) & ~np.isin(t, fixes))  # otherwise: fixes only
    e = estimates[-1]
    assert e.cov.shape == (3, 3) and e.sog == pytest.approx(1.5, abs=0.4) and e.w is not None
    tr = log.truth()
    err = np.hypot(*(np.array([x.vec[:2] for x in estimates]) - tr.interpolate(t)[:, :2]).T)
    assert np.sqrt(np.mean(err**2)) < 1.5  # GNSS sigma 1.5 m per axis, 15 s of dead reckoning


def test_without_gnss_updates_every_record_is_an_outage_from_the_start():
    """``use_gnss=False``: the fixes held for the start are no more fixes than the later ones, so
    the output does not wait ``outage_s`` after them."""
    log = harbour_trial(duration=5.0, rate=5.0)
    est = EkfOnline(motion="odometry", use_gnss=False)
    t = np.array([e.t for r in log.records if (e := est.add(r)) is not None])
    assert len(t) and t[0] < log.t0 + 0.5


def test_late_are_counted_and_ignored():
    log = harbour_trial(duration=5.0, rate=5.0)
    est = EkfOnline(motion="odometry")
    run_online(log, est)
    x = est.stepper.f.x.copy()
    assert est.add(Gnss(log.t0, 0.0, 0.0, 1.0)) is None and est.counts["late"] == 1
    np.testing.assert_array_equal(est.stepper.f.x, x)


def test_unknown_option_is_a_value_error():
    with pytest.raises(ValueError, match="ekf"):
        make_online("ekf", lag=5.0)
    with pytest.raises(ValueError, match="emit"):
        EkfOnline(emit="sometimes")


def test_without_heading_it_starts_after_init_wait():
    log = harbour_trial(duration=6.0, rate=5.0).without(lambda r: r.kind == "heading")
    est = EkfOnline(motion="odometry", init_wait=2.0)
    tr = run_online(log, est)
    assert tr.t[0] == pytest.approx(log.t0 + 2.0) and est.info()["anchor"] == "gnss"
    assert ate(tr, log.truth())["rmse"] < 5.0


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX loopback sockets")
def test_live_cli_with_the_ekf_publishes_parseable_nmea(tmp_path):
    log = harbour_trial(duration=10.0, rate=10.0, seed=3)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.settimeout(0.05)
    p = start_live(tmp_path / "o", "--estimator", "ekf", "-O", "motion=odometry", "--nmea", f"udp://127.0.0.1:{port}",
                   "--publish", f"udp://127.0.0.1:{sink.getsockname()[1]}", "--idle-exit", "1", "--duration", "60",
                   "--json")
    data = []
    deadline = time.monotonic() + 30
    try:
        replay(log, f"udp://127.0.0.1:{port}", speed=10.0)
        while p.poll() is None and time.monotonic() < deadline + 30:
            try:
                data.append(sink.recv(65536))
            except TimeoutError:
                pass
        out, err = p.communicate(timeout=20)
    finally:
        if p.poll() is None:
            p.kill()
        sink.close()
    assert p.returncode == 0, err
    summary = json.loads(out)
    assert summary["estimator"]["estimator"] == "ekf-online" and summary["bad_sentences"] == 0
    # the first fix's epoch starts the filter; once the stream ended (1 s before --idle-exit) it coasted
    assert summary["estimates"] - summary["coasted_estimates"] == len(log.of("gnss")) - 1
    assert summary["coasted_estimates"] >= 1 and summary["estimator"]["coasted_estimates"] >= 1
    lines = [ln for d in data for ln in d.decode("ascii").split("\r\n") if ln]
    msgs = [pynmea2.parse(s, check=True) for s in lines]
    assert {m.sentence_type for m in msgs} == {"GGA", "HDT", "VTG", "ROT"}
    assert summary["published"] == len(lines) == 4 * summary["estimates"]
    frame = LocalFrame(*[log.meta["origin"][k] for k in ("lat", "lon")])
    gga = [m for m in msgs if m.sentence_type == "GGA"]
    coasted = [int(m.gps_qual) == 6 for m in gga]  # GGA quality 6: estimated (dead reckoning), at the end only
    assert sum(coasted) == summary["coasted_estimates"]
    assert all(coasted[len(coasted) - sum(coasted):]) and not any(coasted[:len(coasted) - sum(coasted)])
    gga = [m for m, c in zip(gga, coasted, strict=True) if not c]
    x, y = frame.to_local(np.array([m.latitude for m in gga]), np.array([m.longitude for m in gga]))
    fixes = log.of("gnss")[1:]
    ref = log.truth().interpolate(np.array([r.t for r in fixes]))
    err = np.hypot(x - ref[:, 0], y - ref[:, 1])
    offline = run_online(NavLog(log.records, meta=log.meta), make_online("ekf", motion="odometry"))
    off_err = np.hypot(*(offline.poses[:, :2] - log.truth().interpolate(offline.t)[:, :2]).T)
    rms = lambda e: float(np.sqrt(np.mean(np.square(e))))  # noqa: E731
    assert rms(err) <= 1.2 * rms(off_err) + 0.05, (rms(err), rms(off_err))  # the NMEA path costs ~nothing
    assert rms(err) < 1.5  # inside the GNSS noise (1.5 m per axis)


def test_records_held_before_the_first_fix_are_bounded_and_counted():
    est = EkfOnline(motion="odometry")
    n = est.pending.maxlen + 5
    for k in range(n):
        assert est.add(Heading(0.1 * k, 0.3, 0.02)) is None  # no fix yet: held, nothing estimated
    assert len(est.pending) == est.pending.maxlen and est.counts["dropped_before_start"] == 5
    assert est.counts["heading"] == n


def test_online_is_the_batch_filter_with_imu_motion():
    """A USV's log (no odometry): the INS/GNSS EKF online, given the IMU options the batch reads
    from the log, gives the batch filter's estimates."""
    from graphnav.estimators.ekf import imu_options

    log = load_log(REPO / "data" / "harbour.npz").sliced(None, 60.0)  # the embedded USV log: no odometer
    batch = run_ekf(log)
    assert batch.info["motion"] == "imu"
    est = EkfOnline(emit="all", motion="imu", **imu_options(log, {}))
    t, poses = last_per_time(run_online(log, est))
    np.testing.assert_array_equal(t, batch.trajectory.t[1:])
    np.testing.assert_allclose(poses, batch.trajectory.poses[1:], atol=1e-9)
    e = est._estimate()
    assert e.sog is not None and 1.0 < e.sog < 2.0 and est.info()["imu"] > 0


def test_auto_motion_is_chosen_from_the_stream_as_the_batch_chooses_it():
    """``motion="auto"`` (the default) waits ``init_wait`` after the first fix and picks the batch rule's
    motion from the held records: a boat's GNSS + compass + GNSS velocity (no IMU, no odometer) -> the
    vessel model, and then it is the batch filter; a ROT + SOG odometry marked by ``meta`` too."""
    import math

    from graphnav.log import ODOMETRY_FROM_ROT, Gnss, GnssVelocity, Heading, NavLog, Odometry

    recs = []
    for k in range(120):
        t = float(k)
        recs += [Gnss(t, 2.0 * t, 0.3 * t, 2.0), Heading(t, 0.0, math.radians(0.5)), GnssVelocity(t, 2.0, 0.3, 0.05)]
    log = NavLog.from_unsorted(recs)
    on = EkfOnline(emit="all")
    est = [e for e in (on.add(r) for r in log.records) if e is not None]
    assert on.motion == "vessel" and on.info()["motion"] == "vessel"
    batch = run_ekf(log)
    assert batch.info["motion"] == "vessel"
    t = np.array([e.t for e in est])
    i = np.searchsorted(batch.trajectory.t, t)
    assert np.allclose(np.array([e.vec for e in est])[:, :2], batch.trajectory.poses[i, :2], atol=1e-6)
    rot = recs + [Odometry(k + 0.5, 2.0, 0.0) for k in range(120)]
    plain = EkfOnline(emit="all")
    marked = EkfOnline(emit="all", meta={"odometry": ODOMETRY_FROM_ROT})
    for r in NavLog.from_unsorted(rot).records:
        plain.add(r)
        marked.add(r)
    assert plain.motion == "odometry" and marked.motion == "vessel"  # odometry at k + 0.5: after the first epoch
    # the provisional choice (vessel: the first epoch has no odometry) was replaced by the final one, and the
    # filter rebuilt: from then on it is the batch filter with that motion
    assert plain.stepper is not None and plain.stepper.motion == "odometry"


def test_the_vessel_filter_estimates_its_position_walk_from_the_stream():
    """Fixes wandering 0.4 m/sqrt(s) from the exact SOG/COG: the online vessel filter takes the walk the
    stream shows (as live mode's graph, :class:`graphnav.graph.position_walk.WalkTracker`), close to what
    the batch filter reads from the whole log; a given walk is kept."""
    from _logfactory import wandering_fixes

    from graphnav.graph.position_walk import position_walk
    from graphnav.log import NavLog

    recs = wandering_fixes()
    on = EkfOnline()
    for r in recs:
        on.add(r)
    assert on.motion == "vessel" and on.walker is not None and on.walker.updates >= 3
    whole = position_walk(NavLog(recs))["walk"]
    assert on.stepper is not None
    assert on.stepper.vessel["vessel_position_walk"] == pytest.approx(whole, rel=0.15)
    assert on.info()["position_walk_live"]["walk"] == on.stepper.vessel["vessel_position_walk"]
    given = EkfOnline(motion="vessel", vessel_position_walk=0.1)
    for r in recs:
        given.add(r)
    assert given.walker is None and given.stepper.vessel["vessel_position_walk"] == pytest.approx(0.1)
