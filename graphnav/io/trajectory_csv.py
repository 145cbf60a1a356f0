"""A :class:`Trajectory` as CSV: ``t,x,y,yaw`` plus the 6 unique covariance entries when present, and a
``coasted`` column (0/1) when the trajectory flags its coasted estimates (``meta["coasted"]``: an online
track's predictions through a gap without records)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..trajectory import Trajectory
from .outputs import atomic_open

COV_COLUMNS = ("cov_xx", "cov_xy", "cov_xyaw", "cov_yy", "cov_yyaw", "cov_yawyaw")


def write_trajectory_csv(traj: Trajectory, path: str | Path) -> None:
    """Write ``traj`` as CSV ``t,x,y,yaw`` (+ :data:`COV_COLUMNS` with covariances), atomically, every value at
    full precision (the shortest text that reads back to the same float: POSIX times keep their microseconds)."""
    coasted = (traj.meta or {}).get("coasted")
    coasted = None if coasted is None or len(coasted) != len(traj) else np.asarray(coasted, bool)
    cols = ["t", "x", "y", "yaw"] + (list(COV_COLUMNS) if traj.cov is not None else []) \
        + (["coasted"] if coasted is not None else [])
    with atomic_open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for i in range(len(traj)):
            row = [traj.t[i], *traj.poses[i]]
            if traj.cov is not None:
                c = traj.cov[i]
                row += [c[0, 0], c[0, 1], c[0, 2], c[1, 1], c[1, 2], c[2, 2]]
            w.writerow([repr(float(v)) for v in row] + ([int(coasted[i])] if coasted is not None else []))


def read_trajectory_csv(path: str | Path, name: str = "") -> Trajectory:
    """Read a CSV written by :func:`write_trajectory_csv`; ``name`` defaults to the file's stem."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    head, body = rows[0], np.array(rows[1:], dtype=float).reshape(-1, len(rows[0]))
    cov = None
    if "cov_xx" in head:
        xx, xy, xa, yy, ya, aa = (body[:, head.index(k)] for k in COV_COLUMNS)
        cov = np.stack([np.stack([xx, xy, xa], -1), np.stack([xy, yy, ya], -1),
                        np.stack([xa, ya, aa], -1)], axis=1)
    meta = {"coasted": body[:, head.index("coasted")] != 0} if "coasted" in head else {}
    return Trajectory(body[:, 0], body[:, 1:4], cov, name=name or Path(path).stem, meta=meta)
