"""USV movement parameters from consecutive scan matches (the weighted-ICP paper, eq. 23-25).

A match gives the relative pose ``(dx, dy, dtheta)`` of scan ``k+1`` in the frame of scan ``k``.
Then ``SOG = |T| / dt`` (eq. 23), ``ROT = dtheta / dt`` (eq. 24; the paper writes
``arcsin`` of the rotation matrix's sine entry, which is ``dtheta`` for |dtheta| < 90 deg),
``HDG = HDG0 + sum dtheta`` (eq. 25) and ``COG`` the direction of the step in the world frame.
All angles are radians, yaw convention (CCW from +x); nautical degrees only at the edges
(:func:`graphnav.geometry.yaw_to_heading_deg`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..geometry import wrap_angle


def movement_from_increments(
    increments: ArrayLike, dt: ArrayLike, hdg0: float = 0.0
) -> dict[str, NDArray[np.float64]]:
    """Movement parameters of ``N`` increments ``(dx, dy, dtheta)`` (N, 3) over intervals ``dt``.

    Returns ``sog`` [m/s] (eq. 23), ``rot`` [rad/s] (eq. 24), ``hdg`` [rad] at the end of each
    interval (eq. 25, starting from ``hdg0``), ``cog`` [rad] (world direction of the step: the
    heading at the interval start plus the step's bearing in the body frame) and ``dtheta``.
    """
    inc = np.atleast_2d(np.asarray(increments, dtype=float))
    dt = np.broadcast_to(np.asarray(dt, dtype=float), (len(inc),))
    dth = np.asarray(wrap_angle(inc[:, 2]), dtype=float).reshape(-1)
    hdg = hdg0 + np.cumsum(dth)
    hdg_start = np.concatenate([[hdg0], hdg[:-1]])
    with np.errstate(divide="ignore", invalid="ignore"):
        sog = np.hypot(inc[:, 0], inc[:, 1]) / dt
        rot = dth / dt
    cog = np.asarray(wrap_angle(hdg_start + np.arctan2(inc[:, 1], inc[:, 0])), dtype=float).reshape(-1)
    return {"sog": sog, "rot": rot, "hdg": np.asarray(wrap_angle(hdg), dtype=float).reshape(-1),
            "cog": cog, "dtheta": dth}
