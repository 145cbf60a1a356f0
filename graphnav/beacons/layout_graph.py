"""Beacon layouts scored by a factor graph's marginal covariance (GTSAM, native factors).

The graph of one passage of the paper's fairway (section 7) is built on the planned (true) track:
poses X0..X200, beacons L1..Li; ``PriorFactorPose2`` on X0 (error-free start, eq. 1-2, as a
1e-6 sigma), ``BetweenFactorPose2`` odometry increments (V dt, 0, ROT dt) with the noise of eq. 4-5
mapped through eq. 3 (sigma_V dt along track, sigma_ROT dt in yaw; a 1e-6 m cross-track sigma
since eq. 3 has no lateral noise), ``BearingRangeFactor2D`` per step and beacon (eq. 6-8) and a
``PriorFactorPoint2`` per beacon with the paper's "infinite" 1e6 m^2 variance (eq. 14). Values sit
on the truth and measurements are noise-free, so the linearisation point is the planned track
(the same choice as the EKF's ``linearize="truth"``).

Two criteria: ``online`` is the iSAM2 marginal of X_k right after step k is added (what the
vessel knows at that moment: the filter's covariance), ``smoothed`` the marginal of X_k given
the whole passage. Both give passage means of M_xy, M_x, M_y (eq. 28-30). The track heads east
(yaw 0), so Pose2's body-frame marginal is also the world-frame one.
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

from .layout import Fairway

X = gtsam.symbol_shorthand.X
L = gtsam.symbol_shorthand.L

TINY = 1e-6


def passage_marginals(layout: NDArray[np.float64], fw: Fairway | None = None) -> dict[str, NDArray]:
    """Position marginals of one layout: ``online`` and ``smoothed``, each (steps, 2) = (P00, P11)
    for k = 1..steps."""
    fw = fw or Fairway()
    track = fw.track()
    odo_noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([fw.sigma_v * fw.dt, TINY, fw.sigma_rot * fw.dt]))
    meas_noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([fw.sigma_bearing, fw.sigma_range]))
    beacon_prior = gtsam.noiseModel.Isotropic.Sigma(2, 1e3)
    params = gtsam.ISAM2Params()
    params.setRelinearizeThreshold(1e9)  # values are the truth and data noise-free: never relinearise
    params.setFactorization("QR")  # 1e6 m^2 beacon priors beside 1e-6 sigmas: too ill-conditioned for LDL
    isam = gtsam.ISAM2(params)
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    graph.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(*track[0]), gtsam.noiseModel.Isotropic.Sigma(3, TINY)))
    values.insert(X(0), gtsam.Pose2(*track[0]))
    for j, (bx, by) in enumerate(layout):
        graph.add(gtsam.PriorFactorPoint2(L(j), np.array([bx, by]), beacon_prior))
        values.insert(L(j), np.array([bx, by], dtype=float))
    isam.update(graph, values)
    online = np.empty((fw.steps, 2))
    for k in range(1, fw.steps + 1):
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        prev, cur = gtsam.Pose2(*track[k - 1]), gtsam.Pose2(*track[k])
        graph.add(gtsam.BetweenFactorPose2(X(k - 1), X(k), prev.between(cur), odo_noise))
        values.insert(X(k), cur)
        for j, (bx, by) in enumerate(layout):
            dx, dy = bx - track[k, 0], by - track[k, 1]
            graph.add(gtsam.BearingRangeFactor2D(X(k), L(j), gtsam.Rot2(np.arctan2(dy, dx) - track[k, 2]),
                                                 float(np.hypot(dx, dy)), meas_noise))
        isam.update(graph, values)
        c = isam.marginalCovariance(X(k))
        online[k - 1] = c[0, 0], c[1, 1]
    smoothed = np.empty((fw.steps, 2))
    for k in range(1, fw.steps + 1):  # after the last update: marginals given the whole passage
        c = isam.marginalCovariance(X(k))
        smoothed[k - 1] = c[0, 0], c[1, 1]
    return {"online": online, "smoothed": smoothed}


def _means(var: NDArray) -> list[float]:
    return [float(np.sqrt(var.sum(axis=1)).mean()), float(np.sqrt(var[:, 0]).mean()),
            float(np.sqrt(var[:, 1]).mean())]


def score_chunk_graph(task: dict[str, Any]) -> dict[str, Any]:
    """Sweep task (see :func:`graphnav.beacons.layout.chunk_tasks`) -> ``scores`` for
    ``task["marginals"]`` (``"online"`` or ``"smoothed"``) plus both, ``scores_online`` and
    ``scores_smoothed``, each a list of [mean_mxy, mean_mx, mean_my]."""
    fw = Fairway(**task.get("fairway", {}))
    on, sm = [], []
    for lay in np.asarray(task["layouts"], dtype=float):
        m = passage_marginals(lay, fw)
        on.append(_means(m["online"]))
        sm.append(_means(m["smoothed"]))
    which = task.get("marginals", "online")
    return {"scores": on if which == "online" else sm, "scores_online": on, "scores_smoothed": sm}
