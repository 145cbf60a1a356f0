"""Reader of the UTIAS MRCLAM datasets (Leung et al., IJRR 2011): one robot of a dataset directory.

Files (each ``.dat`` or ``.dat.gz``; ``#`` lines are comments; columns blank/tab separated):

* ``RobotN_Odometry.dat``: time [s], forward velocity v [m/s], angular velocity w [rad/s]
  -> :class:`~graphnav.log.Odometry` ``(t, v, w)`` with **no sigmas** (the dataset gives none).
* ``RobotN_Measurement.dat``: time [s], barcode, range [m], bearing [rad] (the file's header says
  "Subject #", but the column holds barcodes). A barcode that ``Barcodes.dat`` maps to a landmark
  (a subject listed in ``Landmark_Groundtruth.dat``) -> :class:`~graphnav.log.BeaconObs` with
  ``id`` = the landmark's subject number and no sigmas. Sightings of the other robots' barcodes
  and of barcodes not in ``Barcodes.dat`` are dropped and counted in ``meta["dropped"]``.
* ``RobotN_Groundtruth.dat``: time [s], x [m], y [m], orientation [rad] (Vicon) ->
  :class:`~graphnav.log.Truth`, and one :class:`~graphnav.log.PosePrior` at the first truth pose
  with sigma :data:`PRIOR_SIGMA` (m and rad) -- the one stated sigma, it anchors the frame.
* ``Landmark_Groundtruth.dat``: subject, x, y, x std-dev, y std-dev [m]. The landmark positions
  always go to ``meta["landmarks"]`` (for map scoring). With ``charted=True`` they are also
  written as :class:`~graphnav.log.KnownBeacon` with sigma = the larger of the two std-devs
  (the log model has one sigma per beacon); by default they are not, so the estimator has to
  map them (SLAM), as in the dataset's intended use.
* ``Barcodes.dat``: subject -> barcode. Subjects that are not landmarks are robots.

Times stay POSIX seconds. Each file must be in non-decreasing time order. A malformed line raises
:class:`~graphnav.errors.LogError` naming the file, line and field; ``lenient=True`` skips and
counts it (``meta["skipped"]``, first messages in ``meta["skipped_errors"]``).
"""

from __future__ import annotations

import gzip
import math
import zlib
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..errors import LogError
from ..geometry import wrap_angle
from ..log import BeaconObs, KnownBeacon, Limits, NavLog, Odometry, PosePrior, Record, Truth, check_record

PRIOR_SIGMA = 0.01
COLUMNS = {
    "Barcodes": ("subject", "barcode"),
    "Landmark_Groundtruth": ("subject", "x", "y", "x_std", "y_std"),
    "Odometry": ("time", "v", "w"),
    "Measurement": ("time", "barcode", "range", "bearing"),
    "Groundtruth": ("time", "x", "y", "orientation"),
}


def find_file(directory: Path, stem: str) -> Path:
    """``DIR/stem.dat`` or ``DIR/stem.dat.gz`` (LogError naming the first when neither exists)."""
    for name in (f"{stem}.dat", f"{stem}.dat.gz"):
        if (directory / name).is_file():
            return directory / name
    raise LogError("not found (nor its .gz)", file=str(directory / f"{stem}.dat"))


def is_mrclam_dir(path: str | Path) -> bool:
    p = Path(path)
    try:
        find_file(p, "Barcodes")
        find_file(p, "Landmark_Groundtruth")
    except LogError:
        return False
    return True


def robots(directory: str | Path) -> list[int]:
    """Robot numbers N with a ``RobotN_Odometry`` file in the directory."""
    out = []
    for p in Path(directory).glob("Robot*_Odometry.dat*"):
        head = p.name[len("Robot"):].split("_")[0]
        if head.isdigit():
            out.append(int(head))
    return sorted(set(out))


class _Table:
    """Rows of one whitespace-separated file as floats, with per-line error handling."""

    def __init__(self, path: Path, columns: tuple[str, ...], *, lenient: bool, skipped: list[str]) -> None:
        self.path, self.columns, self.lenient, self.skipped = path, columns, lenient, skipped

    def bad(self, err: LogError, lineno: int) -> None:
        err = err.located(file=str(self.path), line=lineno)
        if not self.lenient:
            raise err from None
        self.skipped.append(str(err))

    def rows(self) -> Iterator[tuple[int, list[float]]]:
        """(line number, values) per data line, streamed; bad lines are raised or counted."""
        lineno = 0
        try:
            opener = gzip.open if self.path.name.endswith(".gz") else open
            with opener(self.path, "rb") as fh:
                for raw in fh:
                    lineno += 1
                    try:
                        vals = self._parse(raw)
                    except LogError as err:
                        self.bad(err, lineno)
                        continue
                    if vals is not None:
                        yield lineno, vals
        except (OSError, EOFError, zlib.error) as exc:
            raise LogError(f"cannot read: {exc}", file=str(self.path), line=lineno + 1 if lineno else None) from None

    def _parse(self, raw: bytes) -> list[float] | None:
        try:
            s = raw.decode("ascii").strip()
        except UnicodeDecodeError:
            raise LogError("non-ASCII bytes", field=self.columns[0]) from None
        if not s or s.startswith("#"):
            return None
        tok = s.split()
        if len(tok) != len(self.columns):
            field = self.columns[len(tok)] if len(tok) < len(self.columns) else self.columns[-1]
            raise LogError(f"expected {len(self.columns)} columns ({', '.join(self.columns)}), got {len(tok)}",
                           field=field)
        out = []
        for name, t in zip(self.columns, tok, strict=True):
            try:
                v = float(t)
            except ValueError:
                raise LogError(f"not a number: {t[:20]!r}", field=name) from None
            if not math.isfinite(v):
                raise LogError(f"not finite: {t[:20]!r}", field=name)
            out.append(v)
        return out


