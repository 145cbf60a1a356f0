"""``marina-degraded``: the real marina LiDAR scans with simulated, degraded GNSS and compass.

The log holds the dataset's 177 real scans, its reference track (rebuilt as a world track by
:mod:`graphnav.io.marina`) as ``truth``, and sensors derived from that reference at 1 Hz:

* GNSS, sigma 3 m per axis, with one 40 s outage and one 10 s multipath jump of 20 m
  (direction drawn from the seed);
* a compass with sigma 2 deg and a constant 3 deg bias.

There is no pose prior: the frame is anchored by the first GNSS fix and compass reading.
``jump_m=0`` gives the same log (same noise draws) without the jump, to measure its effect.
Deterministic per seed.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..log import Gnss, Heading, NavLog

GNSS_SIGMA = 3.0
COMPASS_SIGMA = math.radians(2.0)
COMPASS_BIAS = math.radians(3.0)


def degrade(
    base: NavLog,
    seed: int = 1,
    *,
    gnss_sigma: float = GNSS_SIGMA,
    outage_s: float = 40.0,
    jump_m: float = 20.0,
    jump_s: float = 10.0,
    compass_sigma: float = COMPASS_SIGMA,
    compass_bias: float = COMPASS_BIAS,
) -> NavLog:
    """Add simulated GNSS and compass records, derived from the ``truth`` records, to a scan log."""
    rng = np.random.default_rng(seed)
    tr = base.truth()
    if len(tr) < 2:
        raise ValueError("marina-degraded needs a log with truth records")
    t0, t1 = float(tr.t[0]), float(tr.t[-1])
    span = t1 - t0
    # event placement: outage in the first half, jump in the second half (drawn from the seed)
    o0 = t0 + rng.uniform(0.15, 0.45) * span - outage_s / 2
    j0 = t0 + rng.uniform(0.6, 0.85) * span - jump_s / 2
    ang = rng.uniform(-math.pi, math.pi)
    jump = jump_m * np.array([math.cos(ang), math.sin(ang)])
    n = len(tr)
    noise_g = rng.normal(0.0, gnss_sigma, (n, 2))
    noise_c = rng.normal(0.0, compass_sigma, n)
    recs = list(base.records)
    for i in range(n):
        t = float(tr.t[i])
        x, y, yaw = tr.poses[i]
        if not (o0 <= t < o0 + outage_s):
            off = jump if j0 <= t < j0 + jump_s else 0.0
            gx, gy = np.array([x, y]) + off + noise_g[i]
            recs.append(Gnss(t, float(gx), float(gy), gnss_sigma))
        h = yaw + compass_bias + noise_c[i]
        recs.append(Heading(t, float((h + math.pi) % (2 * math.pi) - math.pi), compass_sigma))
    events = [{"kind": "gnss_outage", "t0": o0, "t1": o0 + outage_s}]
    if jump_m:
        events.append({"kind": "gnss_jump", "t0": j0, "t1": j0 + jump_s, "offset_m": jump.tolist()})
    events.append({"kind": "compass_bias", "t0": t0, "t1": t1, "bias_deg": math.degrees(compass_bias)})
    meta = dict(base.meta)
    meta.update(
        {
            "name": "marina-degraded",
            "seed": seed,
            "events": events,
            "simulated": f"gnss (sigma {gnss_sigma:.1f} m, outage, jump), compass (sigma "
            f"{math.degrees(compass_sigma):.1f} deg, bias {math.degrees(compass_bias):.1f} deg)",
        }
    )
    return NavLog.from_unsorted(recs, base.beacons_known, meta)


def simulate_marina_degraded(marina_dir: str | Path, seed: int = 1, **kw) -> NavLog:
    """Read the marina dataset and degrade it (see :func:`degrade`)."""
    from ..io.marina import read_marina

    return degrade(read_marina(marina_dir), seed, **kw)
