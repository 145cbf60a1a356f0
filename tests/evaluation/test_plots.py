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
