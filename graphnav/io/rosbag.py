"""ROS 1 (``.bag``) and ROS 2 (directory, ``.db3``, ``.mcap``) bags via the pure-Python ``rosbags``.

Message types and what they become (details and conventions in docs/live.md, "ROS bags"):

==========================  =================================================================
``sensor_msgs/LaserScan``   ``scan``: angles ``angle_min + i * angle_increment``; ranges outside
                            ``[range_min, range_max]`` or non-finite become NaN (no return);
                            a non-zero ``time_increment`` gives ``meta["lidar"]["sweep_s"] =
                            time_increment * len(ranges)`` (median over the scans; the stamp is
                            the first beam's, docs/log-format.md "LiDAR sweep")
``sensor_msgs/NavSatFix``   ``gnss`` in the local tangent frame (origin: ``origin`` or the first
                            fix, in ``meta["origin"]``); ``sigma = sqrt(mean(cov_xx, cov_yy))``
                            when the covariance is known, else ``DEFAULT_GNSS_SIGMA``; status
                            ``NO_FIX`` and NaN positions are skipped (``meta["no_fix"]``)
``sensor_msgs/Imu``         ``imu`` (REP-103 body axes = ours) unless the message marks angular
                            velocity unknown (covariance[0] = -1): 6-axis (ax, ay, az, wx, wy,
                            wz, gravity included) when it carries real z/x/y axes (linear
                            acceleration known, and az, wx, wy not all exactly 0, which is what a
                            planar source writes), else planar (ax, ay, wz); plus ``heading``
                            from the orientation (REP-103 ENU yaw = ours) when it is given
                            (orientation covariance[0] != -1, non-zero quaternion), at most
                            ``imu_heading_hz`` per topic
``geometry_msgs/``          ``gnss_velocity``: ``twist.linear.x`` east, ``.y`` north [m/s] (a GNSS
``TwistWithCovariance``     driver's velocity in ENU, as ublox_gps's ``fix_velocity``); ``sigma =
``Stamped``                 sqrt(mean(cov_xx, cov_yy))`` when positive, else NaN
``nav_msgs/Odometry``       ``odometry``: ``v = twist.linear.x`` (forward), ``w = twist.angular.z``,
                            sigmas from the twist covariance when positive
``sensor_msgs/PointCloud2`` ``cloud`` (sensor frame, :mod:`graphnav.log` ``Cloud``): fields ``x``,
                            ``y``, ``z`` (any numeric type), ``intensity`` and ``ring`` when present;
                            non-finite points dropped; a ``data`` shorter than ``height * row_step``
                            or fields past ``point_step`` are refused before anything is read
``nmea_msgs/Sentence``      the NMEA decoder (:mod:`graphnav.io.nmea`), records stamped with the
                            message header time (as nmea_navsat_driver does)
==========================  =================================================================

Time is the message ``header.stamp`` (POSIX seconds) when non-zero, else the bag's receive time.
Topics are found by message type; with several topics of one type the one with the most messages
is used (the others are listed in ``meta["topics"]`` with ``"used_as": null``), except ``Imu``:
every IMU topic is read (each gives what it carries; pick one with ``imu=``/``heading=``). An NMEA
topic is read only when there is no NavSatFix topic (they would repeat the same fixes). ``topics``
(``{"scan": "/lidar/scan", ...}``) overrides the choice per kind.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import GraphnavError, LogError, require
from ..geodesy import LocalFrame
from ..geometry import wrap_angle
from ..log import (
    MAX_CLOUD_POINTS,
    MAX_STATED_RANGE,
    Cloud,
    Gnss,
    GnssVelocity,
    Heading,
    Imu,
    Limits,
    NavLog,
    Odometry,
    Record,
    Scan,
    check_record,
    make_cloud,
)
from .nmea import NmeaDecoder, parse_sentence

DEFAULT_GNSS_SIGMA = 3.0  # [m] NavSatFix with COVARIANCE_TYPE_UNKNOWN
DEFAULT_IMU_HEADING_SIGMA_DEG = 2.0
KINDS = {
    "sensor_msgs/msg/LaserScan": "scan",
    "sensor_msgs/msg/NavSatFix": "gnss",
    "sensor_msgs/msg/Imu": "imu",
    "nav_msgs/msg/Odometry": "odometry",
    "nmea_msgs/msg/Sentence": "nmea",
    "sensor_msgs/msg/PointCloud2": "cloud",
    "geometry_msgs/msg/TwistWithCovarianceStamped": "gnss_velocity",
}
#: PointField datatype codes -> numpy (little-endian; ``is_bigendian`` swaps)
POINTFIELD_DTYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
NMEA_SENTENCE_MSG = "std_msgs/Header header\nstring sentence\n"


def typestore(ros1: bool = False):
    """A rosbags typestore (ROS 1 Noetic or ROS 2 Humble) that also knows ``nmea_msgs/msg/Sentence``."""
    require("rosbags", "reading and writing ROS bags")
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    ts.register(get_types_from_msg(NMEA_SENTENCE_MSG, "nmea_msgs/msg/Sentence"))
    return ts


def parse_topic_args(items: list[str] | None) -> dict[str, str]:
    """``["scan=/lidar/scan", "gnss=/fix"]`` -> ``{"scan": "/lidar/scan", "gnss": "/fix"}``."""
    out: dict[str, str] = {}
    for item in items or []:
        kind, sep, topic = item.partition("=")
        if not sep or kind not in set(KINDS.values()) | {"heading"} or not topic:
            raise ValueError(f"--topic {item!r}: expected KIND=TOPIC with KIND one of "
                             f"{', '.join(sorted(set(KINDS.values()) | {'heading'}))}")
        out[kind] = topic
    return out


def _stamp(msg: Any, bag_ns: int) -> float:
    h = getattr(msg, "header", None)
    if h is not None and (h.stamp.sec or h.stamp.nanosec):
        return h.stamp.sec + h.stamp.nanosec * 1e-9
    return bag_ns * 1e-9


def yaw_of_quaternion(x: float, y: float, z: float, w: float) -> float:
    """Yaw (rotation about +z) of a quaternion, radians."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def roll_pitch_of_quaternion(x: float, y: float, z: float, w: float) -> tuple[float, float]:
    """Roll and pitch (ZYX Euler angles, REP-103) of a quaternion, radians."""
    n = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    return roll, pitch


