"""Never an indeterminate system: the motion factor on every pose (known answers for each
fallback), duplicated and equal-time records, empty scans, a GNSS-only log, a degenerate corridor
in the middle of a log, and a solver failure reported as a GraphnavError naming the record."""

from __future__ import annotations

import math
from pathlib import Path

import gtsam
import numpy as np
import pytest
from _scan_sim import raycast

from graphnav.errors import GraphnavError
from graphnav.evaluation.metrics import ate, nees_stats
from graphnav.geometry import se2_between
from graphnav.graph.builder import GraphBuilder
from graphnav.graph.log_runs import run_batch, run_fixed_lag, run_isam2
from graphnav.graph.navigator import Navigator
from graphnav.graph.smoother_config import SmootherConfig
from graphnav.log import Gnss, NavLog, Odometry, PosePrior, Scan, Truth
from graphnav.sim.harbour import HarbourConfig, simulate_harbour
from graphnav.sim.square import square_loop
from graphnav.trajectory import Trajectory

REPO = Path(__file__).resolve().parents[2]

RUNS = (run_isam2, run_batch, run_fixed_lag)


def _sigmas(f: gtsam.NonlinearFactor) -> np.ndarray:
    return np.sqrt(np.diag(np.linalg.inv(f.noiseModel().R().T @ f.noiseModel().R())))


# -- the fallbacks: factor and solution known in closed form ------------------------------------
@pytest.mark.parametrize("dt", [0.0, 0.5, 2.0])
def test_random_walk_factor_grows_with_dt_and_stays_proper_at_zero(dt):
    cfg = SmootherConfig()
    mean, cov, name = GraphBuilder(cfg).motion.prior(dt)
    assert name == "random-walk" and np.allclose(gtsam.Pose2.Logmap(mean), 0)
    floor = np.array([cfg.dynamics.floor_xy] * 2 + [math.radians(cfg.dynamics.floor_yaw_deg)])
    rate = np.array([cfg.dynamics.rw_sigma_v] * 2 + [math.radians(cfg.dynamics.rw_sigma_w_deg)])
    np.testing.assert_allclose(cov, np.diag(floor**2 + (rate * dt) ** 2))
    assert np.all(np.isfinite(cov)) and np.all(np.linalg.eigvalsh(cov) > 0)


def test_constant_velocity_factor_extrapolates_the_last_twist():
    cfg = SmootherConfig()
    b = GraphBuilder(cfg)
    b.motion.twist = np.array([1.0, 0.0, 0.2])  # 1 m/s on a 5 m radius turn
    mean, cov, name = b.motion.prior(2.0)
    assert name == "constant-velocity"
    np.testing.assert_allclose(gtsam.Pose2.Logmap(mean), [2.0, 0.0, 0.4], atol=1e-12)
    floor = np.array([cfg.dynamics.floor_xy] * 2 + [math.radians(cfg.dynamics.floor_yaw_deg)])
    rate = np.array([cfg.dynamics.cv_sigma_v] * 2 + [math.radians(cfg.dynamics.cv_sigma_w_deg)])
    np.testing.assert_allclose(cov, np.diag(floor**2 + (rate * 2.0) ** 2))
    assert GraphBuilder(SmootherConfig(motion_model="random-walk")).motion.prior(1.0)[2] == "random-walk"


def test_random_walk_posterior_between_a_prior_and_a_fix():
    """A pose prior at the origin (exact), one fix 1 s later, nothing else: the 0.5 s grid puts two
    random-walk factors between them (variance q = 2 (floor^2 + (rw 0.5)^2) per axis) and the
    posterior is the scalar Kalman update z q / (q + s^2), variance q s^2 / (q + s^2)."""
    cfg = SmootherConfig(gnss_robust=None, solver="batch")
    nav = Navigator(cfg)
    nav.add(PosePrior(0.0, 0.0, 0.0, 0.0, 1e-6, 1e-6))
    nav.add(Gnss(1.0, 3.0, -1.0, 2.0))
    traj = nav.smoothed()
    np.testing.assert_allclose(traj.t, [0.0, 0.5, 1.0])
    q = 2 * (cfg.dynamics.floor_xy**2 + (cfg.dynamics.rw_sigma_v * 0.5) ** 2)
    k = q / (q + 4.0)
    np.testing.assert_allclose(traj.poses[2, :2], [3.0 * k, -1.0 * k], atol=1e-6)
    # (+0.16 %: the yaw random walk of the middle pose turns its 1 m step a little)
    np.testing.assert_allclose(traj.cov[2, 0, 0], q * 4.0 / (q + 4.0), rtol=5e-3)
    assert nav.info()["motion_fallback"] == 2


