"""Where the odometry baselines start: the graph's anchor, chosen from the same records.

Dead reckoning, ``icp-dr`` and ``scan-to-map`` chain relative motion from one start pose, so that
pose (the heading above all) is their frame for good. They take it by the rule of the graph's anchor
(:mod:`graphnav.graph.anchor`, the records held as the graph holds them): the log's ``pose_prior``;
else the first GNSS fix with the first compass reading (the yaw 0 without one); else two charted
beacons sighted together; else, with nothing absolute in the log, the first truth pose (the frame
the graph takes too: the reference's own, not a measurement); else the origin. Never the truth
while the log holds an absolute record.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..graph.anchor import Anchor
from ..graph.smoother_config import SmootherConfig
from ..log import BeaconObs, Gnss, NavLog, PosePrior, Record, Truth

#: the anchor's names that are a frame, not a measurement (their sigmas are the estimator's own)
FRAMES = ("truth (first pose)", "origin")


@dataclass(frozen=True)
class Start:
    """A start pose ``(x, y, yaw)``, its 1-sigmas, the anchor's name (``info["anchor"]``) and the time
    of the record it came from (``-inf`` for the origin)."""

    pose: NDArray[np.float64]
    sigmas: NDArray[np.float64]
    name: str
    t: float

    @property
    def is_frame(self) -> bool:
        """The start is a frame (the first truth pose, the origin), not an absolute measurement."""
        return self.name in FRAMES


def _source_time(held: list[Record], name: str, charted: set[str]) -> float:
    """The time of the first held record of the kind the anchor named."""
    kind: tuple[type, ...] = (PosePrior,) if name == "pose_prior" else (Gnss,) if "gnss" in name.lower() else \
        (BeaconObs,) if "beacon" in name else (Truth,) if "truth" in name else ()
    for r in held:
        if isinstance(r, kind) and (not isinstance(r, BeaconObs) or r.id in charted):
            return float(r.t)
    return -math.inf


def log_start(log: NavLog) -> Start:
    """The start pose of ``log`` by the graph's anchor rule (the module docstring)."""
    cfg = SmootherConfig()  # the graph's defaults (graphnav.graph.builder.GraphBuilder takes the same two parts)
    anchor = Anchor(cfg.anchor, cfg.mounts)
    charted = {b.id: b for b in log.beacons_known}
    for rec in log.records:  # as the graph's builder takes them (graphnav.graph.builder.GraphBuilder.push)
        if anchor.ready_for(rec, charted):
            break
        anchor.hold(rec)
        if isinstance(rec, PosePrior):
            break
    held = sorted(anchor.held or [], key=lambda r: r.t)
    anchor.choose(charted)
    assert anchor.pose is not None and anchor.sigmas is not None and anchor.name is not None
    return Start(np.asarray(anchor.pose, dtype=float), np.asarray(anchor.sigmas, dtype=float), anchor.name,
                 _source_time(held, anchor.name, set(charted)))


def start_pose(log: NavLog) -> tuple[NDArray[np.float64], str]:
    """The start pose and the anchor's name (:func:`log_start`)."""
    s = log_start(log)
    return s.pose, s.name
