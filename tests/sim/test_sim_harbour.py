"""The harbour simulator (short slices) and the marina-degraded scenario."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from graphnav.io import load_log
from graphnav.sim.harbour import (
    BEACONS,
    HarbourConfig,
    distance_to_segments,
    harbour_polygons,
    raycast,
    segments,
    simulate_harbour,
)

DATA = Path(__file__).resolve().parents[2] / "data" / "harbour.npz"


@pytest.fixture(scope="module")
def short():
    return simulate_harbour(0, duration=20.0)


def test_raycast_closed_form():
    segs = segments([np.array([[10.0, -5.0], [12.0, -5.0], [12.0, 5.0], [10.0, 5.0]])])
    d = np.array([[1.0, 0.0], [-1.0, 0.0], [math.cos(0.3), math.sin(0.3)], [0.0, 1.0]])
    r = raycast(segs, np.zeros(2), d, 40.0)
    assert r[0] == pytest.approx(10.0)
    assert np.isnan(r[1]) and np.isnan(r[3])  # behind / beside: no return
    assert r[2] == pytest.approx(10.0 / math.cos(0.3))
    assert np.isnan(raycast(segs, np.zeros(2), d[:1], 9.0)[0])  # beyond max range


def test_distance_to_segments():
    segs = segments([np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 1.0], [0.0, 1.0]])])
    dist, away = distance_to_segments(segs, np.array([[5.0, -3.0], [13.0, 0.5]]))
    np.testing.assert_allclose(dist, [3.0, 3.0])
    np.testing.assert_allclose(away, [[0.0, -1.0], [1.0, 0.0]])


def test_deterministic_per_seed(short):
    again = simulate_harbour(0, duration=20.0)
    other = simulate_harbour(1, duration=20.0)
    a, b, c = short.of("gnss"), again.of("gnss"), other.of("gnss")
    assert [(r.x, r.y) for r in a] == [(r.x, r.y) for r in b]
    assert [(r.x, r.y) for r in a] != [(r.x, r.y) for r in c]
    np.testing.assert_array_equal(short.of("scan")[7].ranges, again.of("scan")[7].ranges)
    for kind in ("imu", "gnss_velocity", "water_speed", "heading", "beacon", "truth", "pose_prior"):
        assert short.of(kind) == again.of(kind) != other.of(kind), kind
    assert short.meta == again.meta


def test_sensors_and_rates(short):
    cfg = HarbourConfig()
    c = short.counts()
    assert cfg.lidar_hz == 10.0 and c["scan"] == pytest.approx(20 * cfg.lidar_hz, abs=1)
    assert c["gnss"] == pytest.approx(20, abs=1) and c["heading"] == c["gnss"] == c["gnss_velocity"]
    assert c["water_speed"] == c["gnss"] and c["imu"] == 2000  # 100 Hz from t = 0.01 s
    assert "odometry" not in c and c["truth"] == 201 and c["pose_prior"] == 1  # no odometer by default
    assert len(short.beacons_known) == len(BEACONS)
    scan = short.of("scan")[10]
    assert scan.ranges.size == 360 and np.all(scan.ranges[scan.valid()] <= cfg.max_range * (1 + 5 * 0.004258))
    assert short.meta["lidar"]["sigma_r_rel"] == pytest.approx(0.004258)
    # beacon sightings only within 150 m, with the charted positions
    tr = short.truth()
    for ob in short.of("beacon"):
        p = tr.interpolate([ob.t])[0]
        bx, by = BEACONS[ob.id]
        true_r = math.hypot(bx - p[0], by - p[1])
        assert true_r <= cfg.beacon_range
        assert abs(ob.range - true_r) < 5 * cfg.beacon_sigma_r


def test_lidar_noise_follows_the_error_model():
    """Ranges to a wall straight ahead: scatter ~ 0.004258 r, plus the angular jitter's geometry."""
    cfg = HarbourConfig(sigma_alpha=0.0, dropout=0.0)
    log = simulate_harbour(3, cfg, duration=20.0)
    segs = segments(harbour_polygons())
    tr = log.truth()
    res, rr = [], []
    for s in log.of("scan"):
        x, y, yaw = tr.interpolate([s.t])[0]
        d = np.column_stack([np.cos(yaw + s.angles), np.sin(yaw + s.angles)])
        exact = raycast(segs, np.array([x, y]), d, cfg.max_range)
        ok = np.isfinite(exact) & s.valid()
        res.append((s.ranges[ok] - exact[ok]) / exact[ok])
        rr.append(exact[ok])
    rel = np.concatenate(res)
    assert rel.std() == pytest.approx(0.004258, rel=0.1)


