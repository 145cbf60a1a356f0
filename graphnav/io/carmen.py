"""Reader of CARMEN text logs (``.log``, ``.clf``, optionally gzipped): laser scans and their poses.

One message per line, fields separated by blanks (the field lists follow CARMEN's own parser,
``carmen/src/logtools/readlog.c``; full description in docs/datasets.md):

* ``FLASER n r1..rn x y theta odom_x odom_y odom_theta timestamp host logger_timestamp`` -- the
  front laser. The beam angles are not stored: CARMEN's convention is a first beam at -90 deg and
  1 deg spacing for 180/181 beams, 0.5 deg for 360/361, 0.25 deg for 400/401, else 180 deg evenly
  spread over the n beams (``carmen_laser_guess_angle_increment``), so 181 and 361 beams cover
  -90..+90 deg and 180/360 beams -90..+89(.5) deg. ``x y theta`` is the laser pose.
* ``ROBOTLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode n r1..rn
  m e1..em laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv forward_safety_dist
  side_safety_dist turn_axis timestamp host logger_timestamp`` -- beam ``i`` at
  ``start_angle + i * angular_res``.
* ``RAWLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode n r1..rn
  m e1..em timestamp host logger_timestamp`` -- no pose. Used only when the log has no FLASER or
  ROBOTLASER1 message (new CARMEN logs write both kinds for the same scan); otherwise counted
  in ``meta["unused"]``.

What becomes a record:

* every scan -> :class:`~graphnav.log.Scan` (sensor frame = body frame). Returns ``<= 0`` and
  max-range returns are missing returns (NaN), not points: ``r >= max_range`` where the message
  carries one (ROBOTLASER1, RAWLASER1) or the caller gives ``max_range``; for FLASER, which carries
  none, the sensor's saturation is detected (:func:`saturation_threshold`). A beam that reads the
  same value in every scan of the log (a dead or masked beam) is also set missing.
* the laser pose of FLASER/ROBOTLASER1 -> :class:`~graphnav.log.Truth` at the scan's time
  (``truth=False`` leaves it out). This is right for *corrected* logs (the poses are SLAM
  output); in a raw log the poses are odometry and should not be called truth.
* everything else (``PARAM``, ``ODOM``, ``NEFF``, ``SYNC``, ``RLASER``, ``ROBOTLASER2``, unknown
  names) is counted per message name in ``meta["ignored"]``; ``#`` lines are comments.

Time: with ``time="auto"`` the messages' ``timestamp`` field is used when it is strictly increasing
over the scans; otherwise (several corrected logs carry constant, zero or wrapped-around stamps)
scan ``k`` is stamped ``k * scan_dt`` and ``meta["time"]`` says so. ``time="log"`` insists on the
stamps (a backwards stamp is an error at its line), ``time="index"`` always uses the index.

Errors: a malformed line raises :class:`~graphnav.errors.LogError` naming the file, line and field;
``lenient=True`` skips it and counts it (``meta["skipped"]``, the first messages in
``meta["skipped_errors"]``). The file is read line by line (lines longer than
:data:`MAX_LINE_BYTES` are errors, so a file without newlines cannot exhaust memory).
"""

from __future__ import annotations

import gzip
import math
import re
import zlib
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, Literal

import numpy as np
from numpy.typing import NDArray

from ..errors import LogError
from ..geometry import wrap_angle
from ..log import Limits, NavLog, Record, Scan, Truth, check_record

MAX_LINE_BYTES = 4_000_000
MAX_BEAMS = 100_000
#: FLASER saturation: returns within this fraction below the saturation value (the spike) are max-range readings ...
SATURATION_BAND = 0.01
#: ... when they are at least this fraction of all returns (a real sensor cut-off, not one far wall)
SATURATION_MIN_FRACTION = 0.001
#: ... and this many times as many as in the band of equal width just below (a spike, not a tail).
SATURATION_SPIKE = 10.0
#: ... and at least this many (a handful of far returns is not a sensor's saturation).
SATURATION_MIN_COUNT = 10
SATURATION_MAX_ABOVE = 0.1
"""Returns above the saturation value, at most this fraction of the spike (stray readings)."""
#: A beam with the same range in every scan is dead only when the log has at least this many scans.
DEAD_BEAM_MIN_SCANS = 20
DEFAULT_SCAN_DT = 1.0
READ = ("FLASER", "ROBOTLASER1", "RAWLASER1")
_NAME = re.compile(r"[A-Z][A-Z0-9_]*\Z")
LASER_CONFIG = ("laser_type", "start_angle", "fov", "angular_res", "max_range", "accuracy", "remission_mode")
POSE_FIELDS = ("laser_x", "laser_y", "laser_theta", "robot_x", "robot_y", "robot_theta")
ROBOT_FIELDS = ("tv", "rv", "forward_safety_dist", "side_safety_dist", "turn_axis")


