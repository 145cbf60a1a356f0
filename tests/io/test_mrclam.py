"""The UTIAS MRCLAM reader on a small dataset the tests write (plain and gzipped files), its errors,
the convert CLI, and the real Dataset 6 in ../shared/data/mrclam (skipped with the reason when absent)."""

from __future__ import annotations

import gzip
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from graphnav.errors import LogError
from graphnav.io import load_log
from graphnav.io.mrclam import PRIOR_SIGMA, read_mrclam, robots

REPO = Path(__file__).resolve().parents[2]
HEADER = "# UTIAS Multi-Robot Cooperative Localization and Mapping Dataset\n# columns ...\n"


def mrclam_dir() -> Path | None:
    for c in (REPO.parent / "shared" / "data" / "mrclam", REPO.parent.parent / "shared" / "data" / "mrclam"):
        if (c / "MRCLAM_Dataset6").is_dir():
            return c / "MRCLAM_Dataset6"
    return None


def put(d: Path, stem: str, rows: list[str], gz: bool = False) -> Path:
    text = HEADER + "".join(r + "\n" for r in rows)
    if gz:
        p = d / f"{stem}.dat.gz"
        with gzip.open(p, "wt") as fh:
            fh.write(text)
    else:
        p = d / f"{stem}.dat"
        p.write_text(text)
    return p


@pytest.fixture
def dataset(tmp_path) -> Path:
    """Robots = subjects 1, 2 (barcodes 5, 14); landmarks = subjects 6, 7 (barcodes 63, 81)."""
    put(tmp_path, "Barcodes", ["  1 \t   5", "  2 \t  14", "  6 \t  63", "  7 \t  81"])
    put(tmp_path, "Landmark_Groundtruth",
        ["  6 \t 1.0 \t 2.0 \t 0.001 \t 0.003", "  7 \t -1.0 \t 0.5 \t 0.002 \t 0.002"], gz=True)
    put(tmp_path, "Robot1_Odometry", ["100.00 \t 0.1 \t 0.0", "100.01 \t 0.1 \t 0.05", "100.02 \t 0.2 \t -0.05"],
        gz=True)
    put(tmp_path, "Robot1_Measurement", ["100.005 \t 63 \t 2.5 \t 0.1", "100.005 \t 14 \t 1.5 \t -0.2",
                                         "100.015 \t 99 \t 3.0 \t 0.0", "100.015 \t 81 \t 3.5 \t -0.3",
                                         "100.016 \t 5 \t 1.0 \t 0.0"])
    put(tmp_path, "Robot1_Groundtruth", ["99.99 \t 0.5 \t -0.5 \t 3.5", "100.01 \t 0.501 \t -0.5 \t 0.1"], gz=True)
    return tmp_path


def test_reads_sightings_odometry_truth_and_prior(dataset):
    log = read_mrclam(dataset, 1)
    assert log.counts() == {"odometry": 3, "beacon": 2, "truth": 2, "pose_prior": 1}
    b = log.of("beacon")
    assert [r.id for r in b] == ["6", "7"]  # landmark subject numbers, not barcodes
    assert (b[0].t, b[0].range, b[0].bearing) == (100.005, 2.5, 0.1)
    assert all(math.isnan(r.sigma_range) and math.isnan(r.sigma_bearing) for r in b)  # no invented sigmas
    assert all(math.isnan(r.sigma_v) and math.isnan(r.sigma_w) for r in log.of("odometry"))
    assert log.meta["dropped"] == {"robot": {"1": 1, "2": 1}, "unknown_barcode": {"99": 1}}
    assert log.meta["sightings_kept"] == 2
    tr = log.truth()
    assert tr.poses[0, 2] == pytest.approx(3.5 - 2 * math.pi)  # orientation wrapped
    p = log.pose_prior()
    assert (p.t, p.x, p.y) == (99.99, 0.5, -0.5) and p.yaw == tr.poses[0, 2]
    assert p.sigma_xy == PRIOR_SIGMA == p.sigma_yaw == 0.01
    assert log.beacons_known == []  # landmarks are not charted by default ...
    assert log.meta["landmarks"]["6"] == [1.0, 2.0, 0.001, 0.003]  # ... but kept for map scoring
    assert [r.t for r in log.records] == sorted(r.t for r in log.records)
    assert robots(dataset) == [1]


def test_charted_writes_known_beacons_with_the_larger_std(dataset):
    log = read_mrclam(dataset, 1, charted=True)
    kb = {k.id: k for k in log.beacons_known}
    assert set(kb) == {"6", "7"}
    assert (kb["6"].x, kb["6"].y, kb["6"].sigma) == (1.0, 2.0, 0.003)


