"""The Solent mission simulator (section V) and the montecarlo command."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from graphnav.evaluation.monte_carlo_trials import aggregate, improvement_pct
from graphnav.geometry import wrap_angle, yaw_to_heading_deg
from graphnav.io import load_log
from graphnav.sim.solent import START, WAYPOINTS, SolentConfig, _truth, current_direction, simulate_solent


@pytest.fixture(scope="module")
def s3():
    return simulate_solent(scenario=3, seed=5)


def test_same_seed_same_log_other_seed_other_noise():
    a = simulate_solent(scenario=1, seed=3, max_steps=60)
    b = simulate_solent(scenario=1, seed=3, max_steps=60)
    c = simulate_solent(scenario=1, seed=4, max_steps=60)
    np.testing.assert_array_equal(a.columns("gnss")["x"], b.columns("gnss")["x"])
    assert not np.allclose(a.columns("gnss")["x"], c.columns("gnss")["x"])


def test_mission_geometry(s3):
    tr = s3.truth()
    assert tuple(tr.poses[0, :2]) == START
    assert yaw_to_heading_deg(tr.poses[0, 2]) == pytest.approx(210.0)
    assert np.allclose(np.diff(tr.t), 1.0)
    assert s3.meta["waypoints_reached"] == len(WAYPOINTS)
    d_end = np.hypot(*(tr.poses[-1, :2] - WAYPOINTS[-1]))
    assert d_end < SolentConfig.clearance + 2.0  # eq. 29 at the end point
    for wp in WAYPOINTS[:-1]:  # every waypoint was passed within the clearance radius (+ one step)
        assert np.min(np.hypot(tr.poses[:, 0] - wp[0], tr.poses[:, 1] - wp[1])) < SolentConfig.clearance + 2.0


def test_tidal_current_is_eq_30_with_constant_speed():
    cfg = SolentConfig(max_steps=200, current_speed=0.8)
    tr = _truth(cfg)
    own = cfg.speed * np.stack([np.cos(tr["psi"]), np.sin(tr["psi"])], axis=1)
    cur = tr["v"] - own
    np.testing.assert_allclose(np.hypot(cur[:, 0], cur[:, 1]), 0.8, atol=1e-9)
    dirs = np.array([current_direction(p) for p in tr["p"]])
    np.testing.assert_allclose(wrap_angle(np.arctan2(cur[:, 1], cur[:, 0]) - dirs), 0.0, atol=1e-9)


def test_body_frame_imu_integrates_to_the_ground_velocity():
    tr = _truth(SolentConfig(max_steps=300, substeps=20))
    v = tr["v"][0].copy()
    for k in range(len(tr["acc_b"])):  # rotate by the mid-interval heading, eq. 4
        th = 0.5 * (tr["psi"][k] + tr["psi"][k + 1])
        c, s = math.cos(th), math.sin(th)
        a = tr["acc_b"][k]
        v += np.array([c * a[0] - s * a[1], s * a[0] + c * a[1]])
    np.testing.assert_allclose(v, tr["v"][-1], atol=0.02)


def test_sensor_noise_per_scenario(s3):
    tr = s3.truth()
    g = s3.columns("gnss")
    h = s3.columns("heading")
    ex, ey = g["x"] - tr.poses[:, 0], g["y"] - tr.poses[:, 1]
    eh = np.degrees(wrap_angle(h["yaw"] - tr.poses[:, 2]))
    sw = SolentConfig.switch_step
    assert np.std(ex[:sw]) == pytest.approx(8.0, rel=0.2) and np.std(ey[:sw]) == pytest.approx(7.0, rel=0.2)
    assert np.std(ex[sw:]) == pytest.approx(20.0, rel=0.2) and np.std(ey[sw:]) == pytest.approx(20.0, rel=0.2)
    assert np.std(eh[:sw]) == pytest.approx(0.8, rel=0.2) and np.std(eh[sw:]) == pytest.approx(5.0, rel=0.2)
    assert np.all(g["sigma"] == 7.0)  # the datasheet value, not the truth
    assert s3.meta["events"][0]["kind"] == "noise_increase"


def test_calibration_leaves_the_documented_residual_bias(s3):
    imu = s3.meta["imu"]
    true, est, res = (np.array(imu[k]) for k in ("bias_true", "bias_estimate", "bias_residual"))
    np.testing.assert_allclose(true - est, res)
    np.testing.assert_allclose(true, [0.03, 0.02, math.radians(0.28)])
    assert imu["calib_residual_frac"] == 0.1
    raw = simulate_solent(scenario=1, seed=5, calibrate=False)
    np.testing.assert_allclose(raw.meta["imu"]["bias_residual"], true)
    # the IMU records carry exactly the residual bias on top of the truth (+ white noise)
    tr = _truth(SolentConfig(scenario=3, seed=5))
    c = s3.columns("imu")
    n = len(c["t"])
    err = np.stack([c["ax"] - tr["acc_b"][:, 0], c["ay"] - tr["acc_b"][:, 1], c["wz"] - tr["rate"]], axis=1)
    tol = 4 * np.array([imu["acc_std"], imu["acc_std"], imu["gyro_std"]]) / math.sqrt(n)
    assert np.all(np.abs(err.mean(axis=0) - res) < tol)


def test_odometry_is_speed_over_ground_and_rate_of_turn(s3):
    o = s3.columns("odometry")
    tr = _truth(SolentConfig(scenario=3, seed=5))
    sog = np.hypot(tr["v"][:, 0], tr["v"][:, 1])
    assert np.std(o["v"] - sog) == pytest.approx(0.05, rel=0.2) and np.all(o["sigma_v"] == 0.05)
    assert np.std(o["w"][1:] - tr["rate"]) == pytest.approx(math.radians(0.1), rel=0.2)
    fa = simulate_solent(scenario=3, seed=5, odometry="fore_aft").columns("odometry")["v"]
    assert np.mean(fa) < np.mean(o["v"])  # the crab angle makes the fore-aft component smaller


def test_aggregate_and_improvement():
    trials = [{"ukf": {"pos_rmse_m": 4.0, "hdg_rmse_deg": 1.0, "step_ms_median": 0.1},
               "fuzzy-ukf": {"pos_rmse_m": 3.0, "hdg_rmse_deg": 0.5, "step_ms_median": 0.2}},
              {"ukf": {"pos_rmse_m": 6.0, "hdg_rmse_deg": 1.0, "step_ms_median": 0.1},
               "fuzzy-ukf": {"error": "ValueError: x"}}]
    est = aggregate(trials, ["ukf", "fuzzy-ukf"])
    assert est["ukf"]["pos_rmse_m"] == 5.0 and est["fuzzy-ukf"]["runs_ok"] == 1
    assert improvement_pct(est) == pytest.approx(40.0)
    assert "online_pos_rmse_m" not in est["ukf"]
    trials[0]["ukf"]["online_pos_rmse_m"] = 5.0
    trials[1]["ukf"]["online_pos_rmse_m"] = 7.0
    assert aggregate(trials, ["ukf"])["ukf"]["online_pos_rmse_m"] == 6.0


def test_cli_simulate_and_montecarlo_print_one_json_object(tmp_path):
    out = tmp_path / "s2.jsonl"
    cmd = [sys.executable, "-m", "graphnav", "simulate", "solent", "--scenario", "2", "--seed", "1"]
    p = subprocess.run(cmd + ["--out", str(out), "--json"], capture_output=True, text=True, check=True)
    info = json.loads(p.stdout)
    assert info["scenario"] == 2 and out.exists()
    log = load_log(out)
    assert log.meta["scenario"] == 2 and len(log.of("imu")) == info["records"]["imu"]
    cmd = [sys.executable, "-m", "graphnav", "montecarlo", "solent", "--scenario", "1", "--runs", "2"]
    args = ["--estimators", "ukf,fuzzy-ukf", "--scheduler", "serial", "--json"]  # (an unknown name: exit 2)
    p = subprocess.run(cmd + args, capture_output=True, text=True, check=True)
    res = json.loads(p.stdout)
    assert res["scenario"] == 1 and res["runs"] == 2
    assert set(res["estimators"]) == {"ukf", "fuzzy-ukf"} and "skipped" not in res
    for d in res["estimators"].values():
        assert d["runs_ok"] == 2 and d["pos_rmse_m"] > 0 and d["hdg_rmse_deg"] > 0
    u, f = res["estimators"]["ukf"]["pos_rmse_m"], res["estimators"]["fuzzy-ukf"]["pos_rmse_m"]
    assert res["improvement_pct"] == pytest.approx(100 * (u - f) / u)
