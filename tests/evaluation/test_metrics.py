import copy

import numpy as np
import pytest

from graphnav.evaluation.metrics import associate, ate, heading_error, movement, movement_errors, rpe, umeyama_se2
from graphnav.geometry import accumulate, se2_compose
from graphnav.io.trajectory_csv import read_trajectory_csv, write_trajectory_csv
from graphnav.io.tum import read_tum, write_tum
from graphnav.trajectory import Trajectory


def _pair(seed=0, n=120):
    rng = np.random.default_rng(seed)
    inc = np.column_stack([rng.uniform(0.5, 2.0, n - 1), rng.normal(0, 0.05, n - 1), rng.normal(0, 0.08, n - 1)])
    ref = Trajectory(np.arange(n) * 0.5, accumulate(inc, (3.0, -2.0, 0.4)), name="ref")
    noisy = inc + rng.normal(0, [0.05, 0.03, 0.01], inc.shape)
    est = Trajectory(ref.t + rng.uniform(-0.004, 0.004, n), accumulate(noisy, (3.2, -2.1, 0.41)), name="est")
    return est, ref


def test_ate_known_offset():
    ref = Trajectory(np.arange(5.0), np.column_stack([np.arange(5.0), np.zeros(5), np.zeros(5)]))
    est = Trajectory(ref.t, ref.poses + [0.0, 2.0, 0.0])
    a = ate(est, ref)
    assert a["rmse"] == pytest.approx(2.0) and a["max"] == pytest.approx(2.0) and a["n"] == 5
    assert ate(est, ref, align=True)["rmse"] == pytest.approx(0.0, abs=1e-12)


def test_umeyama_recovers_rigid_transform():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(50, 2)) * 10
    T = np.array([4.0, -7.0, 0.9])
    dst = se2_compose(T, np.column_stack([src, np.zeros(50)]))[:, :2]
    assert np.allclose(umeyama_se2(src, dst), T)


def test_associate_drops_far_stamps():
    est = Trajectory([0.0, 1.0, 2.0], np.zeros((3, 3)))
    ref = Trajectory([0.001, 1.5, 2.01], np.zeros((3, 3)))
    ie, ir = associate(est, ref, max_dt=0.02)
    assert ie.tolist() == [0, 2] and ir.tolist() == [0, 2]


def _to_evo(tr: Trajectory):
    from evo.core.trajectory import PoseTrajectory3D

    xyz = np.column_stack([tr.x, tr.y, np.zeros(len(tr))])
    quat = np.column_stack([np.cos(tr.yaw / 2), np.zeros(len(tr)), np.zeros(len(tr)), np.sin(tr.yaw / 2)])
    return PoseTrajectory3D(positions_xyz=xyz, orientations_quat_wxyz=quat, timestamps=tr.t)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ate_and_rpe_match_evo(seed):
    from evo.core import metrics, sync

    est, ref = _pair(seed)
    e_ref, e_est = sync.associate_trajectories(_to_evo(ref), _to_evo(est), max_diff=0.02)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((e_ref, e_est))
    ours = ate(est, ref)
    for k in ("rmse", "mean", "median", "max", "std"):
        assert ours[k] == pytest.approx(ape.get_statistic(getattr(metrics.StatisticsType, k)), abs=1e-6)

    aligned = copy.deepcopy(e_est)
    aligned.align(e_ref)
    ape.process_data((e_ref, aligned))
    assert ate(est, ref, align=True)["rmse"] == pytest.approx(ape.get_statistic(metrics.StatisticsType.rmse),
                                                               abs=1e-6)

    for delta, all_pairs in ((1, False), (10, False), (10, True)):
        r = metrics.RPE(metrics.PoseRelation.translation_part, delta=delta, all_pairs=all_pairs)
        r.process_data((e_ref, e_est))
        mine = rpe(est, ref, delta=delta, all_pairs=all_pairs)
        for k in ("rmse", "mean", "max"):
            assert mine["trans"][k] == pytest.approx(r.get_statistic(getattr(metrics.StatisticsType, k)), abs=1e-6)
        rr = metrics.RPE(metrics.PoseRelation.rotation_angle_deg, delta=delta, all_pairs=all_pairs)
        rr.process_data((e_ref, e_est))
        assert mine["rot"]["rmse"] == pytest.approx(rr.get_statistic(metrics.StatisticsType.rmse), abs=1e-6)


