"""The one trajectory type every estimator returns (its TUM and CSV files: :mod:`graphnav.io.tum`,
:mod:`graphnav.io.trajectory_csv`)."""

from __future__ import annotations

from dataclasses import dataclass, field

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
