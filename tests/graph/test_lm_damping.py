"""LM's damping update (``LmSettings.adaptive``, the ``lm_damping`` option): Nielsen's update from the gain ratio
reaches the same minimum as GTSAM's fixed x10 / 0.1 factor, in fewer iterations along a curved valley, the shape
where the fixed factor crawls (docs/smoother.md, *The closing step's stall rule*)."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from graphnav.graph.smoother_config import SmootherConfig
from graphnav.graph.solver import LmSettings, levenberg_marquardt


def _rosenbrock(a: float) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """Rosenbrock's function as least squares, ``(a (y - x^2))^2 + (1 - x)^2``: minimum 0 at (1, 1), reached from
    the classic start (-1.2, 1) along a parabolic valley whose walls steepen with ``a``."""

    def error(_f: gtsam.CustomFactor, values: gtsam.Values, jac: list[np.ndarray] | None) -> np.ndarray:
        x, y = values.atVector(0)
        if jac is not None:
            jac[0] = np.array([[-2.0 * a * x, a], [-1.0, 0.0]])
        return np.array([a * (y - x * x), 1.0 - x])

    g = gtsam.NonlinearFactorGraph()
    g.add(gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(2), [0], error))
    v = gtsam.Values()
    v.insert(0, np.array([-1.2, 1.0]))
    return g, v


@pytest.mark.parametrize("a", [10.0, 100.0, 1000.0])
def test_nielsen_reaches_the_minimum_in_fewer_iterations(a: float):
    g, v = _rosenbrock(a)
    fixed, it_fixed = levenberg_marquardt(g, v, LmSettings(1e-14, 5000, 0.0, adaptive=False))
    nielsen, it_nielsen = levenberg_marquardt(g, v, LmSettings(1e-14, 5000, 0.0, adaptive=True))
    for values in (fixed, nielsen):
        np.testing.assert_allclose(values.atVector(0), [1.0, 1.0], atol=1e-6)
    assert it_nielsen < 0.8 * it_fixed < 5000


def test_the_option_chooses_the_update():
    assert SmootherConfig().optimizer.lm_damping == "nielsen"
    with pytest.raises(ValueError, match="lm_damping"):
        SmootherConfig.from_options({"lm_damping": "marquardt"})
