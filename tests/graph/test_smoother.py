"""The factor-graph smoother on small synthetic logs with exact truth."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import gtsam
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import factors as F
from graphnav import estimators
from graphnav.evaluation.metrics import ate
from graphnav.geometry import se2_between
from graphnav.graph.keyframes import attachment_error_bound, keyframe_times, nearest, schedule
from graphnav.graph.log_runs import SmootherConfig, run_batch, run_fixed_lag, run_isam2
from graphnav.io import save_log
from graphnav.io.tum import TrajectoryWriter
from graphnav.log import NavLog, Scan
from graphnav.sim.square import square_loop

BEACONS = {"A": (20.0, -25.0), "B": (65.0, 20.0), "C": (-20.0, 30.0)}
FAST = {"covariances": False}


def _ate(result, log) -> float:
    return ate(result.trajectory, log.truth(), max_dt=0.02)["rmse"]


@pytest.fixture(scope="module")
def square():
    return square_loop(0, side=30.0, laps=1)


@pytest.fixture(scope="module")
def square_runs(square):
    opts = {
        "gnss_gate": None,
        "relinearize_threshold": 1e-7,
        "relinearize_threshold_landmarks": 1e-7,
        "relinearize_threshold_bias_deg": 1e-7,
        "final_updates": 10,
        "lm_tol": 1e-14,
        "lm_abs_tol": 0.0,  # solved to the end: the two must reach the same optimum
        "lm_stall_tol": 0.0,
    }
    return run_batch(square, **opts), run_isam2(square, **opts)


def test_batch_and_isam2_agree(square_runs):
    batch, isam = square_runs
    np.testing.assert_allclose(isam.trajectory.poses, batch.trajectory.poses, atol=1e-6)
    assert isam.trajectory.cov is not None and batch.trajectory.cov is not None
    np.testing.assert_allclose(isam.trajectory.cov, batch.trajectory.cov, rtol=1e-3, atol=1e-8)


def test_square_recovers_truth_within_noise(square, square_runs):
    batch, isam = square_runs
    ref = square.truth()
    # GNSS sigma 2 m at 1 Hz + odometry: the smoothed track is far better than a single fix
    assert _ate(batch, square) < 0.6
    # the errors are consistent with the reported marginal covariances (NEES of 3 dof ~ 3)
    truth = ref.interpolate(batch.trajectory.t)
    err = batch.trajectory.poses - truth
    err[:, 2] = (err[:, 2] + math.pi) % (2 * math.pi) - math.pi
    nees = np.einsum("ni,nij,nj->n", err, np.linalg.inv(batch.trajectory.cov), err)
    assert 0.3 < nees.mean() < 9.0
    # online (filter-equivalent) is worse than smoothed, but still bounded
    assert _ate(isam, square) <= ate(isam.online, ref, max_dt=0.02)["rmse"] < 1.5
    assert batch.info["anchor"] == "pose_prior"


def test_beacon_only_localisation_with_charted_beacons():
    log = square_loop(1, side=30.0, gnss=False, compass=False, pose_prior=False, beacons=BEACONS)
    r = run_isam2(log, **FAST)
    assert r.info["anchor"] == "charted beacons"
    assert _ate(r, log) < 0.5
    assert ate(r.online, log.truth(), max_dt=0.02)["rmse"] < 1.0


def test_slam_with_unknown_beacons_converges():
    log = square_loop(2, side=30.0, laps=2, gnss=False, compass=False, beacons=BEACONS, charted=False)
    r = run_batch(log, **FAST)
    est = r.info["beacon_estimates"]
    assert set(est) == set(BEACONS)
    for bid, (x, y) in BEACONS.items():
        init_err = np.hypot(*(np.array(r.info["beacon_init"][bid]) - np.array([x, y])))
        err = np.hypot(est[bid][0] - x, est[bid][1] - y)
        assert err < 0.6 and err <= init_err + 1e-9, (bid, err, init_err)


def test_gnss_jump_is_survived():
    kw = {"side": 30.0, "laps": 1, "compass_bias": math.radians(3.0)}
    clean = square_loop(3, **kw)
    jumped = square_loop(3, gnss_jump=(50.0, 60.0, 20.0, -5.0), **kw)
    for run in (run_isam2, run_batch):
        a0, a1 = _ate(run(clean, **FAST), clean), _ate(run(jumped, **FAST), jumped)
        assert abs(a1 - a0) < 0.1 * a0, (run.__name__, a0, a1)


def test_compass_bias_is_estimated():
    log = square_loop(4, side=30.0, laps=2, compass_bias=math.radians(4.0))
    r = run_isam2(log, **FAST)
    assert r.info["compass_bias_deg"] == pytest.approx(4.0, abs=1.0)


def test_compass_bias_in_segments_is_the_one_constant_bias():
    """``compass.bias_segment_s``: one bias variable per segment, tied by a negligible walk, estimates the
    same constant bias as one variable for the whole log (the same track to 1 cm, the bias to 0.01 deg),
    and every segment's variable holds it (Pose2 and Pose3 graphs)."""
    log = square_loop(4, side=30.0, laps=2, compass_bias=math.radians(4.0))
    for motion in ("odometry", "vessel"):
        one = run_isam2(log, motion=motion, compass_bias_segment_s=None, **FAST)
        seg = run_isam2(log, motion=motion, compass_bias_segment_s=20.0, **FAST)
        assert seg.info["compass_bias_deg"] == pytest.approx(one.info["compass_bias_deg"], abs=0.01)
        if motion == "odometry":  # (the vessel graph, told to ignore the odometer, sees the bias less well)
            assert seg.info["compass_bias_deg"] == pytest.approx(4.0, abs=1.0)
        gap = np.hypot(*(seg.trajectory.poses[:, :2] - one.trajectory.poses[:, :2]).T)
        assert gap.max() < 0.01, (motion, gap.max())
    with pytest.raises(ValueError, match="bias_drift_deg"):
        run_isam2(log, compass_bias_drift_deg=0.0, **FAST)


