"""The ``cloud`` record (3D point clouds in the sensor frame) in every format: JSONL, npz, ROS 1/2 bags
(PointCloud2 next to NavSatFix and Imu), PCD through pypcd4, KITTI ``.bin`` folders; its validity
limits; damaged inputs are LogErrors naming the field."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from graphnav.errors import LogError
from graphnav.io import load_log
from graphnav.io.cloudfile import read_cloud_dir, read_cloud_record
from graphnav.io.dispatch import save_log
from graphnav.io.jsonl import parse_record
from graphnav.io.npz import read_npz, write_npz
from graphnav.io.rosbag import pointcloud2_to_cloud, read_bag, typestore, write_bag
from graphnav.log import MAX_CLOUD_POINTS, Cloud, Gnss, Imu, NavLog, check_record, make_cloud

ORIGIN = {"lat": 43.5, "lon": 16.4, "h": 0.0}


def _cloud(rng, t, n, extras=True):
    pts = np.round(rng.normal(0.0, 15.0, (n, 3)), 3)  # on a 1 mm grid: JSONL keeps them exactly
    if not extras:
        return make_cloud(t, pts)
    return make_cloud(t, pts, np.round(rng.uniform(0, 100, n), 2), rng.integers(0, 16, n))


def _log(seed=0, attitude=False):
    rng = np.random.default_rng(seed)
    recs = []
    for i in range(4):
        t = 1.7e9 + 0.1 * i
        c = _cloud(rng, t, 30 + 7 * i, extras=i != 2)
        recs.append(replace(c, roll=0.01 * i, pitch=-0.02) if attitude and i != 1 else c)
        recs.append(Gnss(t + 0.02, 2.0 * i, -1.0 * i, 1.5))
        recs.append(Imu(t + 0.05, 0.1 * i, -0.2, 0.03))
    recs.append(make_cloud(1.7e9 + 0.5, np.zeros((0, 3))))  # an empty cloud (everything beyond range)
    return NavLog(recs, meta={"origin": ORIGIN, "name": "clouds"})


def _same_clouds(a: NavLog, b: NavLog, atol=0.0):
    ca, cb = a.of("cloud"), b.of("cloud")
    assert len(ca) == len(cb) > 0
    for x, y in zip(ca, cb, strict=True):
        assert x.t == pytest.approx(y.t, abs=1e-6)
        for k in ("roll", "pitch"):
            assert getattr(x, k) == getattr(y, k) or (math.isnan(getattr(x, k)) and math.isnan(getattr(y, k)))
        assert x.points.shape == y.points.shape and y.points.dtype == np.float32
        assert np.allclose(x.points, y.points, atol=atol, rtol=0)
        assert (x.intensity is None) == (y.intensity is None) and (x.ring is None) == (y.ring is None)
        if x.intensity is not None:
            assert np.allclose(x.intensity, y.intensity, atol=atol, rtol=0)
        if x.ring is not None:
            assert np.array_equal(x.ring, y.ring) and y.ring.dtype == np.uint16


@pytest.mark.parametrize("name", ["log.jsonl", "log.jsonl.gz", "log.npz"])
def test_jsonl_and_npz_round_trip(tmp_path, name):
    log = _log(attitude=True)
    assert not math.isnan(log.of("cloud")[0].roll)
    save_log(log, tmp_path / name)
    back = load_log(tmp_path / name)
    assert back.counts() == log.counts()
    assert [r.kind for r in back.records] == [r.kind for r in log.records]
    _same_clouds(log, back, atol=1e-4 if "jsonl" in name else 0.0)


@pytest.mark.parametrize("name", ["c.bag", "c2", "c.mcap"])
def test_bag_with_pointcloud2_navsatfix_imu_reads_back_the_same_log(tmp_path, name):
    log = _log(1)
    storage = "mcap" if name.endswith(".mcap") else "sqlite3"
    path = write_bag(log, tmp_path / name.replace(".mcap", ""), storage=storage,
                     origin=(ORIGIN["lat"], ORIGIN["lon"]))
    back = read_bag(path)
    assert back.meta["topics"]["/points"]["used_as"] == "cloud"
    assert back.counts() == log.counts()
    _same_clouds(log, back)  # float32 both ways: exact
    for g, h in zip(log.of("gnss"), back.of("gnss"), strict=True):
        assert abs(g.x - h.x) < 1e-6 and abs(g.y - h.y) < 1e-6 and h.sigma == pytest.approx(g.sigma)
    for g, h in zip(log.of("imu"), back.of("imu"), strict=True):
        assert (h.ax, h.ay, h.wz) == pytest.approx((g.ax, g.ay, g.wz))


def _pc2(ts, n=4, *, fields=None, data=None, point_step=16, height=1, row_step=None, big=False):
    T = ts.types
    PF = T["sensor_msgs/msg/PointField"]
    fields = fields or [PF(name=c, offset=4 * i, datatype=7, count=1) for i, c in enumerate("xyz")] + [
        PF(name="intensity", offset=12, datatype=7, count=1)]
    if data is None:
        data = np.arange(n * 4, dtype=">f4" if big else "<f4").view(np.uint8)
    hdr = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="l")
    return T["sensor_msgs/msg/PointCloud2"](
        header=hdr, height=height, width=n // height, fields=fields, is_bigendian=big, point_step=point_step,
        row_step=row_step if row_step is not None else point_step * (n // height), data=data, is_dense=False)


def test_pointcloud2_layouts_and_damage():
    ts = typestore()
    T = ts.types
    PF = T["sensor_msgs/msg/PointField"]
    for big in (False, True):  # the byte order is the message's
        c = pointcloud2_to_cloud(_pc2(ts, big=big), 1.0)
        assert np.array_equal(c.points, np.arange(16, dtype=np.float32).reshape(4, 4)[:, :3])
        assert np.array_equal(c.intensity, [3, 7, 11, 15])
    # an organised cloud (2 rows) with NaN points (no return): dropped
    d = np.arange(16, dtype="<f4")
    d[4] = np.nan
    c = pointcloud2_to_cloud(_pc2(ts, data=d.view(np.uint8), height=2), 1.0)
    assert len(c) == 3 and c.ring is None
    # x, y, z as float64 and a uint16 ring after padding
    dt = np.dtype({"names": ["x", "y", "z", "ring"], "formats": ["<f8"] * 3 + ["<u2"], "offsets": [0, 8, 16, 26],
                   "itemsize": 32})
    a = np.zeros(3, dt)
    a["x"], a["ring"] = [1.5, 2.5, 3.5], [0, 7, 15]
    fields = [PF(name=c, offset=8 * i, datatype=8, count=1) for i, c in enumerate("xyz")] + [
        PF(name="ring", offset=26, datatype=4, count=1)]
    c = pointcloud2_to_cloud(_pc2(ts, 3, fields=fields, data=np.frombuffer(a.tobytes(), np.uint8), point_step=32), 0.0)
    assert np.array_equal(c.points[:, 0], [1.5, 2.5, 3.5]) and np.array_equal(c.ring, [0, 7, 15])
    with pytest.raises(LogError) as e:  # data shorter than declared
        pointcloud2_to_cloud(_pc2(ts, data=np.zeros(10, np.uint8)), 0.0)
    assert e.value.field == "data"
    with pytest.raises(LogError) as e:  # no z
        pointcloud2_to_cloud(_pc2(ts, fields=[PF(name=c, offset=4 * i, datatype=7, count=1) for i, c in
                                              enumerate("xy")]), 0.0)
    assert e.value.field == "fields"
    with pytest.raises(LogError) as e:  # a field past the point
        pointcloud2_to_cloud(_pc2(ts, fields=[PF(name=c, offset=4 * i + 8, datatype=7, count=1) for i, c in
                                              enumerate("xyz")]), 0.0)
    assert e.value.field == "fields"
    with pytest.raises(LogError) as e:  # a declared size beyond the bound, refused before reading
        pointcloud2_to_cloud(_wide(ts, MAX_CLOUD_POINTS + 1), 0.0)
    assert e.value.field == "width"


def _wide(ts, n):
    from dataclasses import replace

    return replace(_pc2(ts), width=n)


def test_jsonl_cloud_fields_and_errors():
    rec = parse_record({"t": 1.0, "type": "cloud", "points": [[1, 2, 3], [4.5, 5, 6]], "intensity": [1, 2],
                        "ring": [0, 15]})
    assert isinstance(rec, Cloud) and rec.points.dtype == np.float32 and rec.ring.dtype == np.uint16
    bad = [
        ({"points": [[1, 2]]}, "points"),
        ({"points": [[1, 2, "3"]]}, "points"),
        ({"points": [[1, 2, True]]}, "points"),
        ({"points": [[1, 2, 1e300]]}, "points"),  # finite, but no LiDAR return
        ({"points": "x"}, "points"),
        ({"points": [[1, 2, 3]], "intensity": [1, 2]}, "intensity"),
        ({"points": [[1, 2, 3]], "ring": [-1]}, "ring"),
        ({"points": [[1, 2, 3]], "ring": [1.5]}, "ring"),
        ({"points": [[1, 2, 3]], "ring": [5000]}, "ring"),
    ]
    for extra, field in bad:
        with pytest.raises(LogError) as e:
            parse_record({"t": 1.0, "type": "cloud", **extra})
        assert e.value.field == field, extra
    with pytest.raises(LogError) as e:
        parse_record({"t": 1.0, "type": "cloud"})
    assert e.value.field == "points"


def test_check_record_limits():
    ok = make_cloud(0.0, np.ones((3, 3)))
    check_record(ok)
    for rec, field in [
        (Cloud(0.0, np.ones((3, 3))), "points"),  # float64: not the record's dtype
        (Cloud(0.0, np.ones((3, 2), np.float32)), "points"),
        (Cloud(0.0, np.full((1, 3), np.nan, np.float32)), "points"),
        (Cloud(0.0, np.ones((3, 3), np.float32), np.ones(2, np.float32)), "intensity"),
        (Cloud(0.0, np.ones((3, 3), np.float32), np.full(3, np.inf, np.float32)), "intensity"),
        (Cloud(0.0, np.ones((3, 3), np.float32), None, np.ones(3, np.int64)), "ring"),
        (Cloud(float("nan"), np.ones((3, 3), np.float32)), "t"),
        (Cloud(0.0, np.ones((3, 3), np.float32), roll=2.0), "roll"),
        (Cloud(0.0, np.ones((3, 3), np.float32), pitch=float("inf")), "pitch"),
    ]:
        with pytest.raises(LogError) as e:
            check_record(rec)
        assert e.value.field == field


def test_npz_damage_is_named(tmp_path):
    log = _log()
    p = tmp_path / "a.npz"
    write_npz(log, p)
    with np.load(p) as z:
        arrays = dict(z)
    for key, value in [("cloud/offsets", arrays["cloud/offsets"][::-1].copy()),
                       ("cloud/xyz", arrays["cloud/xyz"][:-1]),
                       ("cloud/ring", arrays["cloud/ring"].astype(np.int32))]:
        bad = dict(arrays)
        bad[key] = value
        q = tmp_path / "b.npz"
        np.savez(q, **bad)
        with pytest.raises(LogError) as e:
            read_npz(q)
        assert e.value.field == key and str(q) in str(e.value)


def test_pcd_via_pypcd4_keeps_intensity_and_ring(tmp_path):
    pypcd4 = pytest.importorskip("pypcd4")
    rng = np.random.default_rng(3)
    a = np.column_stack([rng.normal(0, 5, (50, 3)), rng.uniform(0, 1, 50), rng.integers(0, 16, 50)]).astype(np.float32)
    pypcd4.PointCloud.from_xyzir_points(a).save(tmp_path / "a.pcd")
    c = read_cloud_record(tmp_path / "a.pcd", 3.0)
    assert c.t == 3.0 and np.array_equal(c.points, a[:, :3]) and np.array_equal(c.intensity, a[:, 3])
    assert np.array_equal(c.ring, a[:, 4].astype(np.uint16))
    pypcd4.PointCloud.from_xyz_points(a[:, :3]).save(tmp_path / "b.pcd", encoding=pypcd4.Encoding.BINARY_COMPRESSED)
    c = read_cloud_record(tmp_path / "b.pcd")
    assert np.array_equal(c.points, a[:, :3]) and c.intensity is None and c.ring is None


def test_kitti_folder_is_a_log(tmp_path):
    rng = np.random.default_rng(4)
    seq = tmp_path / "seq"
    (seq / "velodyne").mkdir(parents=True)
    frames = [rng.normal(0, 10, (20 + i, 4)).astype(np.float32) for i in range(3)]
    for i, f in enumerate(frames):
        f.tofile(seq / "velodyne" / f"{i:06d}.bin")
    log = load_log(seq)  # no times.txt: 10 Hz
    assert [c.t for c in log.of("cloud")] == pytest.approx([0.0, 0.1, 0.2]) and "no times.txt" in log.meta["times"]
    (seq / "times.txt").write_text("0.000000e+00\n1.036e-01\n2.073e-01\n")
    log = read_cloud_dir(seq)
    assert [c.t for c in log.of("cloud")] == pytest.approx([0.0, 0.1036, 0.2073])
    for c, f in zip(log.of("cloud"), frames, strict=True):
        assert np.array_equal(c.points, f[:, :3]) and np.array_equal(c.intensity, f[:, 3])
    (seq / "times.txt").write_text("0.0\nnope\n0.2\n")
    with pytest.raises(LogError) as e:
        read_cloud_dir(seq)
    assert e.value.line == 2 and e.value.field == "t"
    (seq / "times.txt").write_text("0.0\n0.1\n")
    with pytest.raises(LogError, match="2 times for 3"):
        read_cloud_dir(seq)


def test_cloud_json_line_is_spec_shaped(tmp_path):
    log = NavLog([make_cloud(1.0, [[1.0, 2.0, 3.0]], [7.0], [3])])
    save_log(log, tmp_path / "a.jsonl")
    obj = json.loads((tmp_path / "a.jsonl").read_text().splitlines()[-1])
    assert obj == {"t": 1.0, "type": "cloud", "points": [[1.0, 2.0, 3.0]], "intensity": [7.0], "ring": [3]}


def test_bag_of_a_3d_harbour_runs_isam2(tmp_path):
    """The issue's round trip: clouds, NavSatFix and Imu in a bag, read back into the same log, and the
    graph runs on it with the cloud factors (a bag's PointCloud2 carries no attitude: level)."""
    pytest.importorskip("open3d")
    from graphnav.graph.log_runs import run_isam2
    from graphnav.sim.harbour3d import Lidar3dConfig, simulate_harbour3d

    full = simulate_harbour3d(2, lidar=Lidar3dConfig(az_deg=1.0), duration=2.5)
    recs = [replace(r, roll=math.nan, pitch=math.nan) if r.kind == "cloud" else r
            for r in full.records if r.kind in ("cloud", "gnss")]
    recs += [Imu(0.05 + 0.1 * k, 0.01, 0.0, 0.002) for k in range(24)]
    log = NavLog.from_unsorted(recs, meta={"origin": ORIGIN})
    back = read_bag(write_bag(log, tmp_path / "h3d.bag", origin=(ORIGIN["lat"], ORIGIN["lon"])))
    assert back.counts() == log.counts()
    _same_clouds(log, back)
    res = run_isam2(back, anchor_sigma_xy=5.0, keyframe_motion=False)  # a keyframe per cloud
    assert res.info["cloud_pairs"] >= 20 and res.info["cloud_failed"] == 0
    assert len(res.trajectory.t) == len(log.of("cloud"))


def test_bag_clouds_take_roll_pitch_from_the_nearest_imu_orientation(tmp_path):
    from scipy.spatial.transform import Rotation

    from graphnav.io.rosbag import attach_attitude, roll_pitch_of_quaternion
    from graphnav.log import Heading

    rng = np.random.default_rng(5)
    for _ in range(50):  # against scipy's ZYX Euler angles
        yaw, pitch, roll = rng.uniform(-3, 3), rng.uniform(-1.4, 1.4), rng.uniform(-3, 3)
        x, y, z, w = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat()
        assert roll_pitch_of_quaternion(x, y, z, w) == pytest.approx((roll, pitch), abs=1e-9)
    recs = [make_cloud(t, np.ones((2, 3))) for t in (0.0, 1.0, 2.0)]
    n = attach_attitude(recs, [(0.96, 0.1, -0.2), (0.02, 0.3, 0.4), (1.5, 0.5, 0.5)])
    assert n == 2 and (recs[0].roll, recs[0].pitch) == (0.3, 0.4) and (recs[1].roll, recs[1].pitch) == (0.1, -0.2)
    assert math.isnan(recs[2].roll)  # nothing within 50 ms
    # end to end: the writer's heading messages are Imu orientations (roll = pitch = 0)
    log = NavLog([make_cloud(1.0, np.ones((3, 3))), Heading(1.01, 0.5, 0.02), make_cloud(2.0, np.ones((3, 3)))])
    back = read_bag(write_bag(log, tmp_path / "a.bag", origin=(ORIGIN["lat"], ORIGIN["lon"])))
    c = back.of("cloud")
    assert back.meta["clouds_with_imu_attitude"] == 1 and c[0].roll == 0.0 and math.isnan(c[1].roll)
