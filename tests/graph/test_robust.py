"""The back end that cannot lose to its inputs (graphnav.graph.gnc): GNC switches off a wrong scan
match and keeps the right ones; the odometry consistency check tells a smoothed track that follows
the odometry within its noise from one a biased matcher has rotated."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from graphnav.graph.chi2 import chi2_median, significant_scale
from graphnav.graph.gnc import (
    SCHEDULES,
    factor_scales,
    group_scales,
    measured_d2s,
    odometry_consistency,
    switch_off,
)
from graphnav.graph.noise import _measured
from graphnav.graph.smoother_config import GNC_SCHEDULE
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
    assert SmootherConfig(robust_groups=["icp", "loop"]).robust.groups == ["icp", "loop"]


def _fixes(sigmas: list[float], stated: float = 1.0, seed: int = 0):
    """Pose2 keyframes 1 m apart tied by exact odometry, each with a fix of true noise ``sigmas[k]``
    under a stated ``stated``."""
    rng = np.random.default_rng(seed)
    g, groups, v = gtsam.NonlinearFactorGraph(), [], gtsam.Values()
    for k, s in enumerate(sigmas):
        if k:
            g.add(gtsam.BetweenFactorPose2(k - 1, k, gtsam.Pose2(1.0, 0.0, 0.0),
                                           gtsam.noiseModel.Diagonal.Sigmas(np.array([0.05, 0.05, 0.01]))))
            groups.append("odometry")
        g.add(gtsam.PoseTranslationPrior2D(k, np.array([k, 0.0]) + rng.normal(0.0, s, 2),
                                           gtsam.noiseModel.Isotropic.Sigma(2, stated)))
        groups.append("gnss")
        v.insert(k, gtsam.Pose2(float(k), 0.0, 0.0))
    values, _ = levenberg_marquardt(g, v, LmSettings(1e-10, 100))
    return g, groups, values


def test_factor_scales_follow_a_receiver_whose_noise_changes():
    """100 fixes as stated, then 100 three times noisier: each fix's scale is its neighbourhood's,
    ~1 (never below) in the first half and ~9 in the second; the whole log's median says neither."""
    g, groups, values = _fixes([1.0] * 100 + [3.0] * 100)
    sc = factor_scales(g, values, groups, ["gnss"])
    idx = [i for i, gi in enumerate(groups) if gi == "gnss"]
    first, second = [sc[i] for i in idx[:75]], [sc[i] for i in idx[125:]]
    assert min(first) >= 1.0 and np.median(first) < 1.5
    assert 5.0 < np.median(second) < 13.0
    whole = group_scales(g, values, groups, ["gnss"])["gnss"]
    assert np.median(first) < whole < np.median(second)
    d2s = {"gnss": measured_d2s(g, values, groups, "gnss")}  # the residuals given once: the same scales
    assert len(d2s["gnss"]) == 200 and all(dim == 2 for _, _, dim in d2s["gnss"])
    assert factor_scales(g, values, groups, ["gnss"], d2s=d2s) == sc
    assert group_scales(g, values, groups, ["gnss"], d2s)["gnss"] == whole


def test_significant_scale_is_the_quantile_of_a_window_median():
    """Against Monte Carlo: the median of 50 samples of chi2_2 / 2 over chi2's median exceeds
    ``significant_scale(2, 0.99)`` in about 1 % of windows."""
    rng = np.random.default_rng(1)
    med = np.median(rng.chisquare(2, size=(20000, 50)) / 2, axis=1) / (chi2_median(np.array([2]))[0] / 2)
    q = float(np.quantile(med, 0.99))
    assert abs(significant_scale(2, 0.99) - q) < 0.06 * q


def test_measured_rows_leave_out_the_graphs_own_pseudo_rows():
    gps = gtsam.GPSFactor(0, np.zeros(3), gtsam.noiseModel.Isotropic.Sigma(3, 1.0))
    assert _measured(gps, "gnss").tolist() == [True, True, False]  # the height is the surface's
    emb = gtsam.BetweenFactorPose3(0, 1, gtsam.Pose3(), gtsam.noiseModel.Isotropic.Sigma(6, 0.1))
    assert np.flatnonzero(_measured(emb, "icp")).tolist() == [2, 3, 4]  # yaw, x, y
    assert _measured(emb, "cloud").all()  # a 3D match measures all six
    p2 = gtsam.PoseRotationPrior2D(0, gtsam.Rot2(0.0), gtsam.noiseModel.Isotropic.Sigma(1, 0.1))
    assert _measured(p2, "compass").tolist() == [True]


