"""Scoring without truth: the GNSS hold-out (windows, withheld fixes, end errors with known answers),
GNSS residuals that never look into a gap, the data checks, and the no-truth report on a slice of a
real sailing log (anemomind psaros33, read from ../shared/data; skipped when absent)."""

from __future__ import annotations

import contextlib
import gzip
import io
import json
from pathlib import Path

import numpy as np
import pytest

from graphnav.cli import main
from graphnav.evaluation.comparison import compare
from graphnav.evaluation.datacheck import gnss_jumps
from graphnav.evaluation.holdout import HoldoutSpec, withhold
from graphnav.evaluation.metrics import gnss_residuals
from graphnav.log import Gnss, GnssVelocity, Heading, NavLog, WaterSpeed
from graphnav.trajectory import Trajectory

REPO = Path(__file__).resolve().parents[2]
PSAROS = next((p for p in (r / "shared" / "data" / "marine" / "anemomind" / "psaros33-20140627-0006.nmea.gz"
                           for r in (REPO.parent, REPO.parent.parent)) if p.exists()),  # (a worktree: one up)
              REPO.parent / "shared" / "data" / "marine" / "anemomind" / "psaros33-20140627-0006.nmea.gz")


def test_holdout_spec_parses_and_refuses():
    assert HoldoutSpec.parse("300,60") == HoldoutSpec(300.0, 60.0)
    assert HoldoutSpec(300, 60).windows(0.0, 1000.0) == [(240.0, 300.0), (540.0, 600.0), (840.0, 900.0)]
    for bad in ("300", "60,300", "300,0", "a,b", "300,60,1", "nan,1"):
        with pytest.raises(ValueError, match="--holdout-gnss"):
            HoldoutSpec.parse(bad)


def _straight(n: int = 400, v: float = 2.0, sigma: float = 1.0) -> NavLog:
    """Due east at ``v`` m/s: a fix, a GNSS velocity, a heading and a speed through water every second."""
    recs = []
    for k in range(n):
        t = float(k)
        recs += [Gnss(t, v * t, 0.0, sigma), GnssVelocity(t, v, 0.0, 0.1), Heading(t, 0.0, 0.01),
                 WaterSpeed(t, v, 0.05)]
    return NavLog(recs)


def test_withheld_fixes_are_those_in_the_windows_and_an_offset_is_scored_exactly():
    log = _straight()
    plan = withhold(log, HoldoutSpec(100, 20))
    assert plan.windows == [(80.0, 100.0), (180.0, 200.0), (280.0, 300.0)]
    assert plan.withheld == {"gnss": 60, "gnss_velocity": 60}
    assert not any(80 <= r.t < 100 for r in plan.log.of("gnss")) and len(plan.log.of("gnss")) == 340
    assert list(plan.fixes["t"][plan.ends]) == [99.0, 199.0, 299.0]
    truth = Trajectory(np.arange(400.0), np.column_stack([2.0 * np.arange(400.0), np.zeros(400), np.zeros(400)]))
    assert plan.score(truth)["rmse_m"] == pytest.approx(0.0, abs=1e-12)
    off = Trajectory(truth.t, truth.poses + [3.0, 4.0, 0.0], np.tile(np.diag([9.0, 16.0, 1.0]), (400, 1, 1)))
    s = plan.score(off)
    assert s["end_errors_m"] == pytest.approx([5.0, 5.0, 5.0]) and s["rmse_m"] == pytest.approx(5.0)
    assert s["nis_mean"] == pytest.approx(9 / 10 + 16 / 17)  # e^T (P + sigma^2 I)^-1 e, sigma = 1
    assert plan.describe()["fix_sigma_m"] == 1.0


