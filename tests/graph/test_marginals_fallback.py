"""graph.solver.marginals: where GTSAM's Cholesky ``Marginals`` finds the system indeterminate for one
key (as it did for one velocity of a 2.7 h real sailing log with GNSS withheld, after thousands of
others), that key and every later one come from the QR-factorised iSAM2 tree of the same graph, with
the same covariance; where QR fails too, a SolverError (a clear error, not an internal one)."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from graphnav.graph import solver as S


def _chain(n: int = 6) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    g, v = gtsam.NonlinearFactorGraph(), gtsam.Values()
    g.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(0, 0, 0), gtsam.noiseModel.Diagonal.Sigmas([0.1, 0.1, 0.01])))
    for k in range(n):
        v.insert(k, gtsam.Pose2(1.0 * k, 0.1 * k, 0.05 * k))
        if k:
            g.add(gtsam.BetweenFactorPose2(k - 1, k, gtsam.Pose2(1.0, 0.1, 0.05),
                                           gtsam.noiseModel.Diagonal.Sigmas([0.2, 0.1, 0.02])))
    return g, v


class _FailsFor:
    """gtsam.Marginals whose marginalCovariance raises GTSAM's RuntimeError for one key."""

    calls: list[int] = []

    def __init__(self, bad: int, graph, values):  # noqa: ANN001
        self.bad, self.m = bad, _REAL(graph, values)

    def marginalCovariance(self, key: int):  # noqa: N802, ANN201
        _FailsFor.calls.append(key)
        if key == self.bad:
            raise RuntimeError("Indeterminate linear system detected while working near variable")
        return self.m.marginalCovariance(key)


_REAL = gtsam.Marginals


def test_one_indeterminate_key_falls_back_to_qr_for_it_and_later_keys(monkeypatch):
    g, v = _chain()
    truth = {k: np.asarray(_REAL(g, v).marginalCovariance(k)) for k in range(6)}
    _FailsFor.calls = []
    monkeypatch.setattr(S.gtsam, "Marginals", lambda graph, values: _FailsFor(3, graph, values))
    m = S.marginals(g, v)
    got = {k: m(k) for k in range(6)}
    for k in range(6):
        np.testing.assert_allclose(got[k], truth[k], rtol=1e-8, atol=1e-12)
    assert _FailsFor.calls == [0, 1, 2, 3]  # after the failure, the Cholesky marginals are not asked again
    assert not np.allclose(truth[5], truth[1])  # the keys' covariances differ: each key's own was returned


def test_qr_failing_too_is_a_solver_error(monkeypatch):
    g, v = _chain()
    g0, v0 = _chain()  # the fake's Cholesky marginals answer the well-posed keys
    v.insert(99, gtsam.Pose2())  # a variable no factor constrains: no factorisation can give its marginal
    g.add(gtsam.BetweenFactorPose2(99, 98, gtsam.Pose2(), gtsam.noiseModel.Isotropic.Sigma(3, 1e-9)))
    v.insert(98, gtsam.Pose2())  # two variables tied to each other only: indeterminate as a pair
    monkeypatch.setattr(S.gtsam, "Marginals", lambda graph, values: _FailsFor(99, g0, v0))
    m = S.marginals(g, v)
    assert m(0).shape == (3, 3)
    with pytest.raises(S.SolverError):
        m(99)
