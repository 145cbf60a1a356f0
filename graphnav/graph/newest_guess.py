"""Batch's guess of a new keyframe's state: the least-squares solution of the keyframe's own factors with
every earlier variable held at its guess -- a filter's update, the earlier state taken as known -- instead of
the motion alone.

Between the incremental solves of ``batch_init="incremental"`` (:func:`graphnav.graph.navigator.batch_initialise`,
at 32, 48, 72, ... keyframes) the poses used to be chained by the motion model only: dead reckoning over up
to a third of the log. A vessel's motion model (the zero-input ``ImuFactor``) then carries the last solved
velocity on for thousands of keyframes; on a 2.7 h sailing log (psaros33-20140627-0006) the chain left its
GNSS fixes by kilometres, and the LM solves from it neither came back (a cost of 5.3e6 at the end against
isam2's ~6 000; 2 340 fixes with a cost above 100 each) nor ended in minutes. With its own fixes, velocity
and heading heard, each new keyframe starts where its measurements put it, and the chain is a filter's track.

A few Gauss-Newton steps on the keyframe's factors (:meth:`gtsam.NonlinearFactorGraph.linearize`, robust
kernels weighted at the current residual) in the new variables only -- the earlier variables' columns of the
whitened Jacobian dropped, so they are held -- with a small damping (``DAMPING``: a direction no factor sees
stays at the motion's guess, the Levenberg-Marquardt regularisation of an underdetermined step); a dense
least-squares solve of a few tens of rows.
"""

from __future__ import annotations

from collections.abc import Callable

import gtsam
import numpy as np

DAMPING = 1e-6  # [whitened units per tangent unit] on the new variables' deltas
ITERATIONS = 5  # Gauss-Newton steps at most
TOL = 1e-3  # a guess: stop once a step's largest element is below this (tangent units: m, rad, m/s)


def solve_newest(graph: gtsam.NonlinearFactorGraph, new: gtsam.Values, earlier: gtsam.Values,
                 type_of: Callable[[int], str]) -> gtsam.Values:
    """``new`` (the keyframe's new variables' guesses) moved to the least-squares solution of ``graph`` (its
    factors) with every other variable they touch held at its value in ``earlier`` (``type_of``: a key's GTSAM
    type name, e.g. ``Pose3``). Factors with a key in neither are left out. Returns new values; ``new`` is not
    changed."""
    vals = gtsam.Values()
    vals.insert(new)
    g = gtsam.NonlinearFactorGraph()
    fixed: set[int] = set()
    for i in range(graph.size()):
        f = graph.at(i)
        ks = [k for k in f.keys() if not new.exists(k)]
        if all(earlier.exists(k) for k in ks):
            g.add(f)
            fixed.update(ks)
    keys = list(new.keys())
    if g.size() == 0 or not keys:
        return gtsam.Values(new)
    for key in fixed:
        vals.insert(key, getattr(earlier, f"at{type_of(key)}")(key))
    zero = vals.zeroVectors()
    dims = [zero.at(k).size for k in keys]
    order = gtsam.Ordering()
    for k in [*keys, *fixed]:
        order.push_back(k)
    n = sum(dims)
    out = gtsam.Values(new)
    for _ in range(ITERATIONS):
        a, b = g.linearize(vals).jacobian(order)  # whitened (robust kernels weighted at the current residual)
        a = np.vstack([a[:, :n], DAMPING * np.eye(n)])  # the earlier variables' columns dropped: held
        dx = np.linalg.lstsq(a, np.concatenate([b, np.zeros(n)]), rcond=None)[0]
        step = gtsam.VectorValues()
        for k, lo, d in zip(keys, np.cumsum([0, *dims[:-1]]), dims, strict=True):
            step.insert(k, dx[lo:lo + d])
        vals, out = vals.retract(step), out.retract(step)
        if float(np.max(np.abs(dx), initial=0.0)) < TOL:
            break
    return out
