"""The factor-graph smoothers (:mod:`graphnav.smoother`) as estimators: ``isam2``, ``batch``, ``fixed-lag``.

Options are the fields of :class:`graphnav.smoother.SmootherConfig` (``-O key=value``).
"""

from __future__ import annotations

from ..smoother import run_batch, run_fixed_lag, run_isam2, unmet
from . import EstimatorSpec

ESTIMATORS = {
    "isam2": EstimatorSpec(
        run_isam2, unmet, "iSAM2 factor-graph smoother: online + smoothed, all sensors", "smoother"
    ),
    "batch": EstimatorSpec(
        run_batch, unmet, "batch Levenberg-Marquardt over the whole factor graph", "smoother"
    ),
    "fixed-lag": EstimatorSpec(
        run_fixed_lag, unmet, "incremental fixed-lag smoother (bounded memory)", "smoother"
    ),
}