def test_gnss_outage_and_multipath_events():
    cfg = HarbourConfig(outage_t0=20.0, multipath_dist=30.0)
    log = simulate_harbour(0, cfg, duration=60.0)
    ev = {e["kind"]: e for e in log.meta["events"]}
    o = ev["gnss_outage"]
    assert o["t1"] - o["t0"] == pytest.approx(30.0)
    t = np.array([g.t for g in log.of("gnss")])
    assert not np.any((t >= o["t0"]) & (t < o["t1"]))
    assert np.any(t < o["t0"]) and np.any(t >= o["t1"])
    assert "gnss_multipath" in ev
    # same seed without multipath: the fixes differ by exactly the bias, pointing away from the wall
    clean = simulate_harbour(0, HarbourConfig(outage_t0=20.0, multipath_amp=0.0), duration=60.0)
    g, g0 = log.of("gnss"), clean.of("gnss")
    diff = np.array([[a.x - b.x, a.y - b.y] for a, b in zip(g, g0, strict=True)])
    p = log.truth().interpolate(t)
    dist, away = distance_to_segments(segments(harbour_polygons()), p[:, :2])
    amp = cfg.multipath_amp * np.clip(1.0 - dist / cfg.multipath_dist, 0.0, 1.0)
    assert amp.max() > 0.5
    np.testing.assert_allclose(diff, amp[:, None] * away, atol=1e-9)


def test_live_options_rates_time_base_and_laps(short):
    """fix_hz, lidar_hz=0, t0 (what the live tests and benchmarks use) and laps; the defaults are
    the embedded scenario, so the 1 Hz draws of a 10 Hz run are not compared (other streams)."""
    cfg = HarbourConfig(fix_hz=10.0, lidar_hz=0.0, t0=1.7e9)
    log = simulate_harbour(0, cfg, duration=20.0)
    assert log.meta["current"]["t"][0] == 1.7e9  # the current's series in record time
    c = log.counts()
    assert "scan" not in c and c["gnss"] == c["heading"] == c["truth"] == 201  # 10 Hz, both ends
    assert c["beacon"] == short.counts()["beacon"]  # beacons stay at 1 Hz
    assert log.t0 == 1.7e9 and log.t1 == pytest.approx(1.7e9 + 20.0)
    np.testing.assert_allclose(log.truth().poses, short.truth().poses)  # the same track, shifted in time
    ev = {e["kind"]: e for e in log.meta["events"]}
    assert ev["gnss_outage"]["t0"] == 1.7e9 + HarbourConfig().outage_t0
    from graphnav.sim.harbour import vessel_track

    coarse = HarbourConfig(dt=0.1, lidar_hz=0.0, imu_hz=10.0)  # 0.1 s track steps: a lap in ~7000 steps
    t1, p1, _ = vessel_track(coarse, np.random.default_rng(0))
    t2, p2, _ = vessel_track(coarse, np.random.default_rng(0), laps=2, t_max=t1[-1] + 60.0)
    np.testing.assert_array_equal(p2[: len(p1)], p1)  # the second lap continues the first
    assert t2[-1] == pytest.approx(t1[-1] + 60.0, abs=0.2)  # up to t_max
    moved = np.hypot(*(p2[-1, :2] - p1[-1, :2]))
    assert moved > 40.0  # ~1.5 m/s on towards the route's second waypoint
    more = simulate_harbour(0, coarse, duration=t1[-1] + 60.0)  # a duration beyond a lap adds laps
    assert more.t1 == pytest.approx(t1[-1] + 60.0, abs=0.2)


