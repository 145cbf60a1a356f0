"""GNSS fix -> ``PoseTranslationPrior2D`` on a pose key, robust by default (multipath jumps)."""

from __future__ import annotations

import gtsam
import numpy as np

from .robust import robustify


def gnss_factor(
    key: int, x: float, y: float, sigma: float, *, robust: str | None = "huber", k: float | None = None
) -> gtsam.PoseTranslationPrior2D:
    """Position prior ``(x, y)`` [m] with isotropic ``sigma`` [m], wrapped in a robust kernel."""
    noise = robustify(gtsam.noiseModel.Isotropic.Sigma(2, float(sigma)), robust, k)
    return gtsam.PoseTranslationPrior2D(key, np.array([x, y], dtype=float), noise)
