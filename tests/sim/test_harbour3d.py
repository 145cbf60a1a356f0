"""The 3D harbour (graphnav.sim.harbour3d): the other sensors are the 2D harbour's, the clouds are in
the tilted sensor frame (levelled by the stated roll/pitch the water is flat), returns lie on the
extruded scene, water returns and spray are sparse, and the CLI writes it."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from graphnav.cli import main
from graphnav.io import load_log
from graphnav.scan.cloud_match import level_rotation
from graphnav.sim.harbour import HarbourConfig, distance_to_segments, segments, simulate_harbour
from graphnav.sim.harbour3d import Lidar3dConfig, rot_zyx, scene_prisms, simulate_harbour3d

pytest.importorskip("open3d")
LIDAR = Lidar3dConfig(az_deg=1.0)  # coarse azimuths: fast, same geometry


@pytest.fixture(scope="module")
def log3():
    return simulate_harbour3d(0, lidar=LIDAR, duration=3.0)


def test_other_sensors_are_the_2d_harbours(log3):
    log2 = simulate_harbour(0, HarbourConfig(lidar_hz=0.0), duration=3.0)
    assert "scan" not in log3.counts()
    for kind in ("gnss", "gnss_velocity", "heading", "water_speed", "imu", "beacon", "truth", "pose_prior"):
        a, b = log2.of(kind), log3.of(kind)
        assert len(a) == len(b) > 0 and all(x == y for x, y in zip(a, b, strict=True)), kind


def test_clouds_at_10_hz_with_16_rings_and_attitude(log3):
    cl = log3.of("cloud")
    assert [c.t for c in cl] == pytest.approx([r.t for r in log3.of("truth")])
    rings = np.concatenate([c.ring for c in cl])
    assert rings.min() == 0 and rings.max() <= 15 and len(np.unique(rings)) >= 10
    att = log3.meta["attitude"]
    roll, pitch = np.array([c.roll for c in cl]), np.array([c.pitch for c in cl])
    assert np.abs(np.degrees(pitch - att["pitch"])).max() < 1.0
    assert np.abs(np.degrees(roll - att["roll"])).max() < 1.0  # the AHRS: truth + 0.2 deg noise
    assert np.abs(np.degrees(np.array(att["roll"]))).max() > 0.3  # the waves roll the vessel
    r = np.linalg.norm(np.concatenate([c.points for c in cl]), axis=1)
    assert r.max() <= LIDAR.max_range + 0.2 and r.min() > 0.3


def test_levelled_water_is_flat_and_returns_lie_on_the_scene(log3):
    mast = log3.meta["lidar3d"]["mast"]
    att = log3.meta["attitude"]
    segs = segments([p for p, _, _ in scene_prisms()])
    for i, (c, tr) in enumerate(zip(log3.of("cloud"), log3.of("truth"), strict=True)):
        if i % 7:
            continue
        roll, pitch, heave = att["roll"][i], att["pitch"][i], att["heave"][i]
        far = np.linalg.norm(c.points, axis=1) > 5.0
        water = far & (c.intensity < 8.0)
        if water.sum() > 5:  # levelled by the true attitude: the sea surface at -(mast + heave)
            z = (c.points[water].astype(float) @ level_rotation(roll, pitch).T)[:, 2]
            assert abs(np.median(z) + mast + heave) < 0.15
        # structure returns, put in the world by the truth pose and attitude: on a wall or a top
        R = rot_zyx(tr.yaw, pitch, roll)
        # cross-check the ZYX composition with scipy
        assert np.allclose(R, Rotation.from_euler("ZYX", [tr.yaw, pitch, roll]).as_matrix())
        wall = far & (c.intensity > 15.0)
        pw = c.points[wall].astype(float) @ R.T + [tr.x, tr.y, mast + heave]
        d, _ = distance_to_segments(segs, pw[:, :2])
        tops = np.array([top for _, top, _ in scene_prisms()])
        on_wall = d < 0.2  # range noise 3 cm plus float32
        on_top = np.isin(np.round(pw[:, 2], 1), np.round(tops, 1)) | (np.abs(pw[:, 2, None] - tops).min(1) < 0.2)
        assert np.mean(on_wall | on_top) > 0.97
        assert np.all(pw[:, 2] > -0.3)  # nothing seen below the water


def test_water_and_spray_are_sparse(log3):
    pts = [c for c in log3.of("cloud")]
    near = np.mean([np.sum(np.linalg.norm(c.points, axis=1) < LIDAR.spray_range[1] + 0.1) for c in pts])
    assert 5 < near < 80  # the spray: Poisson(25) a frame
    n = np.mean([len(c) for c in pts])
    water = np.mean([np.sum((c.intensity < 8) & (np.linalg.norm(c.points, axis=1) > 4)) for c in pts])
    assert 0 < water < 0.1 * n


def test_cli_writes_a_3d_harbour(tmp_path, capsys):
    out = tmp_path / "h3.npz"
    assert main(["simulate", "harbour", "--lidar", "3d", "--seed", "1", "--duration", "1", "--out", str(out),
                 "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["scenario"] == "harbour3d" and d["records"]["cloud"] == d["records"]["truth"] >= 10
    log = load_log(out)
    assert len(log.of("cloud")) == d["records"]["cloud"] and math.isfinite(log.of("cloud")[0].roll)
