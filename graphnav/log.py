"""The navigation log: one typed, time-ordered list of measurement records.

Every estimator reads a :class:`NavLog` and returns a :class:`graphnav.trajectory.Trajectory`.
Units are SI; angles are radians; yaw and bearings are counter-clockwise (yaw from +x = east,
bearings from the bow). See docs/log-format.md for the text form of every record.
"""

from __future__ import annotations

import itertools
import math
import operator
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import MISSING, dataclass, field, fields
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from .errors import LogError

_KIND = operator.attrgetter("kind")  # a record's kind (its class's), for counting

#: Maximum range [m] of a scan whose log states none: a return beyond it is a missing return.
#: Above the rated range of the 2D LiDARs used on vessels and indoors (Scanse Sweep 40 m, Hokuyo
#: UTM-30LX 30 m, SICK LMS1xx 20-50 m / LMS5xx 80 m, Velodyne VLP-16 100 m), so it drops no real
#: return of theirs, and small enough to bound the scan matcher's work (docs/log-format.md).
DEFAULT_MAX_RANGE = 200.0
#: Largest ``range_max`` a log may state [m] (long-range survey LiDARs reach ~2 km; 10 km is none's).
MAX_STATED_RANGE = 1e4


@dataclass(frozen=True, slots=True)
class Scan:
    """A 2D LiDAR scan in polar form (sensor frame = body frame, x forward, CCW angles).

    ``ranges`` [m] and ``angles`` [rad] have equal length; NaN, inf, ``<= 0`` ranges and ranges
    beyond the sensor's maximum are missing returns (kept, so the beam layout survives a round
    trip). ``range_max`` [m] is the sensor's stated maximum range (NaN: not stated, then
    :data:`DEFAULT_MAX_RANGE` applies).
    """

    t: float
    ranges: NDArray[np.float64]
    angles: NDArray[np.float64]
    range_max: float = math.nan
    kind: ClassVar[str] = "scan"

    @property
    def max_range(self) -> float:
        """The maximum range in force [m]: ``range_max`` when stated, else :data:`DEFAULT_MAX_RANGE`."""
        return self.range_max if math.isfinite(self.range_max) else DEFAULT_MAX_RANGE

    def valid(self) -> NDArray[np.bool_]:
        """Mask of real returns (finite, > 0 and <= :attr:`max_range`)."""
        r = self.ranges
        with np.errstate(invalid="ignore"):
            return np.isfinite(r) & (r > 0.0) & (r <= self.max_range)


#: Most points a ``cloud`` record may hold: above an Ouster OS2-128 frame (262 144 points) and a
#: Velodyne HDL-64 frame (~130 000) with room to spare; bounds what a reader allocates per record.
MAX_CLOUD_POINTS = 2_000_000
#: Largest ``ring`` (laser channel) index of a cloud point (the largest sensors have 128 channels).
MAX_RING = 1023


@dataclass(frozen=True, slots=True)
class Cloud:
    """A 3D LiDAR point cloud in the **sensor frame** (docs/conventions.md, "3D point clouds").

    ``points`` (N, 3) float32 [m]: x forward, y left, z up of the sensor as mounted, i.e. tilted
    with the vessel's roll and pitch (nothing is levelled in the record); only real returns (finite).
    ``intensity`` (N,) float32 (the sensor's unit) and ``ring`` (N,) uint16 (laser channel, 0 = the
    lowest beam) are optional (``None``). ``roll``, ``pitch`` [rad] are the sensor's attitude at ``t``
    (an AHRS's, REP-103: roll right-handed about x, pitch about y, bow down positive) when known, else
    NaN; the 3D matcher levels the cloud with them.
    """

    t: float
    points: NDArray[np.float32]
    intensity: NDArray[np.float32] | None = None
    ring: NDArray[np.uint16] | None = None
    roll: float = math.nan
    pitch: float = math.nan
    kind: ClassVar[str] = "cloud"

    def __len__(self) -> int:
        return int(self.points.shape[0])