def test_tum_roundtrip_readable_by_evo(tmp_path):
    from evo.tools import file_interface

    est, _ = _pair()
    write_tum(est, tmp_path / "e.tum")
    back = read_tum(tmp_path / "e.tum")
    assert np.allclose(back.poses, est.poses, atol=1e-8) and np.allclose(back.t, est.t)
    ev = file_interface.read_tum_trajectory_file(str(tmp_path / "e.tum"))
    assert np.allclose(ev.positions_xyz[:, :2], est.poses[:, :2], atol=1e-8)


def test_csv_roundtrip_with_covariance(tmp_path):
    est, _ = _pair()
    rng = np.random.default_rng(0)
    a = rng.normal(size=(len(est), 3, 3))
    est.cov = a @ a.transpose(0, 2, 1)
    write_trajectory_csv(est, tmp_path / "e.csv")
    back = read_trajectory_csv(tmp_path / "e.csv")
    assert np.allclose(back.poses, est.poses, rtol=1e-8) and np.allclose(back.cov, est.cov, rtol=1e-8)


def test_movement_of_a_circle():
    # constant speed 2 m/s, yaw rate 0.1 rad/s, sampled at 1 s, starting east
    t = np.arange(30.0)
    r = 2.0 / 0.1
    th = 0.1 * t
    poses = np.column_stack([r * np.sin(th), r - r * np.cos(th), th])
    mv = movement(Trajectory(t, poses))
    chord = 2 * r * np.sin(0.05)
    assert np.allclose(mv["sog"], chord)  # chord speed over one second
    assert np.allclose(mv["rot"], 0.1)
    assert np.allclose(np.unwrap(mv["cog"]), th[:-1] + 0.05)  # chord direction = mid-interval yaw


def test_movement_errors_and_heading():
    est, ref = _pair()
    m = movement_errors(ref, ref)
    assert all(m[k]["rmse"] == 0.0 for k in m)
    biased = Trajectory(ref.t, ref.poses + [0.0, 0.0, np.radians(3.0)])
    assert heading_error(biased, ref)["rmse"] == pytest.approx(3.0)
    assert movement_errors(biased, ref)["hdg"]["mean"] == pytest.approx(3.0)


def test_window_errors_known_answer():
    """Truth at 10 Hz along x; the estimate is off by 1 m inside [2, 3] s, by 3 m at t = 5.0 s exactly,
    exact elsewhere: the windows see exactly those errors, bounds included."""
    from graphnav.evaluation.metrics import window_errors

    t = np.round(np.arange(0.0, 10.0, 0.1), 10)
    ref = Trajectory(t, np.column_stack([t, np.zeros_like(t), np.zeros_like(t)]))
    off = np.where((t >= 2.0) & (t <= 3.0), 1.0, 0.0) + np.where(t == 5.0, 3.0, 0.0)
    est = Trajectory(t, np.column_stack([t, off, np.zeros_like(t)]))
    w = window_errors(est, ref, [(2.0, 3.0)])
    assert w["n"] == 11 and w["rmse"] == pytest.approx(1.0) and w["max"] == pytest.approx(1.0)
    w = window_errors(est, ref, [(1.0, 2.95), (4.95, 5.05)])  # 21 pairs: 10 exact, 10 at 1 m, 1 at 3 m
    assert w["n"] == 21 and w["max"] == pytest.approx(3.0)
    assert w["rmse"] == pytest.approx(np.sqrt((10 * 1.0 + 9.0) / 21))
    empty = window_errors(est, ref, [(20.0, 30.0)])
    assert empty["n"] == 0 and np.isnan(empty["rmse"])


def test_event_windows_group_by_kind_and_skip_malformed_entries():
    from graphnav.evaluation.metrics import event_windows

    events = [{"kind": "gnss_outage", "t0": 1, "t1": 2}, {"kind": "gnss_jump", "t0": 3.0, "t1": 3.5},
              {"kind": "gnss_outage", "t0": 5.0, "t1": 6.0}, {"kind": "x", "t0": 2.0, "t1": 1.0},
              {"kind": "y", "t0": "a", "t1": 1.0}, {"t0": 0, "t1": 1}, "junk", {"kind": "z", "t0": float("nan"),
                                                                                "t1": 1.0}]
    assert event_windows(events) == {"gnss_outage": [(1.0, 2.0), (5.0, 6.0)], "gnss_jump": [(3.0, 3.5)]}
    assert event_windows(None) == {} and event_windows({"kind": "a"}) == {}


