"""The vessel model's rate of turn (NMEA 0183 ROT, NMEA 2000 127251, Signal K rateOfTurn): the ROT records
are the gyro z samples of the vessel model's preintegration (graph) and the yaw rate of the vessel EKF's
prediction, the yaw's noise the records' own sigma at their rate; the ROT's bias the gyro-z bias state.
Known answers on a weaving boat whose heading is read only every 5 s."""

from __future__ import annotations

import math

import numpy as np
import pytest

from graphnav import estimators
from graphnav.graph.imu_chain import ROT_ACCURACY_DEG_MIN, ImuConfig, RotChain, rot_sigma
from graphnav.log import ODOMETRY_FROM_ROT, Gnss, GnssVelocity, Heading, NavLog, Odometry, Truth

W0, WA, PERIOD = math.radians(2.0), math.radians(5.0), 7.0  # [rad/s] steady turn + weave amplitude, [s] its period
HEADING_EVERY = 5.0  # [s]
FAST = {"lag": 30.0}


def yaw_at(t: np.ndarray | float) -> np.ndarray | float:
    """The true heading: the integral of ``W0 + WA cos(2 pi t / PERIOD)``."""
    return W0 * t + WA * PERIOD / (2 * math.pi) * np.sin(2 * math.pi * np.asarray(t) / PERIOD)


def weaving_boat(rot_hz: float | None = 5.0, *, seconds: float = 120.0, bias_deg: float = 0.0,
                 sigma_w_deg: float | None = 0.1, seed: int = 0, v: float = 3.0) -> NavLog:
    """A boat at ``v`` m/s along its bow, turning at ``W0`` with a weave of ``WA`` (period ``PERIOD``):
    GNSS fixes (1 m) and velocity (0.05 m/s) at 1 Hz, the heading (0.5 deg) every ``HEADING_EVERY`` s, and a
    ROT gyro at ``rot_hz`` (each record the mean rate over its interval, white noise ``sigma_w_deg`` [deg/s],
    stated; None: not stated, the record's is drawn at ``ROT_ACCURACY``; plus ``bias_deg``); ``None``: no ROT."""
    rng = np.random.default_rng(seed)
    dt = 0.01
    tt = np.arange(0.0, seconds + dt / 2, dt)
    yaw = yaw_at(tt)
    x = np.concatenate([[0.0], np.cumsum(v * np.cos(yaw[:-1]) * dt)])
    y = np.concatenate([[0.0], np.cumsum(v * np.sin(yaw[:-1]) * dt)])
    recs: list = []
    for k in range(int(seconds) + 1):
        i = int(round(k / dt))
        t = float(tt[i])
        recs += [Truth(t, x[i], y[i], math.remainder(yaw[i], 2 * math.pi)),
                 Gnss(t, x[i] + rng.normal(0, 1.0), y[i] + rng.normal(0, 1.0), 1.0),
                 GnssVelocity(t, v * math.cos(yaw[i]) + rng.normal(0, 0.05),
                              v * math.sin(yaw[i]) + rng.normal(0, 0.05), 0.05)]
        if k % HEADING_EVERY == 0:
            recs.append(Heading(t, math.remainder(yaw[i] + rng.normal(0, math.radians(0.5)), 2 * math.pi),
                                math.radians(0.5)))
    if rot_hz is not None:
        step = 1.0 / rot_hz
        for k in range(1, int(seconds * rot_hz) + 1):
            t0, t1 = (k - 1) * step, k * step
            w = (yaw_at(t1) - yaw_at(t0)) / step  # the mean rate over (t0, t1]
            s = math.radians(sigma_w_deg) if sigma_w_deg is not None else rot_sigma(Odometry(t1, v, w))
            recs.append(Odometry(t1, v, float(w + math.radians(bias_deg) + rng.normal(0, s)),
                                 math.nan, s if sigma_w_deg is not None else math.nan))
    return NavLog.from_unsorted(recs, meta={"odometry": ODOMETRY_FROM_ROT} if rot_hz is not None else {})


def yaw_errors(log: NavLog, name: str, **options) -> np.ndarray:
    """[deg] the track's heading error at its poses between the headings (at least 1 s from one)."""
    tr = estimators.run(name, log, **options).trajectory
    t = np.asarray(tr.t)
    far = np.abs(t - HEADING_EVERY * np.round(t / HEADING_EVERY)) >= 1.0
    far &= t >= 10.0  # after the start
    err = np.remainder(tr.poses[:, 2] - yaw_at(t) + math.pi, 2 * math.pi) - math.pi
    return np.degrees(np.abs(err[far]))