@dataclass(frozen=True, slots=True)
class LaserMessage:
    """One parsed laser line: ``kind`` (FLASER, ROBOTLASER1, RAWLASER1), ``timestamp`` [s],
    ``ranges`` [m] and ``angles`` [rad] (equal lengths), the message's ``max_range`` [m] (None
    for FLASER) and the laser ``pose`` (x, y, theta; None for RAWLASER1)."""

    kind: str
    timestamp: float
    ranges: NDArray[np.float64]
    angles: NDArray[np.float64]
    max_range: float | None
    pose: tuple[float, float, float] | None


def flaser_angles(n: int) -> NDArray[np.float64]:
    """CARMEN's beam angles for an n-beam FLASER (``carmen_laser_guess_angle_increment``)."""
    if n in (180, 181):
        inc = math.pi / 180.0
    elif n in (360, 361):
        inc = math.pi / 360.0
    elif n in (400, 401):
        inc = math.pi / 720.0
    else:
        inc = math.pi / (n - 1) if n > 1 else 0.0
    return -math.pi / 2 + inc * np.arange(n)


class _Fields:
    """The blank-separated fields of one line, consumed left to right with named checks."""

    def __init__(self, tokens: list[str]) -> None:
        self.tok = tokens
        self.i = 1  # tokens[0] is the message name

    def _next(self, name: str) -> str:
        if self.i >= len(self.tok):
            raise LogError(f"line ends before this field ({len(self.tok) - 1} fields after the name)", field=name)
        s = self.tok[self.i]
        self.i += 1
        return s

    def num(self, name: str, *, finite: bool = True) -> float:
        s = self._next(name)
        try:
            v = float(s)
        except ValueError:
            raise LogError(f"not a number: {s[:20]!r}", field=name) from None
        if finite and not math.isfinite(v):
            raise LogError(f"not finite: {s[:20]!r}", field=name)
        return v

    def count(self, name: str) -> int:
        s = self._next(name)
        if not s.isdigit():
            raise LogError(f"not a non-negative integer: {s[:20]!r}", field=name)
        n = int(s)
        if n > MAX_BEAMS:
            raise LogError(f"{n} exceeds {MAX_BEAMS}", field=name)
        if self.i + n > len(self.tok):
            raise LogError(f"says {n} values but only {len(self.tok) - self.i} fields follow", field=name)
        return n

    def values(self, n: int, name: str) -> NDArray[np.float64]:
        """``n`` numbers; non-finite ones (``nan``, ``inf``) become NaN (missing returns)."""
        out = np.empty(n)
        for k in range(n):
            s = self.tok[self.i + k]
            try:
                out[k] = float(s)
            except ValueError:
                raise LogError(f"value {k} is not a number: {s[:20]!r}", field=f"{name}[{k}]") from None
        self.i += n
        out[~np.isfinite(out)] = np.nan
        return out

    def tail(self) -> float:
        """``timestamp [host [logger_timestamp]]``: the timestamp."""
        t = self.num("timestamp")
        if self.i < len(self.tok):
            self.i += 1  # host: any word
        if self.i < len(self.tok):
            self.num("logger_timestamp")
        if self.i < len(self.tok):
            raise LogError(f"{len(self.tok) - self.i} unexpected field(s) after logger_timestamp: "
                           f"{self.tok[self.i][:20]!r}", field="logger_timestamp")
        return t