#: An IMU orientation at most this far in time from a cloud [s] gives the cloud's roll and pitch.
ATTITUDE_MAX_DT = 0.05


def attach_attitude(records: list[Record], attitude: list[tuple[float, float, float]],
                    max_dt: float = ATTITUDE_MAX_DT) -> int:
    """Give each cloud without an attitude the roll/pitch of the nearest IMU orientation within
    ``max_dt`` (the IMU taken as mounted like the LiDAR); returns how many clouds got one."""
    if not attitude:
        return 0
    a = np.array(sorted(attitude))
    n = 0
    for i, r in enumerate(records):
        if isinstance(r, Cloud) and math.isnan(r.roll) and math.isnan(r.pitch):
            j = int(np.clip(np.searchsorted(a[:, 0], r.t), 1, len(a) - 1)) if len(a) > 1 else 0
            if len(a) > 1 and abs(a[j - 1, 0] - r.t) <= abs(a[j, 0] - r.t):
                j -= 1
            if abs(a[j, 0] - r.t) <= max_dt:
                records[i] = replace(r, roll=float(a[j, 1]), pitch=float(a[j, 2]))
                n += 1
    return n


class _Converter:
    def __init__(self, origin: tuple[float, float] | None, imu_heading_hz: float | None,
                 limits: Limits | None = None) -> None:
        self.frame = LocalFrame(float(origin[0]), float(origin[1])) if origin else None
        self.imu_heading_dt = 1.0 / imu_heading_hz if imu_heading_hz else 0.0
        self.last_imu_heading: dict[str, float] = {}
        self.nmea = NmeaDecoder(self.frame, keep=False, limits=limits)
        self.counts: dict[str, int] = {}
        self.attitude: list[tuple[float, float, float]] = []  # (t, roll, pitch) of IMU orientations
        self.sweeps: list[float] = []  # [s] time_increment x beams of each LaserScan that states a time_increment

    def count(self, k: str) -> None:
        self.counts[k] = self.counts.get(k, 0) + 1

    def scan(self, m, t: float, topic: str) -> list[Record]:
        r = np.asarray(m.ranges, dtype=float).copy()
        r[~np.isfinite(r) | (r < m.range_min) | (r > m.range_max)] = np.nan
        a = m.angle_min + m.angle_increment * np.arange(r.size)
        if math.isfinite(m.time_increment) and m.time_increment != 0.0:  # a sweeping sensor: its beams' times
            self.sweeps.append(float(m.time_increment) * r.size)
        top = float(m.range_max)  # the sensor's stated range, when it is one a log may state
        return [Scan(t, r, a, top if 0.0 < top <= MAX_STATED_RANGE else math.nan)]

    def cloud(self, m, t: float, topic: str) -> list[Record]:
        return [pointcloud2_to_cloud(m, t)]

    def gnss(self, m, t: float, topic: str) -> list[Record]:
        if m.status.status < 0 or not (math.isfinite(m.latitude) and math.isfinite(m.longitude)):
            self.count("no_fix")
            return []
        if self.frame is None:
            self.frame = LocalFrame(float(m.latitude), float(m.longitude))
            self.nmea.frame = self.frame
        x, y = self.frame.to_local(m.latitude, m.longitude)
        cov = np.asarray(m.position_covariance, dtype=float)
        sigma = DEFAULT_GNSS_SIGMA
        if m.position_covariance_type > 0 and cov[0] > 0 and cov[4] > 0:
            sigma = math.sqrt(0.5 * (cov[0] + cov[4]))
        return [Gnss(t, float(x), float(y), sigma)]

    def imu(self, m, t: float, topic: str) -> list[Record]:
        out: list[Record] = []
        if m.angular_velocity_covariance[0] != -1:
            a, w = m.linear_acceleration, m.angular_velocity
            rec = Imu(t, float(a.x), float(a.y), float(w.z))
            if m.linear_acceleration_covariance[0] != -1 and (a.z != 0.0 or w.x != 0.0 or w.y != 0.0):
                rec = replace(rec, az=float(a.z), wx=float(w.x), wy=float(w.y))
                self.count("imu_six_axis")
            out.append(rec)
        q = m.orientation
        if m.orientation_covariance[0] != -1 and (q.x or q.y or q.z or q.w):
            self.attitude.append((t, *roll_pitch_of_quaternion(q.x, q.y, q.z, q.w)))
            if t - self.last_imu_heading.get(topic, -math.inf) >= 0.999 * self.imu_heading_dt:
                c = m.orientation_covariance[8]
                sigma = math.sqrt(c) if c > 0 else math.radians(DEFAULT_IMU_HEADING_SIGMA_DEG)
                out.append(Heading(t, float(wrap_angle(yaw_of_quaternion(q.x, q.y, q.z, q.w))), sigma))
                self.last_imu_heading[topic] = t
        return out

    def gnss_velocity(self, m, t: float, topic: str) -> list[Record]:
        cov = np.asarray(m.twist.covariance, dtype=float)
        sigma = math.sqrt(0.5 * (cov[0] + cov[7])) if cov[0] > 0 and cov[7] > 0 else math.nan
        v = m.twist.twist.linear
        return [GnssVelocity(t, float(v.x), float(v.y), sigma)]

    def odometry(self, m, t: float, topic: str) -> list[Record]:
        cov = np.asarray(m.twist.covariance, dtype=float)
        sv = math.sqrt(cov[0]) if cov[0] > 0 else math.nan
        sw = math.sqrt(cov[35]) if cov[35] > 0 else math.nan
        return [Odometry(t, float(m.twist.twist.linear.x), float(m.twist.twist.angular.z), sv, sw)]

    def nmea_(self, m, t: float, topic: str) -> list[Record]:
        recs = self.nmea.feed(parse_sentence(m.sentence.strip()))
        if self.frame is None and self.nmea.frame is not None:
            self.frame = self.nmea.frame
        return [replace(r, t=t) for r in recs]


