"""A short live-mode trial from the harbour simulator: every sensor at one rate (GNSS, compass,
SOG/ROT odometry; the legacy profile), optional 1 Hz scans, exact truth, POSIX time stamps and a geodetic origin, so
the log turns into NMEA. No multipath, no outage, no beacons: a plain white-noise trial."""

from __future__ import annotations

import math

from graphnav.log import NavLog
from graphnav.sim.harbour import HarbourConfig, simulate_harbour

T0 = 1.7e9
ORIGIN = (43.5, 16.4)
KINDS = ("truth", "gnss", "heading", "odometry", "scan")


def harbour_trial(duration: float = 60.0, rate: float = 10.0, *, sigma_gnss: float = 1.5,
                  sigma_heading_deg: float = 0.5, scans: bool = False, seed: int = 0,
                  odo_sigma: tuple[float, float] | None = None, scan_hz: float = 1.0) -> NavLog:
    """``duration`` s of the harbour route from ``T0``: ``duration * rate`` epochs at ``rate`` Hz
    (a divisor of 50), the first at ``T0``. ``odo_sigma``: (m/s, rad/s) odometry noise (default
    the simulator's)."""
    cfg = HarbourConfig.legacy(fix_hz=rate, lidar_hz=scan_hz if scans else 0.0, t0=T0, gnss_sigma=sigma_gnss,
                               compass_sigma=math.radians(sigma_heading_deg), multipath_amp=0.0, outage_len=0.0)
    if odo_sigma is not None:
        cfg.odo_sigma_v, cfg.odo_sigma_w = odo_sigma
    log = simulate_harbour(seed, cfg, duration=duration - 1e-3)
    meta = {"name": "harbour-trial", "origin": {"lat": ORIGIN[0], "lon": ORIGIN[1]}}
    return NavLog([r for r in log.records if r.kind in KINDS], meta=meta)
