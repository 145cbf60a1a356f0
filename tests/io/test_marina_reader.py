"""The marina reader on the real data (skipped with a reason when ../shared is absent)."""

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy.io import loadmat

from graphnav.errors import LogError
from graphnav.geometry import wrap_angle
from graphnav.io.marina import read_marina, reference_world_track


def test_reference_world_track_closed_form():
    # along-track steps of 1 m; yaw (col 3 - 3pi/2) turns left by 90 deg after two steps
    raw = np.array([[0, 0, 1.5 * np.pi], [1, 0, 1.5 * np.pi], [2, 0, 2.0 * np.pi], [3, 0, 2.0 * np.pi]])
    w = reference_world_track(raw)
    assert np.allclose(w[:, :2], [[0, 0], [1, 0], [2, 0], [2, 1]])
    assert np.allclose(wrap_angle(w[:, 2]), [0, 0, np.pi / 2, np.pi / 2])


def test_marina_counts_and_alignment(marina_dir, marina_log):
    log = marina_log
    assert log.counts() == {"scan": 177, "truth": 176}
    scans = log.of("scan")
    truth = log.truth()
    assert scans[0].t == 0.0 and scans[-1].t == 176.0
    assert truth.t[0] == 1.0 and truth.t[-1] == 176.0  # reference row j belongs to scan j+1
    assert not scans[-1].valid().any()  # the last scan is empty
    n_valid = np.array([s.valid().sum() for s in scans[:-1]])
    assert n_valid.min() >= 100 and np.median(n_valid) > 300
    # the world track keeps the raw step lengths and turns left by ~90 deg then right
    raw = loadmat(marina_dir / "gps.mat")["slam_pose"]
    steps_raw = np.hypot(*np.diff(raw[:, :2], axis=0).T)[:-1]
    steps_world = np.hypot(*np.diff(truth.poses[:, :2], axis=0).T)
    assert np.allclose(steps_raw, steps_world, atol=1e-9)
    assert truth.poses[:, 1].max() > 100.0  # a real world track leaves the x axis
    assert np.degrees(np.ptp(np.unwrap(truth.yaw))) > 80.0


def test_info_cli_reports_marina(marina_dir):
    out = subprocess.run([sys.executable, "-m", "graphnav", "info", str(marina_dir), "--json"],
                         capture_output=True, text=True, check=True)
    obj = json.loads(out.stdout)  # exactly one JSON object on stdout
    assert obj["records"]["scan"] == 177 and obj["records"]["truth"] == 176 and obj["has_truth"] is True
    assert obj["t0"] == 0.0 and obj["t1"] == 176.0


def test_broken_marina_dir(tmp_path):
    for f in ("ranges.mat", "angles.mat", "gps.mat"):
        (tmp_path / f).write_bytes(b"MATLAB garbage")
    with pytest.raises(LogError) as ei:
        read_marina(tmp_path)
    assert "ranges.mat" in str(ei.value)


from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from scipy.io import savemat  # noqa: E402


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.integers(0, 6), st.integers(0, 6), st.integers(0, 6), st.integers(1, 4),
       st.sampled_from([np.nan, 0.0, 1e300, -1.0]))
def test_random_marina_shapes_never_crash(tmp_path, nb, ns, nr, nc, fill):
    rng = np.random.default_rng(nb * 100 + ns * 10 + nr)
    savemat(tmp_path / "ranges.mat", {"ranges_baza": rng.uniform(0, 40, (nb, ns))})
    savemat(tmp_path / "angles.mat", {"angles_baza": rng.uniform(0, 6.3, (nb, ns))})
    pose = rng.normal(size=(nr, nc))
    if pose.size:
        pose.flat[0] = fill
    savemat(tmp_path / "gps.mat", {"slam_pose": pose})
    try:
        log = read_marina(tmp_path)
    except LogError:
        return
    assert log.counts().get("scan", 0) == ns
