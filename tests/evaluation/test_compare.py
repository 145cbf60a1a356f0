"""`graphnav compare`: one loop over the estimators, the JSON contract, the files, the report."""

from __future__ import annotations

import functools
import json

import numpy as np
import pytest
from _compare_cli import run_compare
from _polyworld import synthetic_log

from graphnav import estimators
from graphnav.cli import main
from graphnav.estimators import EstimatorSpec, RunResult
from graphnav.evaluation import plots
from graphnav.evaluation.comparison import compare, ranked
from graphnav.evaluation.metrics import ate, movement_errors
from graphnav.io import save_log
from graphnav.trajectory import Trajectory


def _boom(log, *, on_estimate=None, **options):
    raise RuntimeError("deliberate failure")


def _fake_smoother(log, *, on_estimate=None, **options):
    """Truth plus a known offset, with covariances; online = a worse copy (as a smoother's)."""
    tr = log.truth()
    n = len(tr)
    cov = np.tile(np.diag([0.04, 0.01, 1e-4]), (n, 1, 1))
    smoothed = Trajectory(tr.t, tr.poses + [0.3, 0.0, 0.0], cov, name="fake-smoother")
    online = Trajectory(tr.t, tr.poses + [0.0, 0.6, 0.0], cov, name="fake-smoother")
    for t, p, c in zip(online.t, online.poses, online.cov, strict=True):
        if on_estimate:
            on_estimate(t, p, c)
    return RunResult(smoothed, online, np.full(n, 0.5), info={"lag": options.get("lag", 5)})


FAKES = {
    "zz-boom": EstimatorSpec(_boom, lambda log: None, "always fails", "filter"),
    "fake-smoother": EstimatorSpec(_fake_smoother, lambda log: None if log.has_truth else "needs truth",
                                   "truth + 0.3 m", "smoother"),
}


FIGURES = ("trajectories.png", "trajectory_panels.png", "position_error.png", "heading_error.png", "error_cdf.png",
           "sog_cog.png", "error_bounds.png", "nees.png", "covariance.png")


@pytest.fixture(scope="module")
def log():
    return synthetic_log(30)


@pytest.fixture
def fakes(monkeypatch):
    for k, v in FAKES.items():
        monkeypatch.setitem(estimators.registry(), k, v)


def test_compare_runs_every_runnable_estimator_once(log, fakes):
    entries = compare(log)
    names = [e.name for e in entries]
    assert names == estimators.names()  # every estimator has a row: run, or skipped saying why
    assert [e.name for e in entries if e.skipped is None] == estimators.runnable(log)
    assert all(e.skipped and e.result is None and e.error is None for e in entries if e.name not in
               estimators.runnable(log))
    assert {"dead-reckoning", "scan-to-map", "fake-smoother", "zz-boom"} <= set(names)
    by = {e.name: e for e in entries}
    assert not by["zz-boom"].ok and "deliberate failure" in by["zz-boom"].error
    assert by["zz-boom"].summary is None
    for n in ("dead-reckoning", "scan-to-map", "fake-smoother"):
        e = by[n]
        assert e.ok and e.summary["ate_rmse_m"] >= 0 and e.runtime_s > 0
    assert by["fake-smoother"].summary["ate_rmse_m"] == pytest.approx(0.3)
    assert by["fake-smoother"].summary["online_ate_rmse_m"] == pytest.approx(0.6)
    order = ranked(entries)
    ates = [e.summary["ate_rmse_m"] for e in order if e.ok]
    assert ates == sorted(ates)
    assert [e.name for e in order if not e.ok][0] == "zz-boom" and order[-1].skipped  # failures, then skipped


def test_compare_reports_unknown_and_unrunnable_names(log):
    entries = compare(log.without(lambda r: r.kind == "scan"), ["nope", "scan-to-map", "dead-reckoning"],
                      options={"dead-reckoning": {}})
    by = {e.name: e for e in entries}
    assert "unknown estimator" in by["nope"].error
    assert "needs at least two scans" in by["scan-to-map"].skipped and by["scan-to-map"].error is None
    assert not by["scan-to-map"].ok
    assert by["dead-reckoning"].ok


