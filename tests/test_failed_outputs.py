"""Issue #23 item 7: outputs that are whole or absent. ``trajectory.csv`` keeps full-precision times;
``write_bag`` is all-or-nothing and takes beams rounded as the JSON Lines writer stores them; a failed
``run`` / ``compare`` / ``icp`` leaves nothing of its own in ``--out``."""

from __future__ import annotations

import io
import json
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest
from _harbour import harbour_trial

from graphnav.cli import main
from graphnav.errors import GraphnavError, LogError
from graphnav.io import load_log, save_log
from graphnav.io.trajectory_csv import read_trajectory_csv, write_trajectory_csv
from graphnav.log import NavLog, Scan
from graphnav.trajectory import Trajectory


def cli(*argv: str) -> int:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = main([*argv, "--json"])
    assert "Traceback" not in err.getvalue()
    if out.getvalue().strip():
        json.loads(out.getvalue())
    return code


def test_trajectory_csv_keeps_full_precision_times(tmp_path):
    """POSIX times 10 ms apart: 120 rows, 120 distinct times read back exactly (9 digits gave 8)."""
    t = 1.7e9 + 0.01 * np.arange(120) + 1e-6
    tr = Trajectory(t, np.column_stack([np.linspace(0, 1, 120), np.zeros(120), np.full(120, 0.1)]),
                    cov=np.tile(np.diag([1e-3, 2e-3, 3e-5]), (120, 1, 1)))
    write_trajectory_csv(tr, tmp_path / "trajectory.csv")
    back = read_trajectory_csv(tmp_path / "trajectory.csv")
    assert len(np.unique(back.t)) == 120
    np.testing.assert_array_equal(back.t, tr.t)
    np.testing.assert_array_equal(back.poses, tr.poses)


@pytest.fixture(scope="module")
def rounded_log(tmp_path_factory):
    """A simulated log through the JSON Lines writer: its beam angles rounded to 1e-4 rad."""
    pytest.importorskip("rosbags")
    d = tmp_path_factory.mktemp("bag")
    log = harbour_trial(duration=2.0, rate=10.0, scans=True, seed=1)
    save_log(NavLog([r for r in log.records if r.kind != "truth"], [], log.meta), d / "h.jsonl")
    return load_log(d / "h.jsonl")


@pytest.mark.parametrize("name,storage", [("r.bag", "-"), ("r_mcap", "mcap"), ("r_db3", "sqlite3")])
def test_write_bag_takes_rounded_angles(tmp_path, rounded_log, name, storage):
    from graphnav.io.rosbag import read_bag, write_bag

    a = rounded_log.of("scan")[0].angles
    assert np.ptp(np.diff(a)) > 1e-6  # rounded: not uniform to 1e-6
    p = write_bag(rounded_log, tmp_path / name, storage=storage)
    back = read_bag(p)
    assert back.counts()["scan"] == rounded_log.counts()["scan"]
    np.testing.assert_allclose(back.of("scan")[0].angles, a, atol=1.5e-4)
    assert sorted(e.name for e in tmp_path.iterdir()) == [name]


@pytest.mark.parametrize("name,storage", [("x.bag", "-"), ("x_mcap", "mcap"), ("x.mcap", "mcap")])
def test_write_bag_is_all_or_nothing(tmp_path, rounded_log, name, storage):
    """A scan with uneven beams half-way through: a LogError, and nothing left in the directory (it
    left a 43-byte .mcap that `info` could not read); an existing path is never written over."""
    from graphnav.io.rosbag import write_bag

    recs = list(rounded_log.records)
    mid = len(recs) // 2
    recs.insert(mid, Scan(recs[mid].t, np.full(4, 5.0), np.array([0.0, 0.1, 0.3, 0.35])))
    with pytest.raises(LogError, match="uniformly spaced"):
        write_bag(NavLog(recs, [], rounded_log.meta), tmp_path / name, storage=storage)
    assert list(tmp_path.iterdir()) == []
    (tmp_path / name).write_text("mine")
    with pytest.raises(GraphnavError, match="never written over"):
        write_bag(rounded_log, tmp_path / name, storage=storage)
    assert (tmp_path / name).read_text() == "mine"


@pytest.fixture(scope="module")
def bad_log(tmp_path_factory):
    d = tmp_path_factory.mktemp("bad")
    p = d / "bad.jsonl"
    p.write_text('{"t": 0, "type": "gnss", "x": 0, "y": 0, "sigma": 1}\n{"t": 1, "type": "gnss", "x": 1}\n')
    return p


@pytest.mark.parametrize("argv", [["run", "LOG", "-e", "isam2"], ["run", "LOG", "-e", "ekf"],
                                  ["compare", "LOG", "--estimators", "ekf"], ["icp", "LOG"]])
@pytest.mark.parametrize("existing", [False, True])
def test_a_failed_command_leaves_nothing_in_out(tmp_path, bad_log, argv, existing):
    out = tmp_path / "out"
    if existing:
        out.mkdir()
    assert cli(*[str(bad_log) if a == "LOG" else a for a in argv], "--out", str(out)) == 2
    if existing:
        assert list(out.iterdir()) == []  # the manifest too
    else:
        assert not out.exists()


@pytest.mark.parametrize("fail_after", [0, 30])
def test_a_run_that_dies_mid_way_keeps_only_its_online_estimates(tmp_path, monkeypatch, fail_after):
    """The estimator raises after ``fail_after`` records: before any estimate nothing is left (no
    header-only online.tum); after some, online.tum holds them, listed in the manifest, and nothing else."""
    from graphnav.graph.navigator import Navigator
    from graphnav.sim.square import square_loop

    log = tmp_path / "sq.jsonl"
    save_log(square_loop(0, side=20.0, laps=1), log)
    add = Navigator.add
    seen = [0]

    def failing(self, rec, **kw):
        seen[0] += 1
        if seen[0] > fail_after:
            raise RuntimeError("boom")
        return add(self, rec, **kw)

    monkeypatch.setattr(Navigator, "add", failing)
    out = tmp_path / "o"
    with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
        code = main(["run", str(log), "-e", "isam2", "--out", str(out)])
    assert code == 1
    if fail_after == 0:
        assert not out.exists()
    else:
        names = sorted(p.name for p in out.iterdir())
        assert "online.tum" in names and set(names) <= {"online.tum", "online.cov", ".graphnav-outputs.json"}
        assert len((out / "online.tum").read_text().splitlines()) > 1
