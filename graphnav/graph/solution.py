"""What a navigator reads out of its solver beyond the online estimate: the smoothed solution at the
end of a run, and the marginals carried as priors when the fixed-lag smoother is re-anchored.

The end (:class:`Closing`): fixed-lag takes each pose as it left the window (the window's own at the
end); iSAM2 relinearises ``final_updates`` times and, with ``converge="lm"``, closes with a
Levenberg-Marquardt step from its estimate over the whole graph -- the problem batch solves from its
initial guess --; the LM solutions re-aim the water-speed factors along the solution's bows (they were
made along the builder's estimate of them, and batch's is its chained guess), reconsider the fixes the
online gate rejected and switch off outliers (GNC, :mod:`graphnav.graph.gnc`), drop gross GNSS outliers
by their residual and re-solve, and estimate a noise scale per sensor group when ``noise_estimation``
asks (:mod:`graphnav.graph.noise`).
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, Any

import gtsam
import numpy as np
from numpy.typing import NDArray

import factors as F

from . import gnc, noise, odometry_scale
from .chi2 import significant_scale
from .smoother_config import SmootherConfig
from .solver import Solver, levenberg_marquardt, marginals
from .space import PlanarSpace
from .water import WaterRow, neighbours

if TYPE_CHECKING:
    from .loop_places import Deferred

Vec = NDArray[np.float64]
#: a water-speed factor's scale linearisation point is settled within this (:meth:`Closing._reaim_water`)
SCALE_SETTLED = 1e-3
#: rounds of re-aiming the water-speed factors at most (:meth:`Closing._reaim_water`)
MAX_REAIM = 5


class Closing:
    """The smoothed solution of a run's graph (module docstring). ``groups``: the sensor group of every
    factor in ``solver.graph`` (kept parallel as factors are added or dropped); ``rejected``: the
    factors of the fixes the online GNSS gate rejected; ``defaulted``: the groups whose sigmas came
    from the configuration (``noise_estimation="defaulted"`` scales only those)."""

    def __init__(self, cfg: SmootherConfig, solver: Solver, space: PlanarSpace, groups: list[str],
                 rejected: list[gtsam.NonlinearFactor], defaulted: set[str],
                 intervals: dict[tuple[int, int], odometry_scale.Interval] | None = None,
                 water: list[WaterRow] | None = None) -> None:
        self.cfg, self.solver, self.space = cfg, solver, space
        self.water = water or []  # the water-speed readings, in the order of their factors in the graph
        self.intervals = intervals or {}  # the odometry factors' samples (graphnav.graph.odometry_scale)
        self.groups = groups
        self.rejected, self.defaulted = rejected, defaulted
        self.kept: list[int] | None = None  # fixed-lag: the keyframes the solution holds (the window only in live mode)
        #: the graph the smoothed covariances come from when it is not the solved one (:meth:`batch`)
        self.cov_graph: gtsam.NonlinearFactorGraph | None = None

    def solve(self, n: int, front: Solver | None, info: dict[str, Any]
              ) -> tuple[gtsam.Values, list[Vec], list[Vec | None] | None]:
        """The solution of keyframes ``0..n-1``: the values, the poses (x, y, yaw) and their world
        covariances (``None`` without ``covariances``). ``front``: batch's iSAM2 front end (loops),
        whose estimate is the one LM solve's start. Facts about the solve go into ``info``."""
        cfg, solver, sp = self.cfg, self.solver, self.space
        if cfg.solver == "fixed-lag" or cfg.solver == "isam2" and not solver.keep:
            return self._window(n)  # (iSAM2 without a kept graph: live mode, the keyframes it holds)
        if cfg.solver == "isam2":
            solver.relinearize(cfg.optimizer.final_updates)
            values = solver.current()
            if cfg.optimizer.converge == "lm":
                values = self.batch(values, info)
        else:  # with a loop closer's iSAM2 front end, its estimate is the one LM solve's start
            values = self.batch(front.current() if front is not None else solver.initial, info)
        p2 = [sp.read(values, F.X(k)) for k in range(n)]
        poses = [_vec(p) for p in p2]
        covs: list[Vec | None] | None = None
        if cfg.optimizer.covariances:
            if cfg.solver == "isam2" and cfg.optimizer.converge != "lm":
                covs = [sp.world_cov(p2[k], solver.marginal(F.X(k))) for k in range(n)]
            else:
                m = marginals(self.cov_graph if self.cov_graph is not None else solver.graph, values)
                covs = [sp.world_cov(p2[k], m(F.X(k))) for k in range(n)]
        return values, poses, covs

    def _window(self, n: int) -> tuple[gtsam.Values, list[Vec], list[Vec | None] | None]:
        """Fixed-lag: each pose as it left the window, the window's estimate for the rest; without a history
        (``Navigator(history=False)``) the poses that left it are gone: the keyframes kept are ``kept``. iSAM2
        without a kept graph (live mode): the keyframes of its current segment."""
        cfg, solver, sp = self.cfg, self.solver, self.space
        values = solver.current()
        held = solver.s.valueExists if cfg.solver == "isam2" else values.exists
        poses: list[Vec] = []
        covs: list[Vec | None] = []
        self.kept = []
        for k in range(n):
            fr = solver.frozen.get(F.X(k))
            if fr is None:
                if not held(F.X(k)):  # left the window (an earlier segment) without a history (live mode): not kept
                    continue
                p = sp.read(values, F.X(k))
                c = sp.world_cov(p, solver.marginal(F.X(k))) if cfg.optimizer.covariances else None
            else:
                p, c = fr
            poses.append(_vec(p))
            covs.append(c)
            self.kept.append(k)
        return values, poses, covs if cfg.optimizer.covariances else None

    def batch(self, init: gtsam.Values, info: dict[str, Any]) -> gtsam.Values:
        """LM over the whole graph from ``init``; gross GNSS outliers (residual beyond ``gnss_gate``
        sigmas) dropped and LM re-run (up to 3 times); then the noise estimation when configured.
        The solver's graph becomes the one solved."""
        cfg, lm = self.cfg, self.solver.lm
        c0 = time.perf_counter()
        graph = self.solver.graph
        if self.rejected and cfg.robust.backend == "gnc":  # the fixes the online gate rejected, reconsidered
            graph = gtsam.NonlinearFactorGraph(graph)
            for f in self.rejected:
                graph.add(f)
            self.groups = self.groups + ["gnss"] * len(self.rejected)
            info["gnss_reconsidered"] = len(self.rejected)
        values, iters = levenberg_marquardt(graph, init, lm)
        if self.water:
            graph, values, it = self._reaim_water(graph, values, info)
            iters += it
        d2s: dict[str, list[tuple[int, float, int]]] = {}  # the fixes' measured residuals at (graph, values)
        if cfg.robust.backend == "gnc":
            solved = graph, values
            graph, self.groups, values, info["switched_off"] = gnc.switch_off(
                graph, values, self.groups, lm, cfg.robust.prob, cfg.robust.groups, d2s=d2s,
                schedule=cfg.robust.gnc_schedule)
            if graph is not solved[0] or values is not solved[1]:
                d2s = {}
        dropped, scale = 0, None  # scale: the fixes' local scales of (graph, values) as they now are
        for _ in range(3 if cfg.gnss.gate is not None else 0):
            # the gate in the fixes' own scatter nearby (a receiver's stated sigma may be optimistic: Solent s2
            # states 7 m for 20 m fixes, and a gate on the stated sigma dropped 210 of 555 correct fixes)
            scale = gnc.factor_scales(graph, values, self.groups, ["gnss"], d2s=d2s)
            d2s = {}
            keep = [i for i in range(graph.size()) if not (self.groups[i] == "gnss" and noise.whitened_norm(
                graph.at(i), values, robust=False) > cfg.gnss.gate * np.sqrt(scale.get(i, 1.0)))]
            if len(keep) == graph.size():
                break
            scale = None  # (the graph changes)
            dropped += graph.size() - len(keep)
            graph = noise.subgraph(graph, keep)
            self.groups = [self.groups[i] for i in keep]
            values, it = levenberg_marquardt(graph, values, lm)
            iters += it
        info["gnss_dropped_after_lm"] = dropped
        graph, values = self._inflate_gnss(graph, values, info, scale)
        if cfg.robust.odometry_scale and self.intervals:
            graph, values, rep = odometry_scale.estimate(graph, values, self.groups, self.intervals, self.space, lm)
            if rep is not None:
                info["odometry_scale"] = rep
        vce: dict[str, Any] = {}
        pre = graph
        if cfg.robust.noise_estimation != "off":
            scalable = noise.SCALABLE if cfg.robust.noise_estimation == "all" else tuple(
                g for g in noise.SCALABLE if g in self.defaulted)
            graph, values, vce = noise.estimate_scales(graph, values, self.groups, scalable,
                                                       cfg.robust.noise_iterations, lm)
            info["noise_scale"] = vce
        info["odometry_consistency"] = oc = gnc.odometry_consistency(graph, values, self.groups, cfg.robust.prob)
        self.cov_graph = self._covariance_graph(pre, graph, vce, oc, info)
        self.solver.graph = graph
        info["lm_iterations"] = iters
        info["converge_ms"] = (time.perf_counter() - c0) * 1e3
        return values

    def _reaim_water(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, info: dict[str, Any]
                     ) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values, int]:
        """The water-speed factors re-aimed along the solution's bows and LM re-run, until no keyframe's
        yaw differs from the one its factors were made with by more than the pose relinearisation
        threshold (the rule by which iSAM2 finds a linearisation point stale). A water-speed factor
        (:class:`~graphnav.graph.water.WaterRow`) is linear in the velocities and takes the bow's
        direction from an estimate: the builder's, made as the record came -- iSAM2's online yaw, but
        batch's chained initial guess, which drifts between its incremental solves (psaros33, 1800 s from
        3400 s: half of batch's final error was these factors, and its withheld fixes 7.4 m off against
        isam2's 2.0 m). Re-aimed, batch and isam2 solve one problem, whatever the guess. With the speed log's
        scale a state the factors are linearised about an estimate's speed through water and scale too
        (:mod:`graphnav.graph.water`): re-made about the solution's until those settle as well."""
        rows, at = self.water, [i for i, g in enumerate(self.groups) if g == "water_speed"]
        if len(at) != len(rows):
            raise RuntimeError(f"{len(at)} water-speed factors in the graph, {len(rows)} readings")
        tol = self.cfg.optimizer.relinearize_threshold
        rounds = iters = 0
        ms = neighbours(rows)
        scaled = any(r.scale is not None for r in rows)
        while True:
            now = np.array([self.space.read(values, F.X(r.a)).theta() for r in rows])
            moved = float(np.max(np.abs(np.angle(np.exp(1j * (now - [r.yaw for r in rows])))), initial=0.0))
            made = [r.about(float(y), values, m) for r, y, m in zip(rows, now, ms, strict=True)]
            dk = max((d for _, d in made), default=0.0)
            if moved <= tol and dk <= SCALE_SETTLED and (rounds or not scaled) or rounds == MAX_REAIM:
                break  # (with a scale, once at least: the readings either side of each)
            rows = [r for r, _ in made]
            new = gtsam.NonlinearFactorGraph(graph)
            for i, r in zip(at, rows, strict=True):
                new.replace(i, r.factor())
            graph = new
            values, it = levenberg_marquardt(graph, values, self.solver.lm)
            rounds, iters = rounds + 1, iters + it
        self.water = rows
        info["water_reaimed"] = {"rounds": rounds, "max_yaw_change_deg": math.degrees(moved),
                                 "max_scale_change": dk, "converged": moved <= tol and dk <= SCALE_SETTLED}
        return graph, values, iters

    def _covariance_graph(self, pre: gtsam.NonlinearFactorGraph, post: gtsam.NonlinearFactorGraph,
                          vce: dict[str, Any], oc: dict[str, Any] | None, info: dict[str, Any]
                          ) -> gtsam.NonlinearFactorGraph | None:
        """The noise estimation's scales assume white errors. Where it shrank a group and the smoothed
        motion then disagrees with the odometry beyond chance over windows of keyframes
        (:func:`gnc.odometry_consistency` fails: errors correlated over time, as MRCLAM's commanded
        velocities), the shrunk sigmas understate the uncertainty over the windows that make up a
        position error: the covariances come from the graph returned, with those groups as they were
        before (``None``: the solved graph's), the estimate keeps the estimated weights. MRCLAM DS6 r1-r5 smoothed NEES
        42.4/22.5/6.6/24.9/17.7 -> 3.5/7.1/1.8/4.4/5.7 at the same ATE (docs/smoother.md)."""
        shrunk = sorted(g for g, r in vce.items() if r.get("scale", 1.0) < 1.0)
        if not shrunk or oc is None or oc.get("consistent", True):
            return None
        cov = gtsam.NonlinearFactorGraph()
        for i in range(post.size()):
            cov.add(pre.at(i) if self.groups[i] in shrunk else post.at(i))
        info["covariance_noise"] = {"unshrunk": shrunk,
                                    "why": "odometry windows inconsistent after the noise estimation"}
        return cov

    def _inflate_gnss(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, info: dict[str, Any],
                      scale: dict[int, float] | None = None) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
        """The fixes whose scatter nearby (:func:`gnc.factor_scales`) shows their stated sigma too small
        beyond chance (:func:`~graphnav.graph.chi2.significant_scale`, ``robust.prob``) get their covariance times that
        scale, and LM re-solves: a receiver's stated sigma is a claim the log can refute (Solent s2 states
        7 m for 20 m fixes: NEES 7.6 and 2.7 m before, see docs/smoother.md). Never deflated."""
        if scale is None:  # (the gate's, when it dropped nothing, is of this very graph and values)
            scale = gnc.factor_scales(graph, values, self.groups, ["gnss"])
        if not scale:
            return graph, values
        bound = significant_scale(2, self.cfg.robust.prob)  # a fix measures 2 axes (its height is the surface)
        big = {i: s for i, s in scale.items() if s > bound}
        info["gnss_inflated"] = {"fixes": len(big), "of": len(scale),
                                 "median_scale": float(np.median(list(big.values()))) if big else 1.0}
        if not big:
            return graph, values
        new = gtsam.NonlinearFactorGraph()
        for i in range(graph.size()):
            new.add(noise.scaled(graph.at(i), big[i]) if i in big else graph.at(i))
        values, _ = levenberg_marquardt(new, values, self.solver.lm)
        return new, values


