"""The report's plain sentences: one per estimator saying what it used, what it is and why its figure
looks as it does (equal tracks and why, degenerate registrations, over-confidence, skipped)."""

from __future__ import annotations

import numpy as np

from graphnav.evaluation.comparison import Comparison, Entry
from graphnav.evaluation.report.verdicts import data_lines, verdicts
from graphnav.log import NavLog, Truth
from graphnav.result import RunResult
from graphnav.trajectory import Trajectory


def _entry(name: str, poses: np.ndarray, kind: str = "odometry", summary: dict | None = None, info: dict | None = None,
           description: str = "a test estimator") -> Entry:
    t = np.arange(len(poses), dtype=float)
    res = RunResult(Trajectory(t, poses), info=info or {})
    return Entry(name, kind, description, result=res, summary={"inputs": ["odometry"], **(summary or {})})


def test_equal_tracks_are_said_with_the_reason():
    poses = np.column_stack([np.arange(50.0), np.zeros(50), np.zeros(50)])
    log = NavLog([Truth(float(k), float(k), 0.0, 0.0) for k in range(50)])
    dr = _entry("dead-reckoning", poses, summary={"ate_rmse_m": 3.0})
    icp = _entry("icp-dr", poses + 1e-9, summary={"ate_rmse_m": 3.0},
                 info={"degenerate_registrations": 49, "registrations": 50})
    ukf = _entry("ukf", poses + [0.0, 5.0, 0.0], kind="filter", description="conventional UKF",
                 summary={"inputs": ["imu", "gnss"], "ate_rmse_m": 5.0, "nees_mean": 15.2})
    skipped = Entry("scan-to-map", "odometry", "LiDAR", skipped="needs at least two scans")
    fused = _entry("fused", poses, info={"init": "odometry", "matches": 50, "failed_matches": 1})
    v = verdicts(Comparison([dr, icp, ukf, skipped, fused], log))
    assert v[0].startswith("**dead-reckoning** (odometry): a test estimator. Used: odometry.")
    assert "Its track equals **dead-reckoning**'s within 1e-09 m" in v[1]
    assert "98 % of its registrations were degenerate, so at every step it kept its guess" in v[1]
    assert "Worse than **dead-reckoning** (3 m) although it uses GNSS." in v[2]
    assert "Over-confident: its position NEES is 15.2" in v[2] and "models no IMU biases" in v[2]
    assert v[3].endswith("Not run: needs at least two scans.")
    assert "it starts every scan match from its odometry guess" in v[4]


def test_an_odometry_off_by_its_start_heading_says_so():
    poses = np.column_stack([np.arange(50.0), np.zeros(50), np.full(50, np.radians(1.95))])
    log = NavLog([Truth(float(k), float(k), 0.0, 0.0) for k in range(50)])
    s2m = _entry("scan-to-map", poses, summary={"inputs": ["cloud"], "ate_rmse_m": 4.1, "ate_aligned_rmse_m": 0.015},
                 info={"anchor": "pose_prior"})
    drift = _entry("dead-reckoning", poses, summary={"ate_rmse_m": 10.0, "ate_aligned_rmse_m": 2.0})
    v = verdicts(Comparison([s2m, drift], log))
    assert "Its shape is right (aligned ATE 0.015 m against 4.1 m): the error is its start pose's (pose prior)" in v[0]
    assert "mostly the heading (1.95 deg off the truth's at its first pose)" in v[0]
    assert "shape is right" not in v[1]


def test_data_lines_name_gaps_and_jumps():
    comp = Comparison([], NavLog([]), checks={
        "gaps": {"gnss": {"count": 2, "threshold_s": 5.0, "total_s": 90.0, "longest": [[10.0, 40.0], [50.0, 110.0]]}},
        "gnss_jumps": {"count": 1, "speed_bound_mps": 12.0, "largest": [{"t0": 5.0, "t1": 6.0, "distance_m": 80.0}]}})
    lines = data_lines(comp)
    assert lines[0] == "GNSS: 2 gaps longer than 5 s, 90 s in all (longest: 10.0–40.0 s, 50.0–110.0 s)."
    assert lines[1].startswith("GNSS jumps: 1 steps") and "80.0 m at 6.0 s" in lines[1]
    assert data_lines(Comparison([], NavLog([]))) == ["No gaps in time and no GNSS jumps found."]


def test_an_estimator_reset_on_every_fix_says_its_movement_figures_carry_the_jumps():
    poses = np.column_stack([np.arange(50.0), np.zeros(50), np.zeros(50)])
    log = NavLog([Truth(float(k), float(k), 0.0, 0.0) for k in range(50)])
    wdr = _entry("water-dr", poses, summary={"inputs": ["heading", "water_speed", "gnss"], "ate_rmse_m": 4.8,
                                           "sog_rmse_mps": 4.75}, info={"gnss_resets": 617})
    calm = _entry("other", poses, summary={"ate_rmse_m": 1.0, "sog_rmse_mps": 0.1}, info={"gnss_resets": 0})
    v = verdicts(Comparison([wdr, calm], log))
    assert "put back on every GNSS fix (617 resets)" in v[0] and "SOG (4.75 m/s RMSE), COG and ROT" in v[0]
    assert "resets" not in v[1]


def test_data_lines_name_a_speed_log_that_under_reads():
    windows = [[600.0 * i, 1.06 + 0.01 * (i % 2), 0.01, 0.0, 0.0, 0.0, 300] for i in range(4)]
    comp = Comparison([], NavLog([]), checks={"speed_log": {"windows": windows, "scale": 1.065, "scale_se": 0.005,
                                                             "scale_spread": 0.005, "angle_deg": 0.0}})
    assert any("under-reads by 6 %" in line for line in data_lines(comp))
    comp.checks["speed_log"]["scale"] = 1.01  # within 2 %: not worth a sentence
    assert data_lines(comp) == ["No gaps in time and no GNSS jumps found."]
