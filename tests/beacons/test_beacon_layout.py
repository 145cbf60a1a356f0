"""Batched beacon-layout EKF: grids, closed forms, agreement with the dense reference, symmetry;
the compiled (numba) kernel against the numpy path, compiled and as plain Python."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from graphnav.beacons.layout import (
    Choices,
    Fairway,
    grid,
    initial_covariance,
    motion_terms,
    propagate,
    resolve_backend,
    score,
    summarize_search,
)
from graphnav.estimators.ekf_slam import EkfSlam

FW = Fairway()
BACKENDS = ["numpy", pytest.param("numba", marks=pytest.mark.skipif(
    resolve_backend("auto") != "numba", reason="numba not installed"))]


def dense_reference(layout: np.ndarray, fw: Fairway = FW, ch: Choices | None = None):
    """The paper's filter with dense matrices, noise-free, so it is linearised on the true track."""
    ch = ch or Choices()
    track = fw.track()
    f = EkfSlam(track[0].copy(), len(layout), p0_beacon=ch.p0_beacon, p0_cross=ch.p0_cross,
                w_second=ch.w_second)
    mx, my = [], []
    for k in range(1, fw.steps + 1):
        f.predict(fw.v, 0.0, fw.dt, fw.sigma_v, fw.sigma_rot)
        for j, (bx, by) in enumerate(layout):
            dx, dy = bx - track[k, 0], by - track[k, 1]
            f.update(j, float(np.hypot(dx, dy)), float(np.arctan2(dy, dx) - track[k, 2]),
                     fw.sigma_range, fw.sigma_bearing)
        mx.append(np.sqrt(f.P[0, 0]))
        my.append(np.sqrt(f.P[1, 1]))
    return np.array(mx), np.array(my), f.P


def test_grid_counts_and_paper_layouts():
    assert [len(grid(b)) for b in (1, 2, 4)] == [4000, 6400, 10000]
    g1, g2 = grid(1), grid(2)
    assert np.any(np.all(g1 == [[650.0, 370.0]], axis=(1, 2)))                 # Table 1, i = 1
    assert np.any(np.all(g2 == [[750.0, 0.0], [150.0, 355.0]], axis=(1, 2)))   # Table 1, i = 2
    for g in (g1, g2, grid(4)):
        assert np.all(np.abs(g[..., 1] - 200.0) >= 5.0)                        # never in the XTD corridor
    g4 = grid(4)
    assert np.all(g4[:, 0, 0] < 500) and np.all(g4[:, 1, 0] >= 500) and np.all(g4[:, 3, 1] > 200)
    with pytest.raises(ValueError):
        grid(3)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("layout", [[[650.0, 370.0]], [[750.0, 0.0], [150.0, 355.0]],
                                    [[200.0, 0.0], [600.0, 100.0], [0.0, 305.0], [900.0, 205.0]]])
def test_batched_equals_dense_reference(layout, backend):
    lay = np.array(layout)
    mx, my, P = dense_reference(lay)
    o = propagate(lay[None], FW, Choices(), keep_state=True, backend=backend)
    np.testing.assert_allclose(o["mx"][0], mx, rtol=1e-7)
    np.testing.assert_allclose(o["my"][0], my, rtol=1e-7)
    np.testing.assert_allclose(o["P"][0][:3, :3], P[:3, :3], rtol=1e-6, atol=1e-12)


def test_batched_result_does_not_depend_on_block_size():
    lay = grid(2)[::800]
    a = propagate(lay, block=512, backend="numpy")
    b = propagate(lay, block=5, backend="numpy")
    np.testing.assert_array_equal(a["mx"], b["mx"])
    c = propagate(lay, ch=Choices(linearize="estimate", seed=3), block=512)
    d = propagate(lay, ch=Choices(linearize="estimate", seed=3), block=7)
    np.testing.assert_array_equal(c["my"], d["my"])


def test_no_beacons_is_dead_reckoning_closed_form():
    # x: random walk of V-noise; theta: random walk of ROT-noise; y = sum V dt theta_j
    o = propagate(np.zeros((1, 0, 2)))
    k = np.arange(1, FW.steps + 1)
    var_x = k * (FW.dt * FW.sigma_v) ** 2
    s2 = (FW.dt * FW.sigma_rot) ** 2
    # theta_j = sum_{i<j} eps_i, y_k = V dt sum_{j<k} theta_j -> Var = (V dt)^2 s2 sum_{j,l<k} min(j, l)
    mins = np.minimum.outer(np.arange(FW.steps), np.arange(FW.steps)).astype(float)
    var_y = np.array([(FW.v * FW.dt) ** 2 * s2 * mins[:n, :n].sum() for n in k])
    np.testing.assert_allclose(o["mx"][0] ** 2, var_x, rtol=1e-12)
    np.testing.assert_allclose(o["my"][0] ** 2, var_y, rtol=1e-10)


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 99), st.integers(0, 19))
def test_mirror_symmetry_about_the_track(i, j):
    # reflecting a beacon across the centre line (y -> 400 - y) cannot change the covariance
    x, y = 10.0 * i, 10.0 * j
    lay = np.array([[[x, y]], [[x, 400.0 - y]]])
    s = score(lay)
    np.testing.assert_allclose(s[0], s[1], rtol=1e-9)


def test_a_beacon_helps_and_position_error_is_bounded_by_dead_reckoning():
    dr = score(np.zeros((1, 0, 2)))[0, 0]
    s = score(grid(1)[::40])
    assert np.all(s[:, 0] < dr)
    assert np.all(np.isclose(s[:, 0] ** 2, s[:, 1] ** 2 + s[:, 2] ** 2) | (s[:, 0] ** 2 >= s[:, 1] ** 2))