def test_imu_truth_closed_form():
    """The exact IMU means against the track's own kinematics: the yaw-rate sum is the yaw change,
    the forward-acceleration sum the speed change (no sway), and ay = v w on a steady turn."""
    from graphnav.sim.harbour import imu_truth, vessel_track

    cfg = HarbourConfig.legacy()  # still water: the body acceleration is the water track's alone
    t, p, ctl = vessel_track(cfg, np.random.default_rng(0), t_max=240.0)
    ii, acc, rate = imu_truth(t, p, ctl, 5, cfg.dt)
    T = 5 * cfg.dt
    yaw = np.unwrap(p[:, 2])
    np.testing.assert_allclose(np.cumsum(rate) * T, yaw[ii] - yaw[0], atol=1e-9)
    np.testing.assert_allclose(np.cumsum(acc[:, 0]) * T, ctl[ii - 1, 0] - ctl[0, 0], atol=1e-9)
    turning = np.abs(rate) > np.radians(3.0)
    assert turning.sum() > 50
    speed = np.hypot(*np.diff(p[:, :2], axis=0).T) / cfg.dt  # chord speed of each step
    v_mean = np.array([speed[i - 5:i].mean() for i in ii])
    np.testing.assert_allclose(acc[turning, 1], v_mean[turning] * rate[turning], rtol=0.02)  # centripetal v w
    # dead reckoning on the exact means (the UKF's eq. 1-3 with the interval's mid yaw) stays on the track
    pos, vel = p[0, :2].copy(), ctl[0, 0] * np.array([np.cos(p[0, 2]), np.sin(p[0, 2])])
    th = p[0, 2]
    for k in range(len(ii)):
        mid = th + 0.5 * T * rate[k]
        c, s_ = np.cos(mid), np.sin(mid)
        an = np.array([c * acc[k, 0] - s_ * acc[k, 1], s_ * acc[k, 0] + c * acc[k, 1]])
        pos, vel, th = pos + T * vel + 0.5 * T * T * an, vel + T * an, th + T * rate[k]
    assert np.hypot(*(pos - p[ii[-1], :2])) < 1.0  # after 240 s and ~350 m


def test_imu_records_noise_model_and_origin(short):
    """The legacy IMU records = exact means + the solent scenario's calibrated bias residual + Table 3
    noise; its own random stream (every other record as without it); the geodetic origin in meta."""
    from graphnav.geodesy import LocalFrame
    from graphnav.sim import solent
    from graphnav.sim.harbour import MARINA_GDYNIA, ORIGIN, imu_truth, vessel_track

    cfg = HarbourConfig.legacy()
    log = simulate_harbour(0, duration=300.5, cfg=HarbourConfig.legacy(lidar_hz=0.0, imu_hz=10.0))
    imu = log.columns("imu")
    assert len(imu["t"]) == pytest.approx(3005, abs=1) and imu["t"][0] == pytest.approx(0.1)  # 10 Hz: statistics
    t, p, ctl = vessel_track(cfg, np.random.default_rng(np.random.SeedSequence(0).spawn(5)[0]), t_max=300.5)
    keep = t <= 300.5
    ii, acc, rate = imu_truth(t[keep], p[keep], ctl[keep], 5, cfg.dt)
    np.testing.assert_allclose(imu["t"], t[ii])
    m = log.meta["imu"]
    resid = np.array(m["bias_residual"])
    assert np.all(np.abs(resid) <= 4 * 0.1 * np.abs(m["bias_true"]))
    err = np.column_stack([imu["ax"] - acc[:, 0], imu["ay"] - acc[:, 1], imu["wz"] - rate])
    tol = 4 * np.array([m["acc_std"], m["acc_std"], m["gyro_std"]]) / np.sqrt(len(err))  # 4 sigma of the mean
    assert np.all(np.abs(err.mean(axis=0) - resid) < tol)
    np.testing.assert_allclose(err.std(axis=0), [solent.TABLE3_ACC_STD] * 2 + [np.radians(solent.TABLE3_GYRO_STD_DEG)],
                               rtol=0.05)
    legacy = simulate_harbour(0, HarbourConfig.legacy(), duration=20.0)
    none = simulate_harbour(0, HarbourConfig.legacy(imu_hz=0.0), duration=20.0)
    assert "imu" not in none.counts() and "imu" not in none.meta
    for kind in ("gnss", "heading", "odometry", "beacon", "truth", "pose_prior"):
        assert none.of(kind) == legacy.of(kind), kind
    np.testing.assert_array_equal(none.of("scan")[-1].ranges, legacy.of("scan")[-1].ranges)
    assert log.meta["initial_velocity"] == pytest.approx([ctl[0, 0] * np.cos(p[0, 2]), ctl[0, 0] * np.sin(p[0, 2])])
    assert legacy.counts()["imu"] == 20 and legacy.meta["imu"]["hz"] == 1.0  # legacy: 1 Hz, from t = 1 s
    assert short.meta["origin"] == ORIGIN
    x, y = LocalFrame(ORIGIN["lat"], ORIGIN["lon"], ORIGIN["h"]).to_local(*MARINA_GDYNIA)
    assert (float(x), float(y)) == pytest.approx((150.0, 100.0), abs=0.1)  # the basin's centre on the marina


