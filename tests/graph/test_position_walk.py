"""The vessel model's position random walk estimated from a log (graphnav.graph.position_walk): known answers
on synthetic boats whose fixes wander from their own velocity by a known random walk."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from graphnav.graph.log_runs import run_isam2
from graphnav.graph.navigator import Navigator
from graphnav.graph.position_walk import fit_walk, nnls2, position_walk
from graphnav.log import Gnss, GnssVelocity, Heading, NavLog, Truth


def wandering_boat(walk: float, n: int = 900, *, fix_sigma: float = 2.5, seed: int = 0,
                   jump: tuple[int, int, float] | None = None) -> NavLog:
    """A boat at 2 m/s on a slow S-curve, records at 1 Hz: its GNSS velocity exact to 0.05 m/s (stated), a
    compass, and fixes whose receiver position wanders from the track by a random walk of ``walk`` m/sqrt(s)
    per axis, plus white noise ``fix_sigma`` (stated) and a ``jump`` (first, last index, offset [m]). The
    truth records are the receiver's wandering position (what a receiver's own fixes as a reference are)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n + 1, dtype=float)
    yaw = 0.6 * np.sin(2 * math.pi * t / 300.0)
    vx, vy = 2.0 * np.cos(yaw), 2.0 * np.sin(yaw)
    x = np.concatenate([[0.0], np.cumsum(0.5 * (vx[1:] + vx[:-1]))])
    y = np.concatenate([[0.0], np.cumsum(0.5 * (vy[1:] + vy[:-1]))])
    wander = np.cumsum(rng.normal(0.0, walk, size=(n + 1, 2)), axis=0)
    rx, ry = x + wander[:, 0], y + wander[:, 1]
    recs: list = []
    for k in range(n + 1):
        gx, gy = rx[k] + rng.normal(0, fix_sigma), ry[k] + rng.normal(0, fix_sigma)
        if jump is not None and jump[0] <= k < jump[1]:
            gx += jump[2]
        recs += [Truth(t[k], rx[k], ry[k], float(yaw[k])), Gnss(t[k], gx, gy, fix_sigma),
                 GnssVelocity(t[k], vx[k] + rng.normal(0, 0.05), vy[k] + rng.normal(0, 0.05), 0.05),
                 Heading(t[k], float(yaw[k] + rng.normal(0, math.radians(1.0))), math.radians(1.0))]
    return NavLog.from_unsorted(recs)


def test_fit_recovers_intercept_and_slope():
    rows = [(lag, 3.0 + 0.2 * lag, 500) for lag in (1.0, 5.0, 10.0, 30.0, 60.0)]
    a, q = fit_walk(rows)
    assert a == pytest.approx(3.0, rel=1e-6) and q == pytest.approx(0.2, rel=1e-6)
    assert fit_walk(rows[:2]) is None  # too few lags


@example(rows=[(1.0, 5e-324, 1.0), (1.0, 0.0, 1.0), (0.5, 0.0, 1.0)], tilt=0.0)  # a subnormal b
@example(rows=[(1.0, 5.9e-231, 1.0), (2.0, 5.9e-231, 1.0), (1.0, 0.0, 1.0)], tilt=0.0)  # b @ b underflows to 0
@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.floats(0.1, 100.0), st.floats(-50.0, 50.0), st.floats(0.01, 10.0)), min_size=3,
                max_size=12), st.floats(-5.0, 5.0))
