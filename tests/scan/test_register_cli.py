"""``graphnav register``: one JSON object with T, ms, fitness/rmse, the covariance and, with
--reference, the errors; bad files are clean errors naming the file."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from _cloud_sim import find_kitti, pair, rigid


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "graphnav", "register", *map(str, args)], capture_output=True,
                          text=True)


@pytest.fixture(scope="module")
def clouds(tmp_path_factory):
    import open3d as o3d

    d = tmp_path_factory.mktemp("clouds")
    T = rigid([2.0, -1.0, 0.1], [1.0, -1.0, 20.0])
    src, tgt = pair(np.random.default_rng(0), T, 5000)
    o3d.io.write_point_cloud(str(d / "src.ply"), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(src)))
    np.column_stack([tgt, np.zeros(len(tgt))]).astype(np.float32).tofile(d / "tgt.bin")
    np.savetxt(d / "T.txt", T)
    return d, T


def test_register_json_with_init_and_reference(clouds):
    d, T = clouds
    r = _cli(d / "src.ply", d / "tgt.bin", "--method", "ndt", "--voxel", "0.1", "--init", "1.8,-0.9,0,0,0,18",
             "--reference", d / "T.txt", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)  # exactly one JSON object
    assert np.asarray(out["T"]).shape == (4, 4) and np.asarray(out["cov"]).shape == (6, 6)
    assert out["translation_error_m"] < 0.05 and out["rotation_error_deg"] < 0.5
    assert np.allclose(out["T"], T, atol=0.05)
    for k in ("ms", "ms_prep", "ms_align", "fitness", "rmse", "objective", "converged", "iterations", "cov_convention"):
        assert k in out
    assert out["method"] == "ndt" and out["options"] == {"voxel": 0.1} and out["fitness"] > 0.9


def test_register_human_output_and_option(clouds):
    d, _ = clouds
    r = _cli(d / "src.ply", d / "tgt.bin", "--method", "gicp", "--init", "2,-1,0,0,0,20", "-O", "max_corr=2.0",
             "--reference", d / "T.txt")
    assert r.returncode == 0, r.stderr
    assert "T (source -> target)" in r.stdout and "error" in r.stdout and "sigma" in r.stdout


@pytest.mark.parametrize(("args", "needle"), [
    (["--init", "1,2,3"], "six"),
    (["--method", "nope"], "invalid choice"),
    (["-O", "resolutoin=1"], "unknown registration parameter"),
    (["--voxel", "-1"], "--voxel"),
])
def test_bad_arguments_are_clean_errors(clouds, args, needle):
    d, _ = clouds
    r = _cli(d / "src.ply", d / "tgt.bin", *args, "--json")
    assert r.returncode == 2 and needle in r.stderr and "Traceback" not in r.stderr


def test_bad_files_are_clean_errors_naming_the_file(clouds, tmp_path):
    d, _ = clouds
    bad = tmp_path / "trunc.ply"
    bad.write_bytes((d / "src.ply").read_bytes()[:-100])
    absent = tmp_path / "absent.pcd"
    for args, where in (([bad, d / "tgt.bin"], bad), ([d / "src.ply", absent], absent),
                        ([d / "src.ply", d / "tgt.bin", "--reference", d / "src.ply"], d / "src.ply")):
        r = _cli(*args, "--json")
        assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
        err = json.loads(r.stdout)  # the one JSON object: the error
        assert set(err) == {"error", "where"} and err["where"] == str(where)


@pytest.mark.parametrize("method", ["gicp", "ndt"])
def test_kitti_pair_through_the_cli(method):
    k = find_kitti()
    if k is None:
        pytest.skip("KITTI pair not found at ../shared/data/kitti_pair (research data, not in the repository)")
    r = _cli(k / "source.ply", k / "target.ply", "--method", method, "--reference", k / "T_target_source.txt", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["translation_error_m"] < 0.05 and out["rotation_error_deg"] < 0.5
