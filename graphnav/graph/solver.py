"""One solver wrapper for every factor graph of graphnav: batch Levenberg-Marquardt, iSAM2 or the
incremental fixed-lag smoother, behind the same three calls.

* :func:`isam_params` builds the ``ISAM2Params`` (relinearisation thresholds per variable type,
  skip, partial check, wildfire) -- the one place they are written; the navigation graph
  (:mod:`graphnav.graph.navigator`) passes the thresholds of its state space.
* :class:`Solver` takes per-keyframe factor batches (``update``), answers the online estimate of a
  variable and its marginal (iSAM2 / fixed-lag; batch answers the initial guess and ``None``) and,
  at the end, the smoothed values (:meth:`Solver.smoothed`). iSAM2 and batch keep the whole graph
  (``graph``, ``initial``) so that the closing Levenberg-Marquardt step and the noise estimation
  (:mod:`graphnav.graph.noise`) can run on it; the fixed-lag smoother keeps nothing beyond its
  window, and the estimate (and marginal) of each tracked variable is frozen as it leaves the window.
* Failures of GTSAM (an indeterminate system) are raised as :class:`SolverError` with the message;
  the caller names the record and time.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np
from numpy.typing import ArrayLike, NDArray

KINDS = ("isam2", "fixed-lag", "batch")


class SolverError(RuntimeError):
    """GTSAM could not solve the graph (e.g. an indeterminate linear system)."""


def isam_params(thresholds: Mapping[str, ArrayLike] | float, *, skip: int = 1, partial_check: bool = True,
                wildfire: float | None = None, factorization: str = "QR",
                optimizer: str = "gauss-newton") -> gtsam.ISAM2Params:
    """``ISAM2Params`` with relinearisation ``thresholds`` per variable type (the symbol's character,
    e.g. ``{"x": [0.05]*3, "l": [0.5]*2}``) or one scalar, ``relinearizeSkip`` ``skip``,
    ``enablePartialRelinearizationCheck``, the wildfire threshold, the clique ``factorization``
    and the ``optimizer`` of each update.

    ``factorization``: ``"QR"`` (default) or ``"CHOLESKY"``. Cholesky squares the condition number
    and fails ("indeterminate linear system") on long odometry chains from a tight anchor (7 of the
    9 CARMEN logs); QR does not. ``optimizer``: ``"gauss-newton"`` (default) or ``"dogleg"``
    (Powell's dog leg, a trust region: 1.3x the time on the harbour log, 20x on MRCLAM). An
    undamped Gauss-Newton step diverges where a variable is barely observable (the yaw of a
    GNSS-only log anchored with a yaw sigma of pi: the online yaw oscillated by +-2 rad and the
    track trailed the fixes by 50 m); the builder keeps such priors at 1 rad instead."""
    if optimizer not in ("dogleg", "gauss-newton"):
        raise ValueError(f"optimizer must be 'dogleg' or 'gauss-newton', not {optimizer!r}")
    p = gtsam.ISAM2Params()
    p.setFactorization(factorization)
    if isinstance(thresholds, Mapping):
        th = gtsam.ISAM2ThresholdMap()
        for ch, v in thresholds.items():
            th.insert((ch, np.asarray(v, dtype=float)))
        p.setRelinearizeThreshold(th)
    else:
        p.setRelinearizeThreshold(float(thresholds))
    p.relinearizeSkip = int(skip)
    p.enablePartialRelinearizationCheck = bool(partial_check)
    opt = gtsam.ISAM2DoglegParams() if optimizer == "dogleg" else gtsam.ISAM2GaussNewtonParams()
    if wildfire is not None:
        opt.setWildfireThreshold(float(wildfire))
    p.setOptimizationParams(opt)
    return p


@dataclass
class LmSettings:
    """Levenberg-Marquardt stopping rule."""

    tol: float = 1e-14  # relative and absolute error-decrease tolerance
    max_iterations: int = 100
    #: an iteration that lowers the cost (1/2 chi^2) by less than this ends the solve (at least ``tol``)
    abs_tol: float = 0.0
    #: ``stall_iterations`` iterations in a row that together lower the cost by less than ``stall_tol`` end the
    #: solve (0: off): a crawl along a barely observed direction (:func:`levenberg_marquardt`)
    stall_tol: float = 0.0
    stall_iterations: int = 10
    #: the damping's update: ``True`` Nielsen's from each step's gain ratio (GTSAM's ``useFixedLambdaFactor``
    #: false), ``False`` GTSAM's default (x10 on a failed try, /10 on a success)
    adaptive: bool = False


def lm_params(lm: LmSettings, tol: float, abs_tol: float) -> gtsam.LevenbergMarquardtParams:
    """GTSAM's LM parameters of ``lm`` (iteration cap, damping update) with relative / absolute decrease
    tolerances ``tol`` / ``abs_tol``: every LM graphnav runs, its own solves and GNC's inner one."""
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(lm.max_iterations)
    params.setRelativeErrorTol(tol)
    params.setAbsoluteErrorTol(abs_tol)
    params.setUseFixedLambdaFactor(not lm.adaptive)
    return params


def levenberg_marquardt(graph: gtsam.NonlinearFactorGraph, init: gtsam.Values,
                        lm: LmSettings | None = None) -> tuple[gtsam.Values, int]:
    """``LevenbergMarquardtOptimizer(graph, init)`` iterated to GTSAM's own stopping rule (``optimize()``'s:
    an iteration's decrease of the cost below ``abs_tol`` or ``tol`` relative, ``max_iterations``), and to a
    stall: ``stall_iterations`` iterations that together lowered the cost by less than ``stall_tol``. LM
    crawls where the Gauss-Newton step fails and its damping stays on, along a direction the data barely
    determine: psaros33-20140627-0006's 924 s without a heading (GNSS only) cost 841 iterations after the
    30th for 1.9 of 3540 (the yaws there, free within tens of degrees, moved, positions by 5 mm RMS;
    docs/smoother.md *The closing step's stall rule*). Returns the values and the iterations."""
    lm = lm or LmSettings()
    abs_tol = max(lm.tol, lm.abs_tol)
    params = lm_params(lm, lm.tol, abs_tol)
    try:
        opt = gtsam.LevenbergMarquardtOptimizer(graph, init, params)
        costs = [opt.error()]
        while opt.iterations() < lm.max_iterations and costs[-1] > 0.0:
            opt.iterate()
            costs.append(opt.error())
            drop = costs[-2] - costs[-1]
            if not np.isfinite(costs[-1]) or drop <= abs_tol or drop <= lm.tol * costs[-2] or (
                    len(costs) > lm.stall_iterations and costs[-1 - lm.stall_iterations] - costs[-1] < lm.stall_tol):
                break
        return opt.values(), int(opt.iterations())
    except RuntimeError as exc:
        raise SolverError(_gtsam_message(exc)) from None


def held_part(graph: gtsam.NonlinearFactorGraph, exists: Callable[[int], bool]
              ) -> tuple[gtsam.NonlinearFactorGraph, list[bool]]:
    """The factors of ``graph`` whose every variable ``exists`` (a solver holds it), and per factor whether it is
    one of them."""
    held = [all(exists(key) for key in graph.at(i).keys()) for i in range(graph.size())]
    part = gtsam.NonlinearFactorGraph()
    for i, h in enumerate(held):
        if h:
            part.add(graph.at(i))
    return part, held


def _gtsam_message(exc: BaseException) -> str:
    """GTSAM's message on one line (its indeterminate-system text spans a paragraph)."""
    text = " ".join(str(exc).split())
    if "Indeterminate linear system" in text:
        return "indeterminate linear system: " + text.split("Indeterminate linear system detected", 1)[1].split(
            ". ", 1)[0].strip()
    return text[:300]


class Solver:
    """Batch LM, iSAM2 or fixed-lag behind ``update`` / ``estimate`` / ``marginal`` / ``smoothed``.

    ``kind``: one of :data:`KINDS`. ``params``: ``ISAM2Params`` (iSAM2 and fixed-lag). ``lag`` [s]:
    the fixed-lag window. ``value_type``: the GTSAM type name of tracked variables (``"Pose2"``,
    ``"Pose3"``) for the typed ``calculateEstimate*`` calls. ``keep_graph`` (iSAM2): also keep
    the whole graph (closing LM step, noise estimation, batch marginals).
    """

    def __init__(self, kind: str, params: gtsam.ISAM2Params | None = None, *, lag: float = 20.0,
                 lm: LmSettings | None = None, keep_graph: bool = True) -> None:
        if kind not in KINDS:
            raise ValueError(f"solver must be one of {KINDS}, not {kind!r}")
        self.kind = kind
        self.lm = lm or LmSettings()
        self.lag = float(lag)
        self.params = params if params is not None else isam_params(0.1)
        self.keep = kind == "batch" or (kind == "isam2" and keep_graph)
        self.graph = gtsam.NonlinearFactorGraph()  # everything (batch, and iSAM2 with keep_graph)
        self.initial = gtsam.Values()
        self.frozen: dict[int, tuple[Any, NDArray[np.float64] | None]] = {}  # fixed-lag: left the window
        self._fresh: set[int] = set()  # iSAM2, fixed-lag: the variables the last update inserted (`estimate`)
        self._info: dict[int, NDArray[np.float64]] = {}  # ... their marginal information, once read
        self._marginals: dict[int, NDArray[np.float64]] = {}  # ... its inverse, once asked for (`marginal`)
        self._stamps: dict[int, float] = {}  # fixed-lag: tracked key -> time
        self.done = gtsam.Values()  # iSAM2 after a rebase: the estimates of the variables it no longer holds
        self.updates = 0
        self.new_indices: list[int] = []  # iSAM2 / fixed-lag: the indices of the last update's factors
        if kind == "isam2":
            self.s = gtsam.ISAM2(self.params)
        elif kind == "fixed-lag":
            self.s = gtsam.IncrementalFixedLagSmoother(self.lag, self.params)
        else:
            self.s = None

    @property
    def online(self) -> bool:
        """Whether the solver has an online estimate after every update."""
        return self.kind != "batch"

    def update(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
               stamps: Mapping[int, float] | None = None, *, t: float | None = None,
               track: Callable[[int], tuple[Any, NDArray[np.float64] | None]] | None = None,
               tracked: tuple[int, ...] = (), kept: gtsam.NonlinearFactorGraph | None = None) -> None:
        """Add new factors and variables. Fixed-lag: ``stamps`` are the keys' times, ``t`` the
        newest time; before the update, each key of ``tracked`` (registered in earlier updates) older
        than ``t - lag`` is frozen with ``track(key)`` (its last estimate and marginal). ``kept``: the
        same factors as the closing step is to solve them (default ``graph``)."""
        if self.keep:
            self.graph.push_back(graph if kept is None else kept)
            self.initial.insert(values)
        try:
            if self.kind == "isam2":
                online, held = self._held(graph, values)
                idx = iter(self.s.update(online, values).getNewFactorsIndices())
                self.new_indices = [next(idx) if h else -1 for h in held]
                self._fresh = set(values.keys())
                self._info, self._marginals = {}, {}
            elif self.kind == "fixed-lag":
                if t is not None and track is not None:
                    for key, ts in list(self._stamps.items()):
                        if ts < t - self.lag:
                            self.frozen[key] = track(key)
                            del self._stamps[key]
                for key in tracked:
                    self._stamps[key] = (stamps or {})[key]
                m = gtsam.FixedLagSmootherKeyTimestampMap()
                for key, ts in (stamps or {}).items():
                    m.insert((key, ts))
                self.s.update(graph, values, m)
                self.new_indices = list(self.s.getISAM2Result().getNewFactorsIndices())
                self._fresh = set(values.keys())
                self._info, self._marginals = {}, {}
        except RuntimeError as exc:
            raise SolverError(_gtsam_message(exc)) from None
        self.updates += 1

    def _held(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values
              ) -> tuple[gtsam.NonlinearFactorGraph, list[bool]]:
        """iSAM2 after a rebase: the factors of ``graph`` on variables it holds (or ``values`` brings), and
        per factor whether it is one of them. A factor on a variable of an earlier segment (a loop
        closure back to it) enters only the kept graph, which the closing step solves."""
        if not self.done.size():
            return graph, [True] * graph.size()
        exists, held_key = values.exists, self.s.valueExists
        if all(exists(key) or held_key(key) for key in graph.keyVector()):  # (each key once: the common case)
            return graph, [True] * graph.size()
        return held_part(graph, lambda key: exists(key) or held_key(key))

    def rebase(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, stamps: Mapping[int, float]) -> None:
        """Replace the online smoother by a fresh one holding ``graph``/``values`` (priors carrying the
        marginals of the variables still in use), at the cost of the correlations between those variables.
        Fixed-lag: GTSAM's smoothers keep an empty slot for every factor ever removed (~220 bytes each);
        starting afresh keeps memory flat. iSAM2: its update walks the whole Bayes tree (GTSAM 4.3.0);
        the other variables keep their estimates (:attr:`done`), the kept graph is untouched."""
        if self.kind == "isam2":
            old = self.s.calculateBestEstimate()
            for key in values.keys():
                old.erase(key)
            self.done.insert(old)
            self.s = gtsam.ISAM2(self.params)
            self._fresh, self._info, self._marginals = set(), {}, {}
            try:
                self.s.update(graph, values)
            except RuntimeError as exc:
                raise SolverError(_gtsam_message(exc)) from None
            return
        if self.kind != "fixed-lag":
            raise ValueError("only the fixed-lag smoother and iSAM2 are rebased")
        self.s = gtsam.IncrementalFixedLagSmoother(self.lag, self.params)
        self._fresh, self._info, self._marginals = set(), {}, {}
        self._stamps = {k: v for k, v in self._stamps.items() if values.exists(k)}
        m = gtsam.FixedLagSmootherKeyTimestampMap()
        for key, ts in stamps.items():
            m.insert((key, ts))
        try:
            self.s.update(graph, values, m)
        except RuntimeError as exc:
            raise SolverError(_gtsam_message(exc)) from None

    def remove(self, indices: list[int], settle: int = 3, add: gtsam.NonlinearFactorGraph | None = None,
               relinearize: bool = True) -> list[int]:
        """iSAM2 and fixed-lag: take the factors of ``indices`` (:attr:`new_indices` of earlier updates) out of
        the online problem (``add``: put these in instead), then relinearise ``settle`` times (iSAM2: regardless
        of the skip; the robust kernels' weights of what remains re-evaluated); the new indices of ``add``'s
        factors (-1: not added), ``[]`` for batch. Fixed-lag: the factors the window has marginalised out stay in
        their marginals (only those still held are removed), and a factor of ``add`` only goes in while its
        variables are in the window. ``relinearize=False`` (iSAM2): the swap alone, no relinearisation of
        everything. The kept graph of the closing step is untouched."""
        if self.kind == "batch":
            return []
        add = add if add is not None else gtsam.NonlinearFactorGraph()
        try:
            if self.kind == "fixed-lag":  # (a rebase starts afresh: its caller forgets the indices)
                held, theta = self.s.getFactors(), self.s.getLinearizationPoint()
                indices = [i for i in indices if held.exists(i)]
                sub, ok = held_part(add, theta.exists)
                self.s.update(sub, gtsam.Values(), gtsam.FixedLagSmootherKeyTimestampMap(), indices)
                got = iter(list(self.s.getISAM2Result().getNewFactorsIndices()))
                for _ in range(settle):
                    self.s.update()
            else:
                ok = [True] * add.size()
                got = iter(list(self.s.update(add, gtsam.Values(), list(indices), force_relinearize=relinearize)
                                .getNewFactorsIndices()))
                for _ in range(settle):
                    self.s.update(gtsam.NonlinearFactorGraph(), gtsam.Values(), force_relinearize=True)
        except RuntimeError as exc:
            raise SolverError(_gtsam_message(exc)) from None
        self._info, self._marginals = {}, {}
        return [next(got) if k else -1 for k in ok]

    def relinearize(self, n: int) -> None:
        """``n`` extra ``update()`` calls without new factors (iSAM2 / fixed-lag relinearisation)."""
        if self.kind == "batch":
            return
        try:
            for _ in range(n):
                self.s.update()
        except RuntimeError as exc:
            raise SolverError(_gtsam_message(exc)) from None
        self._info, self._marginals = {}, {}

    def estimate(self, key: int, type_name: str = "Pose2") -> Any:
        """The current estimate of ``key`` (batch: the initial guess).

        iSAM2 and fixed-lag (its iSAM2): a variable the last update inserted (the newest keyframe's state) is
        read from its marginal factor -- the linearisation point moved by the Gauss-Newton step of its clique (the
        root's, or one near it), exact, with its marginal covariance on the way -- without the
        back-substitution of the whole Bayes tree that ``calculateEstimate`` runs first. That
        back-substitution re-solves every clique whose separator moved by more than the wildfire
        threshold, and each GNSS fix moves the whole (rigid) trajectory a little: its cost grew with
        the log (docs/performance.md). Older variables: ``calculateEstimate``."""
        if self.kind == "batch":
            return getattr(self.initial, f"at{type_name}")(key)
        try:
            if key in self._fresh:
                try:
                    return self._newest(key, type_name)
                except RuntimeError:  # a marginal not defined yet (e.g. an IMU bias at the start)
                    pass
            if self.settled(key):
                return getattr(self.done, f"at{type_name}")(key)
            return getattr(self.s, f"calculateEstimate{type_name}")(key)
        except RuntimeError as exc:
            raise SolverError(_gtsam_message(exc)) from None

    def _newest(self, key: int, type_name: str) -> Any:
        """A freshly inserted variable's estimate from its marginal (``estimate``); the marginal
        covariance is kept for :meth:`marginal`."""
        isam = self.s if self.kind == "isam2" else self.s.getISAM2()  # (fixed-lag: a reference, not a copy)
        cond = isam.marginalFactor(key)
        info = np.asarray(cond.information())
        delta = np.asarray(cond.solve(gtsam.VectorValues()).at(key))
        self._info[key] = info  # (inverted when asked for: the IMU bias's and the current's never are)
        theta = getattr(self.s.getLinearizationPoint(), f"at{type_name}")(key)
        if type_name in ("Vector", "Point2", "Point3", "Double"):
            return np.asarray(theta) + delta
        return theta.retract(delta)

    def holds(self, key: int) -> bool:
        """iSAM2 and fixed-lag: whether the online problem holds ``key`` (not an earlier segment's, not
        marginalised out of the window)."""
        if self.kind == "batch":
            return False
        return bool((self.s if self.kind == "isam2" else self.s.getISAM2()).valueExists(key))

    def settled(self, key: int) -> bool:
        """iSAM2: whether ``key``'s estimate no longer changes (an earlier segment's, :attr:`done`)."""
        return self.kind == "isam2" and self.done.exists(key) and not self.s.valueExists(key)

    def read_apart(self, key: int) -> bool:
        """iSAM2: whether :meth:`estimate` reads ``key`` otherwise than from :meth:`held_estimate` (the newest
        variable, from its marginal; an earlier segment's, from the done values)."""
        return key in self._fresh or self.settled(key)

    def held_estimate(self) -> gtsam.Values:
        """iSAM2: the estimates of the variables the smoother holds in one call (``calculateEstimate``: the
        same retraction of the same delta as :meth:`estimate` of each, bit for bit), for reading many at once;
        those that :meth:`read_apart` names are :meth:`estimate`'s to read."""
        try:
            return self.s.calculateEstimate()
        except RuntimeError as exc:
            raise SolverError(_gtsam_message(exc)) from None

    def marginal(self, key: int) -> NDArray[np.float64] | None:
        """Marginal covariance of ``key`` in GTSAM's tangent space (``None`` for batch)."""
        if self.kind == "batch":
            return None
        cached = self._marginals.get(key)
        if cached is None and key in self._info:
            cached = self._marginals[key] = np.linalg.inv(self._info[key])
        if cached is not None:
            return cached.copy()
        try:
            return np.asarray(self.s.marginalCovariance(key))
        except RuntimeError as exc:
            raise SolverError(_gtsam_message(exc)) from None

    def current(self) -> gtsam.Values:
        """Every variable's current estimate: iSAM2 ``calculateBestEstimate`` (full back-substitution; after a
        rebase with the estimates it no longer holds), fixed-lag ``calculateEstimate`` (the window), batch the
        initial guess."""
        if self.kind == "batch":
            return gtsam.Values(self.initial)
        try:
            if self.kind == "fixed-lag":
                return self.s.calculateEstimate()
            values = self.s.calculateBestEstimate()
            if self.done.size():
                values.insert(self.done)
            return values
        except RuntimeError as exc:
            raise SolverError(_gtsam_message(exc)) from None


def marginals(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> Callable[[int], NDArray[np.float64]]:
    """``key -> marginal covariance`` of a batch solution: ``gtsam.Marginals`` (Cholesky), or where
    that finds the system indeterminate -- when it is built, or later for one key (the 2.7 h psaros33
    log with GNSS withheld: a pose's marginal, GTSAM's elimination stopping near a velocity) -- the marginals of a
    QR-factorised iSAM2 Bayes tree of the same graph linearised at ``values``, for that key and every
    later one (the Pose3 graph's loose roll/pitch/height directions and IMU biases, a vessel's
    velocity through a long GNSS gap, leave it ill-conditioned, not singular)."""
    state: dict[str, Any] = {}
    try:
        state["chol"] = gtsam.Marginals(graph, values)
    except RuntimeError:
        pass  # Marginals factorises by Cholesky, which squares the condition number: QR in an iSAM2 tree

    def qr() -> gtsam.ISAM2:
        if "qr" not in state:
            p = isam_params(1e9, factorization="QR")  # at ``values``: no relinearisation
            try:
                isam = gtsam.ISAM2(p)
                isam.update(graph, values)
            except RuntimeError as exc:
                raise SolverError(_gtsam_message(exc)) from None
            state["qr"] = isam
        return state["qr"]

    def marginal(key: int) -> NDArray[np.float64]:
        chol = state.get("chol")
        if chol is not None:
            try:
                return np.asarray(chol.marginalCovariance(key))
            except RuntimeError:
                state["chol"] = None  # indeterminate for this key: QR from now on
        try:
            return np.asarray(qr().marginalCovariance(key))
        except RuntimeError as exc:
            raise SolverError(_gtsam_message(exc)) from None

    if "chol" not in state:
        qr()  # an error building the QR tree is the caller's now, as before
    return marginal
