"""Outputs: written atomically; a run never mixes its files with a previous run's; ``--overwrite``
deletes only what graphnav wrote (the manifest); ``live --out`` starts a new file per run."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from graphnav import cli
from graphnav.io.outputs import MANIFEST, OutDir, atomic_open, atomic_path, write_text_atomic
from graphnav.io.trajectory_csv import write_trajectory_csv
from graphnav.io.tum import read_tum, write_tum
from graphnav.online.live_runner import new_live_file
from graphnav.trajectory import Trajectory


def tiny_log(tmp_path: Path, n: int = 40) -> Path:
    """Odometry, GNSS and truth along a straight line (ekf, dead-reckoning and the smoothers run on it)."""
    p = tmp_path / "tiny.jsonl"
    recs = [{"t": 0.0, "type": "pose_prior", "x": 0, "y": 0, "yaw": 0, "sigma_xy": 1, "sigma_yaw": 0.1}]
    for k in range(1, n):
        t = 0.1 * k
        recs += [{"t": t, "type": "odometry", "v": 1.0, "w": 0.0, "sigma_v": 0.1, "sigma_w": 0.01},
                 {"t": t, "type": "truth", "x": t, "y": 0.0, "yaw": 0.0}]
        if k % 5 == 0:
            recs.append({"t": t, "type": "gnss", "x": t + 0.1, "y": -0.1, "sigma": 0.5})
    p.write_text("".join(json.dumps(r) + "\n" for r in recs))
    return p


def graphnav(capsys, *argv: str) -> tuple[int, str]:
    rc = cli.main(list(argv))
    return rc, capsys.readouterr().err


def listing(d: Path) -> set[str]:
    return {p.name for p in d.iterdir()}


# -- atomic writes
def test_atomic_write_replaces_whole_or_leaves_the_old_file(tmp_path):
    p = tmp_path / "summary.json"
    p.write_text("old")
    with pytest.raises(RuntimeError), atomic_open(p) as fh:
        fh.write("half of the new")
        raise RuntimeError("crash while writing")
    assert p.read_text() == "old" and listing(tmp_path) == {"summary.json"}  # no temporary left
    write_text_atomic(p, "new")
    assert p.read_text() == "new" and listing(tmp_path) == {"summary.json"}


def test_atomic_path_keeps_the_suffix_for_format_inferring_writers(tmp_path):
    tr = Trajectory(np.arange(3.0), np.zeros((3, 3)))
    with atomic_path(tmp_path / "a.tum") as tmp:
        assert tmp.parent == tmp_path and tmp.name.endswith("a.tum") and tmp.name.startswith(".")
        write_tum(tr, tmp)
    assert read_tum(tmp_path / "a.tum").t.tolist() == [0.0, 1.0, 2.0]


def test_trajectory_writers_are_atomic(tmp_path, monkeypatch):
    """A failure while writing a TUM/CSV file leaves the previous file, not a truncated one."""
    tr = Trajectory(np.arange(3.0), np.zeros((3, 3)))
    (tmp_path / "t.tum").write_text("previous\n")
    (tmp_path / "t.csv").write_text("previous\n")

    def boom(*a, **k):
        raise OSError(28, "No space left on device")

    def half(*a, **k):  # the disk fills after the first line
        yield "0.0 0.0\n"
        boom()

    monkeypatch.setattr("graphnav.io.tum.table_lines", half)
    with pytest.raises(OSError):
        write_tum(tr, tmp_path / "t.tum")
    monkeypatch.setattr("csv.writer", boom)
    with pytest.raises(OSError):
        write_trajectory_csv(tr, tmp_path / "t.csv")
    assert (tmp_path / "t.tum").read_text() == "previous\n" and (tmp_path / "t.csv").read_text() == "previous\n"
    assert listing(tmp_path) == {"t.tum", "t.csv"}


# -- run --out
def test_run_refuses_a_non_empty_out_without_overwrite(tmp_path, capsys):
    log, out = tiny_log(tmp_path), tmp_path / "o"
    assert graphnav(capsys, "run", str(log), "-e", "ekf", "--out", str(out))[0] == 0
    before = (out / "summary.json").read_text()
    rc, err = graphnav(capsys, "run", str(log), "-e", "dead-reckoning", "--out", str(out))
    assert rc == 2 and "not empty" in err and "--overwrite" in err
    assert (out / "summary.json").read_text() == before  # nothing touched


def test_overwrite_clears_only_the_previous_runs_files(tmp_path, capsys):
    """ekf writes online.cov; a later dead-reckoning run (no covariance) must not leave it beside its
    own files; a file of the user's stays."""
    log, out = tiny_log(tmp_path), tmp_path / "o"
    assert graphnav(capsys, "run", str(log), "-e", "ekf", "--out", str(out))[0] == 0
    assert (out / "online.cov").exists()
    (out / "notes.txt").write_text("mine")
    (out / "sub").mkdir()
    assert graphnav(capsys, "run", str(log), "-e", "dead-reckoning", "--out", str(out), "--overwrite")[0] == 0
    assert not (out / "online.cov").exists()
    assert (out / "notes.txt").read_text() == "mine" and (out / "sub").is_dir()
    assert json.loads((out / "summary.json").read_text())["estimator"] == "dead-reckoning"
    assert set(json.loads((out / MANIFEST).read_text())["files"]) >= {"online.tum", "summary.json"}