def parse_line(line: str) -> LaserMessage | str | None:
    """Parse one line: a :class:`LaserMessage` for the laser messages read, the message name (str)
    for any other message, ``None`` for blank and ``#`` lines. Anything malformed raises
    :class:`LogError` naming the field (never another exception)."""
    tokens = line.split()
    if not tokens or tokens[0].startswith("#"):
        return None
    name = tokens[0]
    if not _NAME.match(name):
        raise LogError(f"not a CARMEN message name: {name[:20]!r}", field="message")
    if name not in READ:
        return name
    f = _Fields(tokens)
    if name == "FLASER":
        n = f.count("num_readings")
        ranges = f.values(n, "range")
        pose = tuple(f.num(p) for p in POSE_FIELDS)
        return LaserMessage(name, f.tail(), ranges, flaser_angles(n), None, (pose[0], pose[1], pose[2]))
    cfg = {}
    for c in LASER_CONFIG:
        cfg[c] = f.num(c)
    if cfg["angular_res"] == 0.0 or abs(cfg["angular_res"]) > 2 * math.pi:
        raise LogError(f"angular resolution {cfg['angular_res']!r} rad is not in (0, 2 pi]", field="angular_res")
    n = f.count("num_readings")
    ranges = f.values(n, "range")
    m = f.count("num_remissions")
    f.values(m, "remission")
    angles = cfg["start_angle"] + cfg["angular_res"] * np.arange(n)
    max_range = cfg["max_range"] if cfg["max_range"] > 0.0 else None
    pose3 = None
    if name == "ROBOTLASER1":
        pose = tuple(f.num(p) for p in POSE_FIELDS)
        for r in ROBOT_FIELDS:
            f.num(r)
        pose3 = (pose[0], pose[1], pose[2])
    return LaserMessage(name, f.tail(), ranges, angles, max_range, pose3)


def _open(path: Path) -> BinaryIO:
    with open(path, "rb") as probe:
        magic = probe.read(2)
    return gzip.open(path, "rb") if magic == b"\x1f\x8b" else open(path, "rb")


def _lines(path: Path) -> Iterator[tuple[int, str | LogError]]:
    """(line number, text) one line at a time; an over-long or non-ASCII line yields a LogError."""
    lineno = 0
    try:
        with _open(path) as fh:
            while True:
                raw = fh.readline(MAX_LINE_BYTES + 1)
                if not raw:
                    return
                lineno += 1
                if len(raw) > MAX_LINE_BYTES and not raw.endswith(b"\n"):
                    while raw and not raw.endswith(b"\n"):  # skip the rest of the line, bounded chunks
                        raw = fh.readline(MAX_LINE_BYTES)
                    yield lineno, LogError(f"line longer than {MAX_LINE_BYTES} bytes", field="message")
                    continue
                try:
                    yield lineno, raw.decode("ascii")
                except UnicodeDecodeError:
                    yield lineno, LogError("non-ASCII bytes", field="message")
    except (OSError, EOFError, zlib.error) as exc:
        raise LogError(f"cannot read: {exc}", file=str(path), line=lineno + 1 if lineno else None) from None


def is_carmen(path: str | Path, probe_lines: int = 200) -> bool:
    """True when the first non-comment lines of a file look like CARMEN messages (a laser, ODOM,
    PARAM or another upper-case message name followed by numbers), not NMEA sentences."""
    p = Path(path)
    seen = 0
    try:
        for _lineno, item in _lines(p):
            if seen >= probe_lines:
                break
            if isinstance(item, LogError):
                return False
            s = item.strip()
            if not s:
                continue
            if s.startswith("#"):
                if "message formats defined" in s or "CARMEN" in s:
                    return True
                continue
            seen += 1
            tok = s.split()
            if not _NAME.match(tok[0]):
                return False
            if tok[0] in READ or tok[0] in ("PARAM", "ODOM", "SYNC", "TRUEPOS", "RLASER", "NEFF"):
                return True
    except LogError:
        return False
    return False


