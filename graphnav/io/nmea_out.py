"""NMEA 0183 output: pure functions that format sentences with valid checksums.

Internal quantities (SI, yaw CCW from east) are converted at this edge: headings/courses to
degrees clockwise from north, speed to knots, rate of turn to degrees per minute positive to
starboard (``ROT = -degrees(w) * 60``). Times are POSIX seconds (UTC); a log whose times are not
POSIX maps ``t = 0`` to 1970-01-01 00:00:00, which :func:`graphnav.io.nmea.read_nmea` maps back.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from datetime import UTC, datetime

import numpy as np

from ..geodesy import LocalFrame
from ..geometry import wrap_angle, yaw_to_heading_deg
from ..log import Gnss, Heading, NavLog, Odometry
from .nmea import KNOT, UERE_M

#: Origin used when a log has no geodetic origin (meta["origin"]): documented, arbitrary.
DEFAULT_ORIGIN = (43.5, 16.4)


def checksum(body: str) -> str:
    """XOR of the characters between ``$`` and ``*``, two upper-case hex digits."""
    c = 0
    for ch in body:
        c ^= ord(ch)
    return f"{c:02X}"


def sentence(body: str) -> str:
    """``$BODY*CS`` (no line terminator)."""
    return f"${body}*{checksum(body)}"


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


def gga(t: float, lat: float, lon: float, *, quality: int = 1, sats: int = 10, hdop: float = 1.0,
        alt: float = 0.0, talker: str = "GN") -> str:
    """GGA fix: time, position (0.1 mm precision), quality, satellites, HDOP, altitude."""
    la, ns = _ddmm(lat, True)
    lo, ew = _ddmm(lon, False)
    return sentence(f"{talker}GGA,{_hhmmss(t)},{la},{ns},{lo},{ew},{quality:d},{sats:02d},{hdop:.2f},"
                    f"{alt:.1f},M,0.0,M,,")


def rmc(t: float, lat: float, lon: float, sog: float | None = None, cog_yaw: float | None = None, *,
        mode: str = "A", talker: str = "GN") -> str:
    """RMC: time, status A, position, SOG [m/s -> kn], COG [yaw -> deg true], date, mode."""
    la, ns = _ddmm(lat, True)
    lo, ew = _ddmm(lon, False)
    d = _utc(t)
    s = "" if sog is None else f"{sog / KNOT:.3f}"
    c = "" if cog_yaw is None else f"{yaw_to_heading_deg(cog_yaw):.2f}"
    return sentence(f"{talker}RMC,{_hhmmss(t)},A,{la},{ns},{lo},{ew},{s},{c},{d:%d%m%y},,,{mode}")


def zda(t: float, talker: str = "GN") -> str:
    """ZDA: UTC time and date (local zone 00:00)."""
    d = _utc(t)
    return sentence(f"{talker}ZDA,{_hhmmss(t)},{d.day:02d},{d.month:02d},{d.year:04d},00,00")


def hdt(yaw: float, talker: str = "HE") -> str:
    """HDT true heading [yaw rad -> deg clockwise from north, 0.01 deg]."""
    return sentence(f"{talker}HDT,{yaw_to_heading_deg(yaw):.2f},T")


def vtg(sog: float, cog_yaw: float | None = None, talker: str = "GN") -> str:
    """VTG: course over ground (true) and speed in knots and km/h; mode A."""
    c = "" if cog_yaw is None else f"{yaw_to_heading_deg(cog_yaw):.2f}"
    return sentence(f"{talker}VTG,{c},T,,M,{sog / KNOT:.3f},N,{sog * 3.6:.3f},K,A")


def rot(w: float, talker: str = "TI") -> str:
    """ROT: rate of turn [rad/s CCW -> deg/min, positive to starboard], status A."""
    return sentence(f"{talker}ROT,{-math.degrees(w) * 60.0:.3f},A")


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
    last_t = None
    for r in log.records:
        if not isinstance(r, Gnss | Heading | Odometry):
            continue
        if r.t != last_t:
            yield r.t, zda(r.t)
            last_t = r.t
        if isinstance(r, Gnss):
            lat, lon = frame.to_geodetic(r.x, r.y)
            yield r.t, gga(r.t, float(lat), float(lon), quality=quality, hdop=hdop_of(r.sigma, quality))
            if with_rmc:
                yield r.t, rmc(r.t, float(lat), float(lon))
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


def trajectory_to_nmea(t: np.ndarray, poses: np.ndarray, frame: LocalFrame) -> Iterator[tuple[float, str]]:
    """Sentences for a trajectory: ZDA + GGA + HDT per pose, VTG/ROT from the step to the next pose."""
    n = len(t)
    for i in range(n):
        j0, j1 = (i, i + 1) if i + 1 < n else (i - 1, i)
        sog = cog = w = None
        if 0 <= j0 and j1 < n and t[j1] > t[j0]:
            d = poses[j1] - poses[j0]
            dt = t[j1] - t[j0]
            sog = float(np.hypot(d[0], d[1]) / dt)
            cog = float(np.arctan2(d[1], d[0]))
            w = float(wrap_angle(d[2]) / dt)
        yield float(t[i]), zda(float(t[i]))
        for s in solution_sentences(float(t[i]), poses[i], frame, sog=sog, cog_yaw=cog, w=w):
            yield float(t[i]), s