def test_a_window_with_no_other_record_is_marked_silent_and_left_out_of_the_informative_rmse():
    """The compass and speed log silent over the second window (GNSS only was logged then): no estimate
    inside it, so an estimator's end error there is the distance sailed (the last estimate before holds);
    the plan marks that window, and ``rmse_informative_m`` is the other windows' RMSE."""
    log = NavLog([r for r in _straight().records if isinstance(r, Gnss | GnssVelocity) or not 170 <= r.t < 210])
    plan = withhold(log, HoldoutSpec(100, 20))
    assert plan.silent == [False, True, False] and plan.describe()["silent_windows"] == 1
    t = np.array([k for k in range(400) if not 180 <= k < 200], dtype=float)  # an estimate on every record
    est = Trajectory(t, np.column_stack([2.0 * t + 1.0, np.zeros(t.size), np.zeros(t.size)]))
    s = plan.score(est)
    assert s["end_errors_m"] == pytest.approx([1.0, 2.0 * 20 - 1.0, 1.0])  # 199 s scored by the estimate at 179 s
    assert s["rmse_informative_m"] == pytest.approx(1.0)
    assert s["rmse_m"] == pytest.approx(np.sqrt((1 + 39**2 + 1) / 3))
    # a smoother's online track, read the same way: both figures under the online_ names
    assert plan.score_online(est) == pytest.approx({"online_rmse_m": s["rmse_m"], "online_rmse_informative_m": 1.0})
    assert withhold(_straight(), HoldoutSpec(100, 20)).silent == [False, False, False]


def test_a_smoothed_track_is_read_across_its_hole_in_a_silent_window():
    """A smoother's track has no pose inside a silent window either, but its poses on either side are
    tied by the motion factor across it: ``smoothed`` reads it between them (known answers), never a
    still boat; the online (causal) reading keeps the last estimate before."""
    log = NavLog([r for r in _straight().records if isinstance(r, Gnss | GnssVelocity) or not 170 <= r.t < 210])
    plan = withhold(log, HoldoutSpec(100, 20))
    t = np.array([k for k in range(400) if not 180 <= k < 200], dtype=float)
    x = 2.0 * t + np.where(t < 180, 1.0, 3.0)  # 1 m ahead before the hole, 3 m after
    cov = np.tile(np.diag([1.0, 1.0, 0.01]), (t.size, 1, 1))
    cov[t >= 200] = np.diag([4.0, 4.0, 0.01])
    est = Trajectory(t, np.column_stack([x, np.zeros(t.size), np.zeros(t.size)]), cov)
    s = plan.score(est, smoothed=True)
    # 199 s between 179 s (359 m) and 200 s (403 m): 359 + 44 x 20/21 = 400.90 m against the fix's 398 m
    assert s["end_errors_m"] == pytest.approx([1.0, 359.0 + 44.0 * 20 / 21 - 398.0, 3.0])
    assert plan.score(est)["end_errors_m"][1] == pytest.approx(398.0 - 359.0)  # causal: the estimate at 179 s
    r = gnss_residuals(est, np.array([181.0, 199.0]), np.array([[363.0, 0.0], [401.0, 0.0]]), np.ones(2),
                       bridge=True)
    e = np.array([363.0 - (359.0 + 44.0 * 2 / 21), 401.0 - (359.0 + 44.0 * 20 / 21)])
    assert r["residual_m"] == pytest.approx(np.abs(e))
    assert r["nis"] == pytest.approx([e[0] ** 2 / 2.0, e[1] ** 2 / 5.0])  # the nearer pose's covariance + sigma^2


def test_residuals_never_interpolate_across_a_gap_in_the_estimate():
    """An estimate made after a gap is not used for a time inside it: the last one before holds."""
    est = Trajectory(np.array([0.0, 1.0, 60.0]), np.array([[0.0, 0, 0], [1.0, 0, 0], [100.0, 0, 0]]))
    r = gnss_residuals(est, np.array([0.5, 59.0, 61.0, 80.0]), np.array([[0.5, 0], [90.0, 0], [100, 0], [0, 0]]),
                       np.ones(4))
    assert list(r["i_fix"]) == [0, 1, 2]  # 80 s is beyond the estimate's end (more than 10 s)
    assert r["residual_m"] == pytest.approx([0.0, 89.0, 0.0]) and r["nis"] is None


def test_heading_and_water_speed_dead_reckoning_coasts_through_the_windows():
    """With the current zero, the compass and the speed log are exact: the hold-out error is 0, and
    without GNSS resets it is the start fix's error carried along."""
    log = _straight(300)
    comp = compare(log, ["water-dr", "from-start=water-dr"], options={"from-start": {"gnss_reset": False}},
                   holdout=HoldoutSpec(100, 30))
    by = {e.name: e for e in comp}
    assert by["water-dr"].summary["holdout"]["rmse_m"] == pytest.approx(0.0, abs=1e-9)
    assert by["water-dr"].summary["inputs"] == ["gnss", "heading", "water_speed"]
    assert comp.holdout_ranking()[0] in ("water-dr", "from-start")
    assert comp.same_tracks() == {"from-start": ("water-dr", pytest.approx(0.0, abs=1e-9))}


