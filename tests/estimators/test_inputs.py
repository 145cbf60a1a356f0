"""``inputs``: the record kinds each estimator says it used are the ones whose removal changes its output.

On a small log with every record kind, each estimator runs once as is and once per kind with that
kind dropped (:func:`graphnav.io.drop.drop_kinds`): a kind listed in its ``inputs`` must change the
estimate (or make the log unable to feed it), a kind not listed must leave it bit for bit the same.
"""

from __future__ import annotations

import numpy as np
import pytest
from _logfactory import every_record_log

from graphnav import estimators
from graphnav.io.drop import KINDS, drop_kinds
from graphnav.log import Attitude, GnssVelocity, Heading, NavLog, WaterSpeed, make_cloud


def every_kind_log(lidar: str = "scan") -> NavLog:
    """:func:`every_record_log` plus GNSS velocities, water speeds and attitudes; ``lidar="cloud"``:
    a few 3D clouds instead of its 2D scans (a log carries one LiDAR or the other)."""
    base = every_record_log(n=16)
    rng = np.random.default_rng(3)
    extra = []
    for k in range(16):
        t = 0.5 * k + 0.25
        extra.append(Heading(0.5 * k, 0.1 + 0.03 * rng.standard_normal(), 0.035))  # (the base's are random)
        extra += [GnssVelocity(t, 1.4, 0.7, 0.1), WaterSpeed(t, 1.2, 0.05), Attitude(t, 0.01, -0.02, 0.005)]
        if k % 4 == 0:
            extra.append(make_cloud(t, rng.uniform(-20.0, 20.0, (400, 3))))
    other = "cloud" if lidar == "scan" else "scan"
    recs = [r for r in base.records if r.kind not in ("heading", other)] + [r for r in extra if r.kind != other]
    log = NavLog.from_unsorted(recs, base.beacons_known, base.meta)
    assert set(log.counts()) == set(KINDS) - {"cloud" if lidar == "scan" else "scan"}
    return log


def _same(a, b) -> bool:  # noqa: ANN001
    if a is None or b is None:
        return a is None and b is None
    if len(a) != len(b) or not np.array_equal(a.t, b.t) or not np.array_equal(a.poses, b.poses, equal_nan=True):
        return False
    return (a.cov is None) == (b.cov is None) and (a.cov is None or np.array_equal(a.cov, b.cov, equal_nan=True))


def _output(name: str, log: NavLog):  # noqa: ANN202
    if estimators.get(name).unmet(log):
        return "unmet"
    try:
        res = estimators.run(name, log)
    except (ValueError, RuntimeError) as exc:  # the log without the kind cannot feed it
        return f"error: {exc}"
    return res


@pytest.fixture(scope="module")
def log() -> NavLog:
    return every_kind_log()


_LOGS: dict[str, NavLog] = {}


@pytest.mark.parametrize("lidar", ["scan", "cloud"])
@pytest.mark.parametrize("name", estimators.names())
def test_inputs_are_the_kinds_that_change_the_output(name, lidar):
    if lidar not in _LOGS:
        _LOGS[lidar] = every_kind_log(lidar)
    log = _LOGS[lidar]
    if estimators.get(name).unmet(log):
        assert lidar == "cloud", estimators.get(name).unmet(log)
        pytest.skip(f"{name}: {estimators.get(name).unmet(log)}")
    base = _output(name, log)
    assert not isinstance(base, str), base
    used = estimators.inputs(name, log, {}, base.info)
    assert used is not None and used, f"{name} declares no inputs"
    assert set(used) <= set(log.counts())
    wrong = []
    for kind in log.counts():
        out = _output(name, drop_kinds(log, [kind]))
        changed = isinstance(out, str) or not (_same(out.trajectory, base.trajectory)
                                               and _same(out.online, base.online))
        if changed != (kind in used):
            how = out if isinstance(out, str) else "ran"
            wrong.append(f"{kind}: {'changes' if changed else 'does not change'} the output ({how})")
    assert not wrong, f"{name} inputs {used}: " + "; ".join(wrong)


def test_inputs_follow_the_options_and_the_anchor(log):
    assert "odometry" not in estimators.inputs("icp-dr", log, {"init": "cv"})
    assert "odometry" in estimators.inputs("icp-dr", log, {})
    assert "beacon_known" not in estimators.inputs("ekf-slam", log, {"use_known": False})
    nav = estimators.inputs("isam2", log, {"motion": "imu"})  # the one graph on Pose3: every sensor but odometry
    assert {"imu", "gnss", "heading", "scan", "gnss_velocity", "water_speed"} <= set(nav) and "odometry" not in nav
    assert "odometry" in estimators.inputs("isam2", log, {"motion": "imu", "use_odometry": True})
    assert "odometry" in estimators.inputs("isam2", log, {"motion": "odometry"})
    no_prior = drop_kinds(log, ["pose_prior"])  # the graph's anchor: the first GNSS fix and compass reading
    info = estimators.run("dead-reckoning", no_prior).info
    assert info["anchor"] == "first GNSS+compass"
    assert estimators.inputs("dead-reckoning", no_prior, {}, info) == ["gnss", "heading", "odometry"]
    relative = drop_kinds(log, ["pose_prior", "gnss", "heading", "beacon"])  # nothing absolute: the truth's frame
    info = estimators.run("dead-reckoning", relative).info
    assert info["anchor"] == "truth (first pose)"
    assert estimators.inputs("dead-reckoning", relative, {}, info) == ["odometry", "truth"]
