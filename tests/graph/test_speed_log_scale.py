"""The speed log's scale in the Pose3 graph (graphnav.graph.water): ``V - W = k v bow``, ``k`` estimated with
the water current. Known answers on a synthetic boat whose log under-reads by 7 %."""

from __future__ import annotations

import math

import gtsam
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from factors import X
from graphnav.graph.log_runs import run_batch, run_fixed_lag, run_isam2
from graphnav.graph.space import K, V, W
from graphnav.graph.water import SURFACE_V, WaterRow
from graphnav.log import NavLog, WaterSpeed
from tests.graph.test_imu_graph import FAST, turn_log

TRUE_V, READS = 2.0, 0.93  # the log reads 93 % of the speed through water: its scale is 1 / 0.93
CURRENT = (0.3, -0.25)


def logged(n: int = 400, outage: tuple[float, float] | None = None) -> NavLog:
    """A boat turning 1 deg/s at 2 m/s through a (0.3, -0.25) m/s current, GNSS 1 m at 1 Hz (none in
    ``outage``), compass, 10 Hz IMU, and a speed log reading 0.93 of the speed through water."""
    log = turn_log(v=TRUE_V, w_deg=1.0, n=n, gnss_sigma=1.0, gnss_noise=1.0, seed=11, current=CURRENT, imu_rate=10)
    recs = [r for r in log.records if not (outage and r.kind == "gnss" and outage[0] <= r.t < outage[1])]
    recs += [WaterSpeed(float(t), TRUE_V * READS, 0.03) for t in range(1, n + 1)]
    return NavLog.from_unsorted(recs, meta=log.meta)


def exact_error(values: gtsam.Values, v: float, yaw: float | None, sv: float, lee: float) -> float:
    """The measurement model ``z = (V - W) / k + noise`` (graph.water) as GTSAM's error, ``|e|^2 / 2``; the bow
    ``yaw`` (``None``: the pose's in ``values``)."""
    vel, cur, k = (np.asarray(values.atVector(key)) for key in (V(3), W(3), K(0)))
    yaw = values.atPose3(X(3)).rotation().yaw() if yaw is None else yaw
    c, sn = math.cos(yaw), math.sin(yaw)
    e = (vel - cur) / k[0] - v * np.array([c, sn, 0.0])
    along, across = c * e[0] + sn * e[1], -sn * e[0] + c * e[1]
    return 0.5 * ((along / sv) ** 2 + (across / lee) ** 2 + (e[2] / SURFACE_V) ** 2)


@settings(max_examples=40, deadline=None)
@given(st.floats(-math.pi, math.pi), st.floats(0.0, 5.0), st.floats(0.5, 1.5), st.floats(0.0, 5.0),
       st.lists(st.floats(-3.0, 3.0), min_size=6, max_size=6))
def test_the_linear_factor_is_the_reading_model_linearised_about_its_scale(yaw, v, k0, m, vw):
    """At ``k = k0`` the factor's error is the model's (any ``m``); where ``V - W = k0 m`` along the bow its
    slope in ``k`` is the model's too (central differences)."""
    values = gtsam.Values()
    values.insert(V(3), np.array(vw[:3]))
    values.insert(W(3), np.array(vw[3:]))
    values.insert(K(0), np.array([k0]))
    values.insert(X(3), level(yaw))
    row = WaterRow(0.0, 3, v, 0.05, 0.2, yaw, K(0), m, k0)
    assert math.isclose(row.factor().error(values), exact_error(values, v, yaw, 0.05, 0.2), rel_tol=1e-9,
                        abs_tol=1e-9)
    along = m  # V - W along the bow, k0 m: the factor's m is the model's reading there
    values.update(V(3), np.array(vw[3:]) + k0 * m * np.array([math.cos(yaw), math.sin(yaw), 0.0]))
    tangent = WaterRow(0.0, 3, v, 0.05, 0.2, yaw, K(0), along, k0).factor()
    h = 1e-6
    slopes = []
    for f in (tangent.error, lambda x: exact_error(x, v, yaw, 0.05, 0.2)):
        ends = []
        for d in (h, -h):
            x = gtsam.Values(values)
            x.update(K(0), np.array([k0 + d]))
            ends.append(f(x))
        slopes.append((ends[0] - ends[1]) / (2 * h))
    assert math.isclose(slopes[0], slopes[1], rel_tol=1e-4, abs_tol=1e-3), slopes


