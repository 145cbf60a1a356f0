"""benchmarks/leave_one_out.py: the held-out choice (issue #25 item 2) on known tables."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def loo():
    spec = importlib.util.spec_from_file_location("leave_one_out", REPO / "benchmarks" / "leave_one_out.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_value_chosen_without_a_log_and_its_cost(loo):
    # three logs prefer 2, one log (an outlier) prefers 0.5: held out, it gets 2 (chosen on the others)
    table = {"mrclam6-r1": {0.5: 1.2, 1.0: 1.0, 2.0: 0.8},
             "mrclam6-r2": {0.5: 2.4, 1.0: 2.0, 2.0: 1.7},
             "mrclam6-r3": {0.5: 0.6, 1.0: 0.5, 2.0: 0.45},
             "mrclam6-r4": {0.5: 0.4, 1.0: 0.5, 2.0: 0.55}}
    a = loo.analyse(table, [0.5, 1.0, 2.0], 1.0)
    assert a["chosen_on_all"] == 2.0  # mean metric / metric at the default: 0.5 -> 1.1, 1 -> 1, 2 -> 0.9125
    rows = {r["log"]: r for r in a["rows"]}
    assert rows["mrclam6-r4"]["chosen_without"] == 2.0 and rows["mrclam6-r4"]["best_own"] == 0.5
    assert rows["mrclam6-r4"]["m_without"] == pytest.approx(0.55)
    assert rows["mrclam6-r1"]["chosen_without"] == 2.0
    assert a["worst_without_over_all"] == pytest.approx(1.0)
    assert a["mean_default_over_all"] == pytest.approx((1.0 / 0.8 + 2.0 / 1.7 + 0.5 / 0.45 + 0.5 / 0.55) / 4)
    # held out, each log gets 2: against its default run 0.8, 0.85, 0.9, 1.1 (r4 loses 10 %)
    assert a["mean_without_over_default"] == pytest.approx((0.8 + 1.7 / 2.0 + 0.45 / 0.5 + 0.55 / 0.5) / 4)
    assert a["min_without_over_default"] == pytest.approx(0.8)
    assert a["max_without_over_default"] == pytest.approx(1.1)


def test_ties_keep_the_default_and_kinds_cross(loo):
    table = {"carmen-a": {1: 1.0, 2: 1.0}, "carmen-b": {1: 3.0, 2: 3.0},
             "mrclam6-r1": {1: 2.0, 2: 1.0}, "mrclam6-r2": {1: 4.0, 2: 2.0}}
    a = loo.analyse(table, [1, 2], 1)
    across = {c["chosen_on"]: c for c in a["across"]}
    assert across["carmen"]["value"] == 1 and across["carmen"]["own_value"] == 2
    assert across["carmen"]["mean_rel"] == pytest.approx(2.0)  # CARMEN's choice costs MRCLAM 2x
    assert across["mrclam6"]["mean_rel"] == pytest.approx(1.0)


def test_nested_options_and_defaults(loo):
    assert loo.options_of("loop.kernel_k", 2.0) == {"loop": {"kernel_k": 2.0}}
    assert loo.options_of("odo_lateral", 0.2) == {"odo_lateral": 0.2}
    assert loo.default_of("odo_lateral") == 0.1
    assert loo.default_of("loop.kernel_k") == 1.0
    assert loo.default_of("sigma_range", "ekf-slam") == 0.5
    for grid in loo.GRIDS.values():  # every grid holds its default (the held-out comparison needs it)
        est = "ekf-slam" if "sigma_v" in grid else "isam2"
        for p, vals in grid.items():
            assert loo.default_of(p, est) in vals, p