def type_of(key: int, space: PlanarSpace) -> str:
    """The GTSAM type name of a state variable by its symbol (poses, beacons ``l``, velocities ``v``,
    water current ``w``, the speed log's scale ``k``, IMU biases ``i``)."""
    ch = chr(gtsam.Symbol(key).chr())
    return space.point_type if ch == "l" else "Vector" if ch in "vwk" else "ConstantBias" if ch == "i" \
        else space.pose_type


def marginal_priors(solver: Solver, space: PlanarSpace, keys: list[int], t: float
                    ) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values, dict[int, float]]:
    """Priors carrying the current estimates and marginals of ``keys`` (poses, beacons ``l``,
    velocities ``v``, water current ``w``, IMU biases ``i``), their values and time stamps ``t``:
    a fresh fixed-lag smoother's start."""
    g, v, stamps = gtsam.NonlinearFactorGraph(), gtsam.Values(), {}
    for key in keys:
        cov = solver.marginal(key)
        model = gtsam.noiseModel.Gaussian.Covariance(cov)
        kind = type_of(key, space)
        p = solver.estimate(key, kind)
        if kind == space.point_type:
            g.add(space.landmark_prior_cov(key, p, cov))
        elif kind == "Vector":
            g.add(gtsam.PriorFactorVector(key, p, model))
        elif kind == "ConstantBias":
            g.add(gtsam.PriorFactorConstantBias(key, p, model))
        else:
            g.add(space.prior_cov(key, p, cov))
        v.insert(key, p)
        stamps[key] = t
    return g, v, stamps


