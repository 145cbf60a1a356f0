"""``marina-degraded``: the real marina LiDAR scans with simulated, degraded GNSS and compass.

The log holds the dataset's 177 real scans, its reference track (rebuilt as a world track by
:mod:`graphnav.io.marina`) as ``truth``, and sensors derived from that reference at 1 Hz:

* GNSS, sigma 3 m per axis, with one 40 s outage and one 10 s multipath jump of 20 m
  (direction drawn from the seed);
* a compass with sigma 2 deg and a constant 3 deg bias.

There is no pose prior: the frame is anchored by the first GNSS fix and compass reading.
``jump_m=0`` gives the same log (same noise draws) without the jump, to measure its effect.
Deterministic per seed. It is the ``marina-degraded`` preset of :mod:`graphnav.sim.degrade`
(``graphnav simulate degrade DIR --preset marina-degraded`` writes the same log).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

from ..log import NavLog

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
    """Add simulated GNSS and compass records, derived from the ``truth`` records, to a scan log.

    The ``marina-degraded`` preset of :func:`graphnav.sim.degrade.degrade` with these parameters
    (the same draws as ``graphnav simulate degrade DIR --preset marina-degraded``)."""
    from .degrade import PRESETS, Window
    from .degrade import degrade as degrade_log

    preset = PRESETS["marina-degraded"]
    cfg = replace(preset, gnss_sigma=gnss_sigma, compass_sigma=compass_sigma, compass_bias=compass_bias,
                  outages=(replace(preset.outages[0], duration=outage_s),),
                  jumps=(Window(preset.jumps[0].start, jump_s, jump_m),))
    return degrade_log(base, cfg, seed)


def simulate_marina_degraded(marina_dir: str | Path, seed: int = 1, **kw) -> NavLog:
    """Read the marina dataset and degrade it (see :func:`degrade`)."""
    from ..io.marina import read_marina

    return degrade(read_marina(marina_dir), seed, **kw)
