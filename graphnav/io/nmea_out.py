"""NMEA 0183 output: pure functions that build sentences with pynmea2 (which renders them and
computes their checksums); this module only formats the field values.

Internal quantities (SI, yaw CCW from east) are converted at this edge: headings/courses to
degrees clockwise from north, speed to knots, rate of turn to degrees per minute positive to
starboard (``ROT = -degrees(w) * 60``). Times are POSIX seconds (UTC); a log whose times are not
POSIX maps ``t = 0`` to 1970-01-01 00:00:00, which :func:`graphnav.io.nmea.read_nmea` maps back.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from datetime import UTC, datetime

import numpy as np
import pynmea2

from ..geodesy import LocalFrame
from ..geometry import wrap_angle, yaw_to_heading_deg
from ..log import Gnss, Heading, NavLog, Odometry
from .nmea_fields import KNOT, UERE_M

#: Origin used when a log has no geodetic origin (meta["origin"]): documented, arbitrary.
DEFAULT_ORIGIN = (43.5, 16.4)


def checksum(body: str) -> str:
    """XOR of the characters between ``$`` and ``*`` (pynmea2's), two upper-case hex digits."""
    return f"{pynmea2.NMEASentence.checksum(body):02X}"


def sentence(body: str) -> str:
    """``$BODY*CS`` (no line terminator) for any comma-separated body (tests build odd ones)."""
    return f"${body}*{checksum(body)}"


def _render(talker: str, kind: str, fields: Sequence[str]) -> str:
    """One sentence built and rendered by pynmea2 (``$TTKKK,fields*CS``)."""
    return pynmea2.TalkerSentence.sentence_types[kind](talker, kind, list(fields)).render()


def _utc(t: float) -> datetime:
    return datetime.fromtimestamp(round(t, 3), UTC)


def _hhmmss(t: float) -> str:
    d = _utc(t)
    return f"{d.hour:02d}{d.minute:02d}{d.second:02d}.{d.microsecond // 1000:03d}"


def _ddmm(value: float, lat: bool, decimals: int = 7) -> tuple[str, str]:
    hemi = ("N" if value >= 0 else "S") if lat else ("E" if value >= 0 else "W")
    a = abs(value)
    deg = int(a)
    minutes = round((a - deg) * 60.0, decimals)
    if minutes >= 60.0:
        deg, minutes = deg + 1, 0.0
    nd = 2 if lat else 3
    return f"{deg:0{nd}d}{minutes:0{3 + decimals}.{decimals}f}", hemi


def _opt(v: float | None, fmt: str) -> str:
    return "" if v is None or not math.isfinite(v) else format(v, fmt)


def gga(t: float, lat: float, lon: float, *, quality: int = 1, sats: int = 10, hdop: float = 1.0,
        alt: float = 0.0, talker: str = "GN") -> str:
    """GGA fix: time, position (0.1 mm precision), quality, satellites, HDOP, altitude."""
    la, ns = _ddmm(lat, True)
    lo, ew = _ddmm(lon, False)
    return _render(talker, "GGA", [_hhmmss(t), la, ns, lo, ew, f"{quality:d}", f"{sats:02d}", f"{hdop:.2f}",
                                   f"{alt:.1f}", "M", "0.0", "M", "", ""])


def rmc(t: float, lat: float, lon: float, sog: float | None = None, cog_yaw: float | None = None, *,
        mode: str = "A", talker: str = "GN") -> str:
    """RMC: time, status A, position, SOG [m/s -> kn], COG [yaw -> deg true], date, mode."""
    la, ns = _ddmm(lat, True)
    lo, ew = _ddmm(lon, False)
    c = None if cog_yaw is None else yaw_to_heading_deg(cog_yaw)
    s = None if sog is None else sog / KNOT
    return _render(talker, "RMC", [_hhmmss(t), "A", la, ns, lo, ew, _opt(s, ".3f"), _opt(c, ".2f"),
                                   f"{_utc(t):%d%m%y}", "", "", mode])


def no_fix_sentences(t: float, talker: str = "GN") -> list[str]:
    """The "no solution" pair at ``t``: GGA with quality 0 and no position, RMC with status V (void) and
    mode N (data not valid), as a receiver says it has lost its fix."""
    return [_render(talker, "GGA", [_hhmmss(t), "", "", "", "", "0", "00", "", "", "", "", "", "", ""]),
            _render(talker, "RMC", [_hhmmss(t), "V", "", "", "", "", "", "", f"{_utc(t):%d%m%y}", "", "", "N"])]


def zda(t: float, talker: str = "GN") -> str:
    """ZDA: UTC time and date (local zone 00:00)."""
    d = _utc(t)
    return _render(talker, "ZDA", [_hhmmss(t), f"{d.day:02d}", f"{d.month:02d}", f"{d.year:04d}", "00", "00"])


def hdt(yaw: float, talker: str = "HE") -> str:
    """HDT true heading [yaw rad -> deg clockwise from north, 0.01 deg]."""
    return _render(talker, "HDT", [f"{yaw_to_heading_deg(yaw):.2f}", "T"])


def vtg(sog: float, cog_yaw: float | None = None, talker: str = "GN") -> str:
    """VTG: course over ground (true) and speed in knots and km/h; mode A."""
    c = None if cog_yaw is None else yaw_to_heading_deg(cog_yaw)
    return _render(talker, "VTG", [_opt(c, ".2f"), "T", "", "M", f"{sog / KNOT:.3f}", "N", f"{sog * 3.6:.3f}",
                                   "K", "A"])


def rot(w: float, talker: str = "TI") -> str:
    """ROT: rate of turn [rad/s CCW -> deg/min, positive to starboard], status A."""
    return _render(talker, "ROT", [f"{-math.degrees(w) * 60.0:.3f}", "A"])


def frame_of(log: NavLog, origin: tuple[float, float] | None = None) -> LocalFrame:
    """The log's local frame: ``origin`` if given, else ``meta["origin"]``, else :data:`DEFAULT_ORIGIN`."""
    if origin is not None:
        return LocalFrame(float(origin[0]), float(origin[1]))
    o = log.meta.get("origin")
    if isinstance(o, dict) and "lat" in o and "lon" in o:
        return LocalFrame(float(o["lat"]), float(o["lon"]), float(o.get("h", 0.0)))
    return LocalFrame(*DEFAULT_ORIGIN)


def hdop_of(sigma: float, quality: int = 1) -> float:
    """Inverse of the reader's ``sigma = HDOP * UERE(quality)``."""
    return sigma / UERE_M[quality]


def log_to_nmea(log: NavLog, *, origin: tuple[float, float] | None = None, quality: int = 1,
                with_rmc: bool = False) -> Iterator[tuple[float, str]]:
    """Timestamped sentences ``(t, sentence)`` from a log's gnss, heading and odometry records.

    Every new time first gets a ZDA (time and date) so untimed sentences (HDT, VTG, ROT) are
    stamped right when read back. gnss -> GGA (HDOP = sigma / UERE(quality)), heading -> HDT,
    odometry -> VTG (SOG, no course) + ROT. ``with_rmc`` adds an RMC after each GGA (as
    receivers do; the reader keeps one fix per epoch).
    """
    frame = frame_of(log, origin)
    fixes = [r for r in log.records if isinstance(r, Gnss)]
    lats, lons = frame.to_geodetic(np.array([r.x for r in fixes]), np.array([r.y for r in fixes]))  # all at once
    geo = {id(r): (float(la), float(lo)) for r, la, lo in zip(fixes, np.atleast_1d(lats), np.atleast_1d(lons),
                                                               strict=True)}
    last_t = None
    for r in log.records:
        if not isinstance(r, Gnss | Heading | Odometry):
            continue
        if r.t != last_t:
            yield r.t, zda(r.t)
            last_t = r.t
        if isinstance(r, Gnss):
            lat, lon = geo[id(r)]
            yield r.t, gga(r.t, lat, lon, quality=quality, hdop=hdop_of(r.sigma, quality))
            if with_rmc:
                yield r.t, rmc(r.t, lat, lon)
        elif isinstance(r, Heading):
            yield r.t, hdt(r.yaw)
        else:
            yield r.t, vtg(r.v)
            yield r.t, rot(r.w)


def solution_sentences(t: float, pose: np.ndarray, frame: LocalFrame, *, sog: float | None = None,
                       cog_yaw: float | None = None, w: float | None = None, hdop: float = 1.0,
                       quality: int = 1) -> list[str]:
    """The navigation solution at one time as GGA, HDT, VTG and ROT (those whose inputs are known)."""
    lat, lon = frame.to_geodetic(pose[0], pose[1])
    out = [gga(t, float(lat), float(lon), quality=quality, hdop=hdop), hdt(float(pose[2]))]
    if sog is not None:
        out.append(vtg(sog, cog_yaw))
    if w is not None:
        out.append(rot(w))
    return out


#: The sentences :func:`trajectory_to_nmea` writes per pose by default (replay, tests).
TRAJECTORY_SENTENCES = ("ZDA", "GGA", "HDT", "VTG", "ROT")


def trajectory_rates(t: np.ndarray, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """SOG [m/s], COG [yaw rad] and yaw rate [rad/s] at each pose from the step to the next pose
    (the last pose: from the step before it); NaN where the step has no duration or no heading."""
    t = np.asarray(t, float)
    poses = np.asarray(poses, float).reshape(-1, 3)
    n = len(t)
    sog, cog, w = (np.full(n, np.nan) for _ in range(3))
    if n < 2:
        return sog, cog, w
    d = np.diff(poses, axis=0)
    dt = np.diff(t)
    ok = dt > 0
    step_sog = np.where(ok, np.hypot(d[:, 0], d[:, 1]) / np.where(ok, dt, 1.0), np.nan)
    step_cog = np.where(ok, np.arctan2(d[:, 1], d[:, 0]), np.nan)
    step_w = np.where(ok, wrap_angle(d[:, 2]) / np.where(ok, dt, 1.0), np.nan)
    idx = np.minimum(np.arange(n), n - 2)  # pose i -> step (i, i+1); the last pose -> the last step
    return step_sog[idx], step_cog[idx], step_w[idx]


def trajectory_to_nmea(t: np.ndarray, poses: np.ndarray, frame: LocalFrame, *,
                       kinds: Sequence[str] = TRAJECTORY_SENTENCES) -> Iterator[tuple[float, str]]:
    """Sentences for a trajectory, per pose those of ``kinds`` in that order (ZDA, GGA, RMC, HDT, VTG,
    ROT): SOG/COG (RMC, VTG) and the rate of turn (ROT) from the step to the next pose
    (:func:`trajectory_rates`); a pose without a heading (NaN yaw) gets no HDT, one without a rate no
    VTG/ROT (RMC then leaves SOG/COG empty)."""
    unknown = set(kinds) - {"ZDA", "GGA", "RMC", "HDT", "VTG", "ROT"}
    if unknown:
        raise ValueError(f"unknown NMEA sentence type(s) {sorted(unknown)}: ZDA, GGA, RMC, HDT, VTG, ROT")
    t = np.asarray(t, float)
    poses = np.asarray(poses, float).reshape(-1, 3)
    lat, lon = frame.to_geodetic(poses[:, 0], poses[:, 1])  # every pose at once
    sog, cog, w = trajectory_rates(t, poses)
    for i in range(len(t)):
        ti, la, lo = float(t[i]), float(lat[i]), float(lon[i])
        s_i = None if np.isnan(sog[i]) else float(sog[i])
        c_i = None if np.isnan(cog[i]) or s_i is None else float(cog[i])
        for k in kinds:
            if k == "ZDA":
                yield ti, zda(ti)
            elif k == "GGA":
                yield ti, gga(ti, la, lo)
            elif k == "RMC":
                yield ti, rmc(ti, la, lo, s_i, c_i)
            elif k == "HDT" and np.isfinite(poses[i, 2]):
                yield ti, hdt(float(poses[i, 2]))
            elif k == "VTG" and s_i is not None:
                yield ti, vtg(s_i, c_i)
            elif k == "ROT" and np.isfinite(w[i]):
                yield ti, rot(float(w[i]))