def test_gnss_jumps_are_found_and_listed_by_info(tmp_path):
    from graphnav.io import save_log

    log = _straight(100)
    recs = [Gnss(r.t, r.x + (80.0 if 50 <= r.t < 60 else 0.0), r.y, r.sigma) if r.kind == "gnss" else r
            for r in log.records]
    j = gnss_jumps(NavLog(recs))
    assert j["count"] == 2 and [(d["t0"], d["t1"]) for d in j["largest"]] == [(49.0, 50.0), (59.0, 60.0)]
    assert gnss_jumps(log)["count"] == 0
    save_log(NavLog(recs), tmp_path / "j.jsonl")
    rc, obj = _cli("info", str(tmp_path / "j.jsonl"))
    assert rc == 0 and obj["gnss_jumps"]["count"] == 2 and obj["gnss_jumps"]["largest"][0]["distance_m"] == 82.0


@pytest.fixture(scope="module")
def psaros_slice(tmp_path_factory) -> Path:
    """10 minutes of the psaros33 log under way (lines 43609-49000: RMC/GLL/HDG/VHW), as a plain NMEA file."""
    if not PSAROS.exists():
        pytest.skip(f"the anemomind logs are not at {PSAROS}")
    with gzip.open(PSAROS, "rt", encoding="ascii", errors="replace") as fh:
        lines = fh.readlines()[43608:49000]
    p = tmp_path_factory.mktemp("psaros") / "psaros-slice.nmea"
    p.write_text("".join(lines))
    return p


def _cli(*argv: str) -> tuple[int, dict]:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main([*argv, "--json"])
    return rc, json.loads(buf.getvalue())


def test_compare_holdout_on_a_real_log_ranks_and_reports(psaros_slice, tmp_path):
    out = tmp_path / "o"
    rc, obj = _cli("compare", str(psaros_slice), "-e", "water-dr,from-start=water-dr", "-O",
                   "from-start.gnss_reset=false", "--holdout-gnss", "200,40", "--out", str(out), "-j", "1")
    assert rc == 0
    h = obj["holdout"]
    assert h["every_s"] == 200 and h["scored_windows"] == 3 and h["withheld"]["gnss"] > 90
    assert h["ranking"] == ["water-dr", "from-start"]  # restarting at each fix beats one start over 10 min
    wdr = obj["estimators"]["water-dr"]["holdout"]
    assert 1.0 < wdr["rmse_m"] < 40.0 and len(wdr["end_errors_m"]) == 3
    assert obj["estimators"]["from-start"]["gnss_residual_rms_m"] > 10 * obj["estimators"]["water-dr"][
        "gnss_residual_rms_m"]
    md = (out / "report.md").read_text()
    assert md.startswith("# Estimator comparison (no truth)") and "over the truth" not in md
    assert "### GNSS hold-out" in md and "| 1 | water-dr |" in md and "Trajectories (no truth)" in md
    assert "Its track equals" not in md  # the two tracks differ
    assert (out / "map.html").exists() and (out / "trajectories.png").exists()


def test_run_holdout_and_report_for_one_estimator(psaros_slice, tmp_path):
    out = tmp_path / "r"
    rc, obj = _cli("run", str(psaros_slice), "-e", "water-dr", "--holdout-gnss", "200,40", "--out", str(out),
                   "--report")
    assert rc == 0 and obj["holdout"]["scored_windows"] == 3 and obj["holdout"]["rmse_m"] > 0
    for f in ("report.md", "report.html", "map.html", "trajectory.tum", "summary.json", "trajectories.png"):
        assert (out / f).exists(), f
    assert "**water-dr** (odometry)" in (out / "report.md").read_text()
    rc, obj = _cli("run", str(psaros_slice), "-e", "water-dr", "--holdout-gnss", "5000,60")
    assert rc == 2 and "shorter than one period" in obj["error"]
