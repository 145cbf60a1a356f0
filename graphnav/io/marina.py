"""Reader of the weighted-ICP paper's marina dataset (``ranges.mat``, ``angles.mat``, ``gps.mat``).

What the files hold and how it is interpreted (verified on the data; see docs/datasets.md):

* ``ranges_baza``/``angles_baza`` (750 x 177): one column per scan, NaN or 0 = no return.
  Scans are about 1 s apart (the paper's 0.2 s recording, every 5th scan kept); there are no
  time stamps, so scan ``k`` is stamped ``t = k * dt`` with ``dt = 1.0`` s.
* ``slam_pose`` (177 x 3): columns 1-2 are along-track/cross-track steps summed *without
  rotation* (not a world track); column 3 is the yaw relative to the start plus 3*pi/2,
  increasing with left turns (CCW, the LiDAR's sense).
* Reference row ``j`` belongs to scan ``j + 1`` (the reference yaw increments lead the
  LiDAR's by one index at every turn). So scans 1..176 have a reference (176 ``truth``
  records) and scan 0 has none; the last reference row (176) has no scan and is dropped.

The world track is rebuilt by rotating each reference step by the yaw at its start. The local
frame has its origin at the first reference position and +x along the initial heading
(initial yaw 0); it is not geo-referenced.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import LogError
from ..geometry import wrap_angle
from ..log import Limits, NavLog, Record, Scan, Truth, check_record

MARINA_DT = 1.0
YAW_OFFSET = 1.5 * np.pi
FILES = {"ranges.mat": "ranges_baza", "angles.mat": "angles_baza", "gps.mat": "slam_pose"}


def is_marina_dir(path: str | Path) -> bool:
    p = Path(path)
    return p.is_dir() and all((p / f).exists() for f in FILES)


def _load(path: Path, fname: str, var: str) -> NDArray[np.float64]:
    from scipy.io import loadmat

    try:
        m = loadmat(path / fname)
    except Exception as exc:  # scipy raises several types for corrupt files
        raise LogError(f"cannot read MATLAB file: {exc}", file=str(path / fname)) from None
    if var not in m:
        raise LogError(f"variable '{var}' not found", file=str(path / fname), field=var)
    return np.asarray(m[var], dtype=float)


def reference_world_track(slam_pose: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rebuild world poses (x, y, yaw) from the raw ``slam_pose`` rows.

    Step ``j -> j+1`` of the raw x/y is expressed in the vessel frame at row ``j``; it is
    rotated by the yaw at row ``j`` (column 3 minus 3*pi/2) and summed.
    """
    yaw = wrap_angle(slam_pose[:, 2] - YAW_OFFSET)
    steps = np.diff(slam_pose[:, :2], axis=0)
    c, s = np.cos(yaw[:-1]), np.sin(yaw[:-1])
    world = np.column_stack([c * steps[:, 0] - s * steps[:, 1], s * steps[:, 0] + c * steps[:, 1]])
    xy = np.vstack([[0.0, 0.0], np.cumsum(world, axis=0)]) + slam_pose[0, :2]
    return np.column_stack([xy, yaw])


def read_marina(path: str | Path, *, dt: float = MARINA_DT, limits: Limits | None = None) -> NavLog:
    """Read the marina directory into a log of 177 scans and 176 ``truth`` records (each checked by
    :func:`graphnav.log.check_record`; an invalid one is a LogError naming the file and column)."""
    path = Path(path)
    if not path.is_dir():
        raise LogError("not a directory", file=str(path))
    ranges = _load(path, "ranges.mat", "ranges_baza")
    angles = _load(path, "angles.mat", "angles_baza")
    ref = _load(path, "gps.mat", "slam_pose")
    if ranges.shape != angles.shape:
        raise LogError(f"shape {ranges.shape} differs from angles {angles.shape}",
                       file=str(path / "ranges.mat"), field="ranges_baza")
    if ref.ndim != 2 or ref.shape[1] != 3 or ref.shape[0] != ranges.shape[1]:
        raise LogError(f"expected {ranges.shape[1]} x 3, got {ref.shape}", file=str(path / "gps.mat"),
                       field="slam_pose")
    if ranges.ndim != 2 or ranges.shape[1] == 0:
        raise LogError("no scans", file=str(path / "ranges.mat"), field="ranges_baza")
    if not np.all(np.isfinite(ref)):
        raise LogError("non-finite reference values", file=str(path / "gps.mat"), field="slam_pose")
    n = ranges.shape[1]
    world = reference_world_track(ref)
    keep = np.isfinite(angles)  # rows past a scan's length are NaN in both arrays
    angle_cols = [angles[keep[:, k], k] for k in range(n)]  # copies; each matrix is let go once copied,
    del angles  # so the peak holds one matrix fewer (benchmarks/reader_memory.py)
    range_cols = [ranges[keep[:, k], k] for k in range(n)]
    del ranges
    records: list[Record] = []
    for k in range(n):
        records.append(Scan(k * dt, range_cols[k], angle_cols[k]))
        if k >= 1:
            x, y, yaw = world[k - 1]
            records.append(Truth(k * dt, float(x), float(y), float(yaw)))
        for rec in records[-2:] if k >= 1 else records[-1:]:
            try:
                check_record(rec, limits)
            except LogError as err:
                if isinstance(rec, Scan):  # scan k is column k + 1 of ranges_baza, its truth row k of slam_pose
                    fname, var, where = "ranges.mat", "ranges_baza", f"column {k + 1}"
                else:
                    fname, var, where = "gps.mat", "slam_pose", f"row {k}"
                raise LogError(f"{where}: {err.message}", file=str(path / fname), field=f"{var}/{err.field}") from None
    meta = {
        "name": "marina",
        "source": str(path),
        "dt": dt,
        "frame": "origin at the first reference position, +x along the initial heading; not geo-referenced",
        "reference": "slam_pose row j -> scan j+1, rebuilt as a world track (graphnav.io.marina)",
    }
    return NavLog(records, [], meta)