def pointcloud2_to_cloud(m: Any, t: float) -> Cloud:
    """A ``sensor_msgs/PointCloud2`` as a :class:`~graphnav.log.Cloud` (see the module doc)."""
    n = int(m.height) * int(m.width)
    step = int(m.point_step)
    if n > MAX_CLOUD_POINTS:
        raise LogError(f"{n} points, more than {MAX_CLOUD_POINTS}", field="width")
    data = np.asarray(m.data, dtype=np.uint8)
    if n and (step <= 0 or int(m.row_step) < step * int(m.width) or data.size < int(m.row_step) * int(m.height)):
        raise LogError(f"data holds {data.size} bytes, less than height x row_step = {int(m.height)} x "
                       f"{int(m.row_step)} (point_step {step}, width {int(m.width)})", field="data")
    by_name = {f.name: f for f in m.fields}
    missing = [c for c in "xyz" if c not in by_name]
    if missing:
        raise LogError(f"PointCloud2 has no {', '.join(missing)} field", field="fields")
    end = ">" if m.is_bigendian else "<"
    names, formats, offsets = [], [], []
    for name in ("x", "y", "z", "intensity", "ring"):
        f = by_name.get(name)
        if f is None:
            continue
        code = POINTFIELD_DTYPES.get(int(f.datatype))
        if code is None:
            raise LogError(f"field {name!r} has unknown datatype {f.datatype}", field="fields")
        if int(f.offset) + np.dtype(code).itemsize > step:
            raise LogError(f"field {name!r} at offset {f.offset} runs past point_step {step}", field="fields")
        names.append(name)
        formats.append(end + code)
        offsets.append(int(f.offset))
    dt = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": step})
    rows = [np.frombuffer(data[r * int(m.row_step): r * int(m.row_step) + step * int(m.width)].tobytes(), dt)
            for r in range(int(m.height))] if n else [np.zeros(0, dt)]
    a = np.concatenate(rows)
    pts = np.column_stack([a["x"], a["y"], a["z"]]).astype(np.float64)
    keep = np.all(np.isfinite(pts), axis=1)
    inten = a["intensity"][keep] if "intensity" in names else None
    if inten is not None and not np.all(np.isfinite(inten)):
        raise LogError("non-finite intensity of a finite point", field="intensity")
    ring = a["ring"][keep] if "ring" in names else None
    if ring is not None and not np.issubdtype(ring.dtype, np.integer):
        raise LogError(f"ring must be an integer field, got {ring.dtype}", field="ring")
    return make_cloud(t, pts[keep], inten, ring)


