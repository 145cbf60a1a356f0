"""A back end that cannot lose to its own inputs: scan-match and loop factors the data switch off,
and the check that the smoothed motion is as consistent with the odometry as the odometry's own
noise allows.

* :func:`switch_off`: graduated non-convexity (GTSAM's ``GncOptimizer``, truncated least squares;
  Yang et al., RA-L 2020) over the solved graph, with every factor outside :data:`SWITCHABLE` a
  known inlier. A switchable factor whose residual at the solution is within the chi-square bound
  of its own covariance (``prob``) is an inlier; when none does, or only GNSS fixes, no more than chance
  gives and none beyond the family-wise bound (a gross outlier), GNC does not run; otherwise GNC decides,
  the factors it weighs out (weight < 0.5) are removed and Levenberg-Marquardt re-solves the
  original graph (robust kernels kept) without them. The threshold is the chi-square quantile of the
  factor's own dimension: nothing here is fitted to a dataset.
* :func:`odometry_consistency`: the smoothed relative motion over windows of 1, 10, 100 and 1000
  keyframes against the odometry composed over the same window, as a normalised error
  ``e^T C^-1 e`` (``C`` the odometry's own compounded covariance), averaged per degree of freedom
  over non-overlapping windows. The odometry agrees with itself by construction; the smoothed
  local motion may differ from it by no more than its noise: ``consistent`` when the mean of the
  1- and 10-keyframe windows is within the chi-square bound (``prob``) of that many windows (the
  longer windows are reported only: there the smoothed track is meant to correct the odometry's
  drift). Reported in the run's JSON (``odometry_consistency``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import gtsam
import numpy as np

from . import noise
from .chi2 import SCALE_WINDOW, chi2_median, chi2_ppf, ndtri
from .solver import LmSettings, SolverError, _gtsam_message, levenberg_marquardt, lm_params

#: sensor groups whose factors the data may switch off (scan matches, 3D cloud matches, GNSS fixes: a cold
#: start's jumps, multipath; the configuration's ``robust_groups``, which may add "loop")
SWITCHABLE = ("icp", "cloud", "gnss")
#: window lengths [keyframes] of the odometry consistency check: the verdict is on the short ones (the
#: local motion); the long ones are reported, where a smoothed track corrects the odometry's drift and
#: differs from it by more than its stated noise whenever that noise is optimistic over long windows
SCALES = (1, 10, 100, 1000)
VERDICT_SCALES = (1, 10)
#: the groups judged in their neighbours' scatter rather than the whole log's
LOCAL_SCALE = ("gnss",)
#: the groups whose factors beyond their bound make GNC run only beyond chance (:func:`switch_off`)
CHANCE_GROUPS = ("gnss",)
#: the error-decrease tolerance (relative and absolute) of GNC's inner Levenberg-Marquardt solves. They only
#: steer the weights, which end binary; the graph without the factors weighed out is re-solved at the full
#: tolerance. 1e-6 until 2026-12-07: the same factors switched off, half the CPU (psaros33-0006, 2.7 h: 88 -> 43 s)
GNC_INNER_TOL = 1e-3
#: how GNC's ``mu`` grows from its convex start (GTSAM's ``GncScheduler``): "linear", ``mu x 1.4`` a step (Yang et
#: al. 2020); "superlinear", ``sqrt(mu) x 1.4`` while ``mu < 1``, then ``x 1.4``. TLS's surrogate is nearly convex
#: for ``mu << 1``, where the linear schedule spends most of its steps (with ``mu`` from 4e-3: 16 of 20 steps
#: below 1); the decisions are made near and above 1. psaros33-0006's hold-out closing step: the same 8 fixes
#: switched off in 10 steps, the weights binary, against 20 stopped by the cost test (31 against 51 s CPU)
SCHEDULES = {"linear": gtsam.GncScheduler.Linear, "superlinear": gtsam.GncScheduler.SuperLinear}


def _d2(f: gtsam.NonlinearFactor, values: gtsam.Values) -> float:
    """The factor's squared Mahalanobis residual (its Gaussian part)."""
    return float(noise.gaussian(f).squaredMahalanobisDistance(f.unwhitenedError(values)))