def test_compare_passes_options(log):
    (e,) = compare(log, ["scan-to-map"], options={"scan-to-map": {"backend": "gicp"}})
    assert e.ok and e.result.info["config"]["backend"] == "small_gicp:GICP"


def test_plot_errors_are_the_report_errors(log):
    """The plotted series are the same pairs and errors as the table's numbers."""
    est = estimators.run("dead-reckoning", log).trajectory
    ref = log.truth()
    _, e = plots.position_errors(est, ref)
    a = ate(est, ref)
    assert np.sqrt(np.mean(e**2)) == pytest.approx(a["rmse"]) and e.max() == pytest.approx(a["max"])
    s = plots.movement_error_series(est, ref, dt=plots.MOVEMENT_DT_S)  # what sog_cog.png draws
    m = movement_errors(est, ref, dt=plots.MOVEMENT_DT_S)  # what the table's SOG/COG RMSE say
    assert np.sqrt(np.nanmean(s["sog"] ** 2)) == pytest.approx(m["sog"]["rmse"])
    assert np.sqrt(np.mean(s["cog"] ** 2)) == pytest.approx(m["cog"]["rmse"])


@pytest.fixture(scope="module")
def cli_run(log, tmp_path_factory):
    # explicit names keep this test's cost independent of how many estimators exist;
    # discovery is covered by test_compare_runs_every_runnable_estimator_once
    return run_compare(log, tmp_path_factory.mktemp("cmp"), FAKES,
                       ["-O", "fake-smoother.lag=7", "-e", "dead-reckoning,scan-to-map,fake-smoother,zz-boom"])


def test_cli_json_is_one_object_with_the_issue_keys(cli_run):
    rc, stdout, out, path = cli_run
    assert rc == 0
    obj = json.loads(stdout)  # the whole stdout is one JSON object
    assert stdout.strip().count("\n") == 0
    assert obj["log"] == str(path)
    assert obj["icp_cache_hits"] == 0  # none of these estimators uses the weighted ICP
    est = obj["estimators"]
    assert {"dead-reckoning", "scan-to-map", "fake-smoother", "zz-boom"} <= set(est)
    for name, d in est.items():
        for k in ("ate_rmse_m", "rpe_rmse_m", "runtime_s", "step_ms_median"):
            assert k in d, (name, k)
    assert "deliberate failure" in est["zz-boom"]["error"] and est["zz-boom"]["ate_rmse_m"] is None
    assert est["fake-smoother"]["ate_rmse_m"] == pytest.approx(0.3)
    # error (0.3, 0) m against cov diag(0.04, 0.01): NEES 0.09/0.04; online (0, 0.6): 0.36/0.01
    assert est["fake-smoother"]["nees_mean"] == pytest.approx(2.25)
    assert est["fake-smoother"]["online_nees_mean"] == pytest.approx(36.0)
    assert est["fake-smoother"]["heading_rmse_deg"] == pytest.approx(0.0, abs=1e-9)
    assert "nees_mean" in est["scan-to-map"] and est["scan-to-map"]["nees_mean"] is None  # no covariance
    assert est["fake-smoother"]["options"] == {"lag": 7}
    assert est["scan-to-map"]["ate_rmse_m"] < 0.1
    assert obj["dropped"] == []