def cloud_to_pointcloud2(ts: Any, c: Cloud, header: Any) -> Any:
    """A :class:`~graphnav.log.Cloud` as an unorganised (height 1) little-endian ``PointCloud2``:
    x, y, z float32, then intensity float32 and ring uint16 when the cloud has them."""
    T = ts.types
    PF = T["sensor_msgs/msg/PointField"]
    names, formats, fields = ["x", "y", "z"], ["<f4"] * 3, []
    if c.intensity is not None:
        names.append("intensity")
        formats.append("<f4")
    if c.ring is not None:
        names.append("ring")
        formats.append("<u2")
    dt = np.dtype({"names": names, "formats": formats})
    codes = {"<f4": 7, "<u2": 4}
    for name, fmt in zip(names, formats, strict=True):
        fields.append(PF(name=name, offset=dt.fields[name][1], datatype=codes[fmt], count=1))
    a = np.zeros(len(c), dt)
    a["x"], a["y"], a["z"] = c.points[:, 0], c.points[:, 1], c.points[:, 2]
    if c.intensity is not None:
        a["intensity"] = c.intensity
    if c.ring is not None:
        a["ring"] = c.ring
    return T["sensor_msgs/msg/PointCloud2"](
        header=header, height=1, width=len(c), fields=fields, is_bigendian=False, point_step=dt.itemsize,
        row_step=dt.itemsize * len(c), data=np.frombuffer(a.tobytes(), np.uint8), is_dense=True)


