"""``--drop KIND[,KIND]`` (run, compare, --config), and the exit codes of unknown names, a compare in
which nothing ran and a failed run: 2, with nothing left in ``--out``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from _logfactory import every_record_log

from graphnav import cli
from graphnav.io import save_log
from graphnav.io.drop import drop_kinds, parse_kinds
from graphnav.io.outputs import MANIFEST


def _log(tmp_path: Path) -> Path:
    p = tmp_path / "l.jsonl"
    save_log(every_record_log(), p)
    return p


def graphnav(capsys, *argv: str) -> tuple[int, dict, str]:
    rc = cli.main([*argv, "--json"])
    cap = capsys.readouterr()
    return rc, json.loads(cap.out), cap.err


def test_parse_and_drop_kinds():
    log = every_record_log()
    assert parse_kinds("beacon, odometry") == ["odometry", "beacon"] and parse_kinds(None) == []
    assert parse_kinds(["odometry", "beacon_known,odometry"]) == ["odometry", "beacon_known"]
    with pytest.raises(ValueError, match="unknown record kind 'odo'.*known: scan, gnss"):
        parse_kinds("odo")
    out = drop_kinds(log, ["odometry", "beacon_known"])
    assert "odometry" not in out.counts() and not out.beacons_known and out.meta == log.meta
    assert {k: v for k, v in log.counts().items() if k not in ("odometry", "beacon_known")} == out.counts()
    assert "odometry" in log.counts() and log.beacons_known  # the log itself is unchanged


def test_run_drop_leaves_kinds_out_and_says_so(tmp_path, capsys):
    p = _log(tmp_path)
    rc, obj, err = graphnav(capsys, "run", str(p), "-e", "ekf", "--drop", "beacon,odometry", "--drop", "imu")
    assert rc == 0, err
    assert obj["dropped"] == ["odometry", "imu", "beacon"]
    assert obj["inputs"] == ["scan", "gnss", "heading", "pose_prior"]  # without odometry the EKF moves by ICP
    rc, obj, _ = graphnav(capsys, "run", str(p), "-e", "ekf")
    assert rc == 0 and obj["dropped"] == [] and obj["inputs"] == ["gnss", "heading", "odometry", "pose_prior"]
    assert obj["errors_by_event"]["gnss_outage"]["n"] == 5  # truth at 2.0, 2.5, ..., 4.0 s


def test_drop_of_an_unknown_kind_is_exit_2_naming_the_known_ones(tmp_path, capsys):
    p = _log(tmp_path)
    for cmd in (["run", str(p), "-e", "ekf"], ["compare", str(p), "-e", "ekf"]):
        rc, obj, err = graphnav(capsys, *cmd, "--out", str(tmp_path / "o"), "--drop", "odometry,sonar")
        assert rc == 2 and "'sonar'" in obj["error"] and "beacon_known" in obj["error"] and "Traceback" not in err
        assert not (tmp_path / "o").exists()


def test_drop_from_a_config_file(tmp_path, capsys):
    p = _log(tmp_path)
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'log = "{p}"\nestimator = "dead-reckoning"\ndrop = ["beacon", "scan"]\n')
    rc, obj, err = graphnav(capsys, "run", "--config", str(cfg))
    assert rc == 0, err
    assert obj["dropped"] == ["scan", "beacon"]
    cfg.write_text(f'log = "{p}"\nestimators = "ekf,dead-reckoning"\nout = "{tmp_path / "c"}"\ndrop = "imu"\n')
    rc, obj, err = graphnav(capsys, "compare", "--config", str(cfg), "-j", "1")
    assert rc == 0, err
    assert obj["dropped"] == ["imu"] and obj["estimators"]["ekf"]["inputs"] == ["gnss", "heading", "odometry",
                                                                                 "pose_prior"]


@pytest.mark.parametrize("argv, wanted", [
    (["run", "-e", "isam"], "did you mean 'isam2'"),
    (["run", "-e", "ekf", "-O", "ekff.gate=0.9"], "did you mean 'ekf'"),
    (["compare", "-e", "ekf,ukff"], "did you mean 'ukf'"),
    (["compare", "-e", "dr=dead-reckonin"], "did you mean 'dead-reckoning'"),
    (["compare", "-e", "ekf", "-O", "ekf-slamm.gate=0.9"], "did you mean 'ekf-slam'"),
])
def test_an_unknown_estimator_name_is_exit_2_with_a_suggestion(tmp_path, capsys, argv, wanted):
    p = _log(tmp_path)
    out = tmp_path / "o"
    rc, obj, err = graphnav(capsys, argv[0], str(p), *argv[1:], "--out", str(out))
    assert rc == 2 and "unknown estimator" in obj["error"] and wanted in obj["error"], obj
    assert "Traceback" not in err and not out.exists()


def test_a_compare_in_which_nothing_ran_is_exit_2_and_writes_nothing(tmp_path, capsys):
    p = _log(tmp_path)
    out = tmp_path / "o"
    rc, obj, _ = graphnav(capsys, "compare", str(p), "-e", "dead-reckoning,ekf-slam", "--drop", "odometry,imu",
                          "--out", str(out))
    assert rc == 2 and "no estimator ran" in obj["error"] and "(after --drop odometry,imu)" in obj["error"]
    assert "dead-reckoning: not run: needs at least two odometry (or IMU) records" in obj["error"]
    assert not out.exists()
    out.mkdir()
    (out / "mine.txt").write_text("x")
    rc, _, _ = graphnav(capsys, "compare", str(p), "-e", "ekf-slam", "--drop", "beacon", "--out", str(out),
                        "--overwrite")
    assert rc == 2 and sorted(f.name for f in out.iterdir()) == ["mine.txt"]  # no GPX, no manifest: only theirs


def test_a_failed_run_leaves_nothing_in_out(tmp_path, capsys):
    p = _log(tmp_path)
    out = tmp_path / "o"
    rc, obj, _ = graphnav(capsys, "run", str(p), "-e", "dead-reckoning", "--drop", "odometry,imu", "--out", str(out))
    assert rc == 2 and "cannot run" in obj["error"] and "(after --drop odometry,imu)" in obj["error"]
    assert not out.exists()  # no manifest, no header-only online.tum
    out.mkdir()
    rc, _, _ = graphnav(capsys, "run", str(tmp_path / "absent.jsonl"), "-e", "ekf", "--out", str(out))
    assert rc == 2 and list(out.iterdir()) == []  # the directory was there before: kept, empty
    rc, _, _ = graphnav(capsys, "run", str(p), "-e", "ekf", "--out", str(out))
    assert rc == 0 and (out / MANIFEST).exists() and (out / "online.tum").exists()


@pytest.mark.parametrize("argv, wanted", [
    (["montecarlo", "solent", "--runs", "1", "--estimators", "ekf,ufk"], "did you mean 'ukf'"),
    (["montecarlo", "solent", "--runs", "1", "-O", "fuzy-ukf.window=5"], "did you mean 'fuzzy-ukf'"),
    (["live", "--nmea", "udp://127.0.0.1:1", "-e", "isam"], "did you mean 'isam2'"),
])
def test_unknown_names_in_montecarlo_and_live_are_exit_2_with_a_suggestion(capsys, argv, wanted):
    rc, obj, err = graphnav(capsys, *argv)
    assert rc == 2 and wanted in obj["error"] and "Traceback" not in err, obj