def _measured_d2(f: gtsam.NonlinearFactor, values: gtsam.Values, group: str) -> tuple[float, int]:
    """The squared whitened residual over the rows that measure something (``noise.measured_residual``:
    not a fix's height, not the LOOSE rows of an embedded planar match) and their number."""
    e = noise.measured_residual(f, values, group)
    return float(e @ e), int(e.size)


def measured_d2s(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, groups: Sequence[str],
                 g: str) -> list[tuple[int, float, int]]:
    """``(index, squared whitened residual, rows)`` (:func:`_measured_d2`) of each factor of group ``g``
    that measures something, in the graph's order."""
    d = [(i, *_measured_d2(graph.at(i), values, g)) for i, gi in enumerate(groups) if gi == g]
    return [x for x in d if x[2] > 0]


def group_scales(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, groups: Sequence[str],
                 which: Sequence[str], d2s: dict[str, list[tuple[int, float, int]]] | None = None
                 ) -> dict[str, float]:
    """Per group: the variance scale its residuals show, ``median(d2 / dim) / median(chi2_dim / dim)``
    (robust to the outliers being sought), never below 1: a covariance is only ever found too small.
    ``d2s``: the groups' :func:`measured_d2s` when the caller has them."""
    out = {}
    for g in which:
        d = (d2s or {}).get(g)
        d = measured_d2s(graph, values, groups, g) if d is None else d
        if len(d) >= 10:
            dims = np.array([x[2] for x in d])
            ratio = np.array([x[1] for x in d]) / dims
            out[g] = max(1.0, float(np.median(ratio) / np.median(chi2_median(dims) / dims)))
    return out