def make_cloud(t: float, points, intensity=None, ring=None, roll: float = math.nan,
               pitch: float = math.nan) -> Cloud:
    """A :class:`Cloud` with its arrays converted to the record's dtypes (float32 / uint16)."""
    with np.errstate(over="ignore"):  # beyond float32: inf, which check_record refuses
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float32).reshape(-1, 3))
        inten = None if intensity is None else np.ascontiguousarray(np.asarray(intensity, dtype=np.float32).ravel())
    rg = None
    if ring is not None:
        try:
            r = np.asarray(ring).ravel()
        except (OverflowError, ValueError, TypeError):
            raise LogError(f"ring must hold integers in [0, {MAX_RING}]", field="ring") from None
        if r.size and (not np.issubdtype(r.dtype, np.integer) or r.min() < 0 or r.max() > MAX_RING):
            raise LogError(f"ring must hold integers in [0, {MAX_RING}]", field="ring")
        rg = np.ascontiguousarray(r.astype(np.uint16))
    return Cloud(float(t), pts, inten, rg, float(roll), float(pitch))


@dataclass(frozen=True, slots=True)
class Gnss:
    """A GNSS position fix in the local frame [m], ``sigma`` the 1-sigma error per axis [m]."""

    t: float
    x: float
    y: float
    sigma: float
    source: str = ""
    kind: ClassVar[str] = "gnss"


@dataclass(frozen=True, slots=True)
class Heading:
    """Compass/gyrocompass yaw [rad, CCW from east] with 1-sigma [rad]."""

    t: float
    yaw: float
    sigma: float
    source: str = ""
    kind: ClassVar[str] = "heading"


#: ``meta["odometry"]`` of a log whose odometry records are a rate of turn paired with the newest speed
#: over ground (NMEA 0183 ROT, NMEA 2000 127251, Signal K rateOfTurn): not an odometer, whose speed is along
#: the bow (graphnav.graph.smoother_config.auto_motion).
ODOMETRY_FROM_ROT = "rate of turn + SOG"


def odometry_is_rot(meta: Any) -> bool:
    """Whether a log's ``meta`` says its odometry records are a rate of turn with the SOG
    (:data:`ODOMETRY_FROM_ROT`), not an odometer."""
    return isinstance(meta, dict) and meta.get("odometry") == ODOMETRY_FROM_ROT


def note_rot_odometry(meta: dict[str, Any], records: Iterable[Record]) -> None:
    """A reader whose odometry records are a rate of turn with the SOG: ``meta["odometry"]`` says so
    (:data:`ODOMETRY_FROM_ROT`) when it produced any."""
    if any(r.kind == "odometry" for r in records):
        meta["odometry"] = ODOMETRY_FROM_ROT


@dataclass(frozen=True, slots=True)
class Odometry:
    """Speed over ground ``v`` [m/s] and yaw rate ``w`` [rad/s] (ship's log + rate-of-turn sensor).

    ``sigma_v``/``sigma_w`` are optional 1-sigma values (NaN when the log does not give them).
    """

    t: float
    v: float
    w: float
    sigma_v: float = math.nan
    sigma_w: float = math.nan
    source: str = ""
    kind: ClassVar[str] = "odometry"


@dataclass(frozen=True, slots=True)
class Imu:
    """An IMU sample in the body frame (x forward, y left, z up): accelerations ``ax``, ``ay``,
    ``az`` [m/s^2] and angular rates ``wx``, ``wy``, ``wz`` [rad/s], each the mean over the interval
    since the previous sample.

    The planar 3-axis record (``ax``, ``ay``, ``wz``; ``az``, ``wx``, ``wy`` NaN) is the horizontal
    specific force, gravity removed and levelled; a 6-axis record (all finite) is the raw specific
    force of a strapdown IMU, gravity included (``az`` ~ +9.81 at rest, REP-103).
    """

    t: float
    ax: float
    ay: float
    wz: float
    az: float = math.nan
    wx: float = math.nan
    wy: float = math.nan
    kind: ClassVar[str] = "imu"

    @property
    def six_axis(self) -> bool:
        """Whether the record carries all six axes (else it is the planar 3-axis record)."""
        return not (math.isnan(self.az) or math.isnan(self.wx) or math.isnan(self.wy))


@dataclass(frozen=True, slots=True)
class GnssVelocity:
    """GNSS velocity over ground in the local frame: ``vx`` east, ``vy`` north [m/s] (Doppler, or
    SOG/COG of RMC/VTG converted), ``sigma`` the 1-sigma per axis [m/s] (NaN: not given)."""

    t: float
    vx: float
    vy: float
    sigma: float = math.nan
    source: str = ""
    kind: ClassVar[str] = "gnss_velocity"


@dataclass(frozen=True, slots=True)
class WaterSpeed:
    """Speed **through water** along the bow ``v`` [m/s] (a speed log, VHW; negative astern);
    ``sigma_v`` its 1-sigma [m/s] (NaN: not given). Over ground it differs by the water current."""

    t: float
    v: float
    sigma_v: float = math.nan
    source: str = ""
    kind: ClassVar[str] = "water_speed"