def test_nnls2_is_scipy_nnls(rows, tilt):
    """The walk's two-column non-negative least squares against scipy.optimize.nnls (which it replaces): the same
    solution to rounding, including where a component is clipped at 0 (a negative slope or intercept)."""
    from scipy.optimize import nnls  # (here: test_chi2 runs this module's boat in a process without scipy.optimize)

    lag = np.array([r[0] for r in rows])
    w = np.array([r[2] for r in rows])
    A = np.c_[np.ones_like(lag), lag] * w[:, None]
    b = (np.array([r[1] for r in rows]) + tilt * lag) * w
    if np.linalg.matrix_rank(A) < 2 or np.linalg.cond(A) > 1e8:
        return
    ours, ref = nnls2(A, b), nnls(A, b)[0]
    scale = np.abs(b).max() * np.sqrt(b.size) / np.linalg.norm(A, axis=0)  # (|b| without squares: b may be 1e-231)
    assert (ours >= 0.0).all()
    assert np.allclose(ours, ref, rtol=1e-9, atol=1e-9 * scale + np.finfo(float).tiny)
    r_ours, r_ref = A @ ours - b, A @ ref - b
    assert r_ours @ r_ours <= r_ref @ r_ref + 1e-12 * (b @ b)


def test_nnls2_known_answers():
    A = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    assert np.allclose(nnls2(A, np.array([2.0, 1.0, 1.0])), [1.5, 1.0])  # scipy's own examples
    assert np.array_equal(nnls2(A, np.array([-1.0, -1.0, -1.0])), [0.0, 0.0])
    rows = [(lag, 3.0 - 0.01 * lag, 500) for lag in (1.0, 5.0, 10.0, 30.0, 60.0)]  # a falling variance: q = 0
    a, q = fit_walk(rows)
    assert q == 0.0 and a > 0.0


@pytest.mark.parametrize("seed", [0, 1])
def test_position_walk_is_the_fixes_wander_from_the_velocity(seed):
    """0.4 m/sqrt(s) of wander under 2.5 m fixes with a 10 s 20 m jump: estimated within 20 %; the
    velocity's own stated noise (0.05 m/s at 1 Hz) is not counted twice; without wander, near nothing."""
    est = position_walk(wandering_boat(0.4, seed=seed, jump=(600, 610, 20.0)))
    assert est is not None
    assert est["walk"] == pytest.approx(0.4, rel=0.2)
    assert est["velocity_q"] == pytest.approx(0.05**2, rel=1e-6)
    assert est["a"] == pytest.approx(2 * 2.5**2, rel=0.25)  # both ends' white noise
    still = position_walk(wandering_boat(0.0, seed=seed))
    assert still is not None and still["walk"] < 0.15


def test_without_velocity_records_there_is_no_estimate():
    log = wandering_boat(0.4, n=200).without(lambda r: r.kind == "gnss_velocity")
    assert position_walk(log) is None


def test_the_vessel_graph_takes_the_logs_walk_unless_given():
    log = wandering_boat(0.4, n=300)
    est = position_walk(log)
    nav = Navigator.for_log(log, motion="vessel")
    assert nav.builder.motion.imu.vessel_walk == pytest.approx(est["walk"])
    given = Navigator.for_log(log, motion="vessel", imu={"vessel_position_walk": 0.0})
    assert given.builder.motion.imu.vessel_walk == pytest.approx(1e-3)  # integration_sigma: the floor
    assert Navigator.for_log(log, motion="odometry").builder.motion.imu is None


def test_the_walk_makes_the_vessel_graph_consistent_with_wandering_fixes():
    """The known answer end to end: against the receiver's wandering position, the vessel graph that trusts
    the integrated velocity (1 mm/sqrt(s)) is over-confident (NEES several times its 2 degrees of freedom);
    with the log's walk its NEES is within chance of 2 and its error no larger."""
    log = wandering_boat(0.4, n=400, seed=3)
    ref = log.truth()

    def score(**opts):
        r = run_isam2(log, motion="vessel", **opts)
        err = r.trajectory.poses[:, :2] - ref.interpolate(r.trajectory.t)[:, :2]
        nees = np.einsum("ni,nij,nj->n", err, np.linalg.inv(r.trajectory.cov[:, :2, :2]), err).mean()
        return float(nees), float(np.sqrt(np.mean(np.sum(err**2, axis=1))))

    nees, rmse = score()
    nees_stiff, rmse_stiff = score(imu={"vessel_position_walk": 0.0})
    assert nees_stiff > 6.0
    assert 1.0 < nees < 3.5
    assert rmse <= rmse_stiff * 1.05