def test_fixed_lag_close_to_full_smoother(square):
    fl = run_fixed_lag(square, lag=10.0)
    isam = run_isam2(square, **FAST)
    assert len(fl.trajectory) == len(isam.trajectory)
    assert fl.trajectory.cov is not None and np.all(np.linalg.eigvalsh(fl.trajectory.cov) > 0)
    assert _ate(fl, square) < 1.3 * _ate(isam, square) + 0.05


def test_icp_between_factors_carry_the_chain():
    """Scans at each keyframe and a matcher returning noisy true relative poses: with no odometry,
    the ICP factors alone bridge keyframes (and a GNSS outage would not break the chain)."""
    base = square_loop(5, side=30.0, odometry=False)
    ref = base.truth()
    times = ref.t[::5]
    scans = [Scan(float(t), np.ones(4), np.linspace(0, 3, 4)) for t in times]
    log = NavLog.from_unsorted(list(base.records) + scans, base.beacons_known, base.meta)
    rng = np.random.default_rng(0)
    cov = np.diag([0.02**2, 0.02**2, math.radians(0.2) ** 2])

    def matcher(cur, prev, init, *_):
        rel = se2_between(ref.interpolate([prev.t])[0], ref.interpolate([cur.t])[0])
        return True, rel + rng.multivariate_normal(np.zeros(3), cov), cov

    r = run_isam2(log, matcher=matcher, **FAST)
    assert r.info["icp_pairs"] == len(times) - 1 and r.info["icp_failed"] == 0
    assert len(r.icp_ms) == len(times) - 1
    assert _ate(r, log) < 0.5