@dataclass(frozen=True, slots=True)
class Attitude:
    """Roll and pitch [rad] of the body (REP-103: roll about x, pitch about y, bow down positive),
    ``sigma`` their 1-sigma [rad] (NaN: not given)."""

    t: float
    roll: float
    pitch: float
    sigma: float = math.nan
    source: str = ""
    kind: ClassVar[str] = "attitude"


@dataclass(frozen=True, slots=True)
class BeaconObs:
    """Range [m] and bearing [rad, CCW from the bow] to an aid to navigation.

    ``sigma_range``/``sigma_bearing`` are optional (NaN when not given).
    """

    t: float
    id: str
    range: float
    bearing: float
    sigma_range: float = math.nan
    sigma_bearing: float = math.nan
    kind: ClassVar[str] = "beacon"


@dataclass(frozen=True, slots=True)
class Truth:
    """Reference pose (x, y [m], yaw [rad]) from an exact simulator or an RTK reference."""

    t: float
    x: float
    y: float
    yaw: float
    kind: ClassVar[str] = "truth"


@dataclass(frozen=True, slots=True)
class PosePrior:
    """Initial pose with 1-sigma position [m] (per axis) and yaw [rad]."""

    t: float
    x: float
    y: float
    yaw: float
    sigma_xy: float
    sigma_yaw: float
    kind: ClassVar[str] = "pose_prior"


@dataclass(frozen=True, slots=True)
class KnownBeacon:
    """A charted aid to navigation: id, position [m] and 1-sigma per axis [m]. Not time-stamped."""

    id: str
    x: float
    y: float
    sigma: float
    kind: ClassVar[str] = "beacon_known"


Record = (Scan | Gnss | Heading | Odometry | Imu | BeaconObs | Truth | PosePrior | Cloud | GnssVelocity | WaterSpeed
          | Attitude)
RECORD_TYPES: dict[str, type] = {  # new types go last: the npz format stores their index
    c.kind: c for c in (Scan, Gnss, Heading, Odometry, Imu, BeaconObs, Truth, PosePrior, Cloud, GnssVelocity,
                        WaterSpeed, Attitude)
}
#: scalar fields that a record may leave out (NaN): readers of older files fill them with NaN
OPTIONAL_SCALARS: dict[str, tuple[str, ...]] = {
    k: tuple(f.name for f in fields(c) if isinstance(f.default, float) and math.isnan(f.default))
    for k, c in RECORD_TYPES.items()
}
ARRAY_FIELDS = ("ranges", "angles", "points", "intensity", "ring")
#: The sensor a record came from (an NMEA 2000 source address, a Signal K ``$source``; "" = not
#: stated): several sources of one quantity are kept apart by it (docs/log-format.md, "Sources").
SOURCE_FIELD = "source"
#: Longest ``source`` a record may carry (characters).
MAX_SOURCE_CHARS = 64
SCALAR_FIELDS: dict[str, tuple[str, ...]] = {
    k: tuple(f.name for f in fields(c) if f.name not in ARRAY_FIELDS and f.name != SOURCE_FIELD)
    for k, c in RECORD_TYPES.items()
}
#: The record kinds that carry a ``source``.
SOURCED_KINDS: tuple[str, ...] = tuple(k for k, c in RECORD_TYPES.items()
                                       if any(f.name == SOURCE_FIELD for f in fields(c)))


@dataclass(frozen=True)
class Limits:
    """Physical validity bounds of :func:`check_record` (docs/log-format.md, "Validity").

    A value outside them is no physical measurement of a surface vessel (or is in the wrong unit),
    and in a filter its square or inverse can overflow (``sigma: 1e300`` did). Defaults are
    documented there; ``max_speed`` is the one a fast vessel may need to raise (CLI
    ``--max-speed``)."""

    max_speed: float = 50.0  # |v| [m/s], ~97 kn: above any surface vessel but racing craft
    max_yaw_rate: float = 35.0  # |w|, |wz| [rad/s]: 2000 deg/s, the largest MEMS gyro full scale
    max_accel: float = 160.0  # |ax|, |ay| [m/s^2]: ~16 g, the largest full scale of the usual IMUs
    max_beacon_range: float = 1e5  # [m]: beyond any radar/AIS horizon of a surface vessel
    min_sigma: float = 1e-9  # any 1-sigma [field's unit]: below, no sensor; its inverse square ~1e18
    max_sigma: float = 1e6  # any 1-sigma: above, it states nothing; its square stays far from overflow
    max_coord: float = 1e7  # |x|, |y| [m] in the local frame: more than the Earth's radius
    max_time: float = 1e10  # |t| [s]: POSIX seconds reach 1e10 in 2286; larger is ms/us/ns
    max_angle: float = 1e6  # |yaw|, |bearing| [rad]: unwrapped angles of ~160 000 turns