def saturation_threshold(ranges: NDArray[np.float64] | list[NDArray[np.float64]]) -> float | None:
    """The max-range cut for a sensor that does not state its maximum (FLASER).

    The sensor's saturation value ``r_sat`` is the spike it writes at its maximum (81.91 m, 51.15 m or
    32.767 m in the CARMEN logs): the largest reading that at least :data:`SATURATION_MIN_COUNT` returns
    and :data:`SATURATION_MIN_FRACTION` of all returns share exactly, with at most
    :data:`SATURATION_MAX_ABOVE` times as many returns above it (stray readings beyond the maximum, a
    40 m or a 1e308 among 32.767 m saturations, do not move it). Returns ``(1 - SATURATION_BAND) *
    r_sat`` when the returns at or above that cut are :data:`SATURATION_SPIKE` times as many as in the
    band of equal width below it; ``None`` when there is no such spike (no cut). ``ranges``: one array,
    or a list of them (the scans, counted one at a time: no concatenated copy of the whole log)."""
    parts = [ranges] if isinstance(ranges, np.ndarray) else ranges
    counts: Counter[float] = Counter()
    n = 0
    for p in parts:
        ok = np.isfinite(p) & (p > 0.0)
        if ok.any():
            n += int(np.count_nonzero(ok))
            vals, cnt = np.unique(p[ok], return_counts=True)
            counts.update(dict(zip(vals.tolist(), cnt.tolist(), strict=True)))
    if n == 0:
        return None
    r_sat, above = None, 0
    for v in sorted(counts, reverse=True):
        c = counts[v]
        if c >= SATURATION_MIN_COUNT and c >= SATURATION_MIN_FRACTION * n:
            if above <= SATURATION_MAX_ABOVE * c:
                r_sat = v
            break
        above += c
    if r_sat is None:
        return None
    cut = (1.0 - SATURATION_BAND) * r_sat
    top = sum(c for v, c in counts.items() if cut <= v <= r_sat)
    below = sum(c for v, c in counts.items() if cut - SATURATION_BAND * r_sat <= v < cut)
    return cut if top >= SATURATION_SPIKE * below else None


def dead_beams(scans: list[NDArray[np.float64]]) -> NDArray[np.intp]:
    """Indices of beams that read the same finite, positive range in every one of ``scans`` (all
    of one length); none when there are fewer than :data:`DEAD_BEAM_MIN_SCANS` scans."""
    if len(scans) < DEAD_BEAM_MIN_SCANS:
        return np.zeros(0, dtype=np.intp)
    first = scans[0]
    same = np.isfinite(first) & (first > 0.0)
    for r in scans[1:]:  # one scan at a time (no stacked copy of the log)
        same &= r == first
    return np.flatnonzero(same)


