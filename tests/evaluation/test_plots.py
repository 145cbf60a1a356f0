"""The plotting module for notebooks: no backend change on import, Figures returned, given axes used."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

from graphnav.evaluation import plots
from graphnav.trajectory import Trajectory

REPO = Path(__file__).resolve().parents[2]


def test_importing_graphnav_plots_keeps_the_backend_and_pyplot_unloaded(tmp_path):
    code = (
        "import sys, matplotlib\n"
        "import graphnav, graphnav.evaluation.plots as p, graphnav.evaluation.report, graphnav.commands.compare\n"
        "from matplotlib.figure import Figure\n"
        "f = Figure(); f.add_subplot().plot([0, 1]); p.save(f, sys.argv[1])\n"
        "print(matplotlib.get_backend(), 'matplotlib.pyplot' in sys.modules)\n"
    )
    env = {**os.environ, "MPLBACKEND": "svg", "PYTHONPATH": str(REPO)}
    r = subprocess.run([sys.executable, "-c", code, str(tmp_path / "f.png")], capture_output=True, text=True,
                       env=env, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["svg", "False"]  # not switched to Agg; no pyplot state
    assert (tmp_path / "f.png").read_bytes()[:4] == b"\x89PNG"


def _truth(n: int = 300) -> Trajectory:
    t = np.arange(n) * 0.5
    return Trajectory(t, np.column_stack([100 * np.cos(t / 40), 60 * np.sin(t / 40), t / 40 + np.pi / 2]),
                      name="truth")


def _est(truth: Trajectory, sigma: np.ndarray, seed: int, name: str) -> Trajectory:
    """Truth plus errors drawn from diag(sigma^2) (per pose: sigma (N, 3))."""
    rng = np.random.default_rng(seed)
    cov = np.zeros((len(truth), 3, 3))
    for k in range(3):
        cov[:, k, k] = sigma[:, k] ** 2
    return Trajectory(truth.t, truth.poses + rng.standard_normal((len(truth), 3)) * sigma, cov, name=name)


@pytest.fixture(scope="module")
def trajs():
    truth = _truth()
    n = len(truth)
    small = np.tile([0.05, 0.05, 0.002], (n, 1))
    growing = np.column_stack([np.linspace(0.1, 500, n), np.linspace(0.1, 500, n), np.full(n, 0.05)])
    return truth, {"smoother": _est(truth, small, 0, "smoother"), "odometry": _est(truth, growing, 1, "odometry"),
                   "nocov": Trajectory(truth.t, truth.poses + [0.5, 0.0, 0.0], name="nocov")}


ONE_AXES = [
    ("plot_trajectories", lambda tr, tj, ax: plots.plot_trajectories(tj, tr, ax=ax)),
    ("plot_position_error", lambda tr, tj, ax: plots.plot_position_error(tj, tr, ax=ax)),
    ("plot_heading_error", lambda tr, tj, ax: plots.plot_heading_error(tj, tr, ax=ax)),
    ("plot_error_cdf", lambda tr, tj, ax: plots.plot_error_cdf(tj, tr, ax=ax)),
    ("plot_nees", lambda tr, tj, ax: plots.plot_nees(tj, tr, ax=ax)),
    ("trajectory_panel", lambda tr, tj, ax: plots.trajectory_panel(ax, "smoother", tj["smoother"], tr)),
    ("trajectory_panel+zoom", lambda tr, tj, ax: plots.trajectory_panel(ax, "smoother", tj["smoother"], tr,
                                                                        zoom_ax=ax.figure.add_subplot(2, 2, 4))),
    ("nees_panel", lambda tr, tj, ax: plots.nees_panel(ax, "smoother", tj["smoother"], tr)),
    ("covariance_panel", lambda tr, tj, ax: plots.covariance_panel(ax, "odometry", tj["odometry"], tr)),
]
MULTI = [
    ("plot_trajectory_panels", lambda tr, tj, fig: plots.plot_trajectory_panels(tj, tr, fig=fig)),
    ("plot_sog_cog", lambda tr, tj, fig: plots.plot_sog_cog(tj, tr, fig=fig)),
    ("plot_error_bounds", lambda tr, tj, fig: plots.plot_error_bounds(tj, tr, fig=fig)),
    ("plot_nees", lambda tr, tj, fig: plots.plot_nees(tj, tr, fig=fig)),
    ("plot_covariance", lambda tr, tj, fig: plots.plot_covariance(tj, tr, fig=fig)),
]


@pytest.mark.parametrize("name,draw", ONE_AXES, ids=[n for n, _ in ONE_AXES])
def test_one_axes_plots_draw_into_the_given_axes(trajs, name, draw):
    truth, tj = trajs
    fig = Figure()
    ax = fig.add_subplot()
    got = draw(truth, tj, ax)
    assert got is fig
    assert fig.axes[0] is ax and (ax.lines or ax.collections or ax.patches)


@pytest.mark.parametrize("name,draw", MULTI, ids=[n for n, _ in MULTI])
def test_multi_panel_plots_draw_into_the_given_figure(trajs, name, draw):
    truth, tj = trajs
    fig = Figure()
    assert draw(truth, tj, fig) is fig
    assert len(fig.axes) >= 2 and all(isinstance(a.figure, Figure) for a in fig.axes)


@pytest.mark.parametrize("name,draw", ONE_AXES[:5] + MULTI, ids=[n for n, _ in ONE_AXES[:5] + MULTI])
def test_without_axes_each_plot_returns_a_new_figure_that_saves(trajs, name, draw, tmp_path):
    truth, tj = trajs
    fig = draw(truth, tj, None)
    assert isinstance(fig, Figure)
    p = plots.save(fig, tmp_path / "f.svg")
    assert p.stat().st_size > 1000


def test_plots_needing_covariance_skip_or_refuse_without_it(trajs):
    truth, tj = trajs
    nocov = {"nocov": tj["nocov"]}
    assert plots.plot_error_bounds(nocov, truth) is None and plots.plot_nees(nocov, truth) is None
    assert plots.plot_covariance(nocov, truth) is None
    with pytest.raises(ValueError, match="no covariance"):
        plots.nees_panel(Figure().add_subplot(), "nocov", tj["nocov"], truth)


def test_covariance_panels_have_their_own_scale(trajs):
    """A growing odometry covariance (up to 500 m) no longer sets the other panels' magnification,
    and is drawn at true scale inside its own track's view instead of blowing the axes up."""
    truth, tj = trajs
    # an odometry track close to the truth whose covariance grows to 500 m (icp-dr's on the harbour)
    wide = Trajectory(truth.t, tj["smoother"].poses, tj["odometry"].cov)
    fig = plots.plot_covariance({"smoother": tj["smoother"], "odometry": wide}, truth)
    a_s, a_o = fig.axes[:2]
    assert "magnified" in a_s.get_title() and "true scale" in a_o.get_title()
    extent = max(np.ptp(truth.x), np.ptp(truth.y))
    for ax in (a_s, a_o):
        fig.canvas.draw()  # the final limits (aspect adjustment)
        assert np.ptp(ax.get_xlim()) < 2.5 * extent and np.ptp(ax.get_ylim()) < 2.5 * extent
    assert plots.ellipse_magnification(tj["smoother"], extent) > 1
    assert plots.ellipse_magnification(wide, extent) == 1