def test_errors_by_event_smoothed_and_online():
    """A smoothed estimate off by 0.3 m and an online one off by 0.6 m everywhere: per kind those
    figures; ``online_*`` None without an online trajectory; {} without truth."""
    from graphnav.evaluation.evaluate import errors_by_event, summarize
    from graphnav.log import NavLog, Truth
    from graphnav.result import RunResult

    t = np.arange(0.0, 10.0, 0.5)
    log = NavLog([Truth(float(s), float(s), 0.0, 0.0) for s in t],
                 meta={"events": [{"kind": "gnss_outage", "t0": 1.0, "t1": 2.0},
                                  {"kind": "gnss_outage", "t0": 6.0, "t1": 7.0},
                                  {"kind": "gnss_jump", "t0": 8.0, "t1": 8.2}]})
    poses = np.column_stack([t, np.zeros_like(t), np.zeros_like(t)])
    smoothed = Trajectory(t, poses + [0.3, 0.0, 0.0])
    online = Trajectory(t, poses + [0.0, 0.6, 0.0])
    ev = errors_by_event(RunResult(smoothed, online, np.zeros(0)), log)
    assert set(ev) == {"gnss_outage", "gnss_jump"}
    o = ev["gnss_outage"]
    assert o["windows"] == 2 and o["duration_s"] == pytest.approx(2.0) and o["n"] == 6 and o["online_n"] == 6
    assert o["rmse_m"] == pytest.approx(0.3) and o["max_m"] == pytest.approx(0.3)
    assert o["online_rmse_m"] == pytest.approx(0.6) and o["online_max_m"] == pytest.approx(0.6)
    assert ev["gnss_jump"]["n"] == 1
    no_online = errors_by_event(RunResult(smoothed, None, np.zeros(0)), log)["gnss_outage"]
    assert no_online["online_rmse_m"] is None and no_online["rmse_m"] == pytest.approx(0.3)
    s = summarize("x", RunResult(smoothed, online, np.zeros(0)), log, runtime_s=0.0)
    assert s["errors_by_event"] == ev
    assert errors_by_event(RunResult(smoothed, online, np.zeros(0)), NavLog([], meta=log.meta)) == {}


def test_errors_by_event_carry_the_movement_parameters_inside_the_windows():
    """Truth at 1 m/s along x; the estimate exact except for a speed of 1.5 m/s inside 3-5 s (an outage):
    the SOG error there is 0.5 m/s, outside the windows it does not count."""
    from graphnav.evaluation.evaluate import errors_by_event
    from graphnav.log import NavLog, Truth
    from graphnav.result import RunResult

    t = np.arange(0.0, 10.01, 0.5)
    log = NavLog([Truth(float(s), float(s), 0.0, 0.0) for s in t],
                 meta={"events": [{"kind": "gnss_outage", "t0": 3.0, "t1": 5.0}]})
    x = np.where(t <= 3.0, t, np.where(t <= 5.0, 3.0 + 1.5 * (t - 3.0), t + 1.0))
    est = Trajectory(t, np.column_stack([x, np.zeros_like(t), np.zeros_like(t)]))
    o = errors_by_event(RunResult(est, None, np.zeros(0)), log)["gnss_outage"]
    assert o["sog_rmse_mps"] == pytest.approx(0.5) and o["rot_rmse_degps"] == pytest.approx(0.0)
    assert o["cog_rmse_deg"] == pytest.approx(0.0) and o["online_sog_rmse_mps"] is None