def joint_prior(solver: Solver, space: PlanarSpace, keys: list[int], t: float
                ) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values, dict[int, float]]:
    """As :func:`marginal_priors`, but one prior over ``keys`` jointly: their iSAM2 joint marginal
    information ``L`` about their current estimates, ``1/2 d^T L d`` with ``d`` the tangent-space
    offsets (a ``LinearContainerFactor`` of the ``HessianFactor``). A fresh iSAM2 segment's start
    that keeps the correlations -- the pose with its velocity, beacons with the pose -- which
    separate priors drop (MRCLAM r1 in 300-keyframe segments: online NEES 3.5 -> 73 with them)."""
    values = gtsam.Values()
    for key in keys:
        values.insert(key, solver.estimate(key, type_of(key, space)))
    stamps = dict.fromkeys(keys, t)
    jm = solver.s.jointMarginalInformation(keys)
    parts = gtsam.GaussianFactorGraph()
    for i, a in enumerate(keys):
        block = np.asarray(jm.at(a, a))
        parts.push_back(gtsam.HessianFactor(a, block, np.zeros(block.shape[0]), 0.0))
        for b in keys[i + 1:]:
            cross = np.asarray(jm.at(a, b))
            na, nb = cross.shape
            parts.push_back(gtsam.HessianFactor(a, b, np.zeros((na, na)), cross, np.zeros(na),
                                                np.zeros((nb, nb)), np.zeros(nb), 0.0))
    g = gtsam.NonlinearFactorGraph()
    g.add(gtsam.LinearContainerFactor(gtsam.HessianFactor(parts), values))
    return g, values, stamps