def bag_topics(path: str | Path) -> dict[str, dict[str, Any]]:
    """``{topic: {"type": msgtype, "count": n}}`` of a bag, without reading messages."""
    with _open(Path(path)) as reader:
        return {c.topic: {"type": c.msgtype, "count": c.msgcount} for c in reader.connections}


def check_ros1_lengths(path: Path) -> None:
    """Walk a ROS 1 bag's top-level records (``header_len, header, data_len, data``) and refuse one
    whose declared length runs past the end of the file: rosbags reads a declared length in one
    call, which allocates that many bytes first (a damaged length of 0x06000000 cost 96 MiB)."""
    if not path.is_file():
        return
    size = path.stat().st_size
    with open(path, "rb") as f:
        if f.read(13) != b"#ROSBAG V2.0\n":
            return
        pos = 13
        while pos < size:
            for part in ("header", "data"):
                f.seek(pos)
                raw = f.read(4)
                n = int.from_bytes(raw, "little") if len(raw) == 4 else -1
                if n < 0 or pos + 4 + n > size:
                    raise LogError(f"damaged ROS bag: a record's {part} length runs past the end of the file "
                                   f"(at byte {pos})", file=str(path), field=f"{part}_len")
                pos += 4 + n


@contextmanager
def _open(path: Path) -> Iterator[Any]:
    require("rosbags", "reading ROS bags")
    from rosbags.highlevel import AnyReader

    check_ros1_lengths(path)
    try:
        reader = AnyReader([path], default_typestore=typestore())
        reader.open()
    except Exception as exc:  # rosbags raises many types for damaged files
        raise LogError(f"cannot read ROS bag: {exc.__class__.__name__}: {str(exc)[:200]}",
                       file=str(path)) from None
    try:
        yield reader
    finally:
        reader.close()


def choose_topics(conns: list[tuple[str, str, int]], topics: dict[str, str] | None) -> dict[str, str]:
    """``{topic: kind}`` to read from ``(topic, msgtype, count)`` triples (see the module doc)."""
    topics = dict(topics or {})
    chosen: dict[str, str] = {}
    by_topic = {t: (ty, n) for t, ty, n in conns}
    for kind, topic in topics.items():
        if topic not in by_topic:
            have = ", ".join(sorted(by_topic))
            raise LogError(f"topic {topic!r} for {kind} is not in the bag (has: {have})",
                           field="topic")
        ty = by_topic[topic][0]
        want = "imu" if kind == "heading" else kind
        if KINDS.get(ty) != want:
            raise LogError(f"topic {topic!r} has type {ty}, not a {kind} type", field="topic")
        chosen[topic] = kind
    taken = set(topics)
    if taken & {"imu", "heading"}:
        taken |= {"imu", "heading"}
    for kind in sorted(set(KINDS.values()) - taken):
        cands = sorted(((n, t) for t, ty, n in conns if KINDS.get(ty) == kind), key=lambda c: (-c[0], c[1]))
        if (kind == "nmea" and "gnss" in chosen.values()) or (kind == "gnss" and "nmea" in topics):
            continue  # the NMEA stream would repeat the NavSatFix fixes
        if kind == "imu":  # every IMU topic: each gives what it has (rates, orientation or both)
            chosen.update({t: "imu" for _, t in cands})
        elif cands:
            chosen[cands[0][1]] = kind
    return chosen