_LIMITS = [Limits()]


def default_limits() -> Limits:
    """The :class:`Limits` readers use when given none (``Limits()`` unless changed)."""
    return _LIMITS[0]


def set_default_limits(limits: Limits) -> None:
    """Change the process-wide default :class:`Limits` (the CLI's ``--max-speed`` does)."""
    _LIMITS[0] = limits


_BOUNDED = {  # field -> (Limits attribute, what, unit)
    "t": ("max_time", "time", "s"), "x": ("max_coord", "coordinate", "m"), "y": ("max_coord", "coordinate", "m"),
    "yaw": ("max_angle", "angle", "rad"), "bearing": ("max_angle", "angle", "rad"),
    "v": ("max_speed", "speed", "m/s"), "w": ("max_yaw_rate", "yaw rate", "rad/s"),
    "wz": ("max_yaw_rate", "yaw rate", "rad/s"),
    "ax": ("max_accel", "acceleration", "m/s^2"), "ay": ("max_accel", "acceleration", "m/s^2"),
    "az": ("max_accel", "acceleration", "m/s^2"), "wx": ("max_yaw_rate", "angular rate", "rad/s"),
    "wy": ("max_yaw_rate", "angular rate", "rad/s"),
    "vx": ("max_speed", "speed", "m/s"), "vy": ("max_speed", "speed", "m/s"),
}


# field codes of the record check plans (see _plan)
_ID, _SOURCE, _TIME, _OPT_AXIS, _ATTITUDE, _RANGE_MAX, _SIGMA, _RANGE, _VALUE = range(9)
_PLANS: dict[type, tuple[tuple[str, int, Any], ...]] = {}


def _plan(cls: type) -> tuple[tuple[str, int, Any], ...]:
    """What :func:`check_record` checks of each field of a record type, worked out once per type:
    ``(name, code, argument)`` (the argument: the ``_BOUNDED`` entry, or whether a sigma is optional)."""
    plan = []
    for f in fields(cls):
        n = f.name
        if n == "id":
            plan.append((n, _ID, None))
        elif n in ARRAY_FIELDS:
            continue
        elif n == SOURCE_FIELD:
            plan.append((n, _SOURCE, None))
        elif n == "t":
            plan.append((n, _TIME, _BOUNDED["t"]))
        elif n in ("az", "wx", "wy"):
            plan.append((n, _OPT_AXIS, _BOUNDED.get(n)))
        elif n in ("roll", "pitch"):
            plan.append((n, _ATTITUDE, issubclass(cls, Attitude)))
        elif n == "range_max":
            plan.append((n, _RANGE_MAX, None))
        elif n.startswith("sigma"):
            plan.append((n, _SIGMA, isinstance(f.default, float) and math.isnan(f.default)))
        elif n == "range":
            plan.append((n, _RANGE, None))
        else:
            plan.append((n, _VALUE, _BOUNDED.get(n)))
    _PLANS[cls] = out = tuple(plan)
    return out


def _beyond(lim: Limits, bound: tuple[str, str, str], name: str, v: float) -> None:
    attr, what, unit = bound
    top = getattr(lim, attr)
    if abs(v) > top:
        hint = " (--max-speed)" if attr == "max_speed" else ""
        raise LogError(f"{what} {v:g} {unit} beyond the plausible limit {top:g} {unit}{hint}", field=name)