def test_summary_picks_the_minimum():
    lay = grid(1)[:5]
    scores = np.array([[3.0, 1, 1], [1.0, 0.5, 0.6], [2.0, 1, 1], [5.0, 2, 2], [4.0, 1, 1]])
    s = summarize_search(lay, scores)
    assert s["best"]["layout"] == lay[1].tolist() and s["best"]["mean_mxy"] == 1.0
    assert s["worst_mean_mxy"] == 5.0 and s["mean_over_configs_mxy"] == pytest.approx(3.0)
    assert set(s) >= {"beacons", "configs", "best", "worst_mean_mxy", "mean_over_configs_mxy"}


def test_choices_are_validated():
    with pytest.raises(ValueError):
        Choices(linearize="sometimes")


def test_isam2_online_marginals_equal_the_ekf_and_smoothing_only_helps():
    # GTSAM (native factors, iSAM2) cross-checks the hand-written batched EKF: on the planned track
    # the filtering marginal of X_k is the EKF covariance after step k
    from graphnav.beacons.layout_graph import passage_marginals, score_chunk_graph

    lay = np.array([[650.0, 370.0], [300.0, 50.0]])
    m = passage_marginals(lay)
    o = propagate(lay[None])
    # (atol: the graph's 1e-6 m cross-track odometry sigma, where eq. 3 has exactly none)
    np.testing.assert_allclose(m["online"][:, 0], o["mx"][0] ** 2, rtol=1e-4, atol=1e-9)
    np.testing.assert_allclose(m["online"][:, 1], o["my"][0] ** 2, rtol=1e-4, atol=1e-9)
    assert np.all(m["smoothed"] <= m["online"] * (1 + 1e-9))
    assert np.allclose(m["smoothed"][-1], m["online"][-1], rtol=1e-6)   # the last pose: nothing to smooth
    r = score_chunk_graph({"layouts": [lay.tolist()], "marginals": "smoothed"})
    assert r["scores"] == r["scores_smoothed"] and r["scores_smoothed"][0][0] < r["scores_online"][0][0]


# ----------------------------------------------------------------------------- compiled kernel


def _numba_kernel():
    pytest.importorskip("numba")
    from graphnav.beacons import _fast as _beacon_fast

    return _beacon_fast


def _close(a, b, rtol=1e-9):
    """Equal to ``rtol`` of the largest entry (the 1e6 m^2 prior's cancellation at the first
    sighting leaves ~1e-10 relative rounding, whatever the order of operations)."""
    np.testing.assert_allclose(a, b, rtol=0, atol=rtol * np.abs(b).max())


@pytest.mark.parametrize("ch", [Choices(), Choices(w_second="theta")], ids=["reference", "w-theta"])
def test_numba_kernel_equals_numpy(ch, monkeypatch):
    """Compiled kernel = numpy path (mx, my every step; final P; x), over blocks of 7 layouts with a
    partial last block, for 0, 1, 2, 4 beacons."""
    fast = _numba_kernel()
    monkeypatch.setattr(fast, "WIDTH", 7)
    for b in (0, 1, 2, 4):
        lay = grid(max(b, 1))[::701][:, :b]
        assert len(lay) % 7 != 0
        a = propagate(lay, FW, ch, keep_state=True, backend="numba")
        n = propagate(lay, FW, ch, keep_state=True, backend="numpy")
        for k in ("mx", "my", "P"):
            _close(a[k], n[k])
        np.testing.assert_array_equal(a["x"], n["x"])
        assert np.array_equal(a["P"], a["P"].transpose(0, 2, 1))   # symmetric by construction


def test_numba_kernel_logic_equals_numpy_uncompiled():
    """The kernel's code run as plain Python (``.py_func``: no compilation) gives the numpy path's
    figures; the compiled run is the test above."""
    fast = _numba_kernel()
    ch = Choices()
    lay = grid(4)[::3001]                                  # 4 layouts in blocks of 3
    ga, gb, rq = motion_terms(FW, ch)
    mx, my, P = fast.propagate_truth.py_func(
        np.ascontiguousarray(lay[:, :, 0]), np.ascontiguousarray(lay[:, :, 1]), FW.track(),
        initial_covariance(4, ch), ga, gb, rq, FW.sigma_range**2, FW.sigma_bearing**2, True, 3)
    n = propagate(lay, FW, ch, keep_state=True, backend="numpy")
    _close(mx, n["mx"])
    _close(my, n["my"])
    _close(P, n["P"])


def test_backend_choice():
    lay = grid(1)[::500]
    est = Choices(linearize="estimate", seed=2)
    assert resolve_backend("numpy") == "numpy" and resolve_backend("auto", est) == "numpy"
    # estimate-linearised: auto is the numpy path, bit for bit; the compiled kernel refuses
    np.testing.assert_array_equal(propagate(lay, ch=est)["mx"], propagate(lay, ch=est, backend="numpy")["mx"])
    with pytest.raises(ValueError):
        propagate(lay, backend="fortran")
    if resolve_backend("auto") == "numba":
        with pytest.raises(ValueError, match="truth"):
            propagate(lay, ch=est, backend="numba")


def test_without_numba_auto_falls_back_to_numpy(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "graphnav.beacons._fast", None)   # import now raises ImportError
    lay = grid(2)[::900]
    assert resolve_backend("auto") == "numpy"
    np.testing.assert_array_equal(propagate(lay)["my"], propagate(lay, backend="numpy")["my"])
    with pytest.raises(ImportError):
        propagate(lay, backend="numba")