def test_constant_velocity_bridges_a_failed_match_exactly():
    """Scans on a constant-twist arc, no odometry; the matcher returns the exact motion except for
    one pair, where it fails: the constant-velocity factor carries the previous twist over the gap,
    so the bridged pose is exact."""
    twist = np.array([1.0, 0.0, 0.1])
    ts = np.arange(12) * 1.0
    poses = [gtsam.Pose2()]
    for _ in ts[1:]:
        poses.append(poses[-1].compose(gtsam.Pose2.Expmap(twist)))
    poses = [np.array([p.x(), p.y(), p.theta()]) for p in poses]
    truth = dict(zip(ts, poses, strict=True))
    scans = [Scan(float(t), np.ones(3), np.zeros(3)) for t in ts]
    recs = [PosePrior(0.0, 0.0, 0.0, 0.0, 1e-6, 1e-6)] + scans
    cov = np.diag([1e-4, 1e-4, 1e-6])

    def matcher(cur, prev, init, *_):
        if cur.t == 6.0:
            return False, np.zeros(3), np.eye(3)
        return True, se2_between(truth[prev.t], truth[cur.t]), cov

    for run in RUNS:
        r = run(NavLog(recs), matcher=matcher, covariances=False)
        assert r.info["motion_fallback"] == 1 and r.info["icp_failed"] == 1, run.__name__
        np.testing.assert_allclose(r.trajectory.poses, np.array(poses), atol=1e-6, err_msg=run.__name__)


# -- records that used to break the graph --------------------------------------------------------
def _harbour(duration: float, **kw) -> NavLog:
    cfg = HarbourConfig.legacy(**kw)
    return simulate_harbour(3, cfg, duration=duration)


@pytest.mark.parametrize("run", RUNS, ids=lambda r: r.__name__)
def test_duplicated_scan_and_equal_timestamps_leave_a_solvable_graph(run):
    log = _harbour(40.0)
    recs = list(log.records)
    scans = [i for i, r in enumerate(recs) if r.kind == "scan"]
    dup = recs[: scans[50] + 1] + [recs[scans[50]]] + recs[scans[50] + 1:]  # one scan line twice
    # and every record of one epoch at the same time stamp as the scan before it
    same = [r if r.kind not in ("gnss", "heading") else type(r)(**{**_fields(r), "t": _prev_scan_t(recs, r.t)})
            for r in dup]
    for variant in (dup, same):
        lg = NavLog.from_unsorted(variant, log.beacons_known, log.meta)
        r = run(lg, covariances=False)
        assert np.all(np.isfinite(r.trajectory.poses))
        assert ate(r.trajectory, log.truth(), max_dt=0.02)["rmse"] < 0.5


def _fields(r) -> dict:
    from dataclasses import fields

    return {f.name: getattr(r, f.name) for f in fields(r)}


def _prev_scan_t(recs, t: float) -> float:
    return max((r.t for r in recs if r.kind == "scan" and r.t <= t), default=t)


def test_scans_without_returns_and_equal_times_in_the_grid():
    """Empty scans (all beams missing) in the middle and GNSS fixes duplicated at one time stamp,
    no odometry: the matcher fails there and the motion model carries the chain (the Pose2 graph:
    constant velocity; the log's IMU in the Pose3 graph)."""
    log = _harbour(30.0)
    recs = []
    for r in log.records:
        if r.kind == "odometry":
            continue
        if r.kind == "scan" and 10.0 <= r.t <= 12.0:
            r = Scan(r.t, np.full_like(r.ranges, np.nan), r.angles)
        recs.append(r)
        if r.kind == "gnss":
            recs.append(Gnss(r.t, r.x + 0.5, r.y, r.sigma))
    lg = NavLog(recs, log.beacons_known, log.meta)
    for run in RUNS:
        for motion in ("odometry", "auto"):
            r = run(lg, covariances=False, motion=motion, keyframe_motion=False)  # a keyframe per scan
            assert r.info["icp_failed"] >= 10
            assert r.info["state"] == ("planar" if motion == "odometry" else "nav")
            assert r.info["motion_fallback"] >= 10 if motion == "odometry" else r.info["motion_fallback"] == 0
            assert ate(r.trajectory, log.truth(), max_dt=0.02)["rmse"] < 1.0, (run.__name__, motion)