def check_record(rec: Record | KnownBeacon, limits: Limits | None = None) -> None:
    """Raise :class:`LogError` (with the offending field) if a record is not well formed or not
    physically valid (:class:`Limits`; ``None``: :func:`default_limits`)."""
    lim = limits or _LIMITS[0]
    cls = type(rec)
    plan = _PLANS.get(cls) or _plan(cls)
    isfinite = math.isfinite
    for name, code, arg in plan:
        v = getattr(rec, name)
        if code == _ID:
            _check_id(v)
            continue
        if code == _SOURCE:
            _check_source(v)
            continue
        if not isinstance(v, float):
            raise LogError(f"expected a number, got {type(v).__name__}", field=name)
        if code == _VALUE:
            if not isfinite(v):
                raise LogError("value must be finite", field=name)
            if arg is not None and abs(v) > getattr(lim, arg[0]):
                _beyond(lim, arg, name, v)
        elif code == _TIME:
            if not isfinite(v):
                raise LogError("timestamp must be finite", field="t")
            if abs(v) > lim.max_time:
                _beyond(lim, arg, name, v)
        elif code == _SIGMA:
            if arg and math.isnan(v):
                continue
            if not (isfinite(v) and v > 0.0):
                raise LogError("sigma must be finite and > 0", field=name)
            if not lim.min_sigma <= v <= lim.max_sigma:
                raise LogError(f"sigma {v:g} outside the physical range [{lim.min_sigma:g}, {lim.max_sigma:g}]",
                               field=name)
        elif code == _OPT_AXIS:
            if math.isnan(v):
                continue  # the planar 3-axis IMU record
            if not isfinite(v):
                raise LogError("value must be finite", field=name)
            if arg is not None and abs(v) > getattr(lim, arg[0]):
                _beyond(lim, arg, name, v)
        elif code == _ATTITUDE:
            if arg and not isfinite(v):
                raise LogError(f"{name} must be finite", field=name)
            if not (math.isnan(v) or abs(v) <= math.pi / 2):
                raise LogError(f"{name} must be in [-pi/2, pi/2] rad (or absent)", field=name)
        elif code == _RANGE_MAX:
            if not (math.isnan(v) or 0.0 < v <= MAX_STATED_RANGE):
                raise LogError(f"range_max must be in (0, {MAX_STATED_RANGE:g}] m (or absent)", field="range_max")
        else:  # _RANGE
            if not isfinite(v):
                raise LogError("value must be finite", field=name)
            if not 0.0 < v <= lim.max_beacon_range:
                raise LogError(f"range {v:g} m outside (0, {lim.max_beacon_range:g}]", field="range")
    if isinstance(rec, Scan):
        if rec.ranges.ndim != 1 or rec.angles.ndim != 1:
            raise LogError("ranges and angles must be 1-D arrays", field="ranges")
        if rec.ranges.shape != rec.angles.shape:
            raise LogError(
                f"ranges has {rec.ranges.size} values but angles has {rec.angles.size}", field="angles"
            )
        if not np.all(np.isfinite(rec.angles[rec.valid()])):
            raise LogError("every beam with a return needs a finite angle", field="angles")
    elif isinstance(rec, Cloud):
        _check_cloud(rec)


def suspect_rows(cls: type, columns: dict[str, Any], limits: Limits | None = None) -> NDArray[np.bool_]:
    """Which rows of a column-stored record type :func:`check_record` could reject: the same plan
    evaluated on whole columns (``columns``: field name -> sequence, one entry per record). Every row
    ``check_record`` rejects is flagged; a reader checks only the flagged ones record by record (the
    error, its message and field, stay the scalar check's), so a log of valid records costs a few
    array operations per field instead of a Python loop per record. Array fields are not covered."""
    lim = limits or _LIMITS[0]
    plan = _PLANS.get(cls) or _plan(cls)
    n = len(next(iter(columns.values()))) if columns else 0
    bad = np.zeros(n, dtype=bool)
    missing = object()
    defaults = {f.name: f.default for f in fields(cls) if f.default is not MISSING}
    with np.errstate(invalid="ignore"):
        for name, code, arg in plan:
            col = columns.get(name, missing)
            if col is missing:  # a field not given: the record gets its default
                d = defaults.get(name, missing)
                if d is missing:
                    bad[:] = True  # no default: let the scalar check say so
                    continue
                col = [d] * n
            if code in (_ID, _SOURCE):
                for v in set(col):
                    try:
                        (_check_source if code == _SOURCE else _check_id)(v)
                    except LogError:
                        bad |= np.fromiter((c == v for c in col), dtype=bool, count=n)
                continue
            if not (isinstance(col, np.ndarray) and col.dtype == np.float64):
                bad |= np.fromiter((not isinstance(v, float) for v in col), dtype=bool, count=n)
            try:
                a = np.asarray(col, dtype=float)
            except (TypeError, ValueError):
                bad[:] = True
                continue
            if a.shape != (n,):
                bad[:] = True
                continue
            fin, nan = np.isfinite(a), np.isnan(a)
            if code == _VALUE:
                b = ~fin | ((np.abs(a) > getattr(lim, arg[0])) if arg is not None else False)
            elif code == _TIME:
                b = ~fin | (np.abs(a) > lim.max_time)
            elif code == _SIGMA:
                b = ~(fin & (a > 0.0) & (a >= lim.min_sigma) & (a <= lim.max_sigma))
                if arg:
                    b &= ~nan
            elif code == _OPT_AXIS:
                b = ~nan & (~fin | ((np.abs(a) > getattr(lim, arg[0])) if arg is not None else False))
            elif code == _ATTITUDE:
                b = ~(nan | (np.abs(a) <= math.pi / 2)) | ((~fin) if arg else False)
            elif code == _RANGE_MAX:
                b = ~(nan | ((a > 0.0) & (a <= MAX_STATED_RANGE)))
            else:  # _RANGE
                b = ~fin | ~((a > 0.0) & (a <= lim.max_beacon_range))
            bad |= b
    return bad


