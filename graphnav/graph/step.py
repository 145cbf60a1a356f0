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

    def add(self, factor: gtsam.NonlinearFactor, group: str) -> None:
        self.graph.add(factor)
        self.groups.append(group)