def refresh_places(loops: Any, solver: Solver, space: PlanarSpace) -> None:
    """The loop closer's places re-estimated from ``solver`` (after a loop moved the graph): on iSAM2
    each place's pose alone (no full back-substitution of every state), many in one read
    (:func:`place_poses`), the places of earlier segments (the done values after a rebase) once; else from
    the current values."""
    if solver.kind == "isam2":
        loops.refresh(lambda ks: place_poses(solver, space, ks), lambda k: solver.settled(F.X(k)))
    else:
        values = solver.current()
        loops.refresh(lambda ks: [_vec(space.read(values, F.X(k))) if values.exists(F.X(k)) else None for k in ks])


def place_poses(solver: Solver, space: PlanarSpace, ks: list[int]) -> list[Vec | Deferred]:
    """iSAM2: the planar poses ``(x, y, yaw)`` of keyframes ``ks`` bit for bit as
    ``_vec(space.pose2(solver.estimate(X(k))))`` answers them one by one: the Pose2 graph's most from one
    :meth:`Solver.held_estimate` (``extractPose2``); the Pose3 graph's one by one (its held estimate retracts
    every velocity and IMU bias too: dearer), the position now and the yaw when the place is first looked at
    (:class:`Deferred`)."""
    from .loop_places import Deferred  # (here: the loop closer's module imports scipy's k-d tree and ndimage)

    keys = [F.X(k) for k in ks]
    if space.pose_type != "Pose2":
        out: list[Vec | Deferred] = []
        for key in keys:
            p = solver.estimate(key, space.pose_type)
            out.append(Deferred(p.translation()[:2], lambda p=p: _vec(space.pose2(p))))
        return out
    out = [np.zeros(0)] * len(keys)
    rest = []
    for i, key in enumerate(keys):
        if solver.read_apart(key):
            out[i] = _vec(space.pose2(solver.estimate(key, space.pose_type)))
        else:
            rest.append(i)
    if not rest:
        return out
    values = solver.held_estimate()
    row = {key: r for r, key in enumerate(gtsam.utilities.allPose2s(values).keys())}
    xyt = gtsam.utilities.extractPose2(values)
    for i in rest:
        r = row.get(keys[i])
        out[i] = xyt[r] if r is not None else _vec(space.pose2(solver.estimate(keys[i], space.pose_type)))
    return out


def _vec(p: gtsam.Pose2) -> Vec:
    return np.array([p.x(), p.y(), p.theta()])
