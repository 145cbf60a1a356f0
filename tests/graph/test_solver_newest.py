"""The iSAM2 solver reads the newest keyframe's state from its marginal factor (no back-substitution
of the whole Bayes tree): the same estimate and marginal covariance as a full solve."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from graphnav.graph.solver import Solver, isam_params


def X(i):
    return gtsam.symbol("x", i)


def V(i):
    return gtsam.symbol("v", i)


def B(i):
    return gtsam.symbol("i", i)


@pytest.mark.parametrize("kind", ["isam2", "fixed-lag"])
@pytest.mark.parametrize("pose3", [False, True])
def test_the_newest_state_equals_the_full_solve(pose3, kind):
    """The newest state from the marginal factor (iSAM2's, or the fixed-lag smoother's iSAM2 with a window
    of 10 keyframes, so that it marginalises) against the full solve and GTSAM's marginalCovariance."""
    rng = np.random.default_rng(1)
    sol = Solver(kind, isam_params(0.01, skip=3), keep_graph=False, lag=10.0)
    ptype = "Pose3" if pose3 else "Pose2"
    for k in range(60):
        g, v = gtsam.NonlinearFactorGraph(), gtsam.Values()
        if pose3:
            guess = gtsam.Pose3(gtsam.Rot3.Yaw(0.05 * k + 0.1), np.array([k + 0.3, 0.2, 0.0]))
            g.add(gtsam.GPSFactor(X(k), np.array([k, 0.0, 0.0]) + rng.normal(0, 2.0, 3),
                                  gtsam.noiseModel.Isotropic.Sigma(3, 2.0)))
            if k:
                rel = gtsam.Pose3(gtsam.Rot3.Yaw(0.05), np.array([1.0, 0.0, 0.0]))
                g.add(gtsam.BetweenFactorPose3(X(k - 1), X(k), rel, gtsam.noiseModel.Isotropic.Sigma(6, 0.05)))
            else:
                g.add(gtsam.PriorFactorPose3(X(0), gtsam.Pose3(), gtsam.noiseModel.Isotropic.Sigma(6, 1.0)))
            bias_model = gtsam.noiseModel.Isotropic.Sigma(6, 1e-3)
            g.add(gtsam.PriorFactorConstantBias(B(k), gtsam.imuBias.ConstantBias(), bias_model) if not k else
                  gtsam.BetweenFactorConstantBias(B(k - 1), B(k), gtsam.imuBias.ConstantBias(), bias_model))
            v.insert(B(k), gtsam.imuBias.ConstantBias(np.full(3, 0.01), np.full(3, 0.001)))
        else:
            guess = gtsam.Pose2(k + 0.3, 0.2, 0.05 * k + 0.1)
            g.add(gtsam.PoseTranslationPrior2D(X(k), np.array([k, 0.0]) + rng.normal(0, 2.0, 2),
                                               gtsam.noiseModel.Isotropic.Sigma(2, 2.0)))
            if k:
                g.add(gtsam.BetweenFactorPose2(X(k - 1), X(k), gtsam.Pose2(1.0, 0.0, 0.05),
                                               gtsam.noiseModel.Diagonal.Sigmas([0.05, 0.05, 0.01])))
            else:
                g.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(), gtsam.noiseModel.Isotropic.Sigma(3, 1.0)))
        g.add(gtsam.PriorFactorVector(V(k), np.array([1.0, 0.0]) + rng.normal(0, 0.1, 2),
                                      gtsam.noiseModel.Isotropic.Sigma(2, 0.1)))
        v.insert(X(k), guess)
        v.insert(V(k), np.zeros(2))
        if kind == "fixed-lag":
            sol.update(g, v, {key: float(k) for key in v.keys()}, t=float(k))
            full = sol.s.calculateEstimate()  # every variable of the window, full back-substitution
        else:
            sol.update(g, v)
            full = sol.s.calculateBestEstimate()  # every variable, full back-substitution
        got = sol.estimate(X(k), ptype)
        want = getattr(full, f"at{ptype}")(X(k))
        assert np.allclose(np.asarray(want.localCoordinates(got)), 0.0, atol=1e-9)
        assert np.allclose(sol.estimate(V(k), "Vector"), full.atVector(V(k)), atol=1e-9)
        assert np.allclose(sol.marginal(X(k)), sol.s.marginalCovariance(X(k)), rtol=1e-8, atol=1e-12)
        assert np.allclose(sol.marginal(V(k)), sol.s.marginalCovariance(V(k)), rtol=1e-8, atol=1e-12)
        if pose3:
            b = sol.estimate(B(k), "ConstantBias")
            assert np.allclose(b.vector(), full.atConstantBias(B(k)).vector(), atol=1e-9)
        if k > 2:  # an older variable: calculateEstimate (the wildfire back-substitution)
            old = sol.estimate(X(k - 2), ptype)
            assert np.allclose(np.asarray(getattr(full, f"at{ptype}")(X(k - 2)).localCoordinates(old)), 0.0,
                               atol=2e-3)
