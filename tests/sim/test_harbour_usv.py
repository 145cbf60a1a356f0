"""The harbour's default (``usv``) profile: known answers for the sensors a real USV carries, the
tidal current, the ``legacy`` profile reproducing data/harbour.npz, and the CLI options."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from graphnav.cli import main
from graphnav.geometry import wrap_angle
from graphnav.io import load_log, save_log
from graphnav.sim.harbour import EMBEDDED_PROFILE, HarbourConfig, imu_truth, simulate_harbour, vessel_track
from graphnav.sim.water_current import TidalCurrent, current_from_meta

DATA = Path(__file__).resolve().parents[2] / "data" / "harbour.npz"


@pytest.fixture(scope="module")
def usv():
    """Six minutes of the default profile (no scans: they are not what is tested here)."""
    return simulate_harbour(0, HarbourConfig(lidar_hz=0.0), duration=360.0)


def _truth_velocity(log, t):
    """Velocity over ground at times ``t`` from the truth poses alone (central differences, 10 Hz)."""
    tr = log.truth()
    v = np.gradient(tr.poses[:, :2], tr.t, axis=0)
    return np.column_stack([np.interp(t, tr.t, v[:, 0]), np.interp(t, tr.t, v[:, 1])])


def test_default_is_a_usv_without_odometer(usv):
    c = usv.counts()
    assert "odometry" not in c
    assert c["imu"] == 36000 and usv.meta["imu"]["hz"] == 100.0
    assert c["gnss"] == c["gnss_velocity"] == 361 - 30 and c["heading"] == c["water_speed"] == 361
    assert usv.meta["profile"] == "usv" and usv.meta["odometer"] is None
    dev = usv.meta["compass"]["deviation"]
    assert math.radians(1.0) <= dev <= math.radians(2.0)
    err = np.array([wrap_angle(h.yaw - y) for h, y in zip(usv.of("heading"), usv.truth().interpolate(
        [h.t for h in usv.of("heading")])[:, 2], strict=True)])
    sig = usv.meta["compass"]["sigma"]
    assert abs(err.mean() - dev) < 4 * sig / math.sqrt(len(err))  # the constant deviation
    assert err.std() == pytest.approx(sig, rel=0.15)
    assert usv.of("heading")[0].sigma == pytest.approx(math.hypot(sig, dev))
    speed = np.hypot(usv.meta["current"]["vx"], usv.meta["current"]["vy"])
    assert 0.3 - 1e-9 <= speed.min() and speed.max() <= 0.5 + 1e-9


def test_gnss_velocity_is_the_velocity_over_ground(usv):
    g = usv.columns("gnss_velocity")
    meas = np.column_stack([g["vx"], g["vy"]])
    truth = _truth_velocity(usv, g["t"])
    sig = usv.meta["gnss"]["velocity_sigma"]
    assert 0.05 <= sig <= 0.1 and np.all(g["sigma"] == sig)
    np.testing.assert_allclose(meas.mean(axis=0), truth.mean(axis=0), atol=4 * sig / math.sqrt(len(meas)))
    np.testing.assert_allclose((meas - truth).std(axis=0), sig, rtol=0.15)
    o = next(e for e in usv.meta["events"] if e["kind"] == "gnss_outage")
    assert not np.any((g["t"] >= o["t0"]) & (g["t"] < o["t1"]))  # absent in the outage, like the fixes
    np.testing.assert_array_equal(g["t"], usv.columns("gnss")["t"])


def test_water_speed_plus_current_is_the_velocity_over_ground(usv):
    """The speed log along the true heading, plus the true current, is the velocity over ground;
    without the current it is not (the current is across the track)."""
    w = usv.columns("water_speed")
    yaw = usv.truth().interpolate(w["t"])[:, 2]
    bow = np.column_stack([np.cos(yaw), np.sin(yaw)])
    cur = current_from_meta(usv.meta, w["t"])
    truth = _truth_velocity(usv, w["t"])
    res = w["v"][:, None] * bow + cur - truth
    sig = usv.meta["water_speed"]["sigma"]
    along = (res * bow).sum(axis=1)
    across = res[:, 0] * -bow[:, 1] + res[:, 1] * bow[:, 0]
    assert abs(along.mean()) < 4 * sig / math.sqrt(len(along)) and along.std() == pytest.approx(sig, rel=0.15)
    assert np.abs(across).max() < 0.01  # no sideways motion through the water
    without = w["v"][:, None] * bow - truth
    assert np.sqrt((without ** 2).sum(axis=1).mean()) > 0.3  # the current matters


def test_heading_differs_from_course_over_ground(usv):
    tr = usv.truth()
    v = _truth_velocity(usv, tr.t)
    crab = np.degrees(np.abs(wrap_angle(np.arctan2(v[:, 1], v[:, 0]) - tr.poses[:, 2])))
    assert np.median(crab) > 5.0 and crab.max() < 35.0
    still = simulate_harbour(0, HarbourConfig(lidar_hz=0.0, imu_hz=0.0, current=TidalCurrent(0.0, 0.0)),
                             duration=60.0)
    v0 = _truth_velocity(still, still.truth().t)[5:-5]
    crab0 = np.degrees(np.abs(wrap_angle(np.arctan2(v0[:, 1], v0[:, 0]) - still.truth().poses[5:-5, 2])))
    assert crab0.max() < 1.0  # in still water the vessel goes where it heads


def test_imu_integrated_yaw_rate_is_the_heading_change(usv):
    """Sum of wz T over the log = the truth heading change + the bias the records carry (meta), within
    the white noise (angle random walk over the run)."""
    imu = usv.columns("imu")
    m = usv.meta["imu"]
    T = 1.0 / m["hz"]
    yaw = np.unwrap(usv.truth().poses[:, 2])
    dyaw = yaw[-1] - yaw[0]  # truth at t = 0 and t = 360
    assert imu["t"][0] == pytest.approx(T) and imu["t"][-1] == pytest.approx(360.0)
    s = m["bias_series"]
    bias = np.interp(imu["t"], s["t"], s["wz"])
    noise = m["gyro_noise_density"] * math.sqrt(imu["t"][-1])
    assert abs(imu["wz"].sum() * T - bias.sum() * T - dyaw) < 4 * noise
    assert abs(imu["wz"].sum() * T - dyaw) > 4 * noise  # the residual bias is there, and detectable
    assert abs(s["wz"][0] - m["bias_residual"][2]) < 1e-4  # the walk starts at 0


def test_imu_bias_walk_and_white_noise(usv):
    """Records minus the exact interval means: the calibration residual + a random walk of the stated
    strength + white noise at the stated density."""
    cfg = HarbourConfig(lidar_hz=0.0)
    seeds = np.random.SeedSequence(0).spawn(8)
    t, p, ctl = vessel_track(cfg, np.random.default_rng(seeds[0]), t_max=360.0)
    keep = t <= 360.0
    ii, acc, rate = imu_truth(t[keep], p[keep], ctl[keep], 1, cfg.dt, cfg.current)
    imu = usv.columns("imu")
    m = usv.meta["imu"]
    err = np.column_stack([imu["ax"] - acc[:, 0], imu["ay"] - acc[:, 1], imu["wz"] - rate])
    s = m["bias_series"]
    left = np.column_stack([np.interp(imu["t"], s["t"], s[k]) for k in ("ax", "ay", "wz")])
    white = err - left
    std = np.array([m["acc_std"], m["acc_std"], m["gyro_std"]])
    np.testing.assert_allclose(white.std(axis=0), std, rtol=0.05)
    np.testing.assert_allclose(std, np.array([m["acc_noise_density"]] * 2 + [m["gyro_noise_density"]]) * 10.0)
    walk = np.column_stack([s["ax"], s["ay"], s["wz"]]) - m["bias_residual"]
    steps = np.diff(walk, axis=0) / np.sqrt(np.diff(s["t"]))[:, None]  # per sqrt(s)
    q = np.array([m["acc_bias_rw"], m["acc_bias_rw"], m["gyro_bias_rw"]])
    assert np.all(steps.std(axis=0) == pytest.approx(q, rel=0.4))  # 35 increments per channel


def test_imu_truth_with_current_dead_reckons_the_track():
    """The exact IMU means include the current's acceleration: integrated from the initial velocity
    over ground they follow the crabbing track (without that term they drift by metres)."""
    cfg = HarbourConfig()
    t, p, ctl = vessel_track(cfg, np.random.default_rng(0), t_max=240.0)
    every = 10
    ii, acc, rate = imu_truth(t, p, ctl, every, cfg.dt, cfg.current)
    _, acc0, _ = imu_truth(t, p, ctl, every, cfg.dt)
    T = every * cfg.dt
    v0 = ctl[0, 0] * np.array([np.cos(p[0, 2]), np.sin(p[0, 2])]) + cfg.current.velocity(0.0)[0]

    def dead_reckon(a_b):
        pos, vel, th = p[0, :2].copy(), v0.copy(), p[0, 2]
        for k in range(len(ii)):
            mid = th + 0.5 * T * rate[k]
            c, s_ = np.cos(mid), np.sin(mid)
            an = np.array([c * a_b[k, 0] - s_ * a_b[k, 1], s_ * a_b[k, 0] + c * a_b[k, 1]])
            pos, vel, th = pos + T * vel + 0.5 * T * T * an, vel + T * an, th + T * rate[k]
        return np.hypot(*(pos - p[ii[-1], :2]))

    assert dead_reckon(acc) < 0.5  # after 240 s and ~350 m
    assert dead_reckon(acc0) > 5.0


def test_odometer_adds_odometry_and_leaves_the_rest():
    base = simulate_harbour(2, HarbourConfig(lidar_hz=0.0), duration=30.0)
    odo = simulate_harbour(2, HarbourConfig(lidar_hz=0.0, odometer=True), duration=30.0)
    assert "odometry" not in base.counts() and odo.counts()["odometry"] == odo.counts()["truth"] == 301
    for kind in ("imu", "gnss", "gnss_velocity", "heading", "water_speed", "beacon", "truth", "pose_prior"):
        assert odo.of(kind) == base.of(kind), kind
    o = odo.columns("odometry")
    sog = np.hypot(*_truth_velocity(odo, o["t"]).T)
    assert abs((o["v"] - sog)[1:-1].mean()) < 0.02  # speed over ground, not through the water
    assert odo.meta["odometer"]["hz"] == 10.0


@pytest.mark.skipif(not DATA.exists(), reason="data/harbour.npz not generated")
def test_embedded_file_regenerates_bit_identically(tmp_path):
    """``data/harbour.npz`` is what its profile (``meta.profile``, absent: legacy) simulates for seed 0:
    every array of the file, the meta JSON included, bit for bit (columns added to the format since
    are NaN)."""
    committed = np.load(DATA)
    profile = json.loads(str(committed["meta"])).get("profile", "legacy")
    assert profile == EMBEDDED_PROFILE
    out = tmp_path / "h.npz"
    save_log(simulate_harbour(0, HarbourConfig.for_profile(profile)), out)
    fresh = np.load(out)
    for k in committed.files:
        a, b = committed[k], fresh[k]
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), k
    for k in set(fresh.files) - set(committed.files):
        assert fresh[k].dtype.kind == "f" and np.all(np.isnan(fresh[k])), k


def test_cli_profiles_and_options(tmp_path, capsys):
    out = tmp_path / "u.npz"
    assert main(["simulate", "harbour", "--duration", "12", "--lidar-hz", "0", "--odometer",
                 "--current-speed", "0.3", "--out", str(out), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["profile"] == "usv" and d["records"]["odometry"] == 121 and d["records"]["imu"] == 1200
    log = load_log(out)
    assert log.meta["current"]["speed"] == 0.3 and log.meta["current"]["speed_amp"] == 0.1
    assert main(["simulate", "harbour", "--profile", "legacy", "--duration", "12", "--out", str(out), "--overwrite",
                 "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["profile"] == "legacy" and d["records"]["scan"] == 61 and d["records"]["imu"] == 12
    assert "gnss_velocity" not in d["records"] and "water_speed" not in d["records"]
    assert "current" not in load_log(out).meta and "profile" not in load_log(out).meta


@pytest.mark.parametrize("args,option", [
    (["--duration", "0"], "--duration"), (["--duration", "-5"], "--duration"), (["--duration", "nan"], "--duration"),
    (["--duration", "inf"], "--duration"), (["--duration", "1e9"], "--duration"), (["--laps", "0"], "--laps"),
    (["--laps", "-1"], "--laps"), (["--laps", "100000"], "--laps"), (["--fix-hz", "0"], "--fix-hz"),
    (["--lidar-hz", "-1"], "--lidar-hz"), (["--current-speed", "nan"], "--current-speed"),
    (["--t0", "inf"], "--t0"),
])
def test_cli_bad_bounds_exit_2_naming_the_option(tmp_path, capsys, args, option):
    out = tmp_path / "x.npz"
    assert main(["simulate", "harbour", *args, "--out", str(out), "--json"]) == 2
    err = json.loads(capsys.readouterr().out)
    assert option in err["error"] and not out.exists()
