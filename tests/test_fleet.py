"""graphnav run LOG LOG ...: a fleet of logs (the same figures as one by one, a failed log does not stop
the others, resumable). The LocalCluster path is the sweep's (tests/evaluation); here the serial one."""

import json

from _logfactory import every_record_log

from graphnav import cli
from graphnav.commands.run import log_names
from graphnav.io import save_log


def _main(capsys, *args):
    rc = cli.main(list(args))
    return rc, json.loads(capsys.readouterr().out)


def test_fleet_runs_each_log_as_alone(tmp_path, capsys):
    a, b = tmp_path / "a.npz", tmp_path / "b.jsonl"
    save_log(every_record_log(12, seed=1), a)
    save_log(every_record_log(16, seed=2), b)
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"type": "gnss", "t": 0.0}\n')
    est = ("-e", "dead-reckoning", "--json")
    rc, fleet = _main(capsys, "run", str(a), str(b), str(bad), *est, "--out", str(tmp_path / "f"),
                      "--scheduler", "serial")
    assert rc == 2 and fleet["logs"] == 3 and fleet["failed"] == 1 and fleet["reused"] == 0
    runs = {r["log"]: r for r in fleet["runs"]}
    assert "bad.jsonl:1" in runs[str(bad)]["error"] and "ate_rmse_m" not in runs[str(bad)]
    for log, name in ((a, "a"), (b, "b")):
        _, alone = _main(capsys, "run", str(log), *est)
        r = runs[str(log)]
        assert r["estimator"] == "dead-reckoning" and "error" not in r
        assert r["ate_rmse_m"] == alone["ate_rmse_m"] and r["steps"] == alone["steps"]
        assert (tmp_path / "f" / name / "trajectory.tum").is_file()
    assert not (tmp_path / "f" / "bad").exists()  # a failed run leaves nothing
    # resumed: nothing runs again; a changed log runs again
    rc, again = _main(capsys, "run", str(a), str(b), *est, "--out", str(tmp_path / "f"), "--scheduler", "serial")
    assert rc == 0 and again["reused"] == 2 and again["runs"] == fleet["runs"][:2]
    save_log(every_record_log(14, seed=3), a)
    _, changed = _main(capsys, "run", str(a), str(b), *est, "--out", str(tmp_path / "f"), "--scheduler", "serial")
    assert changed["reused"] == 1 and changed["runs"][0]["steps"] != fleet["runs"][0]["steps"]


def test_fleet_needs_out_and_names_are_unique(tmp_path, capsys):
    save_log(every_record_log(6), tmp_path / "a.npz")
    rc = cli.main(["run", str(tmp_path / "a.npz"), str(tmp_path / "a.npz"), "-e", "dead-reckoning", "--json"])
    assert rc == 2 and "--out" in json.loads(capsys.readouterr().out)["error"]
    assert log_names(["x/a.npz", "y/a.jsonl.gz", "a"]) == ["a", "a-2", "a-3"]
