"""ROS 1 / ROS 2 bags: write small bags with rosbags' writer, read them back, topic choice, damage."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from _harbour import harbour_trial

from graphnav.cli import main
from graphnav.errors import LogError
from graphnav.geometry import wrap_angle
from graphnav.io import load_log
from graphnav.io.nmea_out import log_to_nmea
from graphnav.io.rosbag import choose_topics, parse_topic_args, read_bag, write_bag, yaw_of_quaternion
from graphnav.log import Imu, NavLog

ORIGIN = (43.5, 16.4)


@pytest.fixture(scope="module")
def trial():
    log = harbour_trial(duration=3.0, rate=10.0, scans=True, seed=1)
    recs = [r for r in log.records if r.kind != "truth"]
    recs += [Imu(1.7e9 + 0.05 * k, 0.1 * k, -0.2, 0.03) for k in range(20)]
    return NavLog.from_unsorted(recs, meta=log.meta)


def compare(a: NavLog, b: NavLog) -> None:
    assert a.counts() == b.counts()
    for kind, names, tol in (("gnss", ("t", "x", "y", "sigma"), 1e-6),
                             ("heading", ("t", "yaw", "sigma"), 1e-6),
                             ("odometry", ("t", "v", "w", "sigma_v", "sigma_w"), 1e-9),
                             ("imu", ("t", "ax", "ay", "wz"), 1e-9)):
        ca, cb = a.columns(kind), b.columns(kind)
        for n in names:
            d = wrap_angle(ca[n] - cb[n]) if n == "yaw" else ca[n] - cb[n]
            assert np.max(np.abs(d)) <= tol, (kind, n)
    for sa, sb in zip(a.of("scan"), b.of("scan"), strict=True):
        assert sa.t == pytest.approx(sb.t, abs=1e-9)
        np.testing.assert_array_equal(sa.valid(), sb.valid())
        np.testing.assert_allclose(sa.ranges[sa.valid()], sb.ranges[sb.valid()], rtol=1e-6)  # float32
        np.testing.assert_allclose(sa.angles, sb.angles, atol=1e-6)


@pytest.mark.parametrize("name,storage", [("t.bag", "-"), ("t_db3", "sqlite3"), ("t_mcap", "mcap")])
def test_round_trip(tmp_path, trial, name, storage):
    p = write_bag(trial, tmp_path / name, storage=storage)
    back = read_bag(p, origin=ORIGIN)
    compare(back, trial)
    fix = {"type": "sensor_msgs/msg/NavSatFix", "count": 30, "used_as": "gnss"}
    assert back.meta["topics"]["/fix"] == fix
    if storage != "-":  # the storage file itself reads too, and load_log dispatches both
        inner = next(p.glob("*.db3" if storage == "sqlite3" else "*.mcap"))
        compare(load_log(inner, origin=ORIGIN), trial)
        assert load_log(p).counts() == trial.counts()


def test_nmea_topic_path(tmp_path, trial):
    sentences = list(log_to_nmea(trial))
    p = write_bag(trial, tmp_path / "n.bag", nmea_sentences=sentences)
    auto = read_bag(p, origin=ORIGIN)  # NavSatFix present: the NMEA topic is listed, not used
    assert auto.meta["topics"]["/nmea_sentence"]["used_as"] is None
    assert auto.counts()["gnss"] == 30
    via = read_bag(p, {"nmea": "/nmea_sentence", "odometry": "/odom"}, origin=ORIGIN)
    g, ref = via.columns("gnss"), trial.columns("gnss")
    np.testing.assert_allclose(g["x"], ref["x"], atol=1e-3)
    np.testing.assert_allclose(g["t"], ref["t"], atol=1e-6)  # stamped with the message header time
    assert via.counts()["gnss"] == 30 and via.meta["topics"]["/fix"]["used_as"] is None


def test_topic_choice_and_errors():
    conns = [("/a", "sensor_msgs/msg/LaserScan", 5), ("/b", "sensor_msgs/msg/LaserScan", 9),
             ("/fix", "sensor_msgs/msg/NavSatFix", 3), ("/i1", "sensor_msgs/msg/Imu", 3),
             ("/i2", "sensor_msgs/msg/Imu", 3), ("/n", "nmea_msgs/msg/Sentence", 3)]
    assert choose_topics(conns, None) == {"/b": "scan", "/fix": "gnss", "/i1": "imu", "/i2": "imu"}
    assert choose_topics(conns, {"scan": "/a", "heading": "/i2"}) == {"/a": "scan", "/i2": "heading",
                                                                       "/fix": "gnss"}
    with pytest.raises(LogError, match="not in the bag"):
        choose_topics(conns, {"scan": "/nope"})
    with pytest.raises(LogError, match="not a gnss type"):
        choose_topics(conns, {"gnss": "/a"})
    assert parse_topic_args(["scan=/lidar/scan"]) == {"scan": "/lidar/scan"}
    with pytest.raises(ValueError):
        parse_topic_args(["laser=/x"])


def test_quaternion_yaw():
    for yaw in (-3.0, -1.0, 0.0, 0.5, 2.9):
        assert yaw_of_quaternion(0, 0, math.sin(yaw / 2), math.cos(yaw / 2)) == pytest.approx(yaw)


def test_damaged_bags(tmp_path, trial):
    bad = tmp_path / "bad.bag"
    bad.write_bytes(b"#ROSBAG V2.0\nthis is not a bag")
    with pytest.raises(LogError) as ei:
        read_bag(bad)
    assert ei.value.file == str(bad)
    good = write_bag(trial, tmp_path / "g.bag")
    cut = tmp_path / "cut.bag"
    cut.write_bytes(good.read_bytes()[:2000])
    with pytest.raises(LogError, match="ROS bag"):
        load_log(cut)
    mc = write_bag(trial, tmp_path / "m", storage="mcap")
    f = next(mc.glob("*.mcap"))
    f.write_bytes(f.read_bytes()[: f.stat().st_size // 2])
    with pytest.raises(LogError):
        read_bag(f)


def test_info_lists_topics(tmp_path, trial, capsys):
    p = write_bag(trial, tmp_path / "i.bag")
    assert main(["info", str(p), "--json", "--topic", "imu=/imu"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["topics"]["/imu"]["used_as"] == "imu" and out["topics"]["/heading"]["used_as"] is None
    assert out["records"]["gnss"] == 30 and "heading" not in out["records"]


@pytest.mark.parametrize("name", ["six.bag", "six_db3"])
def test_six_axis_imu_and_gnss_velocity(tmp_path, name):
    """A 6-axis Imu (real z, x, y axes) reads back as the 6-axis record, a planar one as planar; a
    TwistWithCovarianceStamped (ENU) as gnss_velocity with sigma = sqrt(mean(cov_xx, cov_yy))."""
    from graphnav.log import GnssVelocity

    t0 = 1.7e9
    recs = [Imu(t0 + 0.01 * k, 0.1, -0.2, 0.03, az=9.81, wx=0.01 * k, wy=-0.02) for k in range(5)]
    recs += [Imu(t0 + 0.1 + 0.01 * k, 0.3, 0.1, -0.05) for k in range(3)]  # planar: NaN az, wx, wy
    recs += [GnssVelocity(t0 + k, 1.5, -0.5, 0.1) for k in range(3)] + [GnssVelocity(t0 + 3.0, 2.0, 0.0)]
    log = NavLog.from_unsorted(recs)
    back = read_bag(write_bag(log, tmp_path / name))
    imu = back.of("imu")
    assert [r.six_axis for r in imu] == [True] * 5 + [False] * 3
    assert imu[2].az == pytest.approx(9.81) and imu[2].wx == pytest.approx(0.02) and imu[2].wy == pytest.approx(-0.02)
    assert math.isnan(imu[6].az) and imu[6].wz == pytest.approx(-0.05)
    assert back.meta["imu_six_axis"] == 5
    vel = back.of("gnss_velocity")
    assert [(v.vx, v.vy) for v in vel] == [(1.5, -0.5)] * 3 + [(2.0, 0.0)]
    assert vel[0].sigma == pytest.approx(0.1) and math.isnan(vel[3].sigma)
    assert back.meta["topics"]["/gnss_vel"]["used_as"] == "gnss_velocity"
