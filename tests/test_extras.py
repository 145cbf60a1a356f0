"""A missing optional dependency (pyproject's extras [open3d] [dask] [ros] [fast]) is one line naming
it and the extra to install, at every optional import site; absent Dask a sweep runs serially, absent
numba the numpy paths run (the import is blocked with ``sys.modules[name] = None``)."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from graphnav.cli import main
from graphnav.errors import GraphnavError, MissingExtra, require


def _block(monkeypatch: pytest.MonkeyPatch, *names: str) -> None:
    for name in names:
        for mod in [m for m in sys.modules if m == name or m.startswith(name + ".")]:
            monkeypatch.delitem(sys.modules, mod)
        monkeypatch.setitem(sys.modules, name, None)
        parent, _, child = name.rpartition(".")
        if parent in sys.modules:  # ``from parent import child`` would find the attribute left by an earlier import
            monkeypatch.delattr(sys.modules[parent], child, raising=False)


def _one_line(err: BaseException, package: str, extra: str) -> None:
    text = str(err)
    assert "\n" not in text
    assert f"needs the optional dependency {package}: pip install 'graphnav[{extra}]'" in text
    assert isinstance(err, GraphnavError)


def test_require_names_the_extra(monkeypatch):
    _block(monkeypatch, "rosbags")
    with pytest.raises(MissingExtra) as exc:
        require("rosbags.highlevel", "reading ROS bags")
    assert str(exc.value) == "reading ROS bags needs the optional dependency rosbags: pip install 'graphnav[ros]'"
    with pytest.raises(KeyError):  # only the extras' modules are optional
        require("json", "x")


def test_open3d_sites(monkeypatch, tmp_path):
    from graphnav.io.cloudfile import read_cloud
    from graphnav.scan import register3d, registration

    _block(monkeypatch, "open3d")
    pts = np.random.default_rng(0).normal(size=(200, 3))
    with pytest.raises(MissingExtra) as exc:
        register3d.register(pts, pts, "o3d-icp")
    _one_line(exc.value, "open3d", "open3d")
    with pytest.raises(MissingExtra) as exc:
        registration.Target(pts[:, :2], "open3d:point_to_point")
    _one_line(exc.value, "open3d", "open3d")
    ply = tmp_path / "c.ply"
    ply.write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                   "property float z\nend_header\n1 2 3\n")
    with pytest.raises(MissingExtra) as exc:  # PLY through open3d
        read_cloud(ply)
    _one_line(exc.value, "open3d", "open3d")
    pcd = tmp_path / "c.pcd"
    pcd.write_text("VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\n"
                   "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n1 2 3\n")
    assert np.allclose(read_cloud(pcd), [[1, 2, 3]])  # PCD through pypcd4: no open3d needed
    from graphnav.sim.harbour3d import Lidar3d, Lidar3dConfig

    with pytest.raises(MissingExtra) as exc:
        Lidar3d(Lidar3dConfig())
    _one_line(exc.value, "open3d", "open3d")


def test_pypcd4_and_kiss_icp_sites(monkeypatch, tmp_path):
    from graphnav.evaluation import scan_matching3d
    from graphnav.io.cloudfile import read_cloud

    _block(monkeypatch, "pypcd4", "kiss_icp")
    pcd = tmp_path / "c.pcd"
    pcd.write_text("VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\n"
                   "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n1 2 3\n")
    with pytest.raises(MissingExtra) as exc:
        read_cloud(pcd)
    _one_line(exc.value, "pypcd4", "pcd")
    with pytest.raises(MissingExtra) as exc:
        scan_matching3d._kiss([np.zeros((10, 3))], 100.0)
    _one_line(exc.value, "kiss-icp", "bench")


def test_rosbags_site(monkeypatch):
    from graphnav.io import rosbag

    _block(monkeypatch, "rosbags")
    with pytest.raises(MissingExtra) as exc:
        rosbag.typestore()
    _one_line(exc.value, "rosbags", "ros")


def test_dask_absent_sweeps_run_serially_unless_a_cluster_is_asked_for(monkeypatch):
    from graphnav.evaluation import sweep

    _block(monkeypatch, "distributed", "dask")
    monkeypatch.setattr(sweep.importlib.util, "find_spec",
                        lambda name, *a: None if name.partition(".")[0] in ("distributed", "dask") else object())
    tasks = [{"key": f"t{i}", "x": i} for i in range(3)]
    report: dict = {}
    assert sweep.run_sweep(_square, tasks, progress=False, report=report) == [0, 1, 4]
    with pytest.raises(MissingExtra) as exc:
        sweep.run_sweep(_square, tasks, scheduler="local", progress=False)
    _one_line(exc.value, "dask", "dask")


def _square(task: dict) -> int:
    return task["x"] ** 2


def test_numba_absent_falls_back_and_explicit_numba_is_one_line(monkeypatch):
    from graphnav.scan import ndt

    _block(monkeypatch, "numba", "graphnav.scan._ndt_fast")
    assert ndt.resolve_backend("auto") == "python"  # the same kernels, interpreted
    with pytest.raises(MissingExtra) as exc:
        ndt.resolve_backend("numba")
    _one_line(exc.value, "numba", "fast")


def test_cli_prints_the_one_line(monkeypatch, tmp_path, capsys):
    _block(monkeypatch, "open3d")
    a = tmp_path / "a.bin"
    np.column_stack([np.random.default_rng(1).normal(size=(300, 3)), np.zeros(300)]).astype(np.float32).tofile(a)
    assert main(["register", str(a), str(a), "--method", "o3d-icp"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == ("graphnav: error: registration method 'o3d-icp' needs the optional dependency open3d: "
                   "pip install 'graphnav[open3d]'")
