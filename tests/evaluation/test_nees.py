"""Position NEES (``nees_mean`` in every summary): known answers on synthetic trajectories."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from graphnav.evaluation.evaluate import summarize
from graphnav.evaluation.metrics import ate, nees_stats, position_nees
from graphnav.log import NavLog, Truth
from graphnav.result import RunResult
from graphnav.trajectory import Trajectory


def _random_covs(rng: np.random.Generator, n: int) -> np.ndarray:
    """n random SPD 3x3 covariances with correlated x/y (sigmas 0.05-3 m, 0.2-5 deg)."""
    s = np.column_stack([rng.uniform(0.05, 3.0, n), rng.uniform(0.05, 3.0, n), np.radians(rng.uniform(0.2, 5, n))])
    rho = rng.uniform(-0.9, 0.9, n)
    c = np.zeros((n, 3, 3))
    c[:, 0, 0], c[:, 1, 1], c[:, 2, 2] = s[:, 0] ** 2, s[:, 1] ** 2, s[:, 2] ** 2
    c[:, 0, 1] = c[:, 1, 0] = rho * s[:, 0] * s[:, 1]
    return c


def _truth(n: int, dt: float = 0.1) -> Trajectory:
    t = np.arange(n) * dt
    return Trajectory(t, np.column_stack([3 * np.cos(t / 20) * t, 2 * t, np.sin(t / 7)]))


def _consistent(n: int, seed: int, scale: float = 1.0) -> tuple[Trajectory, Trajectory]:
    """Truth, and an estimate whose errors are drawn from its stated covariance / ``scale``."""
    rng = np.random.default_rng(seed)
    ref = _truth(n)
    cov = _random_covs(rng, n)
    err = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal((n, 3)))
    return Trajectory(ref.t, ref.poses + err / np.sqrt(scale), cov * 1.0), ref


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_nees_of_errors_drawn_from_the_stated_covariance_is_two(seed):
    n = 5000
    est, ref = _consistent(n, seed)
    s = nees_stats(est, ref)
    # mean of n chi2(2) samples: sd 2/sqrt(n) = 0.028; 0.15 is over 5 sd
    assert s["n"] == n and s["dropped"] == 0
    assert s["mean"] == pytest.approx(2.0, abs=0.15)
    assert s["median"] == pytest.approx(chi2.median(2), abs=0.15)  # 1.386
    assert s["in95"] == pytest.approx(0.95, abs=0.02)


def test_nees_scales_inversely_with_an_overstated_covariance():
    est, ref = _consistent(5000, 3, scale=4.0)  # errors half the stated sigma: NEES / 4
    assert nees_stats(est, ref)["mean"] == pytest.approx(0.5, abs=0.05)


def test_nees_of_zero_error_is_zero_and_none_without_covariance():
    ref = _truth(50)
    exact = Trajectory(ref.t, ref.poses.copy(), _random_covs(np.random.default_rng(0), 50))
    assert nees_stats(exact, ref)["mean"] == 0.0
    assert nees_stats(Trajectory(ref.t, ref.poses + 1.0), ref) is None
    assert position_nees(Trajectory(ref.t, ref.poses), ref) is None


def test_nees_closed_form_matches_a_linear_solve():
    est, ref = _consistent(300, 4)
    r = position_nees(est, ref)
    e = (est.poses - ref.poses)[:, :2]
    want = np.array([ei @ np.linalg.solve(c[:2, :2], ei) for ei, c in zip(e, est.cov, strict=True)])
    np.testing.assert_allclose(r["nees"], want, rtol=1e-10)


def test_nees_uses_the_ate_pairs_and_drops_singular_covariances():
    est, ref = _consistent(200, 5)
    t = est.t.copy()
    t[::4] += 0.05  # a quarter of the stamps too far from the truth's (max_dt 0.02)
    cov = est.cov.copy()
    cov[1, :2, :2] = 0.0  # the EKF's zero P0: no NEES for that sample, counted
    cov[2, 0, 0] = np.nan
    est = Trajectory(t, est.poses, cov)
    s = nees_stats(est, ref)
    assert s["n"] + s["dropped"] == ate(est, ref)["n"] == 150
    assert s["dropped"] == 2


def _log_from(ref: Trajectory) -> NavLog:
    return NavLog([Truth(float(t), float(p[0]), float(p[1]), float(p[2])) for t, p in zip(ref.t, ref.poses,
                                                                                          strict=True)])


def test_summary_carries_nees_and_heading_rmse():
    est, ref = _consistent(3000, 6)
    log = _log_from(ref)
    s = summarize("x", RunResult(est, online=est), log, runtime_s=0.0)
    assert s["nees_mean"] == pytest.approx(2.0, abs=0.2)
    yaw_err = np.degrees(est.yaw - ref.yaw)
    assert s["heading_rmse_deg"] == pytest.approx(np.sqrt(np.mean(yaw_err**2)))
    assert "online_nees_mean" not in s  # online is the trajectory itself
    s = summarize("x", RunResult(Trajectory(ref.t, ref.poses)), log, runtime_s=0.0)
    assert s["nees_mean"] is None and s["heading_rmse_deg"] == 0.0
    online = Trajectory(est.t, est.poses, est.cov * 4.0)
    s = summarize("x", RunResult(est, online=online), log, runtime_s=0.0)
    assert s["online_nees_mean"] == pytest.approx(0.5, abs=0.05)
