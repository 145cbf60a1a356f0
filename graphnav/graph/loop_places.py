"""The loop closer's memory (:mod:`graphnav.graph.loops`): the places -- keyframes with a scan, one
every ``spacing`` metres of travel -- with their position and descriptor indices and their submaps,
and the motion chain -- per keyframe the motion from the previous one, its covariance and the path
length -- that compounds the relative covariance of two keyframes."""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray

from ..scan import correlative as corr
from ..scan import descriptor as desc
from ..scan._kdtree import cKDTree

Vec = NDArray[np.float64]
GRIDS_KEPT = 32  # submaps' likelihood grids kept (least recently used dropped)


@dataclass
class Place:
    k: int
    s: float  # [m] path length
    pose: Vec  # estimate (x, y, yaw), world
    cov: Vec  # world (x, y, yaw) covariance
    xy: Vec  # scan points, sensor frame, scan order
    d: desc.Descriptor | None


@dataclass
class Deferred:
    """A place's refreshed pose whose position is known now and whose yaw is read when the place is
    first looked at: ``read()`` answers the whole ``(x, y, yaw)`` as it was at the refresh."""

    xy: Vec
    read: Callable[[], Vec]


def propagate(cov_w: Vec, pose_prev: Vec, rel: gtsam.Pose2, q: Vec) -> Vec:
    """World covariance of ``pose_prev * rel`` from ``cov_w`` (pose_prev's, world x, y, yaw) and the
    relative motion's body-frame covariance ``q`` (first order)."""
    c, s = math.cos(pose_prev[2]), math.sin(pose_prev[2])
    dx = c * rel.x() - s * rel.y()
    dy = s * rel.x() + c * rel.y()
    J = np.array([[1.0, 0.0, -dy], [0.0, 1.0, dx], [0.0, 0.0, 1.0]])
    th = pose_prev[2] + rel.theta()
    R = np.array([[math.cos(th), -math.sin(th), 0.0], [math.sin(th), math.cos(th), 0.0], [0.0, 0.0, 1.0]])
    return J @ cov_w @ J.T + R @ q @ R.T


def compound(steps: list[tuple[gtsam.Pose2, Vec]]) -> tuple[gtsam.Pose2, Vec]:
    """The relative pose of a chain of steps and its covariance (tangent at the end, GTSAM's
    right-perturbation convention): ``C <- Ad(step^-1) C Ad(step^-1)^T + Q_step``."""
    T, C = gtsam.Pose2(), np.zeros((3, 3))
    for rel, q in steps:
        A = rel.inverse().AdjointMap()
        C = A @ C @ A.T + q
        T = T.compose(rel)
    return T, C


def _pose(v: Vec) -> gtsam.Pose2:
    return gtsam.Pose2(float(v[0]), float(v[1]), float(v[2]))


def _vec(p: gtsam.Pose2) -> Vec:
    return np.array([p.x(), p.y(), p.theta()])


