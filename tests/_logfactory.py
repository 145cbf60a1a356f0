"""Small synthetic logs used by several tests: every record type; fixes wandering from their velocity."""

from __future__ import annotations

import math

import numpy as np

from graphnav import log as L
from graphnav.log import BeaconObs, Gnss, Heading, Imu, KnownBeacon, NavLog, Odometry, PosePrior, Scan, Truth


def every_record_log(n: int = 20, seed: int = 0) -> NavLog:
    rng = np.random.default_rng(seed)
    recs = [PosePrior(0.0, 1.0, 2.0, 0.3, 0.5, 0.05)]
    for k in range(n):
        t = 0.5 * k
        ranges = rng.uniform(1.0, 40.0, 36)
        ranges[rng.random(36) < 0.2] = np.nan
        ranges[3] = 0.0
        angles = np.linspace(-np.pi, np.pi, 36, endpoint=False)
        recs += [
            Scan(t, ranges, angles),
            Gnss(t, float(rng.normal()), float(rng.normal()), 3.0),
            Heading(t, float(rng.uniform(-np.pi, np.pi)), 0.035),
            Odometry(t, 1.5, 0.01, 0.1, 0.002) if k % 2 else Odometry(t, 1.4, -0.02),
            Imu(t, 0.1, -0.05, 0.01),
            BeaconObs(t, "B1", 120.5, -0.7, 0.5, 0.0087),
            Truth(t, float(k), 0.5 * k, 0.1),
        ]
    known = [KnownBeacon("B1", 100.0, 50.0, 0.5), KnownBeacon("7", -20.0, 30.0, 1.0)]
    return NavLog(recs, known, {"name": "every-record", "events": [{"kind": "gnss_outage", "t0": 2.0, "t1": 4.0}]})


def logs_equal(a: NavLog, b: NavLog, *, scan_atol: float = 0.0) -> None:
    assert len(a.records) == len(b.records)
    for ra, rb in zip(a.records, b.records, strict=True):
        assert type(ra) is type(rb)
        if isinstance(ra, Scan):
            assert ra.t == rb.t
            assert np.array_equal(ra.valid(), rb.valid())
            v = ra.valid()
            assert np.allclose(ra.ranges[v], rb.ranges[v], atol=scan_atol, rtol=0)
            assert np.allclose(ra.angles, rb.angles, atol=scan_atol, rtol=0)
        else:
            for f in ra.__dataclass_fields__:
                va, vb = getattr(ra, f), getattr(rb, f)
                assert va == vb or (isinstance(va, float) and np.isnan(va) and np.isnan(vb)), (ra, rb, f)
    assert a.beacons_known == b.beacons_known


def wandering_fixes(n: int = 200, walk: float = 0.4, seed: int = 1) -> list[L.Record]:
    """A boat at 2 m/s weaving (yaw 0.6 sin(2 pi t / 300)), 1 Hz: fixes that wander ``walk`` m/sqrt(s) from its
    exact SOG/COG plus 1 m white noise (stated 1 m), exact GNSS velocities (0.05) and headings (0.02)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    yaw = 0.6 * np.sin(2 * math.pi * t / 300.0)
    vx, vy = 2.0 * np.cos(yaw), 2.0 * np.sin(yaw)
    x, y = np.cumsum(vx), np.cumsum(vy)
    wander = np.cumsum(rng.normal(0.0, walk, size=(n, 2)), axis=0)
    recs: list[L.Record] = []
    for k in range(n):
        recs += [Gnss(t[k], x[k] + wander[k, 0] + rng.normal(0, 1.0), y[k] + wander[k, 1] + rng.normal(0, 1.0), 1.0),
                 L.GnssVelocity(t[k], vx[k], vy[k], 0.05), Heading(t[k], float(yaw[k]), 0.02)]
    return recs


def straight_line(v: np.ndarray, sigma: float, gap: tuple[float, float], *, heading: bool = False,
                  velocity_sigma: float | None = None, odometry: bool = False, n: int = 181,
                  seed: int = 1) -> NavLog:
    """A boat on ``x = v t``: fixes at 1 Hz (+ N(0, ``sigma``) per axis), no record strictly inside ``gap``; with
    each fix a compass along ``v`` (``heading``, 2 deg), a GNSS velocity (``velocity_sigma``) and an odometry
    record (``odometry``: the speed, a zero rate of turn). The coasting tests' silent gap."""
    rng = np.random.default_rng(seed)
    yaw = math.atan2(v[1], v[0])
    recs: list[L.Record] = []
    for k in range(n):
        t = float(k)
        if gap[0] < t < gap[1]:
            continue
        p = v * t + rng.normal(0.0, sigma, 2)
        recs.append(Gnss(t, p[0], p[1], sigma))
        if heading:
            recs.append(Heading(t, yaw, math.radians(2.0)))
        if velocity_sigma is not None:
            u = v + rng.normal(0.0, velocity_sigma, 2)
            recs.append(L.GnssVelocity(t, u[0], u[1], velocity_sigma))
        if odometry:
            recs.append(Odometry(t, float(np.hypot(*v)), 0.0, 0.05, math.radians(0.5)))
    return NavLog(recs)
