"""Append estimates to a TUM file as they are computed (flushed), so an interrupted run keeps them;
write a log's truth beside the estimates (``truth.tum``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..log import NavLog
from .outputs import OutDir


class TrajectoryWriter:
    """``write(t, pose, cov)`` appends one TUM line and flushes; usable as an ``on_estimate`` callback.

    A sidecar ``<name>.cov`` holds ``t`` and the 9 covariance entries when covariances are given.
    ``exclusive``: never replace an existing file (:class:`FileExistsError` instead).
    """

    def __init__(self, path: str | Path, *, exclusive: bool = False) -> None:
        self.path = Path(path)
        self._mode = "x" if exclusive else "w"
        self._fh = open(self.path, self._mode, buffering=1)
        self._fh.write("# timestamp tx ty tz qx qy qz qw\n")
        self._cov = None
        self.count = 0

    def write(self, t: float, pose: np.ndarray, cov: np.ndarray | None = None) -> None:
        x, y, yaw = (float(v) for v in pose)
        # the quaternion of trajectory.yaw_to_quat (scipy's Rotation, as Trajectory.to_tum writes), in
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
    :meth:`graphnav.trajectory.Trajectory.to_tum`), so ``evo_ape tum truth.tum <estimate>.tum`` needs
    nothing hand-made; ``None`` (nothing written) when the log has no truth. An
    :class:`~graphnav.io.outputs.OutDir` records the name in its manifest first."""
    if not log.has_truth:
        return None
    p = out.file("truth.tum") if isinstance(out, OutDir) else Path(out) / "truth.tum"
    log.truth().to_tum(p)
    return p