def read_bag(path: str | Path, topics: dict[str, str] | None = None, *,
             origin: tuple[float, float] | None = None,
             imu_heading_hz: float | None = 10.0, lenient: bool = False, limits: Limits | None = None) -> NavLog:
    """Read a ROS 1/ROS 2 bag into a :class:`NavLog` (see the module docstring).

    ``topics`` maps a kind (``scan``, ``cloud``, ``gnss``, ``imu``, ``heading``, ``odometry``, ``nmea``) to a
    topic name. A damaged bag raises :class:`LogError` naming the file; with ``lenient`` a message
    that cannot be decoded, or gives a physically invalid record (:func:`graphnav.log.check_record`,
    ``limits``), is skipped and counted in ``meta["skipped"]``.
    """
    path = Path(path)
    conv = _Converter(origin, imu_heading_hz, limits)
    records: list[Record] = []
    skipped: list[str] = []
    with _open(path) as reader:
        conns = [(c.topic, c.msgtype, c.msgcount) for c in reader.connections]
        chosen = choose_topics(conns, topics)
        handlers = {"scan": conv.scan, "gnss": conv.gnss, "imu": conv.imu, "heading": conv.imu,
                    "odometry": conv.odometry, "nmea": conv.nmea_, "cloud": conv.cloud,
                    "gnss_velocity": conv.gnss_velocity}
        wanted = [c for c in reader.connections if c.topic in chosen]
        try:
            for i, (conn, ns, raw) in enumerate(reader.messages(connections=wanted)):
                kind = chosen[conn.topic]
                try:
                    msg = reader.deserialize(raw, conn.msgtype)
                    recs = handlers[kind](msg, _stamp(msg, ns), conn.topic)
                    if kind == "heading":
                        recs = [r for r in recs if isinstance(r, Heading)]
                    for r in recs:
                        check_record(r, limits)
                    records.extend(recs)
                except LogError as err:
                    err = LogError(err.message, file=str(path), line=i + 1, field=f"{conn.topic}/{err.field}")
                    if not lenient:
                        raise err from None
                    skipped.append(str(err))
                except Exception as exc:  # a message the typestore cannot decode
                    why = f"{exc.__class__.__name__}: {str(exc)[:80]}"
                    err = LogError(f"cannot decode message {i + 1} ({why})",
                                   file=str(path), field=conn.topic)
                    if not lenient:
                        raise err from None
                    skipped.append(str(err))
        except LogError:
            raise
        except Exception as exc:
            raise LogError(f"damaged ROS bag: {exc.__class__.__name__}: {str(exc)[:200]}",
                           file=str(path)) from None
    meta: dict[str, Any] = {
        "source": str(path), "format": "rosbag",
        "topics": {t: {"type": ty, "count": n, "used_as": chosen.get(t)} for t, ty, n in sorted(conns)},
    }
    if conv.frame is not None:
        meta["origin"] = {"lat": conv.frame.lat0, "lon": conv.frame.lon0, "h": conv.frame.h0}
    if conv.counts:
        meta.update(conv.counts)
    if conv.sweeps:  # the LiDAR's sweep (docs/log-format.md "LiDAR sweep"): beam i of N at stamp + i * sweep_s / N
        meta["lidar"] = {"sweep_s": float(np.median(conv.sweeps))}
    if any(isinstance(r, Cloud) for r in records):
        meta["clouds_with_imu_attitude"] = attach_attitude(records, conv.attitude)
    if lenient:
        meta["skipped"] = len(skipped)
        meta["skipped_errors"] = skipped[:20]
    return NavLog.from_unsorted(records, (), meta)


# ----------------------------------------------------------------------------- writer

def _header(ts, t: float, frame_id: str, ros1: bool):
    Time = ts.types["builtin_interfaces/msg/Time"]
    Header = ts.types["std_msgs/msg/Header"]
    sec = int(math.floor(t))
    stamp = Time(sec=sec, nanosec=int(round((t - sec) * 1e9)) % 1_000_000_000)
    return Header(seq=0, stamp=stamp, frame_id=frame_id) if ros1 else Header(stamp=stamp, frame_id=frame_id)


