"""The anchor of the navigation graph: when it can be chosen, and the first pose's prior.

Records are held until :func:`anchor_ready` says so; :func:`choose_anchor` then picks the prior of
the first keyframe from them (the same priority as a look at the whole log).
"""

from __future__ import annotations

import math
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

import factors as F

from ..log import BeaconObs, Gnss, Heading, KnownBeacon, PosePrior, Record, Truth
from .keyframes import EPS
from .mounts import mount_of, parse_mounts
from .smoother_config import AnchorConfig

RELEASED_SIGMA = 1e4  # [m] the first pose's position sigma once its fix is disowned (Anchor.released): no information


def anchor_ready(held: list[Record], charted: dict[str, KnownBeacon], anchor_wait: float, t_next: float) -> bool:
    """Whether the anchor can be chosen from the ``held`` records once a record at ``t_next`` arrives:
    a ``pose_prior``; a GNSS fix and a compass reading; two charted beacons sighted together; or
    ``anchor_wait`` seconds of log time."""
    kinds = {r.kind for r in held}
    if "pose_prior" in kinds or ("gnss" in kinds and "heading" in kinds):
        return True
    charted = [r for r in held if r.kind == "beacon" and r.id in charted]
    if charted and len({r.id for r in charted if abs(r.t - charted[0].t) <= 1e-6}) >= 2:
        return True
    return t_next - held[0].t > anchor_wait


def choose_anchor(held: list[Record], charted: dict[str, KnownBeacon], cfg: AnchorConfig, mounts: dict[str, Any]
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
    """The first pose's prior (pose, 1-sigmas, name) from the held records, in this order: the
    ``pose_prior``; the first GNSS fix (+ the first compass reading); charted beacons (two sighted
    together give the yaw); the first truth pose (a frame, nothing absolute in the log); the origin."""
    for r in held:
        if isinstance(r, PosePrior):
            return np.array([r.x, r.y, r.yaw]), np.array([r.sigma_xy, r.sigma_xy, r.sigma_yaw]), "pose_prior"
    yaw_sig = math.radians(cfg.sigma_yaw_deg)
    yaw_unknown = math.radians(cfg.sigma_yaw_unknown_deg)
    gnss = [r for r in held if isinstance(r, Gnss)]
    head = [r for r in held if isinstance(r, Heading)]
    if gnss:
        g = gnss[0]
        yaw = head[0].yaw if head else 0.0
        sxy = cfg.sigma_xy if cfg.sigma_xy is not None else 3.0 * g.sigma
        mount = mount_of(parse_mounts(mounts), "gnss", g.source)
        x, y = g.x, g.y
        if mount is not None and (mount.x or mount.y):  # the fix is the antenna's: the body is an arm behind it
            c, s = math.cos(yaw), math.sin(yaw)
            x, y = x - (c * mount.x - s * mount.y), y - (s * mount.x + c * mount.y)
            sxy = math.hypot(sxy, math.hypot(mount.x, mount.y) * (yaw_sig if head else 1.0))
        return (np.array([x, y, yaw]), np.array([sxy, sxy, yaw_sig if head else yaw_unknown]),
                "first GNSS+compass" if head else "first GNSS")
    obs = [r for r in held if isinstance(r, BeaconObs) and r.id in charted]
    if obs:
        t0 = obs[0].t
        first: dict[str, BeaconObs] = {}
        for r in obs:
            if r.t > t0 + 1e-6:
                break
            first.setdefault(r.id, r)
        sxy = cfg.sigma_xy if cfg.sigma_xy is not None else 10.0
        if len(first) >= 2:
            a, b = list(first.values())[:2]
            ca, cb = charted[a.id], charted[b.id]
            pose = F.pose_from_two_beacons((ca.x, ca.y), (a.range, a.bearing), (cb.x, cb.y), (b.range, b.bearing))
            return pose, np.array([sxy, sxy, yaw_sig]), "charted beacons"
        a = obs[0]
        yaw = head[0].yaw if head else 0.0
        ca = charted[a.id]
        pos = np.array([ca.x, ca.y]) - a.range * np.array([math.cos(yaw + a.bearing), math.sin(yaw + a.bearing)])
        return (np.array([pos[0], pos[1], yaw]), np.array([sxy, sxy, yaw_sig if head else yaw_unknown]),
                "charted beacons")
    for r in held:
        if isinstance(r, Truth):  # nothing absolute in the log: the frame is the reference's start
            return np.array([r.x, r.y, r.yaw]), np.array([1e-3, 1e-3, 1e-4]), "truth (first pose)"
    return np.zeros(3), np.array([1e-3, 1e-3, 1e-4]), "origin"


class Anchor:
    """The records held until the anchor can be chosen, then the anchor: the first keyframe's prior
    (``pose``, 1-sigmas ``sigmas``) and how it was chosen (``name``)."""

    def __init__(self, cfg: AnchorConfig, mounts: dict[str, Any]) -> None:
        self.cfg, self.mounts = cfg, mounts
        self.held: list[Record] | None = []  # before the anchor is chosen
        self.pose: NDArray[np.float64] | None = None
        self.sigmas: NDArray[np.float64] | None = None
        self.name: str | None = None
        self.tilt: tuple[float, float, float] | None = None  # the Pose3 graph's (roll, pitch, sigma) of its prior

    @property
    def chosen(self) -> bool:
        return self.held is None

    def ready_for(self, rec: Record, charted: dict[str, KnownBeacon]) -> bool:
        """Whether the anchor can be chosen before ``rec`` is taken: the records of the held time stamps
        are all in (``rec`` is later) and they suffice (:func:`anchor_ready`)."""
        held = self.held
        assert held is not None
        return bool(held) and rec.t > held[-1].t + EPS and anchor_ready(held, charted, self.cfg.wait, rec.t)

    def hold(self, rec: Record) -> None:
        assert self.held is not None
        self.held.append(rec)

    def choose(self, charted: dict[str, KnownBeacon]) -> tuple[float | None, list[Record]]:
        """Choose the anchor from the held records (:func:`choose_anchor`); returns the first one's time
        and the records in time order, the ``pose_prior`` that is the anchor left out, to be taken now."""
        held, self.held = sorted(self.held or [], key=lambda r: r.t), None
        self.pose, self.sigmas, self.name = choose_anchor(held, charted, self.cfg, self.mounts)
        first_prior = next((r for r in held if isinstance(r, PosePrior)), None)
        return (held[0].t if held else None), [r for r in held if r is not first_prior]

    def released(self, space: Any) -> gtsam.NonlinearFactor | None:
        """When the anchor is the first GNSS fix and the GNSS gate re-acquired away from it (graph.fix_gate):
        the first pose's prior with its position released (``RELEASED_SIGMA``), the rest as it was (``space``:
        the graph's :mod:`~graphnav.graph.space`); ``None`` for any other anchor."""
        if self.pose is None or self.sigmas is None or not (self.name or "").startswith("first GNSS"):
            return None
        return space.prior(F.X(0), self.pose, np.array([RELEASED_SIGMA, RELEASED_SIGMA, self.sigmas[2]]), self.tilt)

    def cov(self) -> NDArray[np.float64]:
        """The anchor's (x, y, yaw) covariance."""
        assert self.sigmas is not None
        return np.diag(np.square(self.sigmas))
