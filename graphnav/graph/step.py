"""One keyframe's batch: the new factors and values the builder hands to the solver."""

from __future__ import annotations

from dataclasses import dataclass, field

import gtsam

from .space import PlanarSpace


@dataclass
class Step:
    """New factors/values of keyframe ``k`` (time ``t``), the keys' timestamps (fixed-lag) and
    each factor's sensor group (parallel to ``graph``)."""

    k: int
    t: float
    graph: gtsam.NonlinearFactorGraph
    values: gtsam.Values
    stamps: dict[int, float]
    groups: list[str] = field(default_factory=list)
    icp_ms: float | None = None
    new_keyframe: bool = True  # False: late measurements after the last keyframe (finish)
    space: PlanarSpace = field(default_factory=PlanarSpace)  # the variables' types (graphnav.graph.space)
    #: factors the closing step solves instead of the online one at the same index (a GNSS fix at its stated
    #: sigma where the online estimate inflated it): batch and the closing of iSAM2 solve one problem
    closing: dict[int, gtsam.NonlinearFactor] = field(default_factory=dict)
    #: the GNSS gate re-acquired on this step's fixes (graph.fix_gate): the solver relinearises until it settles
    reacquired: bool = False
    #: the GNSS gate took a fix after an outage untested and counts the fixes behind the estimate afresh
    restarted: bool = False
    #: fixed-lag: a re-acquisition's rejected fixes taken back, which the navigator adds where its window still
    #: holds their keyframes (:class:`~graphnav.graph.fix_gate.OnlineFixes`)
    taken_back: list[gtsam.NonlinearFactor] = field(default_factory=list)

    def add(self, factor: gtsam.NonlinearFactor, group: str, closing: gtsam.NonlinearFactor | None = None) -> None:
        if closing is not None:
            self.closing[self.graph.size()] = closing
        self.graph.add(factor)
        self.groups.append(group)

    def take_back(self, fixes: list[gtsam.NonlinearFactor], window: bool) -> None:
        """A re-acquisition's rejected fixes count again: in this step, or (``window``: the fixed-lag smoother, which
        may have dropped their keyframes) in :attr:`taken_back`."""
        if window:
            self.taken_back.extend(fixes)
        else:
            for f in fixes:
                self.add(f, "gnss")

    def kept(self) -> gtsam.NonlinearFactorGraph:
        """The factors as the closing step solves them (:attr:`closing` substituted)."""
        if not self.closing:
            return self.graph
        out = gtsam.NonlinearFactorGraph()
        for i in range(self.graph.size()):
            out.add(self.closing.get(i, self.graph.at(i)))
        return out
