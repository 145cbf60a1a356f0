"""Robust (M-estimator) wrappers around GTSAM noise models.

``kind`` is ``None``/``"none"`` (plain Gaussian), ``"huber"`` (default threshold 1.345, the 95 %
efficiency constant) or ``"cauchy"`` (default 2.385). Thresholds are on the whitened error.
"""

from __future__ import annotations

import gtsam

DEFAULT_K = {"huber": 1.345, "cauchy": 2.3849}


def robustify(
    noise: gtsam.noiseModel.Base, kind: str | None, k: float | None = None
) -> gtsam.noiseModel.Base:
    """Wrap ``noise`` in a robust model of ``kind`` (or return it unchanged for ``None``)."""
    if kind is None or kind == "none":
        return noise
    kind = kind.lower()
    if kind not in DEFAULT_K:
        raise ValueError(f"unknown robust kernel {kind!r}; use 'huber', 'cauchy' or None")
    k = DEFAULT_K[kind] if k is None else float(k)
    est = (
        gtsam.noiseModel.mEstimator.Huber if kind == "huber" else gtsam.noiseModel.mEstimator.Cauchy
    ).Create(k)
    return gtsam.noiseModel.Robust.Create(est, noise)
