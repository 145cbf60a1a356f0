"""The LM stopping rules (``LmSettings``): an iteration that lowers the cost by less than ``abs_tol`` (the
``lm_abs_tol`` option) ends the solve, at a cost statistically equal to the converged one; so do
``stall_iterations`` iterations that together lower it by less than ``stall_tol`` (``lm_stall_tol``)."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest

from graphnav.graph.solver import LmSettings, levenberg_marquardt


def _ring(n: int = 40, seed: int = 0) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """A ring of ``n`` Pose2 odometry steps closed by a loop, from a guess with the yaw drifted (nonlinear)."""
    rng = np.random.default_rng(seed)
    g = gtsam.NonlinearFactorGraph()
    odo = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.05, 0.05, math.radians(1.0)]))
    g.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(), gtsam.noiseModel.Isotropic.Sigma(3, 1e-3)))
    step = gtsam.Pose2(1.0, 0.0, 2 * math.pi / n)
    guess, v = gtsam.Pose2(), gtsam.Values()
    v.insert(0, guess)
    for k in range(1, n + 1):
        z = gtsam.Pose2(*(np.array([step.x(), step.y(), step.theta()]) + rng.normal(0, [0.05, 0.05, 0.017])))
        g.add(gtsam.BetweenFactorPose2(k - 1, k % n if k == n else k, z, odo))
        if k < n:
            guess = guess.compose(gtsam.Pose2(z.x(), z.y(), z.theta() + 0.05))  # a drifting guess
            v.insert(k, guess)
    return g, v


def test_abs_tol_stops_early_at_a_statistically_equal_cost():
    g, v = _ring()
    full, it_full = levenberg_marquardt(g, v, LmSettings(1e-14, 200, 0.0))
    early, it_early = levenberg_marquardt(g, v, LmSettings(1e-14, 200, 1e-3))
    one, it_one = levenberg_marquardt(g, v, LmSettings(1e-14, 200, 1e12))
    assert it_one == 1 < it_full and it_early <= it_full
    assert g.error(v) > g.error(one) > g.error(full)  # one step is not converged ...
    assert 0.0 <= g.error(early) - g.error(full) < 0.01  # ... the rule's stop is (chi^2 within 0.02)


def _gtsam_optimize(g: gtsam.NonlinearFactorGraph, v: gtsam.Values, tol: float, abs_tol: float, adaptive: bool
                    ) -> tuple[gtsam.Values, int]:
    p = gtsam.LevenbergMarquardtParams()
    p.setMaxIterations(200)
    p.setRelativeErrorTol(tol)
    p.setAbsoluteErrorTol(abs_tol)
    p.setUseFixedLambdaFactor(not adaptive)
    opt = gtsam.LevenbergMarquardtOptimizer(g, v, p)
    return opt.optimize(), int(opt.iterations())


@pytest.mark.parametrize("adaptive", [False, True])
@pytest.mark.parametrize("stall_tol", [0.0, 1e-300])
def test_where_the_stall_rule_does_not_bind_the_solve_is_gtsam_optimize(stall_tol: float, adaptive: bool):
    """The solve iterates GTSAM's LM itself; where the stall rule is off or does not bind it is ``optimize()``: the
    same number of iterations and the same cost (GTSAM's own stopping rule re-stated)."""
    g, v = _ring()
    for tol, abs_tol in ((1e-14, 0.0), (1e-14, 1e-3), (1e-5, 1e-5)):
        ref, it_ref = _gtsam_optimize(g, v, tol, max(tol, abs_tol), adaptive)
        loop, it_loop = levenberg_marquardt(g, v, LmSettings(tol, 200, abs_tol, stall_tol=stall_tol,
                                                             adaptive=adaptive))
        assert it_loop == it_ref >= 3
        assert g.error(loop) == g.error(ref)


def test_stall_rule_truncates_lm_after_its_window():
    """A window of iterations that lowers the cost by less than ``stall_tol`` ends the solve there: the values
    are plain LM's after that many iterations, and a rule that cannot bind before convergence changes nothing."""
    g, v = _ring()
    full, it_full = levenberg_marquardt(g, v, LmSettings(1e-14, 200, 0.0))
    for window in (2, 3):
        cut, it_cut = levenberg_marquardt(g, v, LmSettings(1e-14, 200, 0.0, stall_tol=1e12, stall_iterations=window))
        assert it_cut == window < it_full
        same, _ = levenberg_marquardt(g, v, LmSettings(1e-14, window, 0.0))
        assert g.error(cut) == g.error(same) > g.error(full)
    # the ring's LM lowers the cost by far more than 1e-9 over any 3 iterations until it has converged
    late, it_late = levenberg_marquardt(g, v, LmSettings(1e-14, 200, 0.0, stall_tol=1e-9, stall_iterations=3))
    assert it_late <= it_full and abs(g.error(late) - g.error(full)) < 1e-8