# -- a GNSS-only log follows its fixes --------------------------------------------------------------
def test_gnss_only_log_follows_its_fixes(legacy_harbour):
    """The (legacy) harbour log with everything but GNSS and truth removed (a 30 s outage, multipath near
    the quays): the fixes alone are 4.2 m off; the graph (GNSS velocity as the constant-velocity
    motion, the outage spanned by one motion factor) follows them closer, online and smoothed. Through
    the outage the online output coasts: constant-velocity predictions while the boat turns 148 deg
    (about 20 m off), within their grown covariance."""
    log = legacy_harbour
    gnss = log.without(lambda r: r.kind not in ("gnss", "truth"))
    gnss.beacons_known.clear()
    fixes = gnss.of("gnss")
    raw = Trajectory(np.array([g.t for g in fixes]), np.array([[g.x, g.y, 0.0] for g in fixes]))
    raw_ate = ate(raw, log.truth(), max_dt=0.02)["rmse"]
    assert 4.0 < raw_ate < 4.4
    r = run_isam2(gnss, covariances=False)
    o, c = r.online, np.asarray(r.online.meta["coasted"], bool)
    online = ate(Trajectory(o.t[~c], o.poses[~c]), log.truth(), max_dt=0.02)["rmse"]
    smoothed = ate(r.trajectory, log.truth(), max_dt=0.02)["rmse"]
    assert online <= 4.5 and smoothed <= 3.5, (online, smoothed)  # 3.20 / 1.56 m measured
    coasted = nees_stats(Trajectory(o.t[c], o.poses[c], o.cov[c]), log.truth(), max_dt=0.02)
    assert coasted is not None and 40 <= coasted["n"] == c.sum() <= 60  # 0.5 s apart in the 30 s outage
    assert coasted["mean"] < 4.0  # 2.1 measured (chi-square, 2 dof: 2 when honest)
    assert r.info["anchor"] == "first GNSS"


# -- a degenerate corridor in the middle of a log ---------------------------------------------------
def _box(cx: float, cy: float) -> list[tuple[float, float, float, float]]:
    return [(cx - 1, cy - 1, cx + 1, cy - 1), (cx + 1, cy - 1, cx + 1, cy + 1), (cx + 1, cy + 1, cx - 1, cy + 1),
            (cx - 1, cy + 1, cx - 1, cy - 1)]


def _corridor_world() -> np.ndarray:
    """A 60 m corridor (walls at y = +-2, x in [-30, 30]) between two cluttered 24 m x 16 m halls."""
    segs = [(-30, -2, 30, -2), (-30, 2, 30, 2)]
    for s in (-1.0, 1.0):  # west and east hall
        door, end = 30.0 * s, 54.0 * s
        segs += [(door, -8, end, -8), (door, 8, end, 8), (end, -8, end, 8), (door, -8, door, -2), (door, 2, door, 8)]
        segs += _box(36 * s, 5) + _box(42 * s, -5) + _box(49 * s, 4) + _box(45 * s, 1)
    return np.array(segs, dtype=float)


def _corridor_log(odometry: bool, seed: int = 0) -> NavLog:
    rng = np.random.default_rng(seed)
    segs = _corridor_world()
    ang = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    v, dt = 1.0, 1.0
    recs: list = [PosePrior(0.0, -48.0, 0.0, 0.0, 0.01, 0.001)]
    for i in range(97):  # x from -48 (west hall) through the corridor [-30, 30] to +48 (east hall)
        t = i * dt
        pose = np.array([-48.0 + v * t, 0.0, 0.0])
        r = raycast(segs, pose, ang, max_range=12.0)
        r = r + rng.normal(0, 0.01, r.size) * np.isfinite(r)
        recs += [Truth(t, *pose), Scan(t, r, ang)]
        if odometry:
            recs.append(Odometry(t, v + rng.normal(0, 0.05), rng.normal(0, 0.002), 0.05, 0.002))
    return NavLog(recs, meta={"name": "corridor"})