@pytest.mark.parametrize(("stem", "row", "field", "line"), [
    ("Robot1_Odometry", "100.03 \t abc \t 0.0", "v", 6),
    ("Robot1_Odometry", "100.03 \t 0.1", "w", 6),
    ("Robot1_Odometry", "99.0 \t 0.1 \t 0.0", "time", 6),  # backwards
    ("Robot1_Measurement", "100.02 \t 63 \t -1.0 \t 0.0", "range", 8),
    ("Robot1_Measurement", "100.02 \t 6.5 \t 1.0 \t 0.0", "barcode", 8),
    ("Robot1_Measurement", "100.02 \t 63 \t 1.0 \t nan", "bearing", 8),
    ("Robot1_Groundtruth", "100.02 \t 1 \t 2 \t 3 \t 4", "orientation", 5),
])
def test_malformed_lines_name_file_line_and_field(dataset, stem, row, field, line):
    path = next(dataset.glob(f"{stem}.dat*"))
    if path.name.endswith(".gz"):
        text = gzip.open(path, "rt").read() + row + "\n"
        with gzip.open(path, "wt") as fh:
            fh.write(text)
    else:
        path.write_text(path.read_text() + row + "\n")
    with pytest.raises(LogError) as ei:
        read_mrclam(dataset, 1)
    err = ei.value
    assert (err.file, err.line, err.field) == (str(path), line, field), str(err)
    log = read_mrclam(dataset, 1, lenient=True)
    assert log.meta["skipped"] == 1 and f":{line}:" in log.meta["skipped_errors"][0]


def test_missing_files_and_robot(dataset):
    with pytest.raises(LogError) as ei:
        read_mrclam(dataset, 3)
    assert "Robot3_Odometry.dat" in str(ei.value)
    with pytest.raises(ValueError):
        read_mrclam(dataset, 0)
    with pytest.raises(LogError) as ei:
        load_log(dataset)  # a dataset directory needs the robot
    assert "robot" in str(ei.value)
    assert load_log(dataset, robot=1).counts()["beacon"] == 2


def test_convert_cli(dataset, tmp_path):
    out = tmp_path / "out" / "r1.jsonl.gz"
    r = subprocess.run([sys.executable, "-m", "graphnav", "convert", "mrclam", str(dataset), "--robot", "1",
                        "--out", str(out), "--json"], capture_output=True, text=True, check=True, cwd=REPO)
    obj = json.loads(r.stdout)
    assert obj["records"] == {"odometry": 3, "beacon": 2, "truth": 2, "pose_prior": 1}
    assert (obj["sightings_kept"], obj["dropped_robot"], obj["dropped_unknown_barcode"]) == (2, 2, 1)
    back = load_log(out)
    assert back.counts() == obj["records"]
    assert all(math.isnan(r.sigma_v) for r in back.of("odometry"))  # still no sigmas after the round trip
    r = subprocess.run([sys.executable, "-m", "graphnav", "convert", "mrclam", str(dataset), "--robot", "1",
                        "--charted", "--out", str(out), "--overwrite", "--json"], capture_output=True, text=True,
                       check=True, cwd=REPO)
    assert json.loads(r.stdout)["records"]["beacon_known"] == 2


# ----------------------------------------------------------------------------- the real Dataset 6

@pytest.fixture(scope="module")
def dataset6() -> Path:
    d = mrclam_dir()
    if d is None:
        pytest.skip("MRCLAM Dataset 6 not found at ../shared/data/mrclam (research data, not in the repository)")
    return d


def _data_lines(path: Path) -> list[list[str]]:
    return [ln.split() for ln in gzip.open(path, "rt") if ln.strip() and not ln.startswith("#")]


@pytest.mark.parametrize("robot", [1, 2, 3, 4, 5])
def test_real_robots(dataset6, robot):
    log = read_mrclam(dataset6, robot)
    c = log.counts()
    meas = _data_lines(dataset6 / f"Robot{robot}_Measurement.dat.gz")
    dropped = log.meta["dropped"]
    n_dropped = sum(dropped["robot"].values()) + sum(dropped["unknown_barcode"].values())
    assert c["beacon"] + n_dropped == len(meas)  # nothing lost silently
    assert set(dropped["robot"]) <= {"1", "2", "3", "4", "5"} - {str(robot)}
    assert {r.id for r in log.of("beacon")} <= {str(s) for s in range(6, 21)}
    assert c["odometry"] == len(_data_lines(dataset6 / f"Robot{robot}_Odometry.dat.gz"))
    assert c["truth"] == len(_data_lines(dataset6 / f"Robot{robot}_Groundtruth.dat.gz"))
    assert c["pose_prior"] == 1 and len(log.meta["landmarks"]) == 15
    if robot == 1:  # the reported counts, checked against the raw barcodes
        codes = [int(m[1]) for m in meas]
        assert dropped["unknown_barcode"] == {"43": codes.count(43)} and codes.count(43) >= 1
        assert dropped["robot"] == {"2": codes.count(14), "3": codes.count(41), "4": codes.count(32),
                                    "5": codes.count(23)}


def test_real_robot1_dead_reckoning_drifts_like_the_readme_says(dataset6):
    from graphnav import estimators
    from graphnav.evaluation.evaluate import summarize

    log = read_mrclam(dataset6, 1)
    res = estimators.run("dead-reckoning", log)
    ate = summarize("dead-reckoning", res, log, runtime_s=0.0)["ate_rmse_m"]
    assert 1.0 < ate < 6.0  # README: dead reckoning alone drifts 1.7-4.3 m; a wrong frame or unit would not
    assert np.isfinite(ate)
