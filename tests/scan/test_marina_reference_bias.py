"""benchmarks/marina_reference_bias.py: its de-skew's SE(2) exponential against GTSAM's, and a
constant-twist sweep de-skewed back to the points of a scan taken at one instant."""

from __future__ import annotations

import gtsam
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tests._bench import load_benchmark

BENCH = load_benchmark("marina_reference_bias")
finite = st.floats(-3.0, 3.0, allow_nan=False)


@settings(max_examples=50, deadline=None)
@given(finite, finite, st.floats(-2.0, 2.0, allow_nan=False), finite, finite)
def test_exp_apply_is_gtsam_expmap(vx, vy, w, px, py):
    xi = np.array([[vx, vy, w], [vx, vy, 0.0], [vx, vy, 1e-12]])
    pts = np.array([[px, py]] * 3)
    got = BENCH.se2_exp_apply(xi, pts)
    for i in range(3):
        want = gtsam.Pose2.Expmap(xi[i]).transformFrom(pts[i])
        # GTSAM's Expmap computes (1 - cos w) / w directly: ~1e-8 m of cancellation error at w ~ 1e-8
        np.testing.assert_allclose(got[i], want, atol=1e-7)


def test_deskew_undoes_a_constant_twist_sweep():
    """A sensor moving with a constant twist samples a fixed world point set over one sweep; the
    de-skew with that twist gives the points as seen from the pose at mid-sweep."""
    rng = np.random.default_rng(0)
    n, sweep = 360, 1.0
    twist = np.array([1.2, 0.1, 0.05])
    world = rng.uniform(-20, 20, size=(n, 2))
    tau = (np.arange(n) / n - 0.5) * sweep
    ranges, angles = np.empty(n), np.empty(n)
    for i in range(n):  # sample i is taken from the pose Exp(twist tau_i) (mid-sweep pose = identity)
        p = gtsam.Pose2.Expmap(twist * tau[i]).transformTo(world[i])
        ranges[i], angles[i] = np.hypot(*p), np.arctan2(p[1], p[0])

    class _Scan:
        pass

    scan = _Scan()
    scan.ranges, scan.angles = ranges, angles
    np.testing.assert_allclose(BENCH.deskewed(scan, twist, sweep), world, atol=1e-9)