def test_thinned_keeps_the_own_poses_nearest_to_steps_of_dt():
    """Known answer: estimate poses at 0, 0.8, 1.6, ... s (a smoother's keyframes) and at 0.1 s steps (a
    filter), the truth at 0.1 s: thinned to 1 s, the keyframes stay 0.8 s apart (0.8 is nearer 1 than 1.6),
    the filter's poses are exactly 1 s apart; estimate and reference at the same times, nothing invented."""
    from graphnav.evaluation.metrics import thinned

    tr = np.round(np.arange(0.0, 20.0, 0.1), 10)
    ref = Trajectory(tr, np.column_stack([tr, np.zeros_like(tr), np.zeros_like(tr)]))
    kf = np.round(np.arange(0.0, 20.0, 0.8), 10)
    e, r = thinned(Trajectory(kf, np.column_stack([kf, kf, kf])), ref, 1.0)
    assert np.allclose(e.t, kf) and np.allclose(r.t, kf) and np.allclose(e.poses[:, 1], kf)
    e, r = thinned(Trajectory(tr, ref.poses), ref, 1.0)
    assert np.allclose(np.diff(e.t)[:-1], 1.0) and np.allclose(e.t, r.t) and e.t[0] == 0.0  # then 19 -> 19.9
    gap = np.concatenate([tr[tr < 5], tr[tr > 12]])  # a 7 s hole: the next pose after it, no pose inside
    e, _ = thinned(Trajectory(gap, np.column_stack([gap, 0 * gap, 0 * gap])), ref, 1.0)
    assert not ((e.t > 5) & (e.t < 12)).any() and np.isclose(e.t, 12.1).any()
    holed = Trajectory(gap, np.column_stack([gap, 0 * gap, 0 * gap]))
    m, m0 = movement_errors(holed, ref, dt=1.0)["sog"], movement_errors(ref, ref, dt=1.0)["sog"]
    assert m["n"] == m0["n"] - 7 and m["rmse"] == 0.0  # 20 intervals; 14 with the hole, 4.9 -> 12.1 not scored
    with pytest.raises(ValueError, match="dt > 0"):
        thinned(ref, ref, 0.0)


def test_movement_scored_on_one_clock_whatever_the_output_rate():
    """Two estimates of the same straight 1 m/s run, each with 2 cm of white position jitter: one at 100 Hz
    (a filter's every record), one at 1 Hz (a smoother's keyframes). Scan to scan, the 100 Hz one's SOG
    error is its jitter over 0.01 s (~2.8 m/s); on one 1 s clock both are ~0.028 m/s, as their
    positions deserve."""
    rng = np.random.default_rng(0)
    tr = np.round(np.arange(0.0, 200.0, 0.01), 10)
    ref = Trajectory(tr, np.column_stack([tr, np.zeros_like(tr), np.zeros_like(tr)]))

    def jittered(t):
        return Trajectory(t, np.column_stack([t + rng.normal(0, 0.02, t.size), rng.normal(0, 0.02, t.size),
                                              np.zeros_like(t)]))

    fast, slow = jittered(tr), jittered(np.arange(0.0, 200.0, 1.0))
    assert movement_errors(fast, ref)["sog"]["rmse"] > 1.5
    s_fast = movement_errors(fast, ref, dt=1.0)["sog"]["rmse"]
    s_slow = movement_errors(slow, ref, dt=1.0)["sog"]["rmse"]
    assert 0.02 < s_fast < 0.04 and 0.02 < s_slow < 0.04


def test_rpe_over_one_second_scores_every_output_rate_on_the_same_span():
    """A straight 1 m/s run; a 100 Hz estimate whose position is put back by 5 cm at every 1 Hz fix (a
    filter's correction) and is exact in between, and a 1 Hz estimate 5 cm off at each pose alternately.
    Over one pose the 100 Hz one's RPE is the jump once in 100 pairs (0.005 m RMS); over ~1 s every pair
    holds one jump: 0.05 m, as for the 1 Hz one, which one pose and ~1 s agree on."""
    from graphnav.evaluation.metrics import rpe_over

    tr = np.round(np.arange(0.0, 100.0, 0.01), 10)
    ref = Trajectory(tr, np.column_stack([tr, np.zeros_like(tr), np.zeros_like(tr)]))
    saw = np.where(np.floor(tr).astype(int) % 2 == 0, 0.05, 0.0)  # 5 cm off in even seconds
    fast = Trajectory(tr, np.column_stack([tr + saw, np.zeros_like(tr), np.zeros_like(tr)]))
    ts = np.arange(0.0, 100.0, 1.0)
    slow = Trajectory(ts, np.column_stack([ts + np.where(ts % 2 == 0, 0.05, 0.0), 0 * ts, 0 * ts]))
    assert rpe(fast, ref, delta=1, all_pairs=True)["trans"]["rmse"] == pytest.approx(0.005, rel=0.02)
    # (within 1 %: the last span, 99 -> 99.99 s, has no jump; a few 1 Hz poses meet the truth 0.01 s off)
    assert rpe_over(fast, ref, 1.0)["trans"]["rmse"] == pytest.approx(0.05, rel=0.01)
    assert rpe_over(slow, ref, 1.0)["trans"]["rmse"] == pytest.approx(0.05, rel=0.01)
    assert rpe(slow, ref, delta=1, all_pairs=True)["trans"]["rmse"] == pytest.approx(0.05, rel=0.01)