@pytest.mark.parametrize("odometry", [True, False])
def test_degenerate_corridor_in_the_middle_of_a_log(odometry):
    """40 s of corridor (12 m range: walls only, translation along it unobservable) between two
    cluttered halls: the matches there are kept, weak along the corridor; the graph stays
    solvable and does not slide along it."""
    log = _corridor_log(odometry)
    r = run_isam2(log)
    assert np.all(np.isfinite(r.trajectory.poses))
    p, q = r.trajectory.poses, log.truth().interpolate(r.trajectory.t)
    step_err = np.array([se2_between(se2_between(p[k], p[k + 1]), se2_between(q[k], q[k + 1]))
                         for k in range(31, 65)])  # the steps more than 12 m from both halls
    assert np.max(np.abs(step_err[:, 1])) < 0.01  # across the corridor: observed (1.4 / 2.1 mm measured)
    # along it: odometry, or the constant velocity the weak direction keeps (0.12 / 0.21 m measured)
    assert np.max(np.abs(step_err[:, 0])) < (0.2 if odometry else 0.4)
    nav = Navigator.for_log(log, solver="batch")
    for rec in log:
        nav.add(rec)
    nav.flush()
    g, groups = nav.solver.graph, nav.groups
    sig = []
    for i, grp in enumerate(groups):
        if grp == "icp" and 31 <= gtsam.Symbol(g.at(i).keys()[1]).index() <= 65:
            sig.append(_sigmas(g.at(i)))
    sig = np.array(sig)
    assert len(sig) >= 30  # the corridor's matches are used, degenerate or not
    assert np.median(sig[:, 1]) < 0.05  # firm across
    if odometry:  # along: the odometry factor's alone, not repeated by the match (100 m measured)
        assert np.median(sig[:, 0]) > 10.0
    else:  # along: the constant-velocity model's sigma, 0.5 m/s x 1 s, which the match took there
        assert 0.45 < np.median(sig[:, 0]) < 0.6


def test_the_matcher_gets_the_motion_guess_and_its_covariance():
    """The builder hands the matcher the guess's covariance (``init_cov``): the odometry factor's
    with odometry (then ``guess_in_graph``), else the constant-velocity model's (0.5 m/s, 10 deg/s
    x dt, floor in quadrature) once a motion was measured, a random walk before."""
    for odometry in (True, False):
        log = _corridor_log(odometry)
        seen: list = []

        def matcher(cur, prev, init, init_cov, in_graph, seen=seen):
            seen.append((cur.t - prev.t, np.array(init), np.array(init_cov), in_graph))
            return True, np.array([1.0, 0.0, 0.0]), np.diag([1e-4, 1e-4, 1e-6])

        nav = Navigator.for_log(log, matcher=matcher, solver="batch")
        for rec in log:
            nav.add(rec)
        nav.flush()
        assert len(seen) == 96
        odo_covs = [f.noiseModel().covariance() for f, g in zip(_factors(nav.solver.graph), nav.groups, strict=True)
                    if g == "odometry"]
        for i, (dt, init, cov, in_graph) in enumerate(seen):
            assert in_graph == ("odometry" if odometry else "")
            if odometry:
                np.testing.assert_allclose(cov, odo_covs[i], rtol=1e-9)
                assert abs(init[0] - 1.0) < 0.2
            elif i == 0:  # nothing measured yet: the random walk (2 m/s, 30 deg/s)
                np.testing.assert_allclose(np.sqrt(np.diag(cov)), [2.0, 2.0, math.radians(30.0)], rtol=1e-3)
                np.testing.assert_allclose(init, 0.0)
            else:  # constant velocity: the previous match's twist, its stated sigma
                np.testing.assert_allclose(np.sqrt(np.diag(cov)), [0.5, 0.5, math.radians(10.0)], rtol=1e-3)
                np.testing.assert_allclose(init, [1.0, 0.0, 0.0], atol=1e-12)
            assert dt == 1.0


def _factors(g: gtsam.NonlinearFactorGraph) -> list:
    return [g.at(i) for i in range(g.size())]