def test_cli_json_has_errors_by_event_and_inputs(cli_run):
    """Per estimator: the errors inside the log's GNSS outage and jump (the fake smoother: 0.3 m
    smoothed, 0.6 m online everywhere), and the record kinds it used."""
    _, stdout, out, _ = cli_run
    est = json.loads(stdout)["estimators"]
    ev = est["fake-smoother"]["errors_by_event"]
    assert set(ev) == {"gnss_outage", "gnss_jump"}
    for d in ev.values():
        assert d["n"] > 0 and d["rmse_m"] == pytest.approx(0.3) and d["max_m"] == pytest.approx(0.3)
        assert d["online_rmse_m"] == pytest.approx(0.6) and d["online_max_m"] == pytest.approx(0.6)
    dr = est["dead-reckoning"]["errors_by_event"]["gnss_outage"]
    assert dr["n"] > 0 and dr["online_rmse_m"] == dr["rmse_m"] > 0  # one trajectory: online is the same
    assert est["dead-reckoning"]["inputs"] == ["odometry", "pose_prior"]
    assert est["scan-to-map"]["inputs"] == ["scan", "odometry", "pose_prior"]
    assert est["fake-smoother"]["inputs"] is None  # (a fake: declares none)
    assert "errors_by_event" not in est["zz-boom"]
    report = (out / "report.md").read_text()
    assert "Inputs (record kinds it used): scan, odometry, pose_prior." in report
    row = next(ln for ln in report.splitlines() if ln.startswith("| fake-smoother |"))
    head = next(ln for ln in report.splitlines() if ln.startswith("| estimator | gnss_outage RMSE [m]"))
    assert [c.strip() for c in head.split("|")[2:5]] == ["gnss_outage RMSE [m]", "gnss_outage max [m]",
                                                          "gnss_outage online RMSE [m]"]
    assert [c.strip() for c in row.split("|")[2:5]] == ["0.300", "0.300", "0.600"]


def test_cli_writes_report_figures_and_tum(cli_run):
    from evo.tools import file_interface

    _, stdout, out, _ = cli_run
    est = json.loads(stdout)["estimators"]
    for f in FIGURES + ("report.md",):
        assert (out / f).stat().st_size > 0, f
    ok = [n for n, d in est.items() if "error" not in d]
    for n in ok:
        tum = file_interface.read_tum_trajectory_file(str(out / f"{n}.tum"))
        assert tum.num_poses > 2
    assert (out / "fake-smoother.online.tum").exists()
    assert not (out / "zz-boom.tum").exists()
    report = (out / "report.md").read_text()
    for n in est:
        assert n in report
    assert "deliberate failure" in report
    assert "online ATE RMSE" in report
    assert '"lag": 7' in report  # configuration section
    for f in FIGURES:
        assert f"]({f})" in report


def test_cli_rejects_a_malformed_option(log, tmp_path):
    path = tmp_path / "l.jsonl"
    save_log(log, path)
    assert main(["compare", str(path), "--out", str(tmp_path / "o"), "-O", "backend=gicp"]) == 2


def test_event_shading_has_one_legend_entry_per_kind():
    from matplotlib.figure import Figure

    ax = Figure().add_subplot()
    ev = [("gnss_outage", 1, 2), ("gnss_outage", 5, 6), ("gnss_jump", 3, 4), ("other", 7, 8)]
    h = plots._shade_events(ax, [{"kind": k, "t0": a, "t1": b} for k, a, b in ev])
    assert [p.get_label() for p in h] == ["GNSS outage", "GNSS jump", "other"]
    assert len(ax.patches) == 4


def test_one_estimator_twice_under_labels(log):
    entries = compare(log, ["scan-to-map", "s2m-gicp=scan-to-map", "s2m-gicp=dead-reckoning"],
                      options={"s2m-gicp": {"backend": "gicp"}})
    a, b, c = entries
    assert (a.name, b.name) == ("scan-to-map", "s2m-gicp") and a.ok and b.ok
    assert a.result.info["config"]["backend"] == "small_gicp:VGICP"
    assert b.result.info["config"]["backend"] == "small_gicp:GICP"
    assert b.summary["estimator"] == "s2m-gicp" and "scan-to-map" in b.description
    assert not c.ok and "given twice" in c.error


def test_a_whole_log_condition_is_not_shaded_but_gnss_events_are():
    from matplotlib.figure import Figure

    ax = Figure().add_subplot()
    ev = [("compass_bias", 0, 100), ("gnss_outage", 0, 100), ("noise_increase", 50, 60)]
    h = plots._shade_events(ax, [{"kind": k, "t0": a, "t1": b} for k, a, b in ev], span=(0.0, 100.0))
    assert [p.get_label() for p in h] == ["GNSS outage", "noise_increase"]