def test_online_output_is_flushed_as_it_goes(tmp_path, square):
    path = tmp_path / "online.tum"
    seen = []
    with TrajectoryWriter(path) as w:

        def cb(t, pose, cov):
            w.write(t, pose, cov)
            seen.append(sum(1 for line in open(path) if not line.startswith("#")))

        r = run_isam2(square.sliced(0, 30.0), on_estimate=cb, **FAST)
    assert seen == list(range(1, len(r.online) + 1))  # every estimate on disk when it was emitted
    back = np.loadtxt(path, comments="#")
    np.testing.assert_allclose(back[:, 1:3], r.online.poses[:, :2], atol=1e-6)


def test_run_cli_json(tmp_path):
    log = square_loop(6, side=20.0)
    path = tmp_path / "sq.npz"
    save_log(log, path)
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "graphnav",
            "run",
            str(path),
            "--estimator",
            "isam2",
            "--out",
            str(tmp_path / "o"),
            "--json",
            "-O",
            "covariances=false",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    d = json.loads(out.stdout)
    for k in (
        "estimator",
        "steps",
        "ate_rmse_m",
        "ate_mean_m",
        "rpe_rmse_m",
        "runtime_s",
        "step_ms_median",
        "icp_ms_median",
        "online_ate_rmse_m",
        "anchor",
    ):
        assert k in d, k
    assert d["anchor"] == "pose_prior"
    assert (tmp_path / "o" / "trajectory.tum").exists() and (tmp_path / "o" / "online.tum").exists()


def test_unknown_option_is_an_error(square):
    with pytest.raises(ValueError, match="unknown smoother option"):
        estimators.run("isam2", square, lagg=3)
    assert SmootherConfig.from_options({"lag": 3.0}).optimizer.lag == 3.0


def test_keyframe_policy():
    kf = np.array([0.0, 1.0, 2.0, 3.0])
    np.testing.assert_array_equal(nearest(kf, [-1.0, 0.4, 0.5, 0.6, 2.9, 7.0]), [0, 0, 0, 1, 3, 3])
    att, add = schedule(kf, [0.4, 0.6, 1.0, 2.2])
    np.testing.assert_array_equal(att, [0, 1, 1, 2])
    np.testing.assert_array_equal(add, [1, 1, 1, 3])  # never added before its own time
    assert np.all(add >= att)
    log = square_loop(0, side=20.0, gnss=False)
    t = keyframe_times(log, 0.5)
    assert t[0] == log.t0 and np.allclose(np.diff(t), 0.5)
    ref = log.truth()
    b = attachment_error_bound(t, ref.poses, ref.t)
    assert b["max_offset_s"] == pytest.approx(0.25)
    assert b["position_bound_m"] == pytest.approx(0.25 * 1.0, rel=0.02)  # 1 m/s
    scans = [Scan(float(t), np.ones(3), np.zeros(3)) for t in (0.0, 0.2, 0.4, 0.6, 0.8)]
    with_scans = NavLog(scans)
    np.testing.assert_allclose(keyframe_times(with_scans), [0.0, 0.2, 0.4, 0.6, 0.8])
    np.testing.assert_allclose(keyframe_times(with_scans, scan_stride=2), [0.0, 0.4, 0.8])


def test_world_covariance_rotation():
    from graphnav.graph.log_runs import world_cov

    c = world_cov(gtsam.Pose2(0, 0, math.pi / 2), np.diag([4.0, 1.0, 0.1]))
    np.testing.assert_allclose(c, np.diag([1.0, 4.0, 0.1]), atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(0.01, 5.0), min_size=1, max_size=30),
    st.lists(st.floats(-2.0, 60.0), min_size=1, max_size=30),
)
def test_schedule_properties(gaps, times):
    kf = np.cumsum(gaps)
    att, add = schedule(kf, times)
    t = np.array(times)
    dist = np.abs(t[:, None] - kf[None, :])
    np.testing.assert_allclose(dist[np.arange(len(t)), att], dist.min(axis=1))  # nearest keyframe
    assert np.all(add >= att) and np.all(add - att <= 1)
    inside = t <= kf[-1]
    assert np.all(kf[add[inside]] >= t[inside] - 1e-9)  # never added before the measurement exists


