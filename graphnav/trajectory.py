"""The one trajectory type every estimator returns, and its TUM/CSV export."""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .geometry import wrap_angle


@dataclass
class Trajectory:
    """Time-stamped SE(2) poses with optional 3x3 covariances.

    ``t`` (N,) seconds, ``poses`` (N, 3) as (x [m], y [m], yaw [rad, CCW from east]),
    ``cov`` (N, 3, 3) in the order (x, y, yaw) in the local (world) frame, or ``None``.
    """

    t: NDArray[np.float64]
    poses: NDArray[np.float64]
    cov: NDArray[np.float64] | None = None
    name: str = ""
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, dtype=float).reshape(-1)
        self.poses = np.asarray(self.poses, dtype=float).reshape(-1, 3)
        if self.poses.shape[0] != self.t.shape[0]:
            raise ValueError(f"{self.t.shape[0]} times but {self.poses.shape[0]} poses")
        if self.cov is not None:
            self.cov = np.asarray(self.cov, dtype=float).reshape(-1, 3, 3)
            if self.cov.shape[0] != self.t.shape[0]:
                raise ValueError(f"{self.t.shape[0]} times but {self.cov.shape[0]} covariances")

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def x(self) -> NDArray[np.float64]:
        return self.poses[:, 0]

    @property
    def y(self) -> NDArray[np.float64]:
        return self.poses[:, 1]

    @property
    def yaw(self) -> NDArray[np.float64]:
        return self.poses[:, 2]

    # -- short summaries (the dataclass repr would print every pose) ------------------------------------
    def _facts(self) -> dict[str, str]:
        n = len(self)
        out = {"poses": str(n), "time": f"{self.t[0]:.2f}–{self.t[-1]:.2f} s" if n else "empty"}
        if n:
            out["path length"] = f"{float(np.sum(np.hypot(np.diff(self.x), np.diff(self.y)))):.1f} m"
            out["x range"] = f"{self.x.min():.1f} … {self.x.max():.1f} m"
            out["y range"] = f"{self.y.min():.1f} … {self.y.max():.1f} m"
        out["covariance"] = "yes" if self.cov is not None else "no"
        return out

    def __repr__(self) -> str:
        f = self._facts()
        name = f" {self.name[:40]!r}" if self.name else ""
        cov = ", with covariance" if self.cov is not None else ""
        length = f", {f['path length']}" if "path length" in f else ""
        return f"<Trajectory{name}: {f['poses']} poses, {f['time']}{length}{cov}>"

    def _repr_html_(self) -> str:
        """A small table for notebooks."""
        from html import escape

        rows = "".join(f"<tr><th>{k}</th><td>{escape(v)}</td></tr>" for k, v in self._facts().items())
        return f"<b>Trajectory</b> {escape(self.name)}<table>{rows}</table>"

    def interpolate(self, times: ArrayLike) -> NDArray[np.float64]:
        """Poses at ``times``: linear in x/y, shortest-arc linear in yaw; clamped at the ends."""
        times = np.asarray(times, dtype=float)
        x = np.interp(times, self.t, self.x)
        y = np.interp(times, self.t, self.y)
        uw = np.unwrap(self.yaw)
        yaw = wrap_angle(np.interp(times, self.t, uw))
        return np.column_stack([x, y, np.atleast_1d(yaw)])

    def subset(self, idx: ArrayLike) -> Trajectory:
        """The poses at the given indices (or boolean mask)."""
        cov = None if self.cov is None else self.cov[idx]
        return Trajectory(self.t[idx], self.poses[idx], cov, self.name, dict(self.meta))

    # -- export / import -------------------------------------------------------------------------
    def to_tum(self, path: str | Path) -> None:
        """Write TUM format ``t x y z qx qy qz qw`` (z = 0, rotation about +z; the quaternion by
        :class:`scipy.spatial.transform.Rotation`, scalar last) — evo reads it."""
        from .io.outputs import atomic_path

        arr = np.column_stack([self.t, self.x, self.y, np.zeros(len(self)), yaw_to_quat(self.yaw)])
        with atomic_path(path) as tmp:  # written whole or not at all
            np.savetxt(tmp, arr, fmt="%.9f", header="timestamp tx ty tz qx qy qz qw")

    @classmethod
    def from_tum(cls, path: str | Path, name: str = "") -> Trajectory:
        """Read a TUM file written by :meth:`to_tum` (or any TUM trajectory: its yaw, the rotation's
        first intrinsic Z-Y'-X'' angle)."""
        arr = np.loadtxt(path, comments="#", ndmin=2)
        return cls(arr[:, 0], np.column_stack([arr[:, 1], arr[:, 2], quat_to_yaw(arr[:, 4:8])]),
                   name=name or Path(path).stem)

    def to_csv(self, path: str | Path) -> None:
        """Write CSV ``t,x,y,yaw`` plus the 6 unique covariance entries when present (atomically), every
        value at full precision (the shortest text that reads back to the same float: POSIX times keep
        their microseconds)."""
        from .io.outputs import atomic_open

        cols = ["t", "x", "y", "yaw"]
        if self.cov is not None:
            cols += ["cov_xx", "cov_xy", "cov_xyaw", "cov_yy", "cov_yyaw", "cov_yawyaw"]
        with atomic_open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(cols)
            for i in range(len(self)):
                row = [self.t[i], *self.poses[i]]
                if self.cov is not None:
                    c = self.cov[i]
                    row += [c[0, 0], c[0, 1], c[0, 2], c[1, 1], c[1, 2], c[2, 2]]
                w.writerow([repr(float(v)) for v in row])

    @classmethod
    def from_csv(cls, path: str | Path, name: str = "") -> Trajectory:
        """Read a CSV written by :meth:`to_csv`."""
        with open(path, newline="") as fh:
            rows = list(csv.reader(fh))
        head, body = rows[0], np.array(rows[1:], dtype=float).reshape(-1, len(rows[0]))
        cov = None
        if "cov_xx" in head:
            xx, xy, xa, yy, ya, aa = (body[:, head.index(k)] for k in
                                      ("cov_xx", "cov_xy", "cov_xyaw", "cov_yy", "cov_yyaw", "cov_yawyaw"))
            cov = np.stack([np.stack([xx, xy, xa], -1), np.stack([xy, yy, ya], -1),
                            np.stack([xa, ya, aa], -1)], axis=1)
        return cls(body[:, 0], body[:, 1:4], cov, name=name or Path(path).stem)


def yaw_to_quat(yaw: ArrayLike) -> NDArray[np.float64]:
    """Yaw [rad] -> unit quaternions ``(qx, qy, qz, qw)`` of the rotation about +z, shape (N, 4)."""
    from scipy.spatial.transform import Rotation

    yaw = np.atleast_1d(np.asarray(yaw, dtype=float))
    if yaw.size == 0:
        return np.empty((0, 4))
    return Rotation.from_euler("z", yaw.reshape(-1, 1)).as_quat()


def quat_to_yaw(q: ArrayLike) -> NDArray[np.float64]:
    """Quaternions ``(qx, qy, qz, qw)`` (N, 4) -> yaw [rad]: the first angle of the intrinsic Z-Y'-X''
    decomposition (for a planar rotation, the rotation angle about +z). A zero quaternion raises
    ValueError (scipy)."""
    from scipy.spatial.transform import Rotation

    q = np.asarray(q, dtype=float).reshape(-1, 4)
    if q.shape[0] == 0:
        return np.empty(0)
    return Rotation.from_quat(q).as_euler("ZYX")[:, 0]
