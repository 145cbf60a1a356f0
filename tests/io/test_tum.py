"""TUM files: the quaternions by scipy's Rotation against the closed form, the flushed writer against
Trajectory.to_tum, round trips."""

from __future__ import annotations

import numpy as np
from hypothesis import assume, given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from graphnav.geometry import wrap_angle
from graphnav.io.tum import TrajectoryWriter, quat_to_yaw, read_tum, write_tum, yaw_to_quat
from graphnav.trajectory import Trajectory

YAWS = arrays(float, st.integers(1, 20), elements=st.floats(-np.pi, np.pi))


@given(YAWS)
def test_yaw_to_quat_is_the_closed_form(yaw):
    q = yaw_to_quat(yaw)
    closed = np.column_stack([np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2), np.cos(yaw / 2)])
    sign = np.where(np.sum(q * closed, axis=1) < 0, -1.0, 1.0)[:, None]  # q and -q: one rotation
    np.testing.assert_allclose(q * sign, closed, atol=1e-12)


@given(st.tuples(*[st.floats(-1, 1)] * 4))
def test_quat_to_yaw_is_the_zyx_closed_form(q):
    x, y, z, w = q
    n = np.sqrt(x * x + y * y + z * z + w * w)
    assume(n > 1e-3)
    x, y, z, w = x / n, y / n, z / n, w / n
    assume(abs(2 * (w * y - z * x)) < 0.99)  # away from gimbal lock (pitch +-90 deg)
    closed = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    assert abs(wrap_angle(quat_to_yaw([x, y, z, w])[0] - closed)) < 1e-9


def test_writer_and_to_tum_write_the_same_rotation(tmp_path):
    rng = np.random.default_rng(3)
    t = np.arange(50) * 0.1
    poses = np.column_stack([rng.normal(size=50), rng.normal(size=50), rng.uniform(-np.pi, np.pi, 50)])
    write_tum(Trajectory(t, poses), tmp_path / "a.tum")
    with TrajectoryWriter(tmp_path / "b.tum") as w:
        for k in range(50):
            w.write(float(t[k]), poses[k])
    a, b = np.loadtxt(tmp_path / "a.tum"), np.loadtxt(tmp_path / "b.tum")
    np.testing.assert_allclose(a, b, atol=2e-9)
    back = read_tum(tmp_path / "b.tum")
    assert np.max(np.abs(wrap_angle(back.yaw - poses[:, 2]))) < 1e-8


def test_empty_and_single_pose(tmp_path):
    assert yaw_to_quat(np.empty(0)).shape == (0, 4) and quat_to_yaw(np.empty((0, 4))).shape == (0,)
    write_tum(Trajectory([1.0], [[2.0, 3.0, 0.5]]), tmp_path / "one.tum")
    assert abs(read_tum(tmp_path / "one.tum").yaw[0] - 0.5) < 1e-9


@given(arrays(float, st.tuples(st.integers(0, 9), st.integers(1, 8)),
              elements=st.floats(allow_nan=True, allow_infinity=True, width=64)), st.integers(1, 4))
def test_table_lines_are_what_savetxt_writes(arr, rows):
    """Formatted by blocks (``rows`` each, so a block boundary falls inside the table), byte for byte
    numpy's savetxt: NaN, infinities, -0.0, huge and tiny values alike."""
    import io

    from graphnav.io.tum import table_lines

    buf = io.BytesIO()
    np.savetxt(buf, arr, fmt="%.9f")
    assert "".join(table_lines(arr, "%.9f", rows=rows)).encode() == buf.getvalue()


def test_write_tum_is_savetxt_byte_for_byte(tmp_path):
    rng = np.random.default_rng(5)
    tr = Trajectory(np.arange(7) * 0.1, np.column_stack([rng.normal(size=7) * 1e4, [-0.0] * 7, rng.uniform(-4, 4, 7)]))
    write_tum(tr, tmp_path / "a.tum")
    arr = np.column_stack([tr.t, tr.x, tr.y, np.zeros(7), yaw_to_quat(tr.yaw)])
    np.savetxt(tmp_path / "b.tum", arr, fmt="%.9f", header="timestamp tx ty tz qx qy qz qw")
    assert (tmp_path / "a.tum").read_bytes() == (tmp_path / "b.tum").read_bytes()