def test_error_bounds_state_the_fraction_inside_three_sigma(trajs):
    truth, tj = trajs
    fig = plots.plot_error_bounds({"smoother": tj["smoother"]}, truth)
    titles = [a.get_title() for a in fig.axes]
    assert [t.split(":")[1].split(" error")[0].strip() for t in titles] == ["x", "y", "yaw"]
    fracs = [float(t.split(",")[1].split("%")[0]) for t in titles]
    assert all(f >= 98.0 for f in fracs)  # errors drawn from the covariance: 99.7 % expected, n = 300


def test_loop_closures_are_drawn_between_the_estimate_poses_at_their_times():
    t = np.arange(0.0, 10.0, 0.5)
    est = Trajectory(t, np.column_stack([np.cos(t), np.sin(t), t]), name="isam2")
    edges = [[0.5, 7.0], [1.0, 9.5], [2.0, 99.0]]  # the last is outside the track: left out
    segs = plots.loop_segments(est, edges)
    assert segs.shape == (2, 2, 2)
    np.testing.assert_allclose(segs[0], [[np.cos(0.5), np.sin(0.5)], [np.cos(7.0), np.sin(7.0)]])
    np.testing.assert_allclose(segs[1, 1], [np.cos(9.5), np.sin(9.5)])
    fig = plots.plot_trajectory_panels({"isam2": est}, est, loops={"isam2": edges})
    labels = [c.get_label() for ax in fig.axes for c in ax.collections]
    assert "loop closures (2)" in labels
    fig = plots.plot_trajectory_panels({"isam2": est}, est)
    assert not any(str(c.get_label()).startswith("loop closures") for ax in fig.axes for c in ax.collections)


