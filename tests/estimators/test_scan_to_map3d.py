"""``scan-to-map`` on 3D cloud logs (graphnav.estimators.scan_to_map3d over graphnav.scan.cloud_map):
a short 3D harbour against its truth, the guess sources, the CLI's JSON and bad options."""

from __future__ import annotations

import json

import numpy as np
import pytest

from graphnav import estimators
from graphnav.cli import main
from graphnav.evaluation.metrics import ate
from graphnav.io import save_log
from graphnav.scan.cloud_map import CloudMap, CloudMapConfig, CloudOdometry

pytest.importorskip("open3d")  # the 3D harbour's ray casting


ABSOLUTE = ("pose_prior", "gnss", "heading", "beacon")  # the records an anchor is chosen from


@pytest.fixture(scope="module")
def full():
    from graphnav.sim.harbour3d import Lidar3dConfig, simulate_harbour3d

    return simulate_harbour3d(0, lidar=Lidar3dConfig(az_deg=0.5), duration=2.0)


@pytest.fixture(scope="module")
def log3(full):
    return full.without(lambda r: r.kind in ABSOLUTE)  # nothing absolute: the frame is the first truth pose


def test_3d_log_runs_against_truth(log3):
    res = estimators.run("scan-to-map", log3)
    info = res.info
    assert info["dimension"] == "3d" and info["anchor"] == "truth (first pose)"
    assert info["cloud_map"]["variant"] == "gicp"
    assert len(res.trajectory) == len(log3.of("cloud")) == 21
    assert info["failed_registrations"] == 0 and info["guess_sources"] == {"imu": 20}
    assert ate(res.trajectory, log3.truth())["rmse"] < 0.03
    assert estimators.get("scan-to-map").inputs(log3, {}) == {"cloud", "imu", "pose_prior"}


def test_the_clouds_carry_the_track_without_a_motion_sensor(log3):
    truth = log3.truth()
    assert np.hypot(*(truth.poses[-1][:2] - truth.poses[0][:2])) > 3.0  # standing still: metres off
    res = estimators.run("scan-to-map", log3, predict="cv")
    assert res.info["guess_sources"] == {"none": 1, "cv": 19} and res.info["failed_registrations"] == 0
    assert ate(res.trajectory, truth)["rmse"] < 0.03
    fast = estimators.run("scan-to-map", log3, predict="cv", cloud_map={"variant": "vgicp"})
    assert ate(fast.trajectory, truth)["rmse"] < 0.15  # VGICP on a young 1 m voxel map: coarser
    assert estimators.get("scan-to-map").inputs(log3, {"predict": "cv"}) == {"cloud", "pose_prior"}


def test_failed_matches_keep_the_imu_prediction(log3):
    res = estimators.run("scan-to-map", log3, cloud={"max_range": 5.0})  # nothing beyond the hull survives
    assert res.info["failed_registrations"] == 20 and res.info["registrations"] == 20
    assert ate(res.trajectory, log3.truth())["rmse"] < 0.05  # 2 s of a calibrated IMU from a known velocity


def test_cloud_map_starts_rejects_and_keeps_the_guess(log3):
    from graphnav.scan.cloud_match import CloudMatchConfig, filter_cloud

    c = log3.of("cloud")
    pts = [filter_cloud(x, CloudMatchConfig(), 8.0)[0] for x in c[:2]]
    m = CloudMap(CloudMapConfig())
    first = m.add(pts[0], np.eye(4))
    assert first.inserted and not first.matched
    guess = np.eye(4)
    no = m.add(pts[1], guess, accept=lambda r: False)
    assert not no.matched and not no.inserted and np.array_equal(no.T, guess) and "rejected" in no.extra
    assert not m.add(pts[1][:5], guess).matched  # too few points
    odo = CloudOdometry()
    assert odo.step(pts[0]).inserted and odo.step(pts[1]).matched


