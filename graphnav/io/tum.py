"""TUM trajectory files (``t x y z qx qy qz qw``, read by evo): a whole :class:`Trajectory` written
atomically or read back; estimates appended as they are computed (flushed), so an interrupted run keeps
them; a log's truth beside the estimates (``truth.tum``)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..log import NavLog
from ..trajectory import Trajectory
from .outputs import OutDir, atomic_path

#: the first line of every TUM file written here (np.savetxt's header form)
HEADER = "# timestamp tx ty tz qx qy qz qw\n"


def write_tum(traj: Trajectory, path: str | Path) -> None:
    """Write ``traj`` as TUM ``t x y z qx qy qz qw`` (z = 0, rotation about +z; the quaternion by
    :class:`scipy.spatial.transform.Rotation`, scalar last), whole or not at all."""
    arr = np.column_stack([traj.t, traj.x, traj.y, np.zeros(len(traj)), yaw_to_quat(traj.yaw)])
    with atomic_path(path) as tmp, open(tmp, "w", encoding="ascii", newline="\n") as fh:
        fh.write(HEADER)
        for text in table_lines(arr, "%.9f"):
            fh.write(text)


def table_lines(arr: NDArray[np.float64], fmt: str, rows: int = 20_000) -> Iterator[str]:
    """The lines ``np.savetxt(f, arr, fmt)`` writes (``fmt`` for every column, one space between), by
    blocks of ``rows`` rows formatted at once: a Python format call per block, not per row
    (``savetxt`` spent ~1 s on a harbour compare's 410 868 poses)."""
    line = " ".join([fmt] * arr.shape[1]) + "\n"
    for i in range(0, len(arr), rows):
        block = arr[i:i + rows]
        yield (line * len(block)) % tuple(block.ravel().tolist())


def read_tum(path: str | Path, name: str = "") -> Trajectory:
    """Read a TUM file written by :func:`write_tum` (or any TUM trajectory: its yaw, the rotation's
    first intrinsic Z-Y'-X'' angle); ``name`` defaults to the file's stem."""
    arr = np.loadtxt(path, comments="#", ndmin=2)
    return Trajectory(arr[:, 0], np.column_stack([arr[:, 1], arr[:, 2], quat_to_yaw(arr[:, 4:8])]),
                      name=name or Path(path).stem)


class TrajectoryWriter:
    """``write(t, pose, cov)`` appends one TUM line and flushes; usable as an ``on_estimate`` callback.

    A sidecar ``<name>.cov`` holds ``t`` and the 9 covariance entries when covariances are given.
    ``exclusive``: never replace an existing file (:class:`FileExistsError` instead).
    """

    def __init__(self, path: str | Path, *, exclusive: bool = False) -> None:
        self.path = Path(path)
        self._mode = "x" if exclusive else "w"
        self._fh = open(self.path, self._mode, buffering=1)
        self._fh.write(HEADER)
        self._cov = None
        self.count = 0

    def write(self, t: float, pose: np.ndarray, cov: np.ndarray | None = None) -> None:
        x, y, yaw = (float(v) for v in pose)
        # the quaternion of yaw_to_quat (scipy's Rotation, as write_tum writes), in
        # closed form (0, 0, sin(yaw/2), cos(yaw/2)): scipy costs ~0.1 ms a call, once per estimate here
        # (tests/io/test_tum.py checks the two agree)
        self._fh.write(f"{t:.9f} {x:.9f} {y:.9f} 0 0 0 {np.sin(yaw / 2):.9f} {np.cos(yaw / 2):.9f}\n")
        self._fh.flush()
        if cov is not None:
            if self._cov is None:
                self._cov = open(self.path.with_suffix(".cov"), self._mode, buffering=1)
            self._cov.write(f"{t:.9f} " + " ".join(f"{v:.9g}" for v in np.asarray(cov).ravel()) + "\n")
            self._cov.flush()
        self.count += 1

    def close(self) -> None:
        self._fh.close()
        if self._cov is not None:
            self._cov.close()

    def __enter__(self) -> TrajectoryWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def write_truth(log: NavLog, out: str | Path | OutDir) -> Path | None:
    """``out/truth.tum``: the log's truth in TUM, as the estimates are written (atomically, by
    :func:`write_tum`), so ``evo_ape tum truth.tum <estimate>.tum`` needs
    nothing hand-made; ``None`` (nothing written) when the log has no truth. An
    :class:`~graphnav.io.outputs.OutDir` records the name in its manifest first."""
    if not log.has_truth:
        return None
    p = out.file("truth.tum") if isinstance(out, OutDir) else Path(out) / "truth.tum"
    write_tum(log.truth(), p)
    return p


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