# -- a failure of the solver is the user's error message, not a traceback -------------------------
def test_solver_failure_names_the_record_and_time(monkeypatch):
    from graphnav.graph import solver as S

    log = square_loop(0, side=20.0)
    calls = {"n": 0}
    real = S.Solver.update

    def update(self, *a, **kw):
        calls["n"] += 1
        if calls["n"] == 30:
            raise S.SolverError("indeterminate linear system: while working near variable x29")
        return real(self, *a, **kw)

    monkeypatch.setattr(S.Solver, "update", update)
    with pytest.raises(GraphnavError) as e:
        run_isam2(log)
    assert "record" in e.value.where and "t = " in e.value.where
    assert "could not be solved at the keyframe of t = 14.5 s" in str(e.value)


# -- the GNSS speed-over-ground fallback and the odometry over an interval: closed forms ------------
def _fixes_along(b: GraphBuilder, ts: np.ndarray, vel: np.ndarray, sigma: float) -> None:
    for t in ts:
        b.motion.fixes.append((float(t), float(vel[0] * t), float(vel[1] * t), sigma))


def test_gnss_speed_over_ground_constant_velocity_fallback():
    """No odometry, no scans: the constant-velocity factor moves forward at the least-squares speed
    of the fixes of the last cv_gnss_window seconds; its sigma is the closed form
    sqrt(cv_sigma_v^2 + sigma_speed^2 + (cv_accel age)^2) dt with sigma_speed = sigma / sqrt(sum (t_i -
    mean t)^2)."""
    cfg = SmootherConfig()
    b = GraphBuilder(cfg)
    ts = np.arange(0.0, 10.0 + 1e-9, 1.0)  # 11 fixes, 1 Hz, over the 10 s window
    _fixes_along(b, ts, np.array([1.2, 1.6]), 2.0)  # 2 m/s along a 53 deg course
    speed_sigma = 2.0 / math.sqrt(float(np.sum((ts - ts.mean()) ** 2)))
    twist, sv, age = b.motion.gnss_velocity(10.0)
    np.testing.assert_allclose(twist, [2.0, 0.0, 0.0], atol=1e-12)
    assert sv == pytest.approx(speed_sigma, rel=1e-12) and age == 0.0
    # 3 s after the last fix (an outage): refitted on the 8 fixes left in the window [3, 13] s,
    # 3 s old (the time since the last fix)
    dt = 0.5
    mean, cov, name = b.motion.prior(dt, 13.0)
    assert name == "constant-velocity"
    np.testing.assert_allclose(gtsam.Pose2.Logmap(mean), [2.0 * dt, 0.0, 0.0], atol=1e-12)
    age, tw = 3.0, ts[3:]
    speed_sigma = 2.0 / math.sqrt(float(np.sum((tw - tw.mean()) ** 2)))
    sxy = math.sqrt(cfg.dynamics.cv_sigma_v**2 + speed_sigma**2 + (cfg.dynamics.cv_accel * age) ** 2) * dt
    floor = np.array([cfg.dynamics.floor_xy] * 2 + [math.radians(cfg.dynamics.floor_yaw_deg)])
    sw = math.radians(cfg.dynamics.cv_sigma_w_deg) * dt
    np.testing.assert_allclose(cov, np.diag(floor**2 + np.array([sxy, sxy, sw]) ** 2), rtol=1e-12)
    # older than cv_max_age: nothing known, the random walk
    assert b.motion.prior(dt, 10.0 + cfg.dynamics.cv_max_age + 1.0)[2] == "random-walk"


def test_gnss_speed_below_three_sigma_is_no_motion_and_few_fixes_are_not_used():
    cfg = SmootherConfig()
    b = GraphBuilder(cfg)
    ts = np.arange(0.0, 10.0 + 1e-9, 1.0)
    _fixes_along(b, ts, np.array([0.05, 0.0]), 2.0)  # 0.05 m/s with a 0.19 m/s speed sigma
    twist, sv, _ = b.motion.gnss_velocity(10.0)
    assert 0.05 < 3 * sv and np.all(twist == 0.0)  # direction unknown: standing, with the speed's sigma
    few = GraphBuilder(cfg)
    _fixes_along(few, np.array([0.0, 1.0]), np.array([2.0, 0.0]), 2.0)  # two fixes: no fit
    assert few.motion.gnss_velocity(1.0) is None and few.motion.prior(0.5, 1.0)[2] == "random-walk"


