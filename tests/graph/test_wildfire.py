"""iSAM2's wildfire threshold per graph: 0.01 on the Pose3 graph, GTSAM's 0.001 on the Pose2 graph, the option wins."""

from __future__ import annotations

import pytest

from graphnav.graph.navigator import wildfire_threshold
from graphnav.graph.smoother_config import SolverConfig
from graphnav.graph.space import NavSpace, PlanarSpace


def test_default_per_graph():
    assert wildfire_threshold(SolverConfig(), NavSpace()) == pytest.approx(0.01)
    assert wildfire_threshold(SolverConfig(), PlanarSpace()) == pytest.approx(0.001)


@pytest.mark.parametrize("space", [NavSpace(), PlanarSpace()])
def test_the_option_wins(space):
    assert wildfire_threshold(SolverConfig(wildfire_threshold=0.003), space) == 0.003