def test_attachment_compensation_removes_the_offset_error():
    """Keyframes every 0.7 s, GNSS/compass/sightings at whole seconds (offsets up to 0.35 s at 3 m/s):
    moving each measurement to its keyframe's time by the odometry between them removes the
    attachment error."""
    log = square_loop(
        7,
        side=30.0,
        speed=3.0,
        beacons=BEACONS,
        sigma_range=0.05,
        sigma_bearing=math.radians(0.05),
        sigma_gnss=0.3,
    )
    on = run_batch(log, keyframe_period=0.7, **FAST)
    off = run_batch(log, keyframe_period=0.7, compensate_attachment=False, **FAST)
    a_on, a_off = _ate(on, log), _ate(off, log)
    assert a_on < 0.5 * a_off, (a_on, a_off)


def _initial_guess_ate(nav, log) -> float:
    """ATE of batch's initial guess (before the final LM) against the truth."""
    from graphnav.trajectory import Trajectory

    init = nav.solver.initial
    t = np.array(nav.builder.kf_t)
    poses = np.array([[p.x(), p.y(), p.theta()] for p in (init.atPose2(F.X(k)) for k in range(len(t)))])
    return ate(Trajectory(t, poses), log.truth(), max_dt=0.02)["rmse"]


def test_batch_incremental_initialisation_is_causal_better_and_reaches_the_same_optimum():
    """batch_init="incremental": LM on the graph so far at 32, 48, 72, ... keyframes, the later
    poses chained from that solution. The guess is closer to the truth than dead reckoning's, the
    optimum of this well-posed SLAM problem is the same, and the guess at any time does not depend
    on the records after it."""
    from graphnav.graph.navigator import BATCH_INIT_FIRST, Navigator

    log = square_loop(2, side=30.0, laps=2, gnss=False, compass=False, beacons=BEACONS, charted=False)
    t_cut = log.records[len(log.records) // 2].t
    navs, snap = {}, None
    for how in ("incremental", "chained"):
        nav = Navigator.for_log(log, solver="batch", batch_init=how, covariances=False, lm_abs_tol=0.0,
                                lm_stall_tol=0.0)
        for r in log:
            if how == "incremental" and snap is None and r.t > t_cut:
                snap = gtsam.Values(nav.solver.initial)
            nav.add(r)
        nav.flush()
        navs[how] = (nav, _initial_guess_ate(nav, log), nav.result())
    (inc, inc_ate, inc_r), (_, ch_ate, ch_r) = navs["incremental"], navs["chained"]
    assert inc_ate < 0.5 * ch_ate, (inc_ate, ch_ate)
    np.testing.assert_allclose(inc_r.trajectory.poses, ch_r.trajectory.poses, atol=1e-5)
    n, solves, nxt = len(inc.builder.kf_t), 0, BATCH_INIT_FIRST
    while nxt <= n:
        solves, nxt = solves + 1, max(nxt + 1, math.ceil(nxt * inc.cfg.optimizer.batch_init_growth))
    assert solves >= 3 and inc_r.info["batch_init_solves"] == solves and "batch_init_solves" not in ch_r.info
    # causal: a run on the log cut at t_cut has the very guess the full run had at that time
    cut = Navigator.for_log(log, solver="batch", covariances=False, lm_abs_tol=0.0, lm_stall_tol=0.0)
    for r in log:
        if r.t > t_cut:
            break
        cut.add(r)
    assert cut.extra["batch_init_solves"] >= 1 and cut.solver.initial.size() == snap.size()
    for key in cut.solver.initial.keys():
        if gtsam.Symbol(key).chr() == ord("x"):
            np.testing.assert_array_equal(gtsam.Pose2.Logmap(cut.solver.initial.atPose2(key)),
                                          gtsam.Pose2.Logmap(snap.atPose2(key)))