def _check_id(v: Any) -> None:
    if not isinstance(v, str) or not v:
        raise LogError("beacon id must be a non-empty string", field="id")


def _check_source(v: Any) -> None:
    if not isinstance(v, str) or len(v) > MAX_SOURCE_CHARS or not v.isprintable():
        raise LogError(f"source must be a printable string of at most {MAX_SOURCE_CHARS} characters",
                       field=SOURCE_FIELD)


API_LIMITS = Limits(max_speed=math.inf, max_yaw_rate=math.inf, max_accel=math.inf, max_beacon_range=math.inf)
"""The bounds :func:`validate_record` applies by default: only those that keep the arithmetic finite
(times, coordinates, angles, sigmas); the physical plausibility of speeds and rates is the readers'."""


def validate_record(obj: Any, *, index: int | None = None, limits: Limits | None = None,
                    kinds: Iterable[str] | None = None) -> Record | KnownBeacon:
    """``obj`` if it is a well-formed record (:func:`check_record` with ``limits``, default
    :data:`API_LIMITS`) of one of ``kinds`` (default: any record type, or a :class:`KnownBeacon`), else a
    :class:`LogError` naming the record (``record INDEX``, its type and time) and the field at fault.
    The check for records handed to an estimator one at a time (``Navigator.add``)."""
    what = "record" if index is None else f"record {index}"
    allowed = tuple(RECORD_TYPES[k] for k in kinds) if kinds is not None else (*RECORD_TYPES.values(), KnownBeacon)
    if not isinstance(obj, allowed):
        names = ", ".join(c.__name__ for c in allowed)
        got = type(obj).__name__ if obj is not None else "None"
        if isinstance(obj, tuple(RECORD_TYPES.values())):
            raise LogError(f"a {got} record is not taken here (takes: {names})", file=what)
        raise LogError(f"expected a record ({names}), got {got}", file=what)
    try:
        try:
            check_record(obj, limits or API_LIMITS)
        except LogError:
            ints = {f.name: float(v) for f in fields(obj) if f.name not in ARRAY_FIELDS
                    and isinstance(v := getattr(obj, f.name), int) and not isinstance(v, bool) and abs(v) < 2**53}
            if not ints:
                raise
            from dataclasses import replace  # Gnss(t=0, ...) from Python: the same record in floats

            obj = replace(obj, **ints)
            check_record(obj, limits or API_LIMITS)
    except LogError as err:
        t = getattr(obj, "t", None)
        at = f" at t={t!r}" if t is not None else ""
        raise LogError(err.message, file=f"{what} ({type(obj).__name__}{at})", field=err.field) from None
    return obj


def _tighter(a: Limits, b: Limits) -> bool:
    """Whether every record within bounds ``a`` is within bounds ``b``."""
    return all(getattr(a, f.name) >= getattr(b, f.name) if f.name.startswith("min_")
               else getattr(a, f.name) <= getattr(b, f.name) for f in fields(Limits))