def write_bag(log: NavLog, path: str | Path, *, storage: str = "sqlite3",
              origin: tuple[float, float] | None = None,
              nmea_sentences: list[tuple[float, str]] | None = None) -> Path:
    """Write a log as a bag: ``*.bag`` -> ROS 1, anything else -> a ROS 2 bag directory
    (``storage`` ``"sqlite3"`` or ``"mcap"``). scan -> ``/scan`` LaserScan (uniform beams needed),
    cloud -> ``/points`` PointCloud2,
    gnss -> ``/fix`` NavSatFix, imu -> ``/imu`` Imu (6-axis records with their z/x/y axes), heading ->
    ``/heading`` Imu with orientation only, odometry -> ``/odom`` Odometry, gnss_velocity ->
    ``/gnss_vel`` TwistWithCovarianceStamped (ENU), ``nmea_sentences`` -> ``/nmea_sentence``. For tests,
    demos and converting logs for ROS tools.

    All or nothing: the bag is written in a private directory beside ``path`` and renamed onto it when
    complete; a failure (a record it cannot write) leaves nothing behind. ``path`` must not exist.
    Beams count as uniformly spaced within :data:`BEAM_SPACING_TOL` (angles rounded to 1e-4 rad, as the
    JSON Lines writer stores them, are)."""
    import shutil

    from .outputs import TMP_PREFIX, file_kind

    path = Path(path)
    if file_kind(path) is not None:
        raise GraphnavError("exists: a bag is never written over anything", where=str(path))
    work = path.parent / f"{TMP_PREFIX}{os.getpid()}-{path.name}.d"
    work.mkdir()
    try:
        _write_bag(log, work / path.name, storage=storage, origin=origin, nmea_sentences=nmea_sentences)
        os.replace(work / path.name, path)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return path


#: [rad] a scan's beams are uniformly spaced (a LaserScan) when every spacing is within this of the mean:
#: three times the 0.5e-4 rad rounding of the JSON Lines writer
BEAM_SPACING_TOL = 1.5e-4