def test_cli_json_and_bad_options(tmp_path, log3, capsys):
    p = tmp_path / "h3d.npz"
    save_log(log3, p)
    assert main(["run", str(p), "-e", "scan-to-map", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["ate_rmse_m"] < 0.03 and "cloud" in d["inputs"] and d["steps"] == 21
    assert main(["run", str(p), "-e", "scan-to-map", "-O", 'cloud_map={"nope": 1}', "--json"]) == 2
    assert "nope" in json.loads(capsys.readouterr().out)["error"]
    assert main(["run", str(p), "-e", "scan-to-map", "-O", 'cloud_map={"variant": "ndt"}', "--json"]) == 2
    err = json.loads(capsys.readouterr().out)
    assert "ndt" in err["error"] and "variant" in err["where"]


def test_odometry_is_the_guess_when_the_log_has_it():
    from graphnav.sim.harbour import HarbourConfig
    from graphnav.sim.harbour3d import Lidar3dConfig, simulate_harbour3d

    log = simulate_harbour3d(1, HarbourConfig(odometer=True), Lidar3dConfig(az_deg=0.5), duration=1.0)
    log = log.without(lambda r: r.kind in ABSOLUTE)
    res = estimators.run("scan-to-map", log)
    assert res.info["guess_sources"] == {"odometry": 10} and res.info["failed_registrations"] == 0
    assert ate(res.trajectory, log.truth())["rmse"] < 0.03
    assert estimators.get("scan-to-map").inputs(log, {}) == {"cloud", "odometry", "pose_prior"}


def _with_prior(log, pose):  # noqa: ANN001, ANN202
    from graphnav.log import NavLog, PosePrior

    return NavLog([PosePrior(r.t, *map(float, pose), r.sigma_xy, r.sigma_yaw) if isinstance(r, PosePrior) else r
                   for r in log.records], log.beacons_known, log.meta)


def test_the_start_is_the_pose_prior_and_its_error_the_only_frame_error(full):
    """The track starts exactly at the log's pose prior; its whole unaligned error is that start's:
    from a prior 0.5 m and 2 deg off the first truth pose, moved by the one transform that takes the
    prior onto that pose it is the truth within the aligned figure; from a prior at that pose the
    unaligned ATE is the aligned one."""
    from graphnav.geometry import se2_compose, se2_inverse
    from graphnav.trajectory import Trajectory

    truth = full.truth()
    p0 = se2_compose(truth.poses[0], [0.3, -0.4, np.radians(2.0)])
    res = estimators.run("scan-to-map", _with_prior(full, p0))
    assert res.info["anchor"] == "pose_prior"
    np.testing.assert_allclose(res.trajectory.poses[0], p0, atol=1e-9)
    aligned = ate(res.trajectory, truth, align=True)["rmse"]
    assert aligned < 0.03 and ate(res.trajectory, truth)["rmse"] > 10 * aligned  # the 0.5 m and 2 deg
    fix = se2_compose(truth.poses[0], se2_inverse(p0))
    moved = Trajectory(res.trajectory.t, np.array([se2_compose(fix, p) for p in res.trajectory.poses]))
    assert ate(moved, truth)["rmse"] < aligned + 0.01

    res = estimators.run("scan-to-map", _with_prior(full, truth.poses[0]))
    assert abs(ate(res.trajectory, truth)["rmse"] - ate(res.trajectory, truth, align=True)["rmse"]) < 0.01


def test_without_a_prior_it_starts_where_the_graph_anchors(full):
    """No pose prior: the first GNSS fix and the first compass reading (the graph's anchor), never the
    truth; the report's inputs say so."""
    log = full.without(lambda r: r.kind == "pose_prior")
    g, h = log.of("gnss")[0], log.of("heading")[0]
    res = estimators.run("scan-to-map", log)
    assert res.info["anchor"] == "first GNSS+compass"
    np.testing.assert_allclose(res.trajectory.poses[0], [g.x, g.y, h.yaw], atol=1e-9)
    used = estimators.inputs("scan-to-map", log, {}, res.info)
    assert {"gnss", "heading", "cloud", "imu"} <= set(used) and "truth" not in used
