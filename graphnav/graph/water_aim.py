"""The water-speed factors re-aimed online, by iSAM2's own relinearisation rule.

A water-speed factor (:class:`~graphnav.graph.water.WaterRow`) is linear in the velocities and takes the
bow's direction from an estimate: the keyframe's predicted yaw, as the record comes. iSAM2 relinearises a
nonlinear factor once its variables' estimates move by more than the relinearisation threshold; a linear
factor it keeps as made. Left so, every reading holds the velocity over ground minus the current along
the bow *as it was predicted*, which lags in a turn (10-18 deg on psaros33-0004 leaving the berth), and
the compass-bias frame then settles where those bows agree with the fixes: the factors' bows become the
estimate's, which makes the next ones'. Measured on psaros33-20140627-0004 (``--holdout-gnss 300,60``,
the online graph at t0 + 1100 s, one iSAM2 segment): its optimum puts the compass bias at -4.2 deg with the
bows as made (median 7.9 deg, 90 % 14 deg from the solution's), 0.3 deg with them re-made about the
solution; iSAM2's estimate itself was at -7.5 deg, and with its 500-keyframe segments (each carrying the
marginals of its end) -15.6 deg.

So :class:`WaterAim` re-makes them as iSAM2 would relinearise them: every ``every`` steps (the solver's
relinearisation skip) each factor whose keyframe the online problem still holds and whose yaw estimate
moved beyond ``tol`` (the pose relinearisation threshold) from its bow is swapped for one about the
estimate and the newest scale (its reading ``m`` stays the causal one). Only the online problem changes;
the closing step re-aims the kept graph's factors itself (:meth:`graphnav.graph.solution.Closing._reaim_water`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import gtsam

from factors import X

from .space import PlanarSpace
from .step import Step
from .water import Water, WaterRow, clamp_scale


class WaterAim:
    """The water-speed factors of the online problem and their bows (module docstring)."""

    def __init__(self, tol: float, every: int) -> None:
        self.tol, self.every = float(tol), max(1, int(every))
        self.live: list[tuple[WaterRow, int]] = []  # (the row as its factor was made, the factor's index)
        self.steps = 0
        self.swapped = 0  # factors re-made

    def forget(self) -> None:
        """The solver started afresh (a rebase): the indices no longer name its factors."""
        self.live.clear()

    def step(self, solver: Any, space: PlanarSpace, water: Water, s: Step) -> None:
        """After ``solver`` (a :class:`~graphnav.graph.solver.Solver`) took step ``s``: its water-speed factors
        registered, and every ``every`` steps the stale ones re-made."""
        if solver.kind == "batch" or not solver.new_indices:
            return
        idx = [i for i, g in zip(solver.new_indices, s.groups, strict=True) if g == "water_speed"]
        rows = water.rows[len(water.rows) - len(idx):] if idx else []  # (this step's, in the factors' order)
        self.live.extend((r, i) for r, i in zip(rows, idx, strict=True) if i >= 0)
        self.steps += 1
        if self.steps % self.every or not self.live:
            return
        held = [(r, i) for r, i in self.live if solver.holds(X(r.a))]
        yaws: dict[int, float] = {}
        for r, _ in held:
            if r.a not in yaws:
                yaws[r.a] = space.pose2(solver.estimate(X(r.a), space.pose_type)).theta()
        k0 = clamp_scale(float(water.scale_guess[0]))
        stale: list[tuple[WaterRow, int]] = []
        keep: list[tuple[WaterRow, int]] = []
        for r, i in held:
            (stale if abs(math.remainder(yaws[r.a] - r.yaw, math.tau)) > self.tol else keep).append((r, i))
        if not stale:
            self.live = keep
            return
        made = [replace(r, yaw=yaws[r.a], k0=k0 if r.scale is not None else r.k0) for r, _ in stale]
        add = gtsam.NonlinearFactorGraph()
        for r in made:
            add.add(r.factor())
        new = solver.remove([i for _, i in stale], settle=0, add=add, relinearize=False)
        self.live = keep + [(r, i) for r, i in zip(made, new, strict=True) if i >= 0]
        self.swapped += len(made)
