"""Point-cloud files (graphnav.io.cloudfile): PLY/PCD through open3d, KITTI .bin; bad files are
errors naming the file, never a silent partial read."""

from __future__ import annotations

import numpy as np
import pytest

from graphnav.errors import LogError
from graphnav.io.cloudfile import read_cloud, read_transform


def _points(n=500, seed=0):
    return np.random.default_rng(seed).normal(0, 10, (n, 3))


@pytest.mark.parametrize(("ext", "ascii_", "compressed"), [(".ply", False, False), (".ply", True, False),
                                                          (".pcd", False, False), (".pcd", True, False),
                                                          (".pcd", False, True)])
def test_open3d_formats_round_trip(tmp_path, ext, ascii_, compressed):
    import open3d as o3d

    pts = _points()
    f = tmp_path / f"c{ext}"
    assert o3d.io.write_point_cloud(str(f), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts)),
                                    write_ascii=ascii_, compressed=compressed)
    got = read_cloud(f)
    assert got.shape == pts.shape
    assert np.allclose(got, pts, atol=1e-4 if ascii_ else 0)


def test_kitti_bin_is_float32_xyz_intensity(tmp_path):
    pts = _points().astype(np.float32)
    f = tmp_path / "000000.bin"
    np.column_stack([pts, np.ones(len(pts), np.float32)]).tofile(f)
    assert np.array_equal(read_cloud(f), pts.astype(float))


def test_non_finite_points_are_dropped(tmp_path):
    pts = _points().astype(np.float32)
    pts[:7] = np.nan
    f = tmp_path / "a.bin"
    np.column_stack([pts, np.zeros(len(pts), np.float32)]).tofile(f)
    assert len(read_cloud(f)) == len(pts) - 7


def _ply_binary(tmp_path, n=100, props="xyz"):
    head = f"ply\nformat binary_little_endian 1.0\ncomment test\nelement vertex {n}\n"
    head += "".join(f"property float {p}\n" for p in props) + "end_header\n"
    f = tmp_path / "b.ply"
    f.write_bytes(head.encode() + np.ones((n, len(props)), "<f4").tobytes())
    return f


def test_a_truncated_binary_ply_is_an_error(tmp_path):
    f = _ply_binary(tmp_path)
    assert len(read_cloud(f)) == 100
    f.write_bytes(f.read_bytes()[:-10])
    with pytest.raises(LogError, match="truncated") as ei:
        read_cloud(f)
    assert ei.value.file == str(f)


@pytest.mark.parametrize(("content", "message"), [
    (b"", "no 'end_header'"),
    (b"hello\nend_header\n", "not a PLY"),
    (b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nend_header\n1\n2\n", "no y, z"),
    (b"ply\nformat weird 1.0\nelement vertex 1\nproperty float x\nend_header\n", "unknown PLY format"),
    (b"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int i\nend_header\n3 0 1 2\n", "no 'vertex'"),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
     b"end_header\n1 2 3\n", "truncated.*3 rows"),
    (b"ply\nformat ascii 1.0\nbogus line\nend_header\n", "not understood"),
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 99999999999\nproperty float x\nproperty float y\n"
     b"property float z\nend_header\n", "more than"),
])
def test_bad_ply_files_are_errors_naming_the_file(tmp_path, content, message, capfd):
    f = tmp_path / "bad.ply"
    f.write_bytes(content)
    with pytest.raises(LogError, match=message) as ei:
        read_cloud(f)
    assert str(f) in str(ei.value)
    assert capfd.readouterr().out == ""  # open3d's warnings never reach stdout


@pytest.mark.parametrize(("content", "message"), [
    (b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y\nSIZE 4 4\nTYPE F F\nCOUNT 1 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\n"
     b"DATA ascii\n1 2\n", "no z"),
    (b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 10\nHEIGHT 1\n"
     b"POINTS 10\nDATA binary\n" + b"\0" * 12, "truncated"),
    (b"# .PCD v0.7\nFIELDS x y z\nPOINTS many\nDATA ascii\n", "POINTS"),
    (b"hello", "no 'DATA'"),
    (b"# .PCD v0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 1000000000000\nDATA ascii\n1 2 3\n",
     "not in"),
    (b"# .PCD v0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 3\nDATA ascii\n1 2 3\n", "3 points, the"),
    (b"# .PCD v0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 10\nDATA binary_compressed\n"
     + np.array([1000, 120], "<u4").tobytes() + b"\0" * 20, "compressed block"),
])
def test_bad_pcd_files_are_errors_naming_the_file(tmp_path, content, message, capfd):
    f = tmp_path / "bad.pcd"
    f.write_bytes(content)
    with pytest.raises(LogError, match=message):
        read_cloud(f)
    assert capfd.readouterr().out == ""


def test_bad_bin_unknown_extension_and_missing_file(tmp_path):
    f = tmp_path / "x.bin"
    f.write_bytes(b"\0" * 17)
    with pytest.raises(LogError, match="multiple of 16"):
        read_cloud(f)
    g = tmp_path / "x.xyz"
    g.write_text("1 2 3\n")
    with pytest.raises(LogError, match="unknown point-cloud format"):
        read_cloud(g)
    with pytest.raises(FileNotFoundError):
        read_cloud(tmp_path / "absent.ply")
    h = tmp_path / "nan.bin"
    np.full((4, 4), np.nan, np.float32).tofile(h)
    with pytest.raises(LogError, match="no finite points"):
        read_cloud(h)


def test_read_transform(tmp_path):
    T = np.eye(4)
    T[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    T[:3, 3] = [1, 2, 3]
    f = tmp_path / "T.txt"
    np.savetxt(f, T)
    assert np.array_equal(read_transform(f), T)
    f.write_text(" ".join(map(str, T[:3].ravel())))  # 12 numbers: KITTI's 3x4
    assert np.array_equal(read_transform(f), T)
    for text, message in (("1 2 3", "12 or 16 numbers"), ("a b", "not a transform"),
                          (" ".join(["2"] * 12), "not a rotation")):
        f.write_text(text)
        with pytest.raises(LogError, match=message):
            read_transform(f)