@pytest.mark.parametrize("rate", [10.0, 100.0])
def test_odometry_over_an_interval_closed_form_and_rate_independent(rate):
    """Odometry records without sigmas (the defaults are noise densities), constant (v, w) on an
    arc: the builder's motion between two times is the arc x = v/w sin(w T), y = v/w (1 - cos(w T)),
    yaw = w T, and on a straight line the along-track and yaw variances are the densities times T
    (plus the 1e-4 m floor of each sub-arc), whatever the sample rate."""
    cfg = SmootherConfig()
    v, w = 1.5, 0.2
    for turn in (w, 0.0):
        b = GraphBuilder(cfg)
        for t in np.arange(0.0, 10.0, 1.0 / rate):
            b.motion.odometry.add(Odometry(float(t), v, turn, math.nan, math.nan))
        t0, t1 = 2.03, 6.53  # not on the samples: the first and last sub-arcs are partial
        pose, cov = b.motion.odometry.between(t0, t1)
        T = t1 - t0
        if turn:
            np.testing.assert_allclose([pose.x(), pose.y(), pose.theta()],
                                       [v / w * math.sin(w * T), v / w * (1 - math.cos(w * T)), w * T], atol=1e-9)
        else:
            np.testing.assert_allclose([pose.x(), pose.y(), pose.theta()], [v * T, 0.0, 0.0], atol=1e-12)
            n = len([s for s in np.arange(0.0, 10.0, 1.0 / rate) if t0 < s < t1 - 1e-12]) + 1  # sub-arcs
            sv = math.hypot(cfg.odometry.sigma_v, cfg.odometry.sigma_v_rel * v)
            sw = math.radians(cfg.odometry.sigma_w_deg)
            assert cov[0, 0] == pytest.approx(sv**2 * T + n * 1e-8, rel=1e-9)
            assert cov[2, 2] == pytest.approx(sw**2 * T + n * 1e-8, rel=1e-9)


def test_odometry_chain_in_the_graph_is_the_closed_form_arc():
    """A pose prior and constant (v, w) odometry only: every keyframe of the 0.5 s grid lies on the
    arc (batch and iSAM2), the anchor's frame composed with the closed-form increment."""
    v, w = 1.0, 0.3
    x0 = np.array([2.0, -1.0, 0.4])
    recs = [PosePrior(0.0, *x0, 1e-4, 1e-5)] + [Odometry(float(t), v, w, math.nan, math.nan)
                                                  for t in np.arange(0.0, 6.0 + 1e-9, 0.05)]
    for run in (run_isam2, run_batch):
        r = run(NavLog(recs), covariances=False)
        tr = r.trajectory
        assert r.info["motion_fallback"] == 0
        for t, p in zip(tr.t, tr.poses, strict=True):
            d = gtsam.Pose2(v / w * math.sin(w * t), v / w * (1 - math.cos(w * t)), w * t)
            want = gtsam.Pose2(*x0).compose(d)
            np.testing.assert_allclose(p[:2], [want.x(), want.y()], atol=1e-6, err_msg=run.__name__)
            assert math.remainder(p[2] - want.theta(), 2 * math.pi) == pytest.approx(0, abs=1e-7)


def test_a_log_with_scans_and_clouds_runs_on_its_first_lidar():
    """2D scans and 3D clouds in one log (two LiDARs): the first kind drives the keyframes and the
    matching, the other is counted (it crashed: 'Cloud' object has no attribute 'ranges')."""
    from graphnav.log import make_cloud

    log = _harbour(8.0)
    rng = np.random.default_rng(0)
    clouds = [make_cloud(r.t + 1e-3, rng.normal(0, 10, (300, 3))) for r in log.of("scan")[::2]]
    mixed = NavLog.from_unsorted(list(log.records) + clouds, log.beacons_known, log.meta)
    r = run_isam2(mixed, covariances=False)
    assert r.info["lidar_other"] == len(clouds) and r.info["icp_pairs"] > 10
    assert np.all(np.isfinite(r.trajectory.poses))