def test_online_gnss_scale_finds_a_receiver_noisier_than_stated():
    """Innovations of fixes 3x noisier than stated (prediction covariance P = 1 m^2 per axis): the
    online scale is the variance ratio 9 within sampling error; fixes as stated keep scale 1."""
    from graphnav.graph.measurements import GnssScale

    rng = np.random.default_rng(3)
    P = np.eye(2)
    for true, lo, hi in ((3.0, 7.0, 11.5), (1.0, 1.0, 1.0)):
        sc = GnssScale(0.99)
        for _ in range(200):
            sc.add(rng.normal(0.0, 1.0, 2) + rng.normal(0.0, true, 2), P, 1.0)
        assert lo <= sc.scale <= hi


def test_gnc_leaves_chance_exceedances_of_gnss_alone_and_catches_a_gross_fix():
    """300 consistent fixes: a few lie beyond the 99 % bound by chance (about 3), GNC does not run; one
    fix 30 sigma off lies beyond the family-wise bound and GNC switches it off."""
    g, groups, values = _fixes([1.0] * 300, seed=5)
    _, _, _, rep = switch_off(g, values, list(groups), LmSettings(1e-10, 100))
    assert rep["beyond_bound"] <= rep["chance_bound"] and rep["ran"] is False
    g2 = gtsam.NonlinearFactorGraph(g)
    i = [k for k, gi in enumerate(groups) if gi == "gnss"][150]
    g2.replace(i, gtsam.PoseTranslationPrior2D(150, np.array([150.0, 30.0]), gtsam.noiseModel.Isotropic.Sigma(2, 1.0)))
    values2, _ = levenberg_marquardt(g2, values, LmSettings(1e-10, 100))
    out, _, _, rep2 = switch_off(g2, values2, list(groups), LmSettings(1e-10, 100))
    assert rep2["ran"] is True and 1 <= rep2["switched_off"]["gnss"] <= 3
    kept = [np.asarray(out.at(k).measured()) for k in range(out.size())
            if isinstance(out.at(k), gtsam.PoseTranslationPrior2D)]
    assert not any(np.allclose(m, [150.0, 30.0]) for m in kept)  # the gross fix is among those let go


def _outlier_chain(seed: int):
    """An 80-keyframe chain with two wrong matches and a gross GNSS fix among consistent factors, solved."""
    g, groups, values, _ = _chain(80, wrong=20 + seed * 7, seed=seed)
    g.add(gtsam.BetweenFactorPose2(60, 61, gtsam.Pose2(-1.0, 0.8, -0.6), gtsam.noiseModel.Diagonal.Sigmas(ICP)))
    groups.append("icp")
    g.add(gtsam.PoseTranslationPrior2D(40, np.array([60.0, -25.0]), gtsam.noiseModel.Isotropic.Sigma(2, 1.0)))
    groups.append("gnss")
    values, _ = levenberg_marquardt(g, values, LmSettings(1e-10, 100))
    return g, groups, values


def _decided_alike(g, a, b):
    """Two ``switch_off`` results: the same factors switched off (the two wrong matches among them), the same
    re-solved graph and solution."""
    (g1, gr1, v1, r1), (g2, gr2, v2, r2) = a, b
    assert r1["ran"] and r1["switched_off"] == r2["switched_off"] and r1["switched_off"].get("icp", 0) >= 2
    assert gr1 == gr2 and g1.size() == g2.size() < g.size()
    assert all(g1.at(i).equals(g2.at(i), 0.0) for i in range(g1.size()))
    assert v1.equals(v2, 1e-9)
    return r1


def test_gnc_inner_tolerance_decides_as_a_tight_one(monkeypatch):
    """GNC's inner solves at ``GNC_INNER_TOL`` switch off the same factors as at 1e-6 (the weights end
    binary), so the re-solved graph and its solution are the same: two wrong matches and a gross
    GNSS fix among consistent ones, several seeds."""
    import graphnav.graph.gnc as gnc

    for seed in range(4):
        g, groups, values = _outlier_chain(seed)
        out = {}
        for tol in (1e-6, gnc.GNC_INNER_TOL):
            monkeypatch.setattr(gnc, "GNC_INNER_TOL", tol)
            out[tol] = switch_off(g, values, list(groups), LmSettings(1e-10, 100))
        _decided_alike(g, *out.values())


def test_gnc_schedules_decide_alike():
    """GNC with the superlinear schedule of ``mu`` switches off the same factors as the GNC paper's linear one
    (and the same as the known wrong ones): two wrong matches and a gross GNSS fix among consistent ones,
    several seeds; the re-solved graphs and solutions are equal."""
    for seed in range(4):
        g, groups, values = _outlier_chain(seed)
        r = _decided_alike(g, *(switch_off(g, values, list(groups), LmSettings(1e-10, 100), schedule=s)
                                for s in ("linear", "superlinear")))
        assert r["switched_off"].get("gnss", 0) == 1
    with pytest.raises(KeyError):
        switch_off(g, values, list(groups), LmSettings(1e-10, 100), schedule="quadratic")
    assert set(SCHEDULES) == set(GNC_SCHEDULE)  # every name the option accepts is a schedule GNC knows