def test_a_failed_run_leaves_no_summary_of_the_previous_one(tmp_path, capsys):
    log, out = tiny_log(tmp_path), tmp_path / "o"
    assert graphnav(capsys, "run", str(log), "-e", "ekf", "--out", str(out))[0] == 0
    rc, err = graphnav(capsys, "run", str(log), "-e", "ekf", "-O", "motion=\"nonsense\"", "--out", str(out),
                       "--overwrite")
    assert rc == 2, err
    assert not (out / "summary.json").exists() and not (out / "trajectory.tum").exists()


def test_online_estimates_are_on_disk_as_they_come(tmp_path, monkeypatch, capsys):
    """The online TUM is flushed per estimate: a run that dies keeps every estimate made so far."""
    from graphnav import estimators

    def dies_after_three(name, log, on_estimate=None, **kw):
        for k in range(3):
            on_estimate(float(k), np.array([k, 0.0, 0.0]), None)
        raise RuntimeError("the estimator crashed")

    monkeypatch.setattr(estimators, "run", dies_after_three)
    out = tmp_path / "o"
    rc, err = graphnav(capsys, "run", str(tiny_log(tmp_path)), "-e", "ekf", "--out", str(out))
    assert rc == 1 and "internal error" in err
    assert len((out / "online.tum").read_text().splitlines()) == 1 + 3


# -- compare / demo / icp
def test_compare_leaves_no_stale_estimator_files(tmp_path, capsys):
    log, out = tiny_log(tmp_path), tmp_path / "c"
    assert graphnav(capsys, "compare", str(log), "-e", "ekf,dead-reckoning", "--out", str(out))[0] == 0
    assert {"ekf.tum", "dead-reckoning.tum", "report.md"} <= listing(out)
    rc, err = graphnav(capsys, "compare", str(log), "-e", "ekf", "--out", str(out))
    assert rc == 2 and "--overwrite" in err
    assert graphnav(capsys, "compare", str(log), "-e", "ekf", "--out", str(out), "--overwrite")[0] == 0
    assert "ekf.tum" in listing(out) and "dead-reckoning.tum" not in listing(out)
    assert "dead-reckoning" not in (out / "report.md").read_text()


def test_demo_replaces_its_own_output_but_not_a_directory_with_other_files(tmp_path, capsys):
    log, out = tiny_log(tmp_path), tmp_path / "demo"
    assert graphnav(capsys, "demo", "--log", str(log), "--out", str(out))[0] == 0
    first = listing(out)
    assert "report.md" in first
    assert graphnav(capsys, "demo", "--log", str(log), "--out", str(out))[0] == 0  # its own files: replaced
    assert listing(out) == first
    (out / "mine.txt").write_text("x")
    rc, err = graphnav(capsys, "demo", "--log", str(log), "--out", str(out))
    assert rc == 2 and "--overwrite" in err
    assert graphnav(capsys, "demo", "--log", str(log), "--out", str(out), "--overwrite")[0] == 0
    assert (out / "mine.txt").read_text() == "x"


def test_icp_refuses_a_non_empty_out(tmp_path, capsys):
    out = tmp_path / "i"
    out.mkdir()
    (out / "pairs.csv").write_text("someone else's\n")
    rc, err = graphnav(capsys, "icp", str(tiny_log(tmp_path)), "--out", str(out))
    assert rc == 2 and "not empty" in err
    assert (out / "pairs.csv").read_text() == "someone else's\n"


def test_outdir_records_a_name_before_the_file_is_written(tmp_path):
    d = OutDir(tmp_path / "o", command="test")
    p = d.file("a.tum")
    assert not p.exists() and json.loads((tmp_path / "o" / MANIFEST).read_text())["files"] == ["a.tum"]
    with pytest.raises(ValueError):
        d.file("../escape.txt")


# -- live
def test_live_out_starts_a_new_file_and_keeps_the_previous_runs(tmp_path):
    a = new_live_file(tmp_path, now=1.7e9)
    a.write(1.0, np.zeros(3), np.eye(3))
    a.close()
    b = new_live_file(tmp_path, now=1.7e9)  # same second: another name
    b.write(2.0, np.zeros(3))
    b.close()
    assert a.path != b.path and a.path.name == "live-20231114T221320Z.tum" and b.path.name.startswith("live-")
    assert len(a.path.read_text().splitlines()) == 2 and a.path.with_suffix(".cov").exists()
    assert len(b.path.read_text().splitlines()) == 2