def factor_scales(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, groups: Sequence[str],
                  which: Sequence[str], window: int = SCALE_WINDOW,
                  d2s: dict[str, list[tuple[int, float, int]]] | None = None) -> dict[int, float]:
    """Per factor of the groups ``which``: the variance scale of :func:`group_scales` over the ``window``
    factors of its group nearest to it in the graph's (time) order: a sensor's noise changes over a
    mission (a receiver losing satellites, multipath near a quay; the Solent scenario 3's GNSS goes
    from 8 to 20 m), and a scale of the whole log would call the noisy half outliers. A median over
    ``window`` factors is not moved by fewer than ``window / 2`` outliers in a row (a jump). ``d2s``: as
    :func:`group_scales`'s."""
    out: dict[int, float] = {}
    for g in which:
        d = (d2s or {}).get(g)
        d = measured_d2s(graph, values, groups, g) if d is None else d
        if len(d) < 10:
            continue
        idx = [x[0] for x in d]
        dims = np.array([x[2] for x in d])
        ratio = np.array([x[1] for x in d]) / dims
        ref = chi2_median(dims) / dims
        w = min(window, len(idx))
        lo = np.clip(np.arange(len(idx)) - w // 2, 0, len(idx) - w)
        win = np.lib.stride_tricks.sliding_window_view(ratio, w)[lo]
        rwin = np.lib.stride_tricks.sliding_window_view(ref, w)[lo]
        scale = np.maximum(1.0, np.median(win, axis=1) / np.median(rwin, axis=1))
        out.update(zip(idx, scale.tolist(), strict=True))
    return out


def _beyond_chance(graph: gtsam.NonlinearFactorGraph, groups: Sequence[str], cand: list[int], suspects: list[int],
                   d2: dict[int, float], factor: dict[int, float], top: float, prob: float,
                   report: dict[str, Any]) -> bool:
    """Whether the ``suspects`` (beyond their bound) are more than chance makes. GNSS fixes: of ``n``
    consistent ones about ``n (1 - prob)`` lie beyond their bound by chance, and a mild outlier among
    hundreds of fixes moves nothing; GNC runs for them when more do (beyond the binomial's ``prob``
    quantile, normal approximation) or when one lies beyond the family-wise bound, the chi-square
    quantile ``1 - (1 - prob) / n`` (Bonferroni: any of ``n`` exceeds it by chance with probability
    ``1 - prob`` at most) -- a gross outlier. Any scan match beyond its bound makes it run: a wrong
    relative pose bends the chain after it (CARMEN orebro: 2 matches beyond, 0.54 m with them, 0.40 m
    without)."""
    n, q = len(cand), 1.0 - prob
    chance = n * q + float(ndtri(prob)) * math.sqrt(n * q * prob)
    gross = [i for i in suspects if d2[i] > top * factor[i] / chi2_ppf(prob, graph.at(i).dim())
             * chi2_ppf(1.0 - q / n, graph.at(i).dim())]
    report.update(chance_bound=chance, beyond_family_bound=len(gross))
    return bool(gross) or len(suspects) > chance or any(groups[i] not in CHANCE_GROUPS for i in suspects)


def switch_off(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, groups: list[str], lm: LmSettings,
               prob: float = 0.99, switchable: Sequence[str] = SWITCHABLE,
               d2s: dict[str, list[tuple[int, float, int]]] | None = None, schedule: str = "superlinear"
               ) -> tuple[gtsam.NonlinearFactorGraph, list[str], gtsam.Values, dict[str, Any]]:
    """GNC over ``graph`` solved at ``values`` (module docstring); returns the graph without the
    switched-off factors, its groups, its solution and a report (per group: candidates and switched
    off). ``d2s``: some groups' :func:`measured_d2s` at ``(graph, values)`` when the caller has them (the
    others are added to it). ``schedule``: how GNC's ``mu`` grows (:data:`SCHEDULES`)."""
    cand = [i for i, g in enumerate(groups) if g in switchable]
    report: dict[str, Any] = {"method": "gnc-tls", "prob": prob,
                              "candidates": {g: sum(groups[i] == g for i in cand) for g in switchable
                                             if any(groups[i] == g for i in cand)}}
    if not cand:
        report.update(beyond_bound=0, switched_off={}, ran=False)
        return graph, groups, values, report
    which = sorted({groups[i] for i in cand})
    d2s = d2s if d2s is not None else {}
    for g in which:  # (once for both scales)
        if g not in d2s:
            d2s[g] = measured_d2s(graph, values, groups, g)
    report["scale"] = group_scales(graph, values, groups, which, d2s)
    # GNSS: each fix in its neighbours' scatter (a receiver's noise changes along a mission); a scan match
    # in its group's (a run of bad matches in a look-alike corridor must not widen its own bound)
    local = factor_scales(graph, values, groups, [g for g in which if g in LOCAL_SCALE], d2s=d2s)
    # each candidate's covariance times its scale and chi2_d(prob) / chi2_D(prob) (D the largest
    # dimension), so that GNC's one threshold, chi2_D(prob) / 2, is every factor's own chi-square bound
    dmax = max(graph.at(i).dim() for i in cand)
    top = chi2_ppf(prob, dmax)
    factor = {i: local.get(i, report["scale"].get(groups[i], 1.0)) * chi2_ppf(prob, graph.at(i).dim()) / top
              for i in cand}
    d2 = {i: _d2(graph.at(i), values) for i in cand}
    suspects = [i for i in cand if d2[i] > top * factor[i]]
    report["beyond_bound"] = len(suspects)
    report["switched_off"] = {}
    if not suspects:
        report["ran"] = False
        return graph, groups, values, report
    if not _beyond_chance(graph, groups, cand, suspects, d2, factor, top, prob, report):
        report["ran"] = False
        return graph, groups, values, report
    gnc_graph = gtsam.NonlinearFactorGraph()
    try:
        for i in range(graph.size()):
            gnc_graph.add(noise.scaled(graph.at(i), factor[i]) if i in factor else graph.at(i))
    except RuntimeError:  # GNC re-weights by cloning every factor: a Python CustomFactor (a GNSS lever arm
        report["ran"] = False  # on the Pose2 graph) cannot be cloned
        report["skipped"] = "a factor GTSAM cannot clone (CustomFactor)"
        return graph, groups, values, report
    inner = max(lm.tol, GNC_INNER_TOL)  # GNC's inner LM: the caller's cap and damping, a looser stop
    params = gtsam.GncLMParams(lm_params(lm, inner, inner))
    params.setLossType(gtsam.GncLossType.TLS)
    params.setScheduler(SCHEDULES[schedule])
    params.setAllowNonNoiseModelFactors(True)  # the linear water-speed factors (graph.water): known inliers
    cset = set(cand)
    params.setKnownInliers([i for i in range(graph.size()) if i not in cset])
    try:
        opt = gtsam.GncLMOptimizer(gnc_graph, values, params)
        opt.setInlierCostThresholds(0.5 * top)
        opt.optimize()
        w = np.asarray(opt.getWeights())
    except RuntimeError as exc:
        if "clone" in str(exc):
            report["ran"] = False
            report["skipped"] = "a factor GTSAM cannot clone (CustomFactor)"
            return graph, groups, values, report
        raise SolverError(_gtsam_message(exc)) from None
    report["ran"] = True
    off = {i for i in suspects if w[i] < 0.5}  # beyond its bound at the solution, and weighed out by GNC
    for i in off:
        report["switched_off"][groups[i]] = report["switched_off"].get(groups[i], 0) + 1
    if not off:
        return graph, groups, values, report
    keep = [i for i in range(graph.size()) if i not in off]
    new = gtsam.NonlinearFactorGraph()
    for i in keep:
        new.add(graph.at(i))
    values, _ = levenberg_marquardt(new, values, lm)
    return new, [groups[i] for i in keep], values, report


def odometry_consistency(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, groups: Sequence[str],
                         prob: float = 0.99, scales: Sequence[int] = SCALES) -> dict[str, Any] | None:
    """The smoothed motion against the odometry factors (``BetweenFactorPose2`` of group
    ``odometry``) over windows of ``scales`` keyframes (module docstring); ``None`` without them."""
    steps: dict[int, tuple[gtsam.Pose2, np.ndarray]] = {}  # first key -> (measured, covariance), consecutive keys
    for i, g in enumerate(groups):
        if g != "odometry":
            continue
        f = graph.at(i)
        if not isinstance(f, gtsam.BetweenFactorPose2):
            return None
        k0, k1 = f.keys()
        R = np.asarray(noise.gaussian(f).R())
        steps[int(k0)] = (f.measured(), np.linalg.inv(R.T @ R), int(k1))
    if not steps:
        return None
    chains: list[list[int]] = []  # runs of consecutive odometry steps
    for k0 in sorted(steps):
        if chains and steps[chains[-1][-1]][2] == k0:
            chains[-1].append(k0)
        else:
            chains.append([k0])
    out: dict[str, Any] = {"prob": prob, "scales": []}
    ok = True
    for w in scales:
        nees = []
        for chain in chains:
            for s in range(0, len(chain) - w + 1, w):
                z, c = gtsam.Pose2(), np.zeros((3, 3))
                for k0 in chain[s:s + w]:
                    m, cm, _ = steps[k0]
                    ad = np.asarray(m.inverse().AdjointMap())
                    c = ad @ c @ ad.T + cm
                    z = z.compose(m)
                a, b = chain[s], steps[chain[s + w - 1]][2]
                rel = values.atPose2(a).between(values.atPose2(b))
                e = np.asarray(gtsam.Pose2.Logmap(z.between(rel)))
                nees.append(float(e @ np.linalg.solve(c, e)))
        if not nees:
            continue
        n = len(nees)
        mean = float(np.mean(nees)) / 3.0
        bound = chi2_ppf(prob, 3 * n) / (3 * n)
        if w in VERDICT_SCALES:
            ok &= mean <= bound
        out["scales"].append({"keyframes": w, "windows": n, "nees_per_dof": mean, "bound": bound,
                              "consistent": mean <= bound})
    out["consistent"] = bool(ok)
    return out
