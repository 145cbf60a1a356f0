"""Known answers for the filters on a USV's sensors without an odometer (#21 item 5, #22 item 1):
a constant turn with a biased 20 Hz IMU, noisy 1 Hz GNSS and compass. Every filter must beat its
GNSS fixes and be consistent; with GNSS velocity and a speed log it must find the water current."""

from __future__ import annotations

import math

import numpy as np
import pytest

from graphnav import estimators
from graphnav.evaluation.metrics import ate, nees_stats
from graphnav.log import Gnss, GnssVelocity, Heading, Imu, NavLog, Truth, WaterSpeed

FILTERS = ("ekf", "ukf", "ukf-bias", "fuzzy-ukf", "fuzzy-ukf-bias")
GNSS_SIGMA = 3.0
CURRENT = (0.3, -0.2)  # m/s, east / north


def turn_log(seed: int = 0, hz: float = 20.0, seconds: float = 180.0, speed: float = 2.0,
             rate: float = math.radians(3.0), current: tuple[float, float] = (0.0, 0.0),
             velocity: bool = False, water: bool = False) -> NavLog:
    """A vessel at ``speed`` through the water turning at ``rate`` in a uniform ``current``; IMU at
    ``hz`` (exact planar means ax = 0, ay = speed * rate, wz = rate, plus a constant bias and white
    noise as meta["imu"] states), GNSS 1 Hz (sigma 3 m), compass 1 Hz (1 deg); optionally GNSS
    velocity (0.05 m/s) and the speed through water (0.05 m/s). No odometry, no pose prior."""
    rng = np.random.default_rng(seed)
    th0, p0 = math.radians(20.0), np.array([5.0, -10.0])
    acc_std, gyro_std = 0.0042 * math.sqrt(hz), math.radians(0.036) * math.sqrt(hz)
    bias = np.array([0.004, -0.003, math.radians(0.02)])

    def truth(t: float) -> tuple[float, float, float]:
        th = th0 + rate * t
        r = speed / rate
        x = p0[0] + r * (math.sin(th) - math.sin(th0)) + current[0] * t
        y = p0[1] - r * (math.cos(th) - math.cos(th0)) + current[1] * t
        return x, y, th

    recs: list = []
    n = int(round(seconds * hz))
    for k in range(n):
        t = (k + 1) / hz
        e = rng.normal(0.0, 1.0, 3) * [acc_std, acc_std, gyro_std] + bias
        recs.append(Imu(t, e[0], speed * rate + e[1], rate + e[2]))
    for s in range(int(seconds) + 1):
        x, y, th = truth(float(s))
        recs.append(Truth(float(s), x, y, th))
        recs.append(Gnss(float(s), *(np.array([x, y]) + rng.normal(0.0, GNSS_SIGMA, 2)), GNSS_SIGMA))
        recs.append(Heading(float(s), th + rng.normal(0.0, math.radians(1.0)), math.radians(1.0)))
        if velocity:
            vg = speed * np.array([math.cos(th), math.sin(th)]) + current
            recs.append(GnssVelocity(float(s), *(vg + rng.normal(0.0, 0.05, 2)), 0.05))
        if water:
            recs.append(WaterSpeed(float(s), speed + rng.normal(0.0, 0.05), 0.05))
    meta = {"imu": {"hz": hz, "acc_std": acc_std, "gyro_std": gyro_std, "bias_true": bias.tolist(),
                    "acc_bias_rw": 1e-5, "gyro_bias_rw": 1e-6}}
    return NavLog.from_unsorted(recs, meta=meta)


def _gnss_rmse(log: NavLog) -> float:
    ref = log.truth()
    g = log.columns("gnss")
    i = np.searchsorted(ref.t, g["t"])
    return float(np.sqrt(np.mean((g["x"] - ref.x[i]) ** 2 + (g["y"] - ref.y[i]) ** 2)))


@pytest.fixture(scope="module")
def plain():
    return turn_log()


@pytest.mark.parametrize("name", FILTERS)
def test_every_filter_beats_its_gnss_and_is_consistent_without_odometry(plain, name):
    log = plain
    assert estimators.get(name).unmet(log) is None
    res = estimators.run(name, log)
    ref = log.truth()
    e = ate(res.trajectory, ref)["rmse"]
    assert e < 0.5 * _gnss_rmse(log)  # the fixes' own error is ~4.2 m
    nees = nees_stats(res.trajectory, ref)
    assert nees is not None and 0.3 <= nees["mean"] <= 5.0
    assert res.info["bias_states"] is True  # the IMU states a bias
    if name == "ekf":
        assert res.info["motion"] == "imu"
    used = estimators.inputs(name, log, {}, res.info)
    assert "imu" in used and "gnss" in used and "heading" in used and "odometry" not in used


def test_the_bias_is_estimated(plain):
    for name in ("ekf", "ukf"):
        b = np.array(estimators.run(name, plain).info["bias_final"])
        true = np.array(plain.meta["imu"]["bias_true"])
        assert np.all(np.abs(b - true) < [2e-3, 2e-3, math.radians(0.01)]), (name, b, true)


def test_process_noise_comes_from_the_logs_imu_model(plain):
    r = estimators.run("ukf", plain)
    assert r.info["process_noise"]["source"] == "meta"
    assert r.info["process_noise"]["q_acc"] == pytest.approx(plain.meta["imu"]["acc_std"])
    e = estimators.run("ekf", plain)
    assert e.info["process_noise"]["acc_density"] == pytest.approx(0.0042)


def test_options_turn_the_bias_states_off():
    log = turn_log(seconds=30.0)
    assert estimators.run("ukf", log, bias=False).info["bias_states"] is False
    assert estimators.run("ekf", log, bias=False).info["bias_states"] is False
    with pytest.raises(ValueError):
        estimators.run("ukf", log, bias="maybe")


def test_only_a_bias_free_imu_keeps_the_papers_ukf():
    log = turn_log(seconds=30.0)
    assert estimators.run("ukf", NavLog(log.records, meta={})).info["bias_states"] is True
    free = NavLog(log.records, meta={"imu": {"bias_free": True}})
    assert estimators.run("ukf", free).info["bias_states"] is False
    assert estimators.run("fuzzy-ukf", free).info["bias_states"] is False
    assert estimators.run("ukf-bias", free).info["bias_states"] is True


@pytest.fixture(scope="module")
def with_current():
    return turn_log(seed=1, current=CURRENT, velocity=True, water=True)


@pytest.mark.parametrize("name", FILTERS)
def test_gnss_velocity_and_water_speed_give_the_current(with_current, name):
    log = with_current
    res = estimators.run(name, log)
    assert res.info["current_states"] is True
    np.testing.assert_allclose(res.info["current_final"], CURRENT, atol=0.1)
    ref = log.truth()
    assert ate(res.trajectory, ref)["rmse"] < 0.5 * _gnss_rmse(log)
    nees = nees_stats(res.trajectory, ref)
    assert nees is not None and 0.3 <= nees["mean"] <= 5.0
    used = estimators.inputs(name, log, {}, res.info)
    assert {"gnss_velocity", "water_speed"} <= set(used)


def test_gnss_velocity_improves_the_estimate():
    with_v = turn_log(seed=2, velocity=True)
    ref = with_v.truth()
    for name in ("ekf", "ukf"):
        a = ate(estimators.run(name, with_v).trajectory, ref)["rmse"]
        b = ate(estimators.run(name, with_v.without(lambda r: r.kind == "gnss_velocity")).trajectory, ref)["rmse"]
        assert a < b