def test_parallel_workers_give_the_same_table(log, fakes):
    names = ["dead-reckoning", "fake-smoother", "zz-boom"]
    seq = compare(log, names)
    par = compare(log, names, workers=2)
    assert [e.name for e in par] == names
    for a, b in zip(seq, par, strict=True):
        assert a.ok == b.ok
        if a.ok:
            assert b.summary["ate_rmse_m"] == pytest.approx(a.summary["ate_rmse_m"])
            assert np.allclose(a.result.trajectory.poses, b.result.trajectory.poses)
    assert "deliberate failure" in par[2].error


def test_meanwhile_runs_once_while_the_workers_run(log, fakes):
    """``meanwhile`` (compare's idle parent importing the figures' modules) runs once per comparison, before
    any result is collected; with one process, before the first estimator."""
    names = ["dead-reckoning", "fake-smoother"]
    for workers in (1, 2):
        calls: list[str] = []
        compare(log, names, workers=workers, progress=calls.append,
                meanwhile=functools.partial(calls.append, "meanwhile"))
        assert calls.count("meanwhile") == 1 and set(calls) == {"meanwhile", *names}
        assert calls.index("meanwhile") <= (1 if workers > 1 else 0)


def test_dcog_error_ignores_a_constant_course_offset(log):
    """A track rotated as a whole has a constant COG error and no ΔCOG error (the weighted-ICP
    paper's increment differences, Figs. 14-15)."""
    from graphnav.geometry import se2_compose

    ref = log.truth()
    rotated = Trajectory(ref.t, se2_compose(np.array([0.0, 0.0, 0.05]), ref.poses))
    s = plots.movement_error_series(rotated, ref)
    assert np.allclose(s["cog"], np.degrees(0.05))
    assert np.allclose(s["dcog"], 0.0, atol=1e-9) and len(s["dcog"]) == len(s["cog"]) - 1
    assert np.allclose(s["sog"], 0.0, atol=1e-9)


def test_report_configuration_summarises_long_arrays():
    from graphnav.evaluation.comparison import Entry
    from graphnav.evaluation.report import _config

    res = RunResult(Trajectory([0.0], [[0.0, 0.0, 0.0]]), info={"k": 3, "nested": {"a": np.arange(500)},
                                                                "short": [1, 2]})
    cfg = _config(Entry("x", options={"lag": 2}, result=res))
    assert cfg == {"options": {"lag": 2}, "k": 3, "nested": {"a": "<500 values>"}, "short": [1, 2]}


def test_parallel_smoothers_share_their_matches_in_one_process():
    """With workers the smoothers form one work unit (one process, in order), so the second one
    still takes every weighted-ICP match from the first; the table equals the sequential one."""
    from _polyworld import synthetic_log

    from graphnav.evaluation.comparison import groups
    from graphnav.scan import icp_cache

    log = synthetic_log(12)
    assert groups([(0, "batch"), (1, "ekf"), (2, "isam2"), (3, "ukf")]) == [
        [(0, "batch"), (2, "isam2")], [(1, "ekf")], [(3, "ukf")]]
    # heaviest first: the shared unit, scan-to-map, fixed-lag (its own matches: never isam2's), icp-dr, the filters
    assert groups([(0, "ekf"), (1, "icp-dr"), (2, "fixed-lag"), (3, "isam2"), (4, "ukf"), (5, "scan-to-map"),
                   (6, "batch")]) == [[(3, "isam2"), (6, "batch")], [(5, "scan-to-map")], [(2, "fixed-lag")],
                                      [(1, "icp-dr")], [(0, "ekf")], [(4, "ukf")]]
    names = ["batch", "dead-reckoning", "isam2"]
    seq = compare(log, names, cache=icp_cache.MatchCache())
    par = compare(log, names, cache=icp_cache.MatchCache(), workers=2)
    n_pairs = len(log.of("scan")) - 1
    for a, b in zip(seq, par, strict=True):
        assert a.ok and b.ok
        np.testing.assert_array_equal(a.result.trajectory.poses, b.result.trajectory.poses)
    assert [e.summary.get("icp_cache_hits") for e in par] == [0, 0, n_pairs]
