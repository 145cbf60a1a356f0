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


@pytest.fixture(scope="module")
def log3():
    from graphnav.sim.harbour3d import Lidar3dConfig, simulate_harbour3d

    log = simulate_harbour3d(0, lidar=Lidar3dConfig(az_deg=0.5), duration=2.0)
    return log.without(lambda r: r.kind == "pose_prior")  # anchored at the first truth pose


def test_3d_log_runs_against_truth(log3):
    res = estimators.run("scan-to-map", log3)
    info = res.info
    assert info["dimension"] == "3d" and info["anchor"] == "truth" and info["cloud_map"]["variant"] == "gicp"
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
    log = log.without(lambda r: r.kind == "pose_prior")
    res = estimators.run("scan-to-map", log)
    assert res.info["guess_sources"] == {"odometry": 10} and res.info["failed_registrations"] == 0
    assert ate(res.trajectory, log.truth())["rmse"] < 0.03
    assert estimators.get("scan-to-map").inputs(log, {}) == {"cloud", "odometry", "pose_prior"}
