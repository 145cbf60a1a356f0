"""Loop closures: a keyframe that comes back to a place seen before is tied to it by a scan match.

:class:`LoopCloser` is fed every keyframe by the :class:`~graphnav.graph.builder.GraphBuilder`
(:meth:`LoopCloser.step`) and adds the verified loops to that keyframe's factor batch. Four stages:

1. **Places.** A keyframe with a scan enters the place database every ``spacing`` metres of travel:
   its points, its Scan Context descriptor (:mod:`graphnav.scan.descriptor`), its pose estimate
   and world covariance, and its path length ``s`` (metres along the chain).
2. **Candidates** for the keyframe ``k`` (only places at least ``skip_recent`` metres back along the
   path: nearer ones are the consecutive matches' business), at most ``max_candidates``:
   * proximity: places whose estimated position lies within the Mahalanobis gate
     ``d^2 = dp^T (C_k + C_i)^-1 dp <= chi2_2(gate_prob)`` (the marginal covariances of both
     poses; nearest ``gate_neighbours`` by Euclidean distance from a k-d tree, then the gate);
   * appearance: the ``descriptor_neighbours`` nearest ring keys (k-d tree), kept when the Scan
     Context distance is below ``descriptor_max`` and the estimate can have drifted that far
     (the estimated offset within the gate of the relative covariance plus the search window).
   A proximity candidate whose relative position is known to ``min_sigma`` already is skipped.
3. **Verification** of a candidate ``(i, k)``: the relative covariance (:meth:`LoopCloser.relative_cov`:
   the smaller of the two marginals and the compounded chain) sets the search: the correlative
   matcher (:mod:`graphnav.scan.correlative`) of keyframe ``k``'s scan on a submap of place ``i``
   and its ``submap`` neighbours, within 3 sigma (``window`` to ``max_window`` metres) of the guess
   (the estimate, or the same spot at the descriptor's yaw) and 3 sigma of yaw plus
   ``yaw_margin_deg``; a match needs ``min_hits`` of its points on a reference surface and no
   distinct second peak above ``max_ambiguity`` of its score (a look-alike place), and must be
   plausible against the estimate (``chi2_3(chain_prob)``). Then the weighted ICP
   (:func:`graphnav.scan.weighted_icp.match_points`) from the correlative pose on the submap
   (``refine_submap``): it must converge, not be degenerate and stay within ``refine_agree`` /
   ``refine_agree_deg`` of the correlative pose. Its covariance is the loop's.
4. **Consistency** (pairwise, in the spirit of PCM, Mangelson et al. 2018): a verified loop is
   held until another verified loop within ``pair_span`` metres of path on both ends agrees
   with it: the cycle loop1 -> chain -> loop2^-1 -> chain closes within ``chi2_3(consistency_prob)``
   of the sum of the two loops' covariances and the two short chain segments' (the motion factors'
   covariances compounded). Both then become ``BetweenFactorPose2`` with a robust kernel (Cauchy,
   ``kernel_k``), so even a wrong pair that passed cannot pull with more than bounded weight.

docs/loops.md has what it does on the CARMEN logs and the harbour. The place database (positions,
ring keys, submaps) and the motion chain are :mod:`graphnav.graph.loop_places`'s.

Everything is bounded: one place per ``spacing`` metres, at most ``max_candidates`` verifications
per place, k-d trees rebuilt when the unindexed tail exceeds a quarter of the database (amortised
O(log n) per place, the tail a vectorised scan).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

import factors as F

from ..scan import correlative as corr
from ..scan import descriptor as desc
from .chi2 import chi2_ppf
from .loop_places import (  # noqa: F401  (propagate, compound: the loop closer's public names)
    MotionChain,
    Place,
    Places,
    _pose,
    _vec,
    compound,
    propagate,
)

Vec = NDArray[np.float64]


@dataclass
class LoopConfig:
    """Settings of the loop closer (``-O loop='{"key": value}'``; metres, degrees, probabilities)."""

    spacing: float = 1.0  # [m] of travel between two places (and two searches)
    skip_recent: float = 15.0  # [m] of path: nearer places are not candidates
    gate_prob: float = 0.999  # proximity gate: chi-square probability (2 dof) of the position difference
    gate_neighbours: int = 16  # nearest places looked at by the proximity search
    descriptor_neighbours: int = 4  # nearest ring keys looked at by the appearance search
    descriptor_max: float = 0.35  # Scan Context distance below which a place is a candidate
    max_candidates: int = 2  # verifications per place (best first)
    min_sigma: float = 0.5  # [m] a proximity candidate is verified only when the relative position's 1-sigma
    #                          (largest axis) exceeds this: else the graph knows it already (GNSS, a short chain)
    window: float = 4.0  # [m] half-width of the correlative search (at least) ...
    max_window: float = 6.0  # [m] ... and at most: 3 sigma of the relative position in between
    max_chain: int = 2000  # keyframes: the chain's covariance is compounded up to this far apart
    yaw_margin_deg: float = 5.0  # the yaw search: 3 sigma of the relative yaw (or a descriptor sector) plus this
    submap: int = 5  # the reference: the place and this many places on each side
    min_hits: float = 0.4  # fraction of the scan's points within hit_radius of the reference
    max_ambiguity: float = 0.9  # a distinct second peak above this x the best score: a look-alike place
    refine_submap: int = 5  # the refinement's target: the place and this many on each side (more overlap;
    #                         1 gave fewer, as biased loops on edmonton and lost most of seattle's)
    refine_agree: float = 0.5  # [m] the ICP refinement must stay this close to the correlative pose
    refine_agree_deg: float = 3.0
    pair_span: float = 30.0  # [m] of path: two loops this close on both ends check each other ...
    pair_min: float = 0.0  # [m] ... and at least this far apart at the current end (5 m lost seattle: 0.84 -> 5.2 m)
    consistency_prob: float = 0.999  # chi-square probability (3 dof) of the cycle error
    chain_prob: float = 0.999  # ... of a loop against the estimate (both marginals + the loop's)
    kernel: str = "cauchy"  # robust kernel of the loop factors: "cauchy", "dcs", "none"
    kernel_k: float = 1.0  # its parameter (whitened units; DCS: Phi)
    cov_floor_xy: float = 0.05  # [m] 1-sigma floor of a loop's covariance (quadrature)
    cov_floor_yaw_deg: float = 0.5
    correlative: dict[str, Any] = field(default_factory=dict)  # CorrelativeConfig options
    descriptor: dict[str, Any] = field(default_factory=dict)  # DescriptorConfig options


@dataclass
class Loop:
    i: int  # place keyframe (older)
    k: int  # current keyframe
    si: float
    sk: float
    z: Vec  # pose of k in i's frame
    cov: Vec  # its covariance (GTSAM tangent convention)
    source: str  # "gate" or "descriptor"
    accepted: bool = False


class LoopCloser:
    """Place database, candidate search, verification and pairwise consistency (module docstring).

    ``icp_match(src_xy, tgt_xy, init) -> (ok, pose, cov, quality)``: the weighted-ICP refinement;
    ``cov_of(cov)``: the covariance treatment of the graph's ICP factors (scale and floor);
    ``points(scan)``: a scan's points in the body frame (:meth:`points`).
    """

    def __init__(self, cfg: LoopConfig, icp_match: Callable[..., tuple[bool, Vec, Vec, dict[str, Any]]],
                 cov_of: Callable[[Vec], Vec | None], points: Callable[[Any], Vec] | None = None) -> None:
        self.cfg = cfg
        self.icp_match = icp_match
        self.cov_of = cov_of
        self._points = points
        self.ccfg = corr.CorrelativeConfig(**cfg.correlative)
        self.dcfg = desc.DescriptorConfig(**cfg.descriptor)
        self.places = Places(self.ccfg, cfg.submap, cfg.refine_submap)  # the place database
        self.chain = MotionChain()  # per keyframe: the motion from k-1, its covariance, the path length
        self.loops: list[Loop] = []  # verified (pending or accepted)
        self.chi_gate = chi2_ppf(cfg.gate_prob, 2)
        self.chi_pair = chi2_ppf(cfg.consistency_prob, 3)
        self.chi_chain = chi2_ppf(cfg.chain_prob, 3)
        self.counts = {"loop_candidates": 0, "loop_verified": 0, "loop_closures": 0, "loop_rejected_match": 0,
                       "loop_rejected_refine": 0, "loop_rejected_chain": 0, "loop_known": 0, "loop_unconfirmed": 0}
        self.accepted: list[tuple[int, int]] = []
        self.stale = False  # an accepted loop moved the estimate: refresh the places' poses
        self.last_place_s = -math.inf
        self.ms = 0.0  # [ms] spent in step()

    def points(self, scan: Any) -> Vec:
        """A scan's points in the body frame (the places' points)."""
        if self._points is None:
            raise ValueError("this loop closer was made without a scan -> points function")
        return self._points(scan)

    # -- per keyframe ------------------------------------------------------------------------------
    def step(self, s: Any, k: int, pose: gtsam.Pose2, cov_w: Vec, rel: gtsam.Pose2 | None, q: Vec | None,
             xy: Vec | None, oldest: int = 0) -> None:
        """Keyframe ``k`` (``pose``: its predicted pose, ``cov_w`` its world covariance; ``rel``/``q``
        the motion from ``k-1`` and its covariance; ``xy`` its scan's points or ``None``): candidates,
        verification, consistency; accepted loops go into the batch ``s``. ``oldest``: the oldest
        keyframe still in the solver."""
        c0 = time.perf_counter()
        try:
            self._step(s, k, pose, cov_w, rel, q, xy, oldest)
        finally:
            self.ms += (time.perf_counter() - c0) * 1e3

    def _step(self, s: Any, k: int, pose: gtsam.Pose2, cov_w: Vec, rel: gtsam.Pose2 | None, q: Vec | None,
              xy: Vec | None, oldest: int) -> None:
        cfg = self.cfg
        self.chain.add(None if k == 0 else rel, q)
        sk = self.chain.s[k]
        if xy is None or len(xy) < self.ccfg.min_points or sk - self.last_place_s < cfg.spacing:
            return
        self.last_place_s = sk
        pk = _vec(pose)
        place = Place(k, sk, pk, np.asarray(cov_w, dtype=float), np.asarray(xy, dtype=float),
                      desc.describe(xy, self.dcfg))
        valid = self.places.valid(sk, cfg.skip_recent)
        cands = self._candidates(place, valid, oldest)
        for src, pi, guess, ywin, win in cands[: cfg.max_candidates]:
            self.counts["loop_candidates"] += 1
            loop = self._verify(place, self.places[pi], guess, ywin, win, src)
            if loop is not None:
                self._consider(s, loop)
        self._expire(sk)
        self.places.add(place)

    def observe(self, k: int, pose: Vec, cov_w: Vec | None) -> None:
        """The solved estimate of keyframe ``k`` (replaces the prediction of its place)."""
        self.places.observe(k, pose, cov_w)

    def refresh(self, estimate: Callable[[list[int]], list[Vec | None]],
                final: Callable[[int], bool] | None = None) -> None:
        """New estimates of the places (after an accepted loop moved the graph): :meth:`Places.refresh`."""
        self.places.refresh(estimate, final)
        self.stale = False

    # -- stages --------------------------------------------------------------------------------------
    def _candidates(self, q: Place, valid: int, oldest: int) -> list[tuple[str, int, Vec, float, float]]:
        """(source, place index, guess of q's pose in the place's frame, yaw half-window [deg], window [m]),
        best first: proximity ones by Mahalanobis distance, then appearance ones by descriptor."""
        cfg = self.cfg
        if valid == 0:
            return []
        out: list[tuple[float, str, int, Vec, float, float]] = []
        seen: set[int] = set()
        near = [(j, self.places[j]) for _, j in self.places.near(q.pose[:2], cfg.gate_neighbours, valid)]
        near = [(j, p) for j, p in near if p.k >= oldest]
        # the Mahalanobis distances: one batched solve (LAPACK on each 2x2 system, as one by one)
        dps = q.pose[:2] - np.array([p.pose[:2] for _, p in near]).reshape(-1, 2)
        S = q.cov[:2, :2] + np.array([p.cov[:2, :2] for _, p in near]).reshape(-1, 2, 2)
        for (j, p), dp, x in zip(near, dps, np.linalg.solve(S, dps[..., None])[..., 0], strict=True):
            d2 = float(dp @ x)
            if d2 <= self.chi_gate:
                guess = _vec(_pose(p.pose).between(_pose(q.pose)))
                out.append((d2 / self.chi_gate, "gate", j, guess, 0.0, 0.0))
                seen.add(j)
        if q.d is not None:
            for j in self.places.similar(q.d.key, cfg.descriptor_neighbours, valid):
                p = self.places[j]
                if j in seen or p.k < oldest or p.d is None:
                    continue
                dd, yaw = desc.distance(q.d, p.d, self.dcfg.min_overlap)
                if dd <= cfg.descriptor_max:
                    sector = 360.0 / self.dcfg.sectors
                    out.append((1.0 + dd, "descriptor", j, np.array([0.0, 0.0, yaw]), sector, cfg.window))
        out.sort(key=lambda c: c[0])
        return [(src, j, g, yw, w) for _, src, j, g, yw, w in out]

    def _verify(self, q: Place, p: Place, guess: Vec, yaw_window: float, window: float, source: str) -> Loop | None:
        cfg = self.cfg
        S_rel = self.relative_cov(p, q)
        if source == "gate" and float(np.linalg.eigvalsh(S_rel[:2, :2])[-1]) < cfg.min_sigma**2:
            self.counts["loop_known"] += 1  # the relative position is known already: nothing to gain
            #                                 (a descriptor candidate: the estimate cannot be that far off)
            return None
        if source == "descriptor":  # "the same place": must the estimate have drifted that far?
            T = _pose(p.pose).between(_pose(q.pose))
            e = np.array([T.x(), T.y()])
            if float(e @ np.linalg.solve(S_rel[:2, :2] + (window / 3) ** 2 * np.eye(2), e)) > self.chi_gate:
                self.counts["loop_known"] += 1
                return None
        if source == "gate":  # the search spans 3 sigma of the relative pose (within the bounds)
            sxy = math.sqrt(max(float(np.linalg.eigvalsh(S_rel[:2, :2])[-1]), 0.0))
            window = float(np.clip(3 * sxy, cfg.window, cfg.max_window))
            yaw_window = min(3 * math.degrees(math.sqrt(max(S_rel[2, 2], 0.0))), 180.0)
        yaw_window = min(yaw_window + cfg.yaw_margin_deg, 180.0)
        grid, target = self.places.submap_of(self.places.of[p.k])
        r = corr.correlative_match(q.xy, grid,
                                   guess, window=window, yaw_window_deg=yaw_window,
                                   second_above=cfg.max_ambiguity, cfg=self.ccfg)
        if not r.ok or r.hits < cfg.min_hits or r.second > cfg.max_ambiguity * r.score:
            self.counts["loop_rejected_match"] += 1
            return None
        if not self._plausible(p, q, r.pose, S_rel + np.diag([self.ccfg.resolution**2] * 2
                                                             + [math.radians(1.0) ** 2])):
            self.counts["loop_rejected_chain"] += 1
            return None
        ok, pose, cov, quality = self.icp_match(q.xy, target, r.pose)
        cov2 = self.cov_of(cov) if ok else None
        if (not ok or cov2 is None or quality.get("degenerate", False)
                or math.hypot(pose[0] - r.pose[0], pose[1] - r.pose[1]) > cfg.refine_agree
                or abs(math.remainder(pose[2] - r.pose[2], 2 * math.pi)) > math.radians(cfg.refine_agree_deg)):
            self.counts["loop_rejected_refine"] += 1
            return None
        floor = np.diag([cfg.cov_floor_xy**2] * 2 + [math.radians(cfg.cov_floor_yaw_deg) ** 2])
        self.counts["loop_verified"] += 1
        return Loop(p.k, q.k, p.s, q.s, np.asarray(pose, dtype=float), cov2 + floor, source)

    def relative_cov(self, p: Place, q: Place) -> Vec:
        """Covariance of ``q``'s pose in ``p``'s frame (x, y in that frame, yaw): the smaller (by
        trace) of the two poses' marginals rotated into it -- relative to the anchor, generous -- and
        the chain's between them (the motion covariances compounded, loops ignored: an upper bound),
        the latter when at most ``max_chain`` keyframes apart."""
        c, s = math.cos(p.pose[2]), math.sin(p.pose[2])
        R = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # world -> the place's frame
        best = R @ (p.cov + q.cov) @ R.T
        if 0 < q.k - p.k <= self.cfg.max_chain:
            C = self.chain.covariance(p.k, q.k)
            T = _pose(p.pose).between(_pose(q.pose))
            A = T.AdjointMap()  # tangent at q -> p's frame
            C = A @ C @ A.T
            if np.trace(C) < np.trace(best):
                best = C
        return best

    def _plausible(self, p: Place, q: Place, z: Vec, S: Vec) -> bool:
        """Consistency with the estimate: the loop's relative pose ``z`` against the estimated one,
        within ``chi2_3(chain_prob)`` of the relative covariance ``S`` (plus the match's
        resolution): a look-alike place farther than the drift can explain is refused."""
        est = _pose(p.pose).between(_pose(q.pose))
        e = np.asarray(gtsam.Pose2.Logmap(est.between(_pose(z))))
        return float(e @ np.linalg.solve(S, e)) <= self.chi_chain

    def consistent(self, l1: Loop, l2: Loop) -> bool:
        """The cycle ``i1 -> k1 (loop 1) -> k2 (chain) -> i2 (loop 2 inverted) -> i1 (chain)`` closes
        within the chi-square bound of its covariance (first order, every term at the identity's
        frame: the cycle is short)."""
        z1, z2 = _pose(l1.z), _pose(l2.z)
        ck, Ck = self.chain.between(l1.k, l2.k)
        ci, Ci = self.chain.between(l2.i, l1.i)
        cyc = z1.compose(ck).compose(z2.inverse()).compose(ci)
        e = np.asarray(gtsam.Pose2.Logmap(cyc))
        S = l1.cov + l2.cov + Ck + Ci
        return float(e @ np.linalg.solve(S, e)) <= self.chi_pair

    def _consider(self, s: Any, loop: Loop) -> None:
        cfg = self.cfg
        partners = [m for m in self.loops
                    if cfg.pair_min <= abs(m.sk - loop.sk) <= cfg.pair_span and abs(m.si - loop.si) <= cfg.pair_span
                    and self.consistent(loop, m)]
        self.loops.append(loop)
        if not partners:
            return
        for m in [*partners, loop]:
            if not m.accepted:
                self._add_factor(s, m)

    def _add_factor(self, s: Any, loop: Loop) -> None:
        cfg = self.cfg
        base = gtsam.noiseModel.Gaussian.Covariance(loop.cov)
        if cfg.kernel == "cauchy":
            model = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Cauchy.Create(cfg.kernel_k), base)
        elif cfg.kernel == "dcs":
            model = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.DCS.Create(cfg.kernel_k), base)
        else:
            model = base
        s.add(s.space.between(F.X(loop.i), F.X(loop.k), np.asarray(loop.z, dtype=float), loop.cov, model=model), "loop")
        loop.accepted = True
        self.accepted.append((loop.i, loop.k))
        self.counts["loop_closures"] += 1
        self.stale = True

    def _expire(self, sk: float) -> None:
        keep = []
        for m in self.loops:
            if sk - m.sk <= self.cfg.pair_span:
                keep.append(m)
            elif not m.accepted:
                self.counts["loop_unconfirmed"] += 1
        self.loops = keep

    def info(self) -> dict[str, Any]:
        return {**self.counts, "places": len(self.places), "loop_ms": self.ms,
                "loop_edges": [list(e) for e in self.accepted]}
