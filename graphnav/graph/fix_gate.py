"""The graph's online GNSS gate (docs/smoother.md, "The online GNSS gate").

A fix whose innovation ``d`` (the fix minus the predicted antenna position, covariance
``S = P_pred + sigma^2 I``) fails the chi-square test ``d^T S^-1 d <= gate^2`` is rejected online
(the closing step reconsiders it), unless

1. ``max_rejects`` fixes in a row were rejected (re-acquire after the estimate drifted off), or
2. the rejected fixes in a row that agree with each other (consecutive innovations within the gate of
   each other, covariance ``(sigma_i^2 + sigma_j^2) I``) outnumber the fixes the estimate rests on: those
   accepted since the start or the last re-acquisition. A cold start whose first fixes were the wrong
   ones (a receiver before its almanac) is left after one fix more than it had; a jump after minutes
   of tracking (multipath, a datum switch) is refused by the evidence behind the estimate.

The first fix after an outage (a gap of ``gate_outage``) is taken without the test and restarts the count:
across the gap the estimate rests on the motion model, not on the fixes before it (the filters' gate: a
filter that accepted nothing for ``confirm_s`` is not tracking). A coast that drifted farther than its
covariance says (a current, leeway) is then left after two fixes that agree, instead of one fix in
``max_rejects``.

On a re-acquisition (2.) the run's rejected fixes are taken back (``taken_back``), the fixes are taken
ungated until one passes the test again, and the navigator takes the fixes the old estimate rested on
out of iSAM2's (or the fixed-lag window's) online problem (:class:`OnlineFixes`; the closing step still
judges them all).
The rule is the filters' gate's (graphnav.estimators.gating, rules 2-4) in the graph's terms, with the
number of fixes for the time a filter has tracked.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray


class FixGate:
    """``accept(d, S, var) -> bool`` for each fix (``var``: its variance per axis, ``sigma^2``); ``rejected``
    counts the rejections, ``reacquired`` the re-acquisitions by rule 2 (module docstring)."""

    def __init__(self, gate: float, max_rejects: int) -> None:
        self.limit = float(gate) ** 2
        self.max_rejects = int(max_rejects)
        self.rejected = 0
        self.reacquired = 0
        self.consecutive = 0  # rejections in a row
        self.tracked = 0  # fixes accepted since the start or the last re-acquisition
        self.run: list[tuple[NDArray[np.float64], float]] = []  # the rejections in a row that agree: (d, var)
        self.reacquiring = False  # taking fixes ungated until one passes the test
        self.taken_back = 0  # after a re-acquisition: how many of the newest rejected fixes (the run) to take back
        self.lone: Any = None  # the sample of a lone rejection, released by the newest verdict (accept)
        self._held: Any = None  # the newest rejection's sample while it is a run of one

    def passed(self) -> None:
        """A fix taken without the test (the first, or the first after an outage): the estimate rests on it and
        on the motion model alone, so the count of fixes behind it starts again (module docstring)."""
        self.lone = None
        self.reacquiring = False
        self.tracked = 0
        self._accept()

    def accept(self, d: NDArray[np.float64], S: NDArray[np.float64], var: float, sample: Any = None) -> bool:
        """The verdict on one fix. ``sample``: what the caller learns the fixes' noise from (the online
        variance scale); :attr:`lone` then holds the sample of a rejection that turned out to agree with
        neither neighbour (noise, to be learnt from), and a run's samples are dropped: a jump cannot widen
        the gate that rejects it (the filters' rule 1)."""
        inside = float(d @ np.linalg.solve(S, d)) <= self.limit
        self.lone = None
        if inside:
            self.reacquiring = False
        if inside or self.reacquiring:
            self.lone, self._held = self._held, None
            self._accept()
            return True
        if self.run and not self._agree(self.run[-1], (d, var)):
            self.lone = self._held if len(self.run) == 1 else None
            self.run = []
        self._held = sample if not self.run else None
        self.run.append((d, var))
        if self.consecutive >= self.max_rejects:
            self._accept()
            return True
        if len(self.run) > self.tracked:
            self.reacquired += 1
            self.reacquiring = True
            self.taken_back = len(self.run) - 1
            self.rejected -= self.taken_back
            self.tracked = len(self.run)
            self.consecutive = 0
            self.run = []
            return True
        self.rejected += 1
        self.consecutive += 1
        return False

    def _accept(self) -> None:
        self._held = None
        self.tracked += 1
        self.consecutive = 0
        self.run = []

    def _agree(self, a: tuple[NDArray[np.float64], float], b: tuple[NDArray[np.float64], float]) -> bool:
        diff = a[0] - b[0]
        return float(diff @ diff) / (a[1] + b[1]) <= self.limit


def gate_info(gate: FixGate | None) -> dict[str, int]:
    """The run summary's counts of the online gate (``None``: it is off)."""
    return {"gnss_rejected": gate.rejected if gate else 0, "gnss_reacquired": gate.reacquired if gate else 0}


class OnlineFixes:
    """The navigator's side of a re-acquisition (iSAM2 and fixed-lag): the factor indices of the fixes the gate
    accepted since it last re-acquired or restarted after an outage (at most ``max_rejects``, the most a run can
    outnumber) and of the anchor's prior. When a step re-acquired, those fixes leave iSAM2's online problem and
    an anchor taken from the first fix is released (:meth:`~graphnav.graph.anchor.Anchor.released`): the
    estimate rests on the fixes that outnumbered them (the closing step still judges them all)."""

    def __init__(self, max_rejects: int) -> None:
        self.indices: deque[int] = deque(maxlen=max(1, int(max_rejects)))
        self.anchor: int | None = None
        self.held = self.lost = 0  # fixed-lag: fixes taken back into its window, and those it no longer held

    def forget(self) -> None:
        """The solver started afresh (a fixed-lag rebase): the indices no longer name its factors."""
        self.indices.clear()
        self.anchor = None

    def step(self, solver: Any, builder: Any, s: Any) -> None:
        """After ``solver`` (a :class:`~graphnav.graph.solver.Solver`) took step ``s``."""
        if solver.kind == "batch" or not solver.new_indices:
            return
        new = list(zip(solver.new_indices, s.groups, strict=True))
        if s.k == 0 and s.new_keyframe:
            self.anchor = next((i for i, g in new if g == "anchor"), None)
        elif s.restarted:  # the fixes before an outage are not what a run after it contradicts
            self.indices.clear()
            self.anchor = None
        if s.reacquired and (self.indices or s.taken_back):
            old, add = list(self.indices), gtsam.NonlinearFactorGraph()
            released = builder.anchor.released(builder.space) if self.anchor is not None else None
            if released is not None:
                add.add(released)
                old.append(self.anchor)
                self.anchor = None
            for f in s.taken_back:  # (fixed-lag: the run's fixes, where the window holds their keyframes)
                add.add(f)
            back = solver.remove(old, add=add)[add.size() - len(s.taken_back):]
            self.held += sum(i >= 0 for i in back)
            self.lost += sum(i < 0 for i in back)
            self.indices.clear()
            self.indices.extend(i for i in back if i >= 0)
        self.indices.extend(i for i, g in new if g == "gnss" and i >= 0)

    def info(self) -> dict[str, int]:
        """The run summary's counts of the fixes taken back into a fixed-lag window (none: nothing)."""
        return {"gnss_taken_back_held": self.held, "gnss_taken_back_lost": self.lost} if self.held + self.lost else {}
