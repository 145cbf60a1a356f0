"""graph.noise.group_statistics at an exact solution: every residual is zero, so the sparse Jacobian
has no entry in its b column; the columns are then still the variables' (a known answer: chi2 = 0,
the same redundancy as an inexact solution nearby)."""

from __future__ import annotations

import gtsam
import pytest

from graphnav.graph.noise import group_statistics


def _graph() -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values, list[str]]:
    g, v = gtsam.NonlinearFactorGraph(), gtsam.Values()
    n = gtsam.noiseModel.Isotropic.Sigma(3, 0.1)
    g.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(), n))
    groups = ["prior"]
    for k in range(1, 8):
        g.add(gtsam.BetweenFactorPose2(k - 1, k, gtsam.Pose2(1, 0, 0), n))
        g.add(gtsam.PriorFactorPose2(k, gtsam.Pose2(k, 0, 0), n))
        groups += ["odometry", "gnss"]
    for k in range(8):
        v.insert(k, gtsam.Pose2(k, 0, 0))
    return g, v, groups


def test_exact_solution_has_zero_chi2_and_the_same_redundancy():
    g, v, groups = _graph()
    exact = group_statistics(g, v, groups, ["odometry", "gnss"])
    near = gtsam.Values(v)
    near.update(3, gtsam.Pose2(3.001, 0.0, 0.0))
    other = group_statistics(g, near, groups, ["odometry", "gnss"])
    for grp in ("odometry", "gnss"):
        assert exact[grp]["chi2"] == pytest.approx(0.0, abs=1e-20)
        assert exact[grp]["m"] == other[grp]["m"] == 21.0
        assert exact[grp]["redundancy"] == pytest.approx(other[grp]["redundancy"], rel=0.15)  # Hutchinson noise
    assert exact["odometry"]["redundancy"] + exact["gnss"]["redundancy"] == pytest.approx(42 - 24 + 3, abs=4)


def test_rows_by_group_with_factors_of_several_dimensions():
    """Each row counted in its factor's group (factors of 3 and 2 rows interleaved, a group asked about but
    absent): ``m`` the group's rows, ``chi2`` the sum of its factors' squared whitened residuals."""
    g, v, groups = _graph()
    pt = gtsam.noiseModel.Isotropic.Sigma(2, 0.5)
    for j in range(3):
        g.add(gtsam.PriorFactorPoint2(gtsam.symbol("l", j), [j + 0.1, 0.2 * j], pt))
        groups.append("beacon")
        v.insert(gtsam.symbol("l", j), [float(j), 0.0])
    g.add(gtsam.BetweenFactorPose2(0, 7, gtsam.Pose2(7.05, 0.0, 0.01), gtsam.noiseModel.Isotropic.Sigma(3, 0.1)))
    groups.append("odometry")
    near = gtsam.Values(v)
    near.update(3, gtsam.Pose2(3.02, -0.01, 0.003))
    out = group_statistics(g, near, groups, ["beacon", "odometry", "chart"])
    assert set(out) == {"beacon", "odometry"}
    assert out["beacon"]["m"] == 6.0 and out["odometry"]["m"] == 24.0
    for grp in ("beacon", "odometry"):
        chi2 = sum(2.0 * g.at(i).error(near) for i, gi in enumerate(groups) if gi == grp)
        assert out[grp]["chi2"] == pytest.approx(chi2, rel=1e-9)