def _yaw(a: float) -> float:
    """``a`` wrapped to [-pi, pi) only when outside it (in-range values stay bit-exact)."""
    return a if -math.pi <= a < math.pi else float(wrap_angle(a))


def _integer(v: float, name: str) -> int:
    if v != int(v) or v < 0:
        raise LogError(f"{v!r} is not a non-negative integer", field=name)
    return int(v)


def read_mrclam(directory: str | Path, robot: int, *, lenient: bool = False, charted: bool = False,
                prior_sigma: float = PRIOR_SIGMA, limits: Limits | None = None) -> NavLog:
    """Read robot ``robot`` of an MRCLAM dataset directory (see the module docstring).

    ``meta`` holds ``robot``, ``landmarks`` ({id: [x, y, x_std, y_std]}), ``sightings_kept``,
    ``dropped`` (``{"robot": {subject: n}, "unknown_barcode": {barcode: n}}``) and, with
    ``lenient``, ``skipped``/``skipped_errors``.
    """
    d = Path(directory)
    if not d.is_dir():
        raise LogError("not a directory", file=str(d))
    if isinstance(robot, bool) or not isinstance(robot, int) or robot < 1:
        raise ValueError(f"robot must be a positive integer, not {robot!r}")
    skipped: list[str] = []

    def table(stem: str, kind: str) -> _Table:
        return _Table(find_file(d, stem), COLUMNS[kind], lenient=lenient, skipped=skipped)

    barcodes: dict[int, int] = {}  # barcode -> subject
    t = table("Barcodes", "Barcodes")
    for lineno, (subj, code) in t.rows():
        try:
            s, c = _integer(subj, "subject"), _integer(code, "barcode")
            if c in barcodes and barcodes[c] != s:
                raise LogError(f"barcode {c} already belongs to subject {barcodes[c]}", field="barcode")
            barcodes[c] = s
        except LogError as err:
            t.bad(err, lineno)
    landmarks: dict[int, tuple[float, float, float, float]] = {}
    t = table("Landmark_Groundtruth", "Landmark_Groundtruth")
    for lineno, (subj, x, y, sx, sy) in t.rows():
        try:
            s = _integer(subj, "subject")
            if sx < 0 or sy < 0:
                raise LogError("a std-dev is negative", field="x_std" if sx < 0 else "y_std")
            if charted and max(sx, sy) <= 0.0:
                raise LogError("both std-devs are 0 (a charted beacon needs sigma > 0)", field="x_std")
            landmarks[s] = (x, y, sx, sy)
        except LogError as err:
            t.bad(err, lineno)
    records: list[Record] = []
    t = table(f"Robot{robot}_Odometry", "Odometry")
    for rec in _timed(t, lambda v: Odometry(v[0], v[1], v[2]), limits):
        records.append(rec)
    dropped_robot: Counter = Counter()
    dropped_unknown: Counter = Counter()
    t = table(f"Robot{robot}_Measurement", "Measurement")
    kept = 0
    for lineno, (tm, code, rng, brg) in _ordered(t):
        try:
            c = _integer(code, "barcode")
            if rng <= 0.0:
                raise LogError(f"range {rng!r} m is not > 0", field="range")
        except LogError as err:
            t.bad(err, lineno)
            continue
        subject = barcodes.get(c)
        if subject is None:
            dropped_unknown[c] += 1
        elif subject not in landmarks:
            dropped_robot[subject] += 1
        else:
            obs = BeaconObs(tm, str(subject), rng, brg)
            try:
                check_record(obs, limits)
            except LogError as err:
                t.bad(err, lineno)
                continue
            records.append(obs)
            kept += 1
    t = table(f"Robot{robot}_Groundtruth", "Groundtruth")
    first: Truth | None = None
    for rec in _timed(t, lambda v: Truth(v[0], v[1], v[2], _yaw(v[3])), limits):
        records.append(rec)
        if first is None:
            first = rec
    if first is not None:
        records.append(PosePrior(first.t, first.x, first.y, first.yaw, prior_sigma, prior_sigma))
    known = [KnownBeacon(str(s), x, y, max(sx, sy)) for s, (x, y, sx, sy) in sorted(landmarks.items())] \
        if charted else []
    meta: dict[str, Any] = {
        "name": f"{d.name}-robot{robot}", "source": str(d), "format": "mrclam", "robot": robot,
        "landmarks": {str(s): list(v) for s, v in sorted(landmarks.items())},
        "sightings_kept": kept,
        "dropped": {"robot": {str(k): v for k, v in sorted(dropped_robot.items())},
                    "unknown_barcode": {str(k): v for k, v in sorted(dropped_unknown.items())}},
        "charted": charted,
    }
    if lenient:
        meta["skipped"] = len(skipped)
        meta["skipped_errors"] = skipped[:20]
    return NavLog.from_unsorted(records, known, meta)


def _ordered(t: _Table) -> Iterator[tuple[int, list[float]]]:
    """Rows whose time (column 0) does not go backwards (a backwards row is an error)."""
    last = -math.inf
    for lineno, vals in t.rows():
        if vals[0] < last:
            t.bad(LogError(f"time goes backwards ({vals[0]!r} after {last!r})", field="time"), lineno)
            continue
        last = vals[0]
        yield lineno, vals


def _timed(t: _Table, make, limits: Limits | None = None) -> Iterator[Record]:
    """Records ``make(values)`` of the rows in time order, each checked by
    :func:`graphnav.log.check_record` (a bad one raised or counted, as a bad line)."""
    for lineno, vals in _ordered(t):
        rec = make(vals)
        try:
            check_record(rec, limits)
        except LogError as err:
            t.bad(err, lineno)
            continue
        yield rec