def test_ukfs_run_on_the_harbour_imu():
    """The IMU-driven filters run on a harbour slice and stay within the GNSS noise of the truth."""
    from graphnav import estimators
    from graphnav.evaluation.metrics import ate

    log = simulate_harbour(0, HarbourConfig.legacy(lidar_hz=0.0), duration=120.0)  # the UKFs' T = 1 s
    for name in ("ukf", "fuzzy-ukf"):
        r = estimators.run(name, log)
        assert ate(r.trajectory, log.truth(), max_dt=0.06)["rmse"] < HarbourConfig().gnss_sigma


@pytest.mark.skipif(not DATA.exists(), reason="data/harbour.npz not generated")
def test_embedded_log_is_seed0():
    log = load_log(DATA)
    assert log.meta["name"] == "harbour" and log.meta["seed"] == 0
    assert DATA.stat().st_size < 5e6
    assert 600 < log.t1 - log.t0 < 900  # 10-15 minutes
    fresh = simulate_harbour(0, HarbourConfig.for_profile(log.meta.get("profile", "legacy")), duration=5.0)
    a = [(r.x, r.y) for r in log.of("gnss") if r.t <= 5.0]
    b = [(r.x, r.y) for r in fresh.of("gnss")]
    np.testing.assert_allclose(a, b)


@pytest.mark.marina
def test_marina_degraded(marina_dir):
    from graphnav.sim.marina_degraded import simulate_marina_degraded

    log = simulate_marina_degraded(marina_dir, 1)
    again = simulate_marina_degraded(marina_dir, 1, jump_m=0.0)
    c = log.counts()
    assert c["scan"] == 177 and c["truth"] == 176 and c["heading"] == 176
    ev = {e["kind"]: e for e in log.meta["events"]}
    o, j = ev["gnss_outage"], ev["gnss_jump"]
    assert o["t1"] - o["t0"] == pytest.approx(40.0) and j["t1"] - j["t0"] == pytest.approx(10.0)
    assert math.hypot(*j["offset_m"]) == pytest.approx(20.0)
    g, g0 = log.of("gnss"), again.of("gnss")
    assert c["gnss"] == len(g0) == 176 - 40
    d = np.array([[a.x - b.x, a.y - b.y] for a, b in zip(g, g0, strict=True)])
    jumped = np.hypot(*d.T) > 1e-9
    assert jumped.sum() == 10 and np.allclose(d[jumped], j["offset_m"])  # same noise, only the jump differs
    tr = log.truth()
    h = log.of("heading")
    bias = np.degrees(
        np.mean([(r.yaw - y + math.pi) % (2 * math.pi) - math.pi for r, y in zip(h, tr.yaw, strict=True)])
    )
    assert bias == pytest.approx(3.0, abs=0.6)


def test_isam2_with_weighted_icp_on_a_harbour_slice():
    """End to end on 8 s of the legacy harbour: real scan matching, odometry, GNSS, compass, beacons."""
    from graphnav.evaluation.metrics import ate
    from graphnav.graph.log_runs import run_isam2

    log = simulate_harbour(0, HarbourConfig.legacy(), duration=8.0)
    r = run_isam2(log, covariances=False)
    # its 1 Hz IMU: the IMU graph, keyframes by the motion rule, a match between consecutive keyframes
    assert r.info["icp"] and r.info["icp_pairs"] == len(r.trajectory) - 1 >= len(log.of("scan")) / 5
    assert r.info["icp_failed"] < 0.2 * r.info["icp_pairs"]
    assert r.info["anchor"] == "pose_prior"
    ref = log.truth()
    assert ate(r.trajectory, ref, max_dt=0.02)["rmse"] < 0.3
    assert ate(r.online, ref, max_dt=0.02)["rmse"] < 0.6