def _write_bag(log: NavLog, path: Path, *, storage: str, origin: tuple[float, float] | None,
               nmea_sentences: list[tuple[float, str]] | None) -> None:
    from .nmea_out import frame_of

    ros1 = path.suffix == ".bag"
    ts = typestore(ros1)
    T = ts.types
    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    frame = frame_of(log, origin)
    unknown9 = np.array([-1.0] + [0.0] * 8)
    if ros1:
        from rosbags.rosbag1 import Writer as W1

        writer = W1(path)
        ser = ts.serialize_ros1
    else:
        from rosbags.rosbag2 import StoragePlugin
        from rosbags.rosbag2 import Writer as W2

        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        writer = W2(path, version=9, storage_plugin=plugin)
        ser = ts.serialize_cdr
    with writer:
        conns: dict[str, Any] = {}

        def put(topic: str, msgtype: str, t: float, msg) -> None:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[topic], int(round(t * 1e9)), ser(msg, msgtype))

        def imu_msg(t, ax=0.0, ay=0.0, wz=0.0, yaw=None, sigma=None, az=0.0, wx=0.0, wy=0.0):
            ori = Q(x=0.0, y=0.0, z=0.0, w=0.0)
            ocov = unknown9.copy()
            if yaw is not None:
                ori = Q(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
                ocov = np.diag([1e-2, 1e-2, sigma ** 2]).ravel()
            acov = unknown9.copy() if yaw is not None else np.zeros(9)
            return T["sensor_msgs/msg/Imu"](
                header=_header(ts, t, "base_link", ros1), orientation=ori, orientation_covariance=ocov,
                angular_velocity=V3(x=wx, y=wy, z=wz), angular_velocity_covariance=acov,
                linear_acceleration=V3(x=ax, y=ay, z=az), linear_acceleration_covariance=acov)

        lidar = log.meta.get("lidar") if isinstance(log.meta.get("lidar"), dict) else {}
        sweep = float(lidar.get("sweep_s", 0.0) or 0.0)
        for r in log.records:
            if isinstance(r, Scan):
                a = r.angles
                inc = float((a[-1] - a[0]) / (a.size - 1)) if a.size > 1 else 0.0
                if a.size > 2 and not np.allclose(np.diff(a), inc, rtol=0.0, atol=BEAM_SPACING_TOL):
                    raise LogError(f"a LaserScan needs uniformly spaced beams (within {BEAM_SPACING_TOL:g} rad); "
                                   f"the scan at t={r.t:.9g} has spacings {np.diff(a).min():.6g} .. "
                                   f"{np.diff(a).max():.6g} rad", field="angles")
                ranges = np.where(r.valid(), r.ranges, np.inf).astype(np.float32)
                put("/scan", "sensor_msgs/msg/LaserScan", r.t, T["sensor_msgs/msg/LaserScan"](
                    header=_header(ts, r.t, "laser", ros1), angle_min=float(a[0]) if a.size else 0.0,
                    angle_max=float(a[-1]) if a.size else 0.0, angle_increment=inc,
                    time_increment=sweep / a.size if a.size else 0.0, scan_time=0.0, range_min=0.0,
                    range_max=float(r.max_range), ranges=ranges,
                    intensities=np.zeros(0, dtype=np.float32)))
            elif isinstance(r, Cloud):
                put("/points", "sensor_msgs/msg/PointCloud2", r.t,
                    cloud_to_pointcloud2(ts, r, _header(ts, r.t, "lidar", ros1)))
            elif isinstance(r, Gnss):
                lat, lon = frame.to_geodetic(r.x, r.y)
                put("/fix", "sensor_msgs/msg/NavSatFix", r.t, T["sensor_msgs/msg/NavSatFix"](
                    header=_header(ts, r.t, "gps", ros1),
                    status=T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
                    latitude=float(lat), longitude=float(lon), altitude=0.0,
                    position_covariance=np.diag([r.sigma ** 2, r.sigma ** 2, (2 * r.sigma) ** 2]).ravel(),
                    position_covariance_type=2))
            elif isinstance(r, Imu):
                six = r.six_axis
                put("/imu", "sensor_msgs/msg/Imu", r.t, imu_msg(r.t, r.ax, r.ay, r.wz, az=r.az if six else 0.0,
                                                                wx=r.wx if six else 0.0, wy=r.wy if six else 0.0))
            elif isinstance(r, GnssVelocity):
                cov = np.zeros(36)
                if math.isfinite(r.sigma):
                    cov[0] = cov[7] = r.sigma ** 2
                tw = T["geometry_msgs/msg/Twist"](linear=V3(x=r.vx, y=r.vy, z=0.0), angular=V3(x=0.0, y=0.0, z=0.0))
                put("/gnss_vel", "geometry_msgs/msg/TwistWithCovarianceStamped", r.t,
                    T["geometry_msgs/msg/TwistWithCovarianceStamped"](
                        header=_header(ts, r.t, "enu", ros1),
                        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=cov)))
            elif isinstance(r, Heading):
                put("/heading", "sensor_msgs/msg/Imu", r.t, imu_msg(r.t, yaw=r.yaw, sigma=r.sigma))
            elif isinstance(r, Odometry):
                cov = np.zeros(36)
                cov[0] = r.sigma_v ** 2 if math.isfinite(r.sigma_v) else 0.0
                cov[35] = r.sigma_w ** 2 if math.isfinite(r.sigma_w) else 0.0
                P = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                                                orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0))
                tw = T["geometry_msgs/msg/Twist"](linear=V3(x=r.v, y=0.0, z=0.0),
                                                  angular=V3(x=0.0, y=0.0, z=r.w))
                put("/odom", "nav_msgs/msg/Odometry", r.t, T["nav_msgs/msg/Odometry"](
                    header=_header(ts, r.t, "odom", ros1), child_frame_id="base_link",
                    pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=P, covariance=np.zeros(36)),
                    twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=cov)))
        for t, s in nmea_sentences or []:
            put("/nmea_sentence", "nmea_msgs/msg/Sentence", t, T["nmea_msgs/msg/Sentence"](
                header=_header(ts, t, "gps", ros1), sentence=s))
