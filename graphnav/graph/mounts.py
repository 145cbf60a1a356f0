"""Sensor mounts (lever arms and rotations): where each sensor sits on the hull, in the body frame.

A mount is the sensor frame's pose in the body frame (x forward, y left, z up; docs/conventions.md):
the offset ``x, y, z`` [m] of the sensor's origin (the GNSS antenna's phase centre, the LiDAR's
optical centre, the IMU's, the speed log's transducer) from the body origin, and its rotation
``roll, pitch, yaw`` [rad] (ZYX, REP-103). They come from the log's meta (``"mounts"``) and from the
smoother's option ``mounts`` (``-O mounts='{"gnss": {"x": 3}}'``, ``[options.mounts.gnss]`` in a
``--config`` file), the option winning per sensor. ``SENSOR@SOURCE`` (``gnss@52``) is one source's
mount (two receivers on one bus, each with its antenna; a record's ``source``), over the sensor's
(used for GNSS). docs/mounts.md says what each factor does with them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..config import OptionError, Range, number

#: the sensors a mount may be given for
SENSORS = ("gnss", "lidar", "imu", "water_speed")
#: the fields of a mount
FIELDS = ("x", "y", "z", "roll", "pitch", "yaw")
#: [m] an offset beyond this is no place on a vessel (the largest ships are ~400 m long)
MAX_OFFSET = 500.0
_OFFSET = Range(lo=-MAX_OFFSET, hi=MAX_OFFSET)
_ANGLE = Range(lo=-2 * math.pi, hi=2 * math.pi)


@dataclass(frozen=True)
class Mount:
    """A sensor's pose in the body frame: offset [m] and rotation [rad] (ZYX)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0

    @property
    def is_identity(self) -> bool:
        return all(getattr(self, f) == 0.0 for f in FIELDS)

    @property
    def planar(self) -> tuple[float, float, float]:
        """``(x, y, yaw)``: the mount as an SE(2) pose in the body frame."""
        return (self.x, self.y, self.yaw)

    def pose3(self) -> Any:
        """The mount as a ``gtsam.Pose3`` (imports GTSAM)."""
        import gtsam
        import numpy as np

        return gtsam.Pose3(gtsam.Rot3.Ypr(self.yaw, self.pitch, self.roll), np.array([self.x, self.y, self.z]))


def parse_mount(value: Any, where: str) -> Mount:
    """A mount from a table ``{x, y, z, roll, pitch, yaw}`` (each optional, default 0); an unknown
    field, a non-number or a value beyond its range is an :class:`OptionError` naming ``where.FIELD``."""
    if isinstance(value, Mount):
        return value
    if not isinstance(value, Mapping):
        raise OptionError(where, f"{where}: expected a table of {', '.join(FIELDS)}, got {type(value).__name__}")
    bad = sorted(str(k) for k in value if k not in FIELDS)
    if bad:
        raise OptionError(f"{where}.{bad[0]}",
                          f"{where}: unknown field(s) {', '.join(bad)}; known: {', '.join(FIELDS)}")
    vals = {k: float(number(f"{where}.{k}", v, _OFFSET if k in ("x", "y", "z") else _ANGLE)) for k, v in value.items()}
    return Mount(**vals)


def parse_mounts(value: Any, where: str = "mounts") -> dict[str, Mount]:
    """``{sensor: Mount}`` from ``{sensor: {x, y, ...}}``; sensors are :data:`SENSORS`."""
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise OptionError(where, f"{where}: expected a table of sensors ({', '.join(SENSORS)}), "
                                 f"got {type(value).__name__}")
    out = {}
    for name, m in value.items():
        sensor, at, source = str(name).partition("@")
        if sensor not in SENSORS or (at and not source):
            raise OptionError(f"{where}.{name}", f"{where}: unknown sensor {name!r}; known: {', '.join(SENSORS)} "
                                                 "(SENSOR@SOURCE: one source's, e.g. gnss@52)")
        out[str(name)] = parse_mount(m, f"{where}.{name}")
    return out


def mount_of(mounts: dict[str, Mount], sensor: str, source: str = "") -> Mount | None:
    """The mount of ``sensor``'s ``source`` (``SENSOR@SOURCE``), else the sensor's, else ``None``."""
    return (mounts.get(f"{sensor}@{source}") if source else None) or mounts.get(sensor)


def merged(meta: Any, option: Any) -> dict[str, Mount]:
    """The mounts of a log's meta (``meta["mounts"]``) overridden per sensor by the option's."""
    return {**parse_mounts(meta, "log meta mounts"), **parse_mounts(option, "mounts")}


__all__ = ["FIELDS", "MAX_OFFSET", "SENSORS", "Mount", "merged", "mount_of", "parse_mount", "parse_mounts"]