def _check_cloud(rec: Cloud) -> None:
    """A cloud's arrays: (N, 3) float32 points, N <= MAX_CLOUD_POINTS, finite and within
    MAX_STATED_RANGE of the sensor; intensity (N,) finite float32; ring (N,) uint16 <= MAX_RING."""
    p = rec.points
    if not isinstance(p, np.ndarray) or p.ndim != 2 or p.shape[1] != 3 or p.dtype != np.float32:
        raise LogError("points must be an (N, 3) float32 array", field="points")
    n = p.shape[0]
    if n > MAX_CLOUD_POINTS:
        raise LogError(f"{n} points, more than {MAX_CLOUD_POINTS}", field="points")
    if not np.all(np.isfinite(p)):
        raise LogError("every point must be finite (store real returns only)", field="points")
    if n and float(np.abs(p).max()) > MAX_STATED_RANGE:
        raise LogError(f"a point lies beyond {MAX_STATED_RANGE:g} m of the sensor", field="points")
    if rec.intensity is not None:
        a = rec.intensity
        if not isinstance(a, np.ndarray) or a.shape != (n,) or a.dtype != np.float32:
            raise LogError(f"intensity must be an ({n},) float32 array", field="intensity")
        if not np.all(np.isfinite(a)):
            raise LogError("intensity must be finite", field="intensity")
    if rec.ring is not None:
        a = rec.ring
        if not isinstance(a, np.ndarray) or a.shape != (n,) or a.dtype != np.uint16:
            raise LogError(f"ring must be an ({n},) uint16 array", field="ring")
        if n and int(a.max()) > MAX_RING:
            raise LogError(f"ring index beyond {MAX_RING}", field="ring")