def level(yaw: float, roll: float = 0.0, pitch: float = 0.0) -> gtsam.Pose3:
    return gtsam.Pose3(gtsam.Rot3.Ypr(yaw, pitch, roll), gtsam.Point3(1.0, 2.0, 0.0))


@settings(max_examples=40, deadline=None)
@given(st.floats(-math.pi, math.pi), st.floats(0.5, 5.0), st.floats(0.5, 1.5), st.booleans(),
       st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3))
def test_the_factor_turns_the_heading_as_the_model_does(yaw, v, k0, scaled, cur):
    """About a reading the model meets (``V - W = k0 v bow``), a turn ``h`` of the keyframe's (level) pose costs
    what the model says to second order: the factor's yaw column is the model's derivative across the bow
    (without it the readings could not tell the heading, and a compass bias went unobserved online)."""
    values = gtsam.Values()
    bow = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    values.insert(W(3), np.array(cur))
    values.insert(V(3), np.array(cur) + k0 * v * bow)
    values.insert(K(0), np.array([k0]))
    row = WaterRow(0.0, 3, v, 0.05, 0.2, yaw, K(0) if scaled else None, v, k0 if scaled else 1.0)
    if not scaled:
        values.update(V(3), np.array(cur) + v * bow)
        values.update(K(0), np.array([1.0]))
    values.insert(X(3), level(yaw))
    assert row.factor().error(values) < 1e-12
    for h in (2e-3, -3e-3):
        values.update(X(3), level(yaw + h))
        got, want = row.factor().error(values), exact_error(values, v, None, 0.05, 0.2)
        assert want > 0 and math.isclose(got, want, rel_tol=0.02), (h, got, want)


def test_a_straight_leg_leaves_the_scale_to_its_prior():
    """900 s at one speed on one heading, readings with 0.05 m/s of noise: the scale and the current along
    the track are one unknown, so the scale stays where its prior and the current's put it (1.008 with
    noiseless readings); a linearisation whose k column carried the readings' noise moved it to 0.10-1.22."""
    rng = np.random.default_rng(1)
    log = turn_log(v=TRUE_V, w_deg=0.0, n=900, gnss_sigma=1.0, gnss_noise=1.0, seed=11, current=CURRENT, imu_rate=10)
    recs = list(log.records) + [WaterSpeed(float(t), TRUE_V * READS + rng.normal(0, 0.05), 0.05) for t in range(1, 901)]
    info = run_isam2(NavLog.from_unsorted(recs, meta=log.meta), **FAST).info
    assert abs(info["log_scale_final"] - 1.008) < 0.04, info["log_scale_final"]


def test_the_scale_and_the_current_are_recovered_in_isam2_batch_and_fixed_lag():
    """The log under-reads by 7 %: each solver finds its scale (1 / 0.93 = 1.075) within 0.01 and the current
    within 0.05 m/s, throughout; with the readings taken as true the current absorbs the error, turning
    with the bow (0.15 m/s off)."""
    log = logged()
    truth = np.array(CURRENT)
    for run in (run_isam2, run_batch, run_fixed_lag):
        info = run(log, **FAST).info
        assert abs(info["log_scale_final"] - 1 / READS) < 0.01, (run.__name__, info["log_scale_final"])
        s = np.array(info["water_current"]["series"])  # (fixed-lag's: its window; after the first 50 s)
        err = np.abs(s[s[:, 0] > 50.0, 1:] - truth)
        assert len(err) and err.max() < 0.05, (run.__name__, err.max())
    info = run_isam2(log, water_scale_sigma=None, **FAST).info
    assert "log_scale_final" not in info
    s = np.array(info["water_current"]["series"])
    assert np.abs(s[s[:, 0] > 50.0, 1:] - truth).max() > 0.1


def test_the_scale_carries_the_coast_through_a_gnss_outage():
    """60 s without GNSS after 300 s of turning: the online track at the outage's end, coasting on the IMU,
    the compass and the speed log, is closer with the scale estimated than with the readings as true."""
    log = logged(outage=(300.0, 360.0))
    ref = log.truth()

    def end_error(**opts) -> float:
        online = run_isam2(log, **FAST, **opts).online
        i = int(np.argmin(np.abs(online.t - 359.0)))
        j = int(np.argmin(np.abs(ref.t - online.t[i])))
        return float(np.hypot(*(online.poses[i, :2] - ref.poses[j, :2])))

    with_scale, without = end_error(), end_error(water_scale_sigma=None)
    assert with_scale < 0.6 * without, (with_scale, without)