def test_thin_minmax_keeps_every_column_extreme_and_the_gaps():
    rng = np.random.default_rng(3)
    x = np.linspace(0.0, 100.0, 20001)
    y = rng.standard_normal(len(x))
    y[5000] = 50.0  # one spike up, one down, and a gap
    y[12000] = -40.0
    y[8000:8100] = np.nan
    tx, ty = plots.thin_minmax(x, y, 200)
    assert len(tx) < 0.1 * len(x) and np.all(np.diff(tx) >= 0)
    assert np.nanmax(ty) == 50.0 and np.nanmin(ty) == -40.0
    assert tx[0] == x[0] and tx[-1] == x[-1] and np.isnan(ty).any()
    # each column's min and max among the kept samples (a column is 0.5 wide)
    col = np.minimum((x / 0.5).astype(int), 199)
    tcol = np.minimum((tx / 0.5).astype(int), 199)
    for c in (0, 37, 99, 160, 199):
        np.testing.assert_equal(np.nanmax(ty[tcol == c]), np.nanmax(y[col == c]))
        np.testing.assert_equal(np.nanmin(ty[tcol == c]), np.nanmin(y[col == c]))
    # few samples per column, or not sorted: untouched
    assert len(plots.thin_minmax(x[:500], y[:500], 200)[0]) == 500
    assert len(plots.thin_minmax(x[::-1], y, 200)[0]) == len(x)


def test_thin_track_keeps_the_peak_value_and_the_ends():
    t = np.linspace(0.0, 2 * np.pi, 5001)
    x, y = 100 * np.cos(t), 100 * np.sin(t)
    v = np.zeros(len(t) - 1)
    v[1234] = 7.0
    segs, sv = plots.thin_track(x, y, v, cell=1.0)
    assert len(segs) < 0.2 * len(v) and sv.max() == 7.0
    np.testing.assert_allclose(segs[0, 0], [x[0], y[0]])
    np.testing.assert_allclose(segs[-1, 1], [x[-1], y[-1]])
    np.testing.assert_allclose(segs[1:, 0], segs[:-1, 1])  # still one connected track
    segs0, sv0 = plots.thin_track(x, y, v, cell=0.0)
    assert len(segs0) == len(v) and np.array_equal(sv0, v)
    tx, ty = plots.thin_xy(x, y, 1.0)
    assert len(tx) == len(segs) + 1 and np.max(np.hypot(np.diff(tx), np.diff(ty))) < 3.0


def test_in_window_keeps_the_segments_crossing_it_and_breaks_between_runs():
    x = np.array([-10.0, -5.0, 0.5, 5.0, 10.0, 20.0, 0.2, 30.0])
    y = np.array([0.0, 0.0, 0.5, 0.0, -5.0, 20.0, 0.0, 0.0])
    wx, wy = plots._in_window(x, y, -1.0, 1.0, -1.0, 1.0)
    # (-5,0)-(0.5,0.5)-(5,0) meets it; (20,20)-(0.2,0)-(30,0) too; (5,0)-(10,-5) and (10,-5)-(20,20) do not
    assert np.isnan(wx).sum() == 1
    np.testing.assert_array_equal(wx[~np.isnan(wx)], [-5.0, 0.5, 5.0, 20.0, 0.2, 30.0])
    # a segment crossing the window with both ends outside is kept
    wx, _ = plots._in_window(np.array([-5.0, 5.0, 9.0]), np.zeros(3), -1.0, 1.0, -1.0, 1.0)
    np.testing.assert_array_equal(wx, [-5.0, 5.0])


def test_sog_cog_small_multiples_share_one_time_axis_and_keep_the_rms(trajs):
    truth, tj = trajs
    fig = plots.plot_sog_cog(tj, truth)
    axes = np.array(fig.axes).reshape(len(tj), 3)
    assert len({a.get_xlim() for a in fig.axes}) == 1
    for j in range(3):
        assert len({a.get_ylim() for a in axes[:, j]}) == 1
    assert not any(lab.get_visible() for a in axes[:-1].ravel() for lab in a.get_xticklabels())
    series = plots.movement_error_series(tj["smoother"], truth, dt=plots.MOVEMENT_DT_S)
    rms = float(np.sqrt(np.nanmean(series["sog"] ** 2)))
    assert axes[0, 0].get_title(loc="left") == f"smoother: SOG RMS {rms:.3f} m/s"


def test_the_report_and_the_imu_gate_take_scipy_stats_quantiles_without_importing_it():
    """The NEES band and the IMU-consistency gate are scipy.stats' chi-square quantiles to the bit, without
    its ~0.9 s import (in the report's process and in scan-to-map's)."""
    code = (
        "import sys\n"
        "import graphnav.evaluation.plots as p, graphnav.evaluation.report.assemble\n"
        "import graphnav.estimators.icp_odometry\n"
        "from graphnav.graph.chi2 import chi2_ppf\n"
        "gate = [chi2_ppf(q, d) for q in (0.99, 0.999) for d in (2, 3)]\n"
        "loaded = 'scipy.stats' in sys.modules\n"
        "from scipy.stats import chi2\n"
        "print(loaded, p.NEES_BAND == tuple(float(v) for v in chi2.ppf([0.025, 0.975], 2)),\n"
        "      gate == [float(chi2.ppf(q, d)) for q in (0.99, 0.999) for d in (2, 3)])\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(REPO)}, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["False", "True", "True"]