@dataclass
class NavLog:
    """A time-ordered navigation log.

    ``records`` are sorted by time (non-decreasing; ties keep their order), ``beacons_known``
    are charted beacons, ``meta`` holds free-form provenance: ``name``, ``source``, the local
    frame's geodetic ``origin`` (lat, lon in degrees) when GNSS came as lat/lon, and ``events``
    (e.g. ``{"kind": "gnss_outage", "t0": .., "t1": ..}``) that reports shade.
    """

    records: list[Record]
    beacons_known: list[KnownBeacon] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)
    # the records a reader checked (the very objects, in order) and the bounds they passed
    _checked: tuple[tuple[Record, ...], Limits | None] = field(default=((), None), init=False, repr=False,
                                                              compare=False)

    def __post_init__(self) -> None:
        t = [r.t for r in self.records]
        if all(map(operator.le, t, itertools.islice(t, 1, None))):  # (in order: no walk by index)
            return
        for i in range(1, len(self.records)):
            if self.records[i].t < self.records[i - 1].t:
                raise LogError(
                    f"time goes backwards: {self.records[i].t!r} after {self.records[i - 1].t!r}",
                    field="t",
                )

    @classmethod
    def from_unsorted(
        cls, records: Iterable[Record], beacons_known: Iterable[KnownBeacon] = (), meta: dict | None = None
    ) -> NavLog:
        """Build a log from records in any order (stable sort by time)."""
        recs = sorted(records, key=lambda r: r.t)
        return cls(recs, list(beacons_known), dict(meta or {}))

    def __len__(self) -> int:
        return len(self.records)

    def __iter__(self) -> Iterator[Record]:
        return iter(self.records)

    def of(self, kind: str | type) -> list[Record]:
        """Records of one type (``"gnss"`` or ``Gnss``), in time order."""
        k = kind if isinstance(kind, str) else kind.kind
        return [r for r in self.records if r.kind == k]

    def counts(self) -> dict[str, int]:
        """Number of records per type (``beacon_known`` included when present)."""
        c = Counter(map(_KIND, self.records))
        out = {k: c.get(k, 0) for k in RECORD_TYPES if c.get(k, 0)}
        if self.beacons_known:
            out["beacon_known"] = len(self.beacons_known)
        return out

    @property
    def t0(self) -> float | None:
        return self.records[0].t if self.records else None

    @property
    def t1(self) -> float | None:
        return self.records[-1].t if self.records else None

    @property
    def has_truth(self) -> bool:
        return any(r.kind == "truth" for r in self.records)

    def columns(self, kind: str) -> dict[str, NDArray]:
        """Scalar fields of one record type as arrays, e.g. ``log.columns("gnss")["x"]``."""
        recs = self.of(kind)
        names = SCALAR_FIELDS[kind]
        out: dict[str, NDArray] = {}
        for n in names:
            vals = [getattr(r, n) for r in recs]
            out[n] = np.array(vals, dtype=object if n == "id" else float)
        return out

    def truth(self):  # -> Trajectory (import kept local: trajectory imports nothing from here)
        """The reference trajectory from the ``truth`` records (empty if there are none)."""
        from .trajectory import Trajectory

        c = self.columns("truth")
        return Trajectory(c["t"], np.column_stack([c["x"], c["y"], c["yaw"]]), name="truth")

    def pose_prior(self) -> PosePrior | None:
        """The first ``pose_prior`` record, if any."""
        for r in self.records:
            if isinstance(r, PosePrior):
                return r
        return None

    def sliced(self, t0: float | None = None, t1: float | None = None) -> NavLog:
        """The records with ``t0 <= t <= t1`` (charted beacons and meta kept)."""
        lo = -math.inf if t0 is None else t0
        hi = math.inf if t1 is None else t1
        return NavLog([r for r in self.records if lo <= r.t <= hi], list(self.beacons_known),
                      dict(self.meta)).checks_from(self)

    def without(self, predicate) -> NavLog:
        """A copy without the records for which ``predicate(record)`` is true."""
        return NavLog([r for r in self.records if not predicate(r)], list(self.beacons_known),
                      dict(self.meta)).checks_from(self)

    # -- validation once: what a reader checked is not checked again -----------------------------
    def mark_checked(self, limits: Limits | None = None) -> NavLog:
        """Note that every record now in ``records`` passed :func:`check_record` with ``limits``
        (``None``: :func:`default_limits`); the readers call it. Returns the log."""
        self._checked = (tuple(self.records), limits or _LIMITS[0])
        return self

    def checks_from(self, parent: NavLog) -> NavLog:
        """Keep ``parent``'s checks when this log's records are a subsequence of the records
        ``parent``'s reader checked (a copy with records left out). Returns the log."""
        snap, lim = parent._checked
        if snap:
            it = iter(snap)
            if all(any(r is s for s in it) for r in self.records):
                self._checked = (tuple(self.records), lim)
        return self

    def checked_records(self, limits: Limits | None = None) -> Iterator[tuple[Record, bool]]:
        """Each record with whether it already passed :func:`check_record` with bounds at least as tight
        as ``limits`` (default :data:`API_LIMITS`): true only for the very object a reader checked, at
        its place; a record added or replaced since then is false (and gets checked where it is used)."""
        snap, lim = self._checked
        ok = bool(snap) and lim is not None and _tighter(lim, limits or API_LIMITS)
        n = len(snap) if ok else 0
        for i, r in enumerate(self.records):
            yield r, i < n and snap[i] is r

    # -- short summaries (the dataclass repr would print every record) ------------------------------
    def _span(self) -> str:
        return f"{self.t0:.1f}–{self.t1:.1f} s" if self.records else "empty"

    def __repr__(self) -> str:
        name = self.meta.get("name")
        counts = ", ".join(f"{k} {v}" for k, v in self.counts().items())
        head = f"NavLog {str(name)[:40]!r}" if name else "NavLog"
        return f"<{head}: {len(self.records)} records, {self._span()}; {counts or 'no records'}>"

    def _repr_html_(self) -> str:
        """A small table for notebooks: records per type with their time span and rate."""
        from html import escape

        rows = []
        for k, n in self.counts().items():
            if k == "beacon_known":
                rows.append(f"<tr><td>{k}</td><td>{n}</td><td colspan=2>(charted, not time-stamped)</td></tr>")
                continue
            t = np.array([r.t for r in self.records if r.kind == k])
            rate = f"{(n - 1) / (t[-1] - t[0]):.3g} Hz" if n > 1 and t[-1] > t[0] else "–"
            rows.append(f"<tr><td>{k}</td><td>{n}</td><td>{t[0]:.1f}–{t[-1]:.1f} s</td><td>{rate}</td></tr>")
        meta = ", ".join(f"{escape(str(k))}: {escape(str(v))[:80]}" for k, v in self.meta.items()
                         if k in ("name", "source", "origin"))
        return (f"<b>NavLog</b> {len(self.records)} records, {self._span()}"
                + (f" <small>({meta})</small>" if meta else "")
                + "<table><tr><th>record</th><th>count</th><th>time span</th><th>rate</th></tr>"
                + "".join(rows) + "</table>")


def odometry_samples(log: NavLog, sigma_v: float = 0.1, sigma_w: float = math.radians(1.0)) -> NDArray[np.float64]:
    """The log's odometry records as an (N, 5) array ``t, v, w, sigma_v, sigma_w`` (the given
    sigmas where a record has none); the input of :func:`graphnav.geometry.increment`."""
    rows = [[r.t, r.v, r.w, r.sigma_v if math.isfinite(r.sigma_v) else sigma_v,
             r.sigma_w if math.isfinite(r.sigma_w) else sigma_w] for r in log.of("odometry")]
    return np.array(rows, dtype=float).reshape(-1, 5)