@pytest.mark.parametrize("rot_hz", [1.0, 10.0])
def test_rot_makes_the_yaw_between_headings(rot_hz):
    """Headings every 5 s on a boat weaving +-5 deg/s (period 7 s): with the ROT gyro (0.1 deg/s per record)
    the smoothed yaw between headings stays within 1 deg of the truth (the ROT's white noise integrated over
    2.5 s is 0.1-0.16 deg, plus the headings' 0.5 deg); the vessel model alone interpolates between headings and
    is off by several degrees."""
    with_rot = yaw_errors(weaving_boat(rot_hz), "isam2", **FAST)
    without = yaw_errors(weaving_boat(None), "isam2", **FAST)
    assert with_rot.max() < 1.0, with_rot.max()
    assert without.max() > 3.0, without.max()
    assert np.sqrt(np.mean(without**2)) > 4 * np.sqrt(np.mean(with_rot**2))


def test_rot_makes_the_ekf_yaw_between_headings():
    """The vessel EKF with the same model: the ROT's rate carries the filtered yaw between the headings (a
    filter: within 1.5 deg, 3 sigma of the heading's 0.5 deg it last took); without it the heading is held."""
    with_rot = yaw_errors(weaving_boat(1.0), "ekf")
    without = yaw_errors(weaving_boat(None), "ekf")
    assert with_rot.max() < 1.5, with_rot.max()
    assert without.max() > 3.0, without.max()


def test_rot_bias_is_estimated():
    """A ROT gyro reading 0.3 deg/s too high (3x the bias prior's 0.1 deg/s): the graph's gyro-z bias state
    takes it (within 0.05 deg/s by the end) and the yaw between headings stays within 1 deg; with the bias
    held at zero (a prior of 1e-6 deg/s) the integrated bias bends the yaw between headings by ~0.3 deg/s x 2.5 s."""
    log = weaving_boat(5.0, seconds=240.0, bias_deg=0.3)
    res = estimators.run("isam2", log, **FAST)
    b = res.info["imu_bias_final"]
    assert math.degrees(b[5]) == pytest.approx(0.3, abs=0.05)
    assert yaw_errors(log, "isam2", **FAST).max() < 1.0
    held = yaw_errors(log, "isam2", imu={"bias_sigma_gyro_deg": 1e-6}, **FAST)
    free = yaw_errors(log, "isam2", **FAST)
    assert np.sqrt(np.mean(held**2)) > 1.5 * np.sqrt(np.mean(free**2))
    ekf = estimators.run("ekf", log)
    assert math.degrees(ekf.info["bias_final"][2]) == pytest.approx(0.3, abs=0.05)


def test_rot_sigma_is_the_records_or_the_indicators_accuracy():
    """A record's stated sigma wins; else IMO A.526(13)'s 0.5 deg/min + 5 % of the rate; the yaw's variance over
    an interval is the per-record variance over the records' rate, independent of the rate."""
    assert rot_sigma(Odometry(0.0, 1.0, 0.1, math.nan, 0.02)) == 0.02
    assert rot_sigma(Odometry(0.0, 1.0, -0.1)) == pytest.approx(math.radians(ROT_ACCURACY_DEG_MIN / 60) + 0.005)
    for hz in (1.0, 10.0):
        c = RotChain(ImuConfig())
        for k in range(0, 50):
            c.add_rot(Odometry(k / hz, 1.0, 0.05, math.nan, 0.01))
        w, dt, var = c.interval(1.0, 3.0)
        assert float(np.sum(w * dt)) == pytest.approx(0.1)
        assert var == pytest.approx(0.01**2 / hz * 2.0)
    c = RotChain(ImuConfig())
    for t in (0.0, 1.0, 2.0, 5.0):
        c.add_rot(Odometry(t, 1.0, 0.05, math.nan, 0.01))
    assert c.interval(0.5, 1.5) is not None
    assert c.interval(1.5, 4.5) is None  # a 3 s gap: the vessel model's walk
    assert c.interval(5.0, 8.0) is None  # held 3 s beyond the newest


@pytest.mark.parametrize("w", [1e200, -40.0])
def test_an_implausible_rate_of_turn_is_ignored_not_integrated(w):
    """A ROT record beyond any gyro's full scale (``Limits.max_yaw_rate``, 35 rad/s; records handed to the API are
    checked for finiteness only) is counted and left out, by the graph and the EKF: 1e200 rad/s raised
    OverflowError, 40 rad/s turned the yaw by up to 180 deg."""
    recs = [r if not (isinstance(r, Odometry) and 10.0 < r.t < 11.0) else Odometry(r.t, r.v, w)
            for r in weaving_boat(5.0, seconds=40.0).records]
    log = NavLog(recs, meta={"odometry": ODOMETRY_FROM_ROT})
    r = estimators.run("isam2", log, **FAST)
    assert r.info["vessel_rot"]["implausible"] == sum(isinstance(q, Odometry) and q.w == w for q in recs) == 4
    assert yaw_errors(log, "isam2", **FAST).max() < 2.0
    assert yaw_errors(log, "ekf").max() < 5.0  # (1.8 deg with the good records alone)