def read_carmen(path: str | Path, *, lenient: bool = False, truth: bool = True,
                time: Literal["auto", "log", "index"] = "auto", scan_dt: float = DEFAULT_SCAN_DT,
                max_range: float | None = None, limits: Limits | None = None) -> NavLog:
    """Read a CARMEN log (see the module docstring) into scans and, by default, ``truth`` poses.

    ``max_range`` [m], when given, replaces every message's own maximum and the FLASER
    saturation detection. ``meta`` reports ``messages`` (laser messages read per name),
    ``ignored`` (other messages per name), ``unused`` (RAWLASER1 beside pose-carrying lasers),
    ``time``, ``max_range`` (the distinct cuts used per message name, [] = none),
    ``missing_returns`` (max-range and dead-beam returns set missing), ``dead_beams`` and, with
    ``lenient``, ``skipped``/``skipped_errors``. Every record passes :func:`graphnav.log.check_record`
    (``limits``); an invalid one is an error naming the scan, or with ``lenient`` skipped and counted.
    """
    path = Path(path)
    if time not in ("auto", "log", "index"):
        raise ValueError(f"time must be 'auto', 'log' or 'index', not {time!r}")
    if not (math.isfinite(scan_dt) and scan_dt > 0.0):
        raise ValueError(f"scan_dt must be finite and > 0, not {scan_dt!r}")
    if max_range is not None and not (math.isfinite(max_range) and max_range > 0.0):
        raise ValueError(f"max_range must be finite and > 0, not {max_range!r}")
    posed: list[LaserMessage] = []
    raw: list[LaserMessage] = []
    ignored: Counter = Counter()
    skipped: list[str] = []
    last_t = {"posed": -math.inf, "raw": -math.inf}
    for lineno, item in _lines(path):
        try:
            if isinstance(item, LogError):
                raise item
            msg = parse_line(item)
            if msg is None:
                continue
            if isinstance(msg, str):
                ignored[msg] += 1
                continue
            group = "raw" if msg.kind == "RAWLASER1" else "posed"
            if time == "log":
                if msg.timestamp < last_t[group]:
                    raise LogError(f"time goes backwards ({msg.timestamp!r} after {last_t[group]!r})",
                                   field="timestamp")
                last_t[group] = msg.timestamp
            (raw if group == "raw" else posed).append(msg)
        except LogError as err:
            err = err.located(file=str(path), line=lineno)
            if not lenient:
                raise err from None
            skipped.append(str(err))
    msgs = posed if posed else raw
    meta: dict[str, Any] = {"name": path.name.split(".")[0], "source": str(path), "format": "carmen",
                            "messages": dict(Counter(m.kind for m in msgs))}
    if posed and raw:
        meta["unused"] = {"RAWLASER1": len(raw)}
    if ignored:
        meta["ignored"] = dict(sorted(ignored.items()))
    stamps = np.array([m.timestamp for m in msgs])
    increasing = bool(len(stamps) < 2 or np.all(np.diff(stamps) > 0.0))
    if time == "log" or (time == "auto" and increasing):
        times = stamps
        meta["time"] = "log timestamps [s]"
    else:
        times = scan_dt * np.arange(len(msgs), dtype=float)
        why = "" if time == "index" else (
            f" (the log's scan timestamps are not strictly increasing: {int(np.count_nonzero(np.diff(stamps) <= 0))}"
            f" of {len(stamps) - 1} steps)")
        meta["time"] = f"scan index x {scan_dt:g} s{why}"
    ranges, cuts, missing, dead = _clean_ranges(msgs, max_range)
    meta["max_range"] = cuts
    meta["missing_returns"] = missing
    if dead:
        meta["dead_beams"] = dead
    records: list[Record] = []
    for k, (m, t, r) in enumerate(zip(msgs, times, ranges, strict=True)):
        recs: list[Record] = [Scan(float(t), r, m.angles)]
        if truth and m.pose is not None:
            x, y, th = m.pose
            recs.append(Truth(float(t), x, y, th if -math.pi <= th < math.pi else float(wrap_angle(th))))
        for rec in recs:
            try:
                check_record(rec, limits)
            except LogError as err:
                err = LogError(f"{m.kind} scan {k + 1} ({rec.kind}): {err.message}", file=str(path), field=err.field)
                if not lenient:
                    raise err from None
                skipped.append(str(err))
            else:
                records.append(rec)
    if lenient:
        meta["skipped"] = len(skipped)
        meta["skipped_errors"] = skipped[:20]
    return NavLog(records, [], meta)


def _clean_ranges(msgs: list[LaserMessage], max_range: float | None
                  ) -> tuple[list[NDArray[np.float64]], dict[str, list[float]], dict[str, int], dict[str, list[int]]]:
    """Ranges with max-range returns and dead beams set to NaN, the distinct cuts used per message
    name, the number of returns set missing per cause, and the dead beams per message name/length."""
    out = [m.ranges for m in msgs]  # the messages' own arrays, edited in place (no second copy of every scan)
    missing = {"max_range": 0, "dead_beam": 0}
    flaser = [i for i, m in enumerate(msgs) if m.kind == "FLASER"]
    flaser_cut = max_range
    if flaser and max_range is None:
        flaser_cut = saturation_threshold([out[i] for i in flaser])
    used: dict[str, set[float]] = {}
    for i, m in enumerate(msgs):
        cut = max_range if max_range is not None else (flaser_cut if m.kind == "FLASER" else m.max_range)
        used.setdefault(m.kind, set())
        if cut is not None:
            used[m.kind].add(cut)
            r = out[i]
            hit = np.isfinite(r) & (r >= cut)
            missing["max_range"] += int(np.count_nonzero(hit))
            r[hit] = np.nan
    dead: dict[str, list[int]] = {}
    groups: dict[tuple[str, int], list[int]] = {}
    for i, m in enumerate(msgs):
        groups.setdefault((m.kind, m.ranges.size), []).append(i)
    for (kind, n), idx in groups.items():
        beams = dead_beams([out[i] for i in idx])
        if beams.size:
            dead[f"{kind}/{n}"] = beams.tolist()
            for i in idx:
                out[i][beams] = np.nan
            missing["dead_beam"] += beams.size * len(idx)
    return out, {k: sorted(v) for k, v in used.items()}, missing, dead
