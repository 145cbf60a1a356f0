"""The back end that cannot lose to its inputs (graphnav.graph.gnc): GNC switches off a wrong scan
match and keeps the right ones; the odometry consistency check tells a smoothed track that follows
the odometry within its noise from one a biased matcher has rotated."""

from __future__ import annotations

import gtsam
import numpy as np

from graphnav.graph.gnc import odometry_consistency, switch_off
from graphnav.graph.solver import LmSettings, levenberg_marquardt

ODO = np.array([0.05, 0.05, np.radians(1.0)])  # odometry sigmas per step
ICP = np.array([0.01, 0.01, np.radians(0.2)])


def _chain(n: int, icp_yaw_bias: float = 0.0, wrong: int | None = None, seed: int = 0):
    """A straight-and-turning Pose2 chain: odometry with its noise, ICP with its noise (plus a yaw
    bias per step, or one grossly wrong match at step ``wrong``)."""
    rng = np.random.default_rng(seed)
    g, groups, v = gtsam.NonlinearFactorGraph(), [], gtsam.Values()
    g.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(), gtsam.noiseModel.Diagonal.Sigmas(np.full(3, 1e-3))))
    groups.append("anchor")
    truth = [gtsam.Pose2()]
    for k in range(1, n):
        step = gtsam.Pose2(0.5, 0.0, 0.05 if (k // 20) % 2 else -0.05)
        truth.append(truth[-1].compose(step))
        odo = step.compose(gtsam.Pose2(*(rng.normal(size=3) * ODO)))
        g.add(gtsam.BetweenFactorPose2(k - 1, k, odo, gtsam.noiseModel.Diagonal.Sigmas(ODO)))
        groups.append("odometry")
        icp = step.compose(gtsam.Pose2(*(rng.normal(size=3) * ICP + [0, 0, icp_yaw_bias])))
        if k == wrong:
            icp = gtsam.Pose2(2.0, 1.0, 0.5)
        g.add(gtsam.BetweenFactorPose2(k - 1, k, icp, gtsam.noiseModel.Diagonal.Sigmas(ICP)))
        groups.append("icp")
        v.insert(k - 1, truth[k - 1])
    v.insert(n - 1, truth[n - 1])
    values, _ = levenberg_marquardt(g, v, LmSettings(1e-10, 100))
    return g, groups, values, truth


def test_gnc_switches_off_the_wrong_match_only():
    g, groups, values, truth = _chain(60, wrong=30)
    # the wrong match pulls the solution away
    assert np.linalg.norm(values.atPose2(59).translation() - truth[59].translation()) > 0.5
    g2, groups2, v2, rep = switch_off(g, values, groups, LmSettings(1e-10, 100))
    assert rep["ran"] and rep["switched_off"] == {"icp": 1}
    assert g2.size() == g.size() - 1 and len(groups2) == g2.size()
    assert np.linalg.norm(v2.atPose2(59).translation() - truth[59].translation()) < 0.3


def test_gnc_does_not_run_on_consistent_data():
    g, groups, values, _ = _chain(60)
    g2, _, v2, rep = switch_off(g, values, groups, LmSettings(1e-10, 100))
    assert rep["ran"] is False and rep["switched_off"] == {} and g2.size() == g.size()


def test_odometry_consistency_flags_a_biased_matcher():
    g, groups, values, _ = _chain(200)
    ok = odometry_consistency(g, values, groups)
    assert ok is not None and ok["consistent"]
    assert [s["keyframes"] for s in ok["scales"]] == [1, 10, 100]
    g, groups, values, _ = _chain(200, icp_yaw_bias=np.radians(1.0))  # 1 deg per step, the odometry's sigma
    bad = odometry_consistency(g, values, groups)
    assert not bad["consistent"]
    assert not bad["scales"][1]["consistent"]  # it accumulates: 10 steps, 10 deg against 3.2 deg


def test_odometry_consistency_without_odometry_is_none():
    g, groups, values, _ = _chain(10)
    assert odometry_consistency(g, values, [("icp" if x == "odometry" else x) for x in groups]) is None


def test_gnc_without_candidates_is_a_no_op():
    g, groups, values, _ = _chain(10)
    g2, _, _, rep = switch_off(g, values, ["odometry" if x == "icp" else x for x in groups], LmSettings(1e-10, 100))
    assert rep["ran"] is False and g2.size() == g.size()


def test_robust_options_are_checked():
    import pytest

    from graphnav.graph.smoother_config import SmootherConfig

    for bad in ({"robust_groups": 5}, {"robust_groups": ["odometry"]}, {"robust_prob": 1.0},
                {"robust_backend": "dcs"}):
        with pytest.raises(ValueError):
            SmootherConfig(**bad)
    assert SmootherConfig(robust_groups=["icp", "loop"]).robust_groups == ["icp", "loop"]
