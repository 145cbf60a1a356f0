"""Physical validity in the log model's record check (graphnav.log.check_record, Limits): every
reader rejects physically senseless values with a LogError naming file, line and field, or with
``lenient`` skips and counts them (issue #14)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.io import savemat

from graphnav import cli
from graphnav.errors import LogError
from graphnav.io import load_log, save_log
from graphnav.io.jsonl import read_jsonl
from graphnav.log import BeaconObs, Gnss, Limits, NavLog, Odometry, Truth, check_record, default_limits
from tests._logfactory import every_record_log

GOOD = '{"t": 0, "type": "truth", "x": 0, "y": 0, "yaw": 0}'
GOOD2 = '{"t": 5, "type": "heading", "yaw": 0, "sigma": 0.1}'
INVALID = [  # (line, field): each one physically senseless
    ('{"t": 1, "type": "beacon", "id": "B1", "range": -12.0, "bearing": 0.1}', "range"),
    ('{"t": 1, "type": "beacon", "id": "B1", "range": 0, "bearing": 0.1}', "range"),
    ('{"t": 1, "type": "beacon", "id": "B1", "range": 1e6, "bearing": 0.1}', "range"),
    ('{"t": 1, "type": "gnss", "x": 0, "y": 0, "sigma": 1e300}', "sigma"),
    ('{"t": 1, "type": "gnss", "x": 0, "y": 0, "sigma": 1e-300}', "sigma"),
    ('{"t": 1, "type": "heading", "yaw": 0, "sigma": 0}', "sigma"),
    ('{"t": 1, "type": "beacon", "id": "B1", "range": 10, "bearing": 0, "sigma_range": 1e300}', "sigma_range"),
    ('{"t": 1, "type": "odometry", "v": 1e308, "w": 0}', "v"),
    ('{"t": 1, "type": "odometry", "v": -60.0, "w": 0}', "v"),
    ('{"t": 1, "type": "odometry", "v": 1.0, "w": 1e5}', "w"),
    ('{"t": 1, "type": "odometry", "v": 1.0, "w": 0.0, "sigma_v": Infinity}', "sigma_v"),
    ('{"t": 1, "type": "imu", "ax": 1e4, "ay": 0, "wz": 0}', "ax"),
    ('{"t": 1, "type": "truth", "x": 1e12, "y": 0, "yaw": 0}', "x"),
    ('{"t": 1, "type": "truth", "x": 0, "y": 0, "yaw": 1e30}', "yaw"),
    ('{"t": 1e15, "type": "truth", "x": 0, "y": 0, "yaw": 0}', "t"),
    ('{"t": 1, "type": "pose_prior", "x": 0, "y": 0, "yaw": 0, "sigma_xy": 1e300, "sigma_yaw": 0.1}', "sigma_xy"),
    ('{"type": "beacon_known", "id": "B1", "x": 0, "y": 0, "sigma": -1}', "sigma"),
]


@pytest.mark.parametrize("line,field", INVALID)
def test_invalid_value_names_file_line_field_or_is_skipped(tmp_path, line, field):
    p = tmp_path / "v.jsonl"
    p.write_text(f"{GOOD}\n{line}\n{GOOD2}\n")
    with pytest.raises(LogError) as ei:
        read_jsonl(p)
    assert (ei.value.file, ei.value.line, ei.value.field) == (str(p), 2, field)
    log = read_jsonl(p, lenient=True)
    assert log.meta["skipped"] == 1 and len(log) == 2 and f":2: field '{field}'" in log.meta["skipped_errors"][0]


def test_bounds_hold_at_the_limit():
    lim = default_limits()
    check_record(Odometry(0.0, lim.max_speed, -lim.max_yaw_rate))
    check_record(Odometry(0.0, -lim.max_speed, 0.0, lim.min_sigma, lim.max_sigma))
    check_record(BeaconObs(0.0, "B", lim.max_beacon_range, 0.0))
    check_record(Gnss(0.0, -lim.max_coord, lim.max_coord, 3.0))
    check_record(Truth(lim.max_time, 0.0, 0.0, -lim.max_angle))


def test_speed_limit_is_configurable(tmp_path):
    p = tmp_path / "fast.jsonl"
    p.write_text('{"t": 1, "type": "odometry", "v": 60.0, "w": 0}\n')
    with pytest.raises(LogError):
        read_jsonl(p)
    assert read_jsonl(p, limits=Limits(max_speed=70.0)).of("odometry")[0].v == 60.0
    assert len(load_log(p, limits=Limits(max_speed=70.0))) == 1


def test_cli_max_speed_and_clean_error(tmp_path, capsys):
    p = tmp_path / "fast.jsonl"
    p.write_text('{"t": 1, "type": "odometry", "v": 60.0, "w": 0}\n')
    assert cli.main(["info", str(p), "--json"]) == 2
    err = json.loads(capsys.readouterr().out)
    assert "field 'v'" in err["where"] and "plausible limit 50" in err["error"]
    try:
        assert cli.main(["info", str(p), "--json", "--max-speed", "70"]) == 0
        assert json.loads(capsys.readouterr().out)["records"] == {"odometry": 1}
    finally:
        from graphnav.log import set_default_limits

        set_default_limits(Limits())


def test_sigma_1e300_is_rejected_before_the_ekf(tmp_path, capsys):
    """``sigma: 1e300`` raised OverflowError inside the ekf; now the reader rejects the fix."""
    log = every_record_log(n=6)
    save_log(log, tmp_path / "ok.jsonl")
    lines = (tmp_path / "ok.jsonl").read_text().splitlines()
    k = next(i for i, s in enumerate(lines) if '"type":"gnss"' in s)
    obj = json.loads(lines[k])
    obj["sigma"] = 1e300
    lines[k] = json.dumps(obj)
    (tmp_path / "bad.jsonl").write_text("\n".join(lines) + "\n")
    assert cli.main(["run", str(tmp_path / "bad.jsonl"), "-e", "ekf", "--json"]) == 2
    err = json.loads(capsys.readouterr().out)
    assert err["where"] == f"{tmp_path / 'bad.jsonl'}, line {k + 1}, field 'sigma'"
    assert cli.main(["run", str(tmp_path / "bad.jsonl"), "-e", "ekf", "--json", "--lenient"]) == 0
    assert math.isfinite(json.loads(capsys.readouterr().out)["ate_rmse_m"])


def test_negative_beacon_range_is_rejected_in_every_writable_format(tmp_path):
    log = NavLog([BeaconObs(0.0, "B1", 10.0, 0.0), BeaconObs(1.0, "B1", -10.0, 0.0)])
    for name in ("b.jsonl", "b.npz"):
        save_log(log, tmp_path / name)  # the writers do not check
        with pytest.raises(LogError) as ei:
            load_log(tmp_path / name)
        assert ei.value.field.endswith("range")
        lenient = load_log(tmp_path / name, lenient=True)
        assert len(lenient) == 1 and lenient.meta["skipped"] == 1


def test_npz_lenient_keeps_order(tmp_path):
    log = every_record_log(n=4)
    recs = list(log.records)
    i = next(k for k, r in enumerate(recs) if isinstance(r, Odometry))
    recs[i] = Odometry(recs[i].t, 1e308, 0.0)
    save_log(NavLog(recs, log.beacons_known, log.meta), tmp_path / "o.npz")
    back = load_log(tmp_path / "o.npz", lenient=True)
    assert len(back) == len(recs) - 1 and back.meta["skipped"] == 1
    assert [(r.kind, r.t) for r in back.records] == [(r.kind, r.t) for k, r in enumerate(recs) if k != i]


def test_rosbag_invalid_odometry(tmp_path):
    pytest.importorskip("rosbags")
    from graphnav.io.rosbag import read_bag, write_bag

    log = NavLog([Odometry(0.0, 1.0, 0.0), Odometry(1.0, 1e308, 0.0), Odometry(2.0, 1.0, 0.0)])
    write_bag(log, tmp_path / "o.bag")
    with pytest.raises(LogError) as ei:
        read_bag(tmp_path / "o.bag")
    assert ei.value.field.endswith("/v") and ei.value.line == 2
    back = read_bag(tmp_path / "o.bag", lenient=True)
    assert len(back) == 2 and back.meta["skipped"] == 1


def test_marina_invalid_reference_names_file_and_column(tmp_path):
    rng = np.random.default_rng(0)
    savemat(tmp_path / "ranges.mat", {"ranges_baza": rng.uniform(1, 40, (20, 4))})
    savemat(tmp_path / "angles.mat", {"angles_baza": np.tile(np.linspace(0, 6, 20)[:, None], (1, 4))})
    pose = np.zeros((4, 3))
    pose[:, 0] = [0.0, 1.0, 1e13, 3.0]
    savemat(tmp_path / "gps.mat", {"slam_pose": pose})
    with pytest.raises(LogError) as ei:
        load_log(tmp_path)
    assert ei.value.file == str(tmp_path / "gps.mat") and ei.value.field in ("slam_pose/x", "slam_pose/y")
    assert ei.value.message.startswith("row 3:")