class _Index:
    """Points that grow one at a time: a k-d tree over the first ``n_tree`` and a linear scan
    over the rest, rebuilt when the rest exceeds a quarter of all (amortised O(log n)). The rows live
    in one array (doubled when full): the tail scan is a slice, not a list turned into an array per
    query (O(n) per query on the 2 h harbour: the ring keys' tail is up to a quarter of the places)."""

    def __init__(self) -> None:
        self.buf = np.zeros((0, 0))
        self.n = 0  # rows held: buf[:n]
        self.tree: cKDTree | None = None
        self.n_tree = 0

    def __len__(self) -> int:
        return self.n

    @property
    def rows(self) -> Vec:
        return self.buf[:self.n]

    def add(self, v: Vec) -> None:
        v = np.asarray(v, dtype=float)
        if self.n == len(self.buf):
            buf = np.zeros((max(64, 2 * self.n), v.size))
            if self.n:
                buf[:self.n] = self.buf[:self.n]
            self.buf = buf
        self.buf[self.n] = v
        self.n += 1
        if self.n - self.n_tree > max(32, self.n // 4):
            self.rebuild()

    def set(self, j: int, v: Vec) -> None:
        """Row ``j`` moves (the k-d tree keeps where it was until the next rebuild)."""
        self.buf[j] = v

    def rebuild(self) -> None:
        self.n_tree = self.n
        # (copy_data: the tree keeps the rows as they are now, whatever ``set`` does later)
        self.tree = cKDTree(self.buf[:self.n], copy_data=True) if self.n else None

    def replace(self, start: int, rows: Vec) -> None:
        """Rows ``start`` onwards anew (``rows``: as many), and the tree rebuilt over all."""
        self.buf[start:self.n] = rows
        self.rebuild()

    def nearest(self, q: Vec, n: int, valid: int) -> list[tuple[float, int]]:
        """Up to ``n`` nearest rows among the first ``valid`` ones: (distance, index)."""
        out: list[tuple[float, int]] = []
        if self.tree is not None and self.n_tree:
            kk = min(n + max(0, self.n_tree - valid), self.n_tree)
            d, idx = self.tree.query(q, k=kk)
            d, idx = np.atleast_1d(d), np.atleast_1d(idx)
            ok = np.isfinite(d) & (idx < valid)
            out.extend(zip(d[ok].tolist(), idx[ok].tolist(), strict=True))
        lo, hi = self.n_tree, min(self.n, valid)
        if hi > lo:
            x = self.buf[lo:hi] - q
            d = np.sqrt(np.add.reduce(x * x, axis=1))  # (np.linalg.norm's own arithmetic along an axis)
            j = np.arange(lo, hi)
            if hi - lo > n > 0:  # only the tail's n nearest (and their ties) can be among the n nearest
                keep = ~(d > np.partition(d, n - 1)[n - 1])
                d, j = d[keep], j[keep]
            out.extend(zip(d.tolist(), j.tolist(), strict=True))
        out.sort()
        return out[:n]


class Places:
    """The place database: places in order, their positions (k-d tree) and ring keys (k-d tree), and
    the submap of each place as a correlative matcher's likelihood grid (cached) with the points the
    ICP refinement matches against: the place and its ``submap`` (``refine_submap``) neighbours on
    each side, in the place's frame."""

    def __init__(self, ccfg: corr.CorrelativeConfig, submap: int, refine_submap: int) -> None:
        self.ccfg = ccfg
        self.submap, self.refine_submap = submap, refine_submap
        self.all: list[Place] = []
        self.of: dict[int, int] = {}  # keyframe -> place index
        self.pos_index = _Index()
        self.key_index = _Index()
        self.key_rows: list[int] = []  # key_index row -> place index
        self.grids: OrderedDict[int, tuple[corr.LikelihoodGrid, Vec]] = OrderedDict()
        self.settled = 0  # the leading places whose estimate no longer changes (:meth:`refresh`)
        self.deferred: dict[int, Callable[[], Vec]] = {}  # place index -> its yaw's read (:class:`Deferred`)

    def __len__(self) -> int:
        return len(self.all)

    def __getitem__(self, j: int) -> Place:
        if self.deferred:
            self._resolve(j)
        return self.all[j]

    def _resolve(self, j: int) -> None:
        read = self.deferred.pop(j, None)
        if read is not None:
            self.all[j].pose = np.array(read(), dtype=float)

    def valid(self, sk: float, skip_recent: float) -> int:
        """Number of places at least ``skip_recent`` metres of path back from ``sk``."""
        n = len(self.all)
        while n > 0 and sk - self.all[n - 1].s < skip_recent:
            n -= 1
        return n

    def near(self, xy: Vec, n: int, valid: int) -> list[tuple[float, int]]:
        """Up to ``n`` places nearest to ``xy`` among the first ``valid``: (distance, place index)."""
        return self.pos_index.nearest(xy, n, valid)

    def similar(self, key: Vec, n: int, valid: int) -> list[int]:
        """Up to ``n`` places among the first ``valid`` whose ring keys are nearest to ``key``."""
        m = len(self.key_rows)
        while m > 0 and self.key_rows[m - 1] >= valid:
            m -= 1
        return [self.key_rows[r] for _, r in self.key_index.nearest(key, n, m)]

    def submap_of(self, j: int) -> tuple[corr.LikelihoodGrid, Vec]:
        """Place ``j``'s submap: the likelihood grid and the refinement's target points."""
        got = self.grids.get(j)
        if got is not None:
            self.grids.move_to_end(j)
            return got
        base = _pose(self[j].pose)
        lines = []
        for m in range(max(0, j - self.submap), min(len(self.all), j + self.submap + 1)):
            pm = self[m]
            T = base.between(_pose(pm.pose))
            c, s = math.cos(T.theta()), math.sin(T.theta())
            xy = pm.xy[np.hypot(pm.xy[:, 0], pm.xy[:, 1]) <= self.ccfg.max_range]
            lines.append(xy @ np.array([[c, s], [-s, c]]) + np.array([T.x(), T.y()]))
        g = corr.LikelihoodGrid(lines, self.ccfg)
        lo = j - max(0, j - self.submap)  # the ICP refinement's target: the place and its nearest neighbours
        got = (g, np.vstack(lines[max(0, lo - self.refine_submap):lo + self.refine_submap + 1]))
        self.grids[j] = got
        while len(self.grids) > GRIDS_KEPT:
            self.grids.popitem(last=False)
        return got

    def add(self, place: Place) -> None:
        self.of[place.k] = len(self.all)
        self.all.append(place)
        self.pos_index.add(place.pose[:2])
        if place.d is not None:
            self.key_rows.append(len(self.all) - 1)
            self.key_index.add(place.d.key)

    def observe(self, k: int, pose: Vec, cov_w: Vec | None) -> None:
        """The solved estimate of keyframe ``k`` (replaces the prediction of its place)."""
        j = self.of.get(k)
        if j is not None:
            self.deferred.pop(j, None)
            self.all[j].pose = np.asarray(pose, dtype=float)
            self.pos_index.set(j, self.all[j].pose[:2])
            if cov_w is not None:
                self.all[j].cov = np.asarray(cov_w, dtype=float)

    def refresh(self, estimate: Callable[[list[int]], list[Vec | Deferred | None]],
                final: Callable[[int], bool] | None = None) -> None:
        """New estimates of the places (after a loop moved the graph): ``estimate(keyframes)`` answers
        their poses (``None``: unchanged; :class:`Deferred`: the yaw read when first looked at). ``final(k)``:
        whether keyframe ``k``'s estimate can no longer change (an earlier iSAM2 segment's: the solver's done
        values); the leading places whose estimate was read while final are not read again (:attr:`settled`).
        The submaps are rebuilt when next asked for."""
        start = self.settled
        todo = self.all[start:]
        for j, (p, v) in enumerate(zip(todo, estimate([p.k for p in todo]), strict=True), start):
            if isinstance(v, Deferred):
                p.pose = np.array([v.xy[0], v.xy[1], math.nan])
                self.deferred[j] = v.read
            elif v is not None:
                p.pose = np.array(v, dtype=float)
                self.deferred.pop(j, None)
        if final is not None:
            while self.settled < len(self.all) and final(self.all[self.settled].k):
                self.settled += 1
        self.pos_index.replace(start, np.array([p.pose[:2] for p in todo]).reshape(-1, 2))
        self.grids.clear()


#: [keyframes] up to this many steps MotionChain.covariance compounds directly (exact to rounding whatever
#: the chain's length before ``a``); beyond, from the prefixes
DIRECT_STEPS = 64


class MotionChain:
    """Per keyframe: the motion from the previous one and its covariance, ``Ad(step^-1)`` (the
    covariance compounding) and the path length ``s`` [m]."""

    def __init__(self) -> None:
        self.steps: list[tuple[gtsam.Pose2, Vec]] = []
        self.adj: list[Vec] = []
        self.s: list[float] = []
        self.pose0: list[gtsam.Pose2] = []  # each keyframe's pose relative to keyframe 0 along the chain
        self.cov0: list[Vec] = []  # ... and its covariance (tangent at the keyframe): covariance()

    def add(self, rel: gtsam.Pose2 | None, q: Vec | None) -> None:
        """The next keyframe's motion ``rel`` and its covariance ``q`` (``None``: none, the first)."""
        if rel is None:
            self.steps.append((gtsam.Pose2(), np.zeros((3, 3))))
            self.adj.append(np.eye(3))
            self.s.append(self.s[-1] if self.s else 0.0)
        else:
            self.steps.append((rel, np.asarray(q, dtype=float)))
            self.adj.append(rel.inverse().AdjointMap())
            self.s.append(self.s[-1] + math.hypot(rel.x(), rel.y()))
        step, Q = self.steps[-1]
        A = self.adj[-1]
        self.pose0.append(self.pose0[-1].compose(step) if self.pose0 else gtsam.Pose2())
        self.cov0.append(A @ self.cov0[-1] @ A.T + Q if self.cov0 else np.zeros((3, 3)))

    def covariance(self, a: int, b: int) -> Vec:
        """The covariance of keyframe ``b``'s pose relative to ``a``'s (``a < b``), tangent at ``b``:
        ``C_k = Ad_k C_(k-1) Ad_k^T + Q_k`` from ``a``. Over more than :data:`DIRECT_STEPS` steps, from the
        prefixes instead (O(1)): the recursion is linear, so with ``P_k`` the chain's covariance from
        keyframe 0, ``P_b = M P_a M^T + C``, ``M = Ad(T_ab^-1)`` (on a 30 min harbour the direct loop was
        4 of 35 CPU seconds: a long chain per new loop candidate)."""
        if b - a <= DIRECT_STEPS:
            C = np.zeros((3, 3))
            for k in range(a + 1, b + 1):
                A = self.adj[k]
                C = A @ C @ A.T + self.steps[k][1]
            return C
        M = self.pose0[a].between(self.pose0[b]).inverse().AdjointMap()
        return self.cov0[b] - M @ self.cov0[a] @ M.T

    def between(self, a: int, b: int) -> tuple[gtsam.Pose2, Vec]:
        """The chain's relative pose from keyframe ``a`` to ``b`` (either order) and its covariance."""
        if a <= b:
            return compound(self.steps[a + 1:b + 1])
        T, C = compound(self.steps[b + 1:a + 1])
        A = T.AdjointMap()
        return T.inverse(), A @ C @ A.T
