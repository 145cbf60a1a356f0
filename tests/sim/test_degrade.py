"""The degrade simulator: the unicycle arc fit against closed forms, noise-free odometry that dead
reckoning integrates back onto the truth, the noise model's statistics, GNSS/compass windows, the
marina-degraded preset against the original simulator, the CLI, and the real CARMEN logs
(skipped with the reason when ../shared/data is absent)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from graphnav.estimators.dead_reckoning import run_dead_reckoning, unicycle_step
from graphnav.io import load_log, save_log
from graphnav.log import Gnss, Heading, NavLog, Odometry, Scan, Truth
from graphnav.sim.degrade import (
    PRESETS,
    SIGMA_V_FLOOR,
    DegradeConfig,
    OdometryNoise,
    Window,
    degrade,
    unicycle_fit,
)

REPO = Path(__file__).resolve().parents[2]


def truth_log(poses: np.ndarray, t: np.ndarray, scans: bool = True) -> NavLog:
    recs = []
    for ti, (x, y, yaw) in zip(t, poses, strict=True):
        if scans:
            recs.append(Scan(float(ti), np.array([1.0, 2.0]), np.array([0.0, 0.5])))
        recs.append(Truth(float(ti), float(x), float(y), float(yaw)))
    return NavLog(recs, [], {"name": "synthetic"})


def arc_track(v: float, w: float, dt: float, n: int, start=(2.0, -1.0, 0.3)) -> np.ndarray:
    poses = [np.array(start, dtype=float)]
    for _ in range(n - 1):
        poses.append(unicycle_step(poses[-1], v, w, dt))
    return np.array(poses)


# ----------------------------------------------------------------------------- the arc fit

def test_fit_straight_line():
    v, w, lat = unicycle_fit(np.array([1.0, 2.0, 0.5]), np.array([1.0 + 3 * math.cos(0.5), 2.0 + 3 * math.sin(0.5),
                                                                  0.5]), 2.0)
    assert v == pytest.approx(1.5, abs=1e-12) and w == 0.0 and lat == pytest.approx(0.0, abs=1e-12)


def test_fit_quarter_circle():
    # radius 2, a left quarter turn in 4 s from the origin heading east: ends at (2, 2) heading north
    v, w, lat = unicycle_fit(np.zeros(3), np.array([2.0, 2.0, math.pi / 2]), 4.0)
    assert w == pytest.approx(math.pi / 8, abs=1e-15)
    assert v == pytest.approx(2.0 * math.pi / 8, abs=1e-12)  # v = R w (chord 2 sqrt 2 = 2 (v/w) sin(pi/4))
    assert lat == pytest.approx(0.0, abs=1e-12)


def test_fit_reversing_and_slip():
    v, w, lat = unicycle_fit(np.zeros(3), np.array([-1.0, 0.0, 0.0]), 1.0)
    assert (v, w) == (-1.0, 0.0) and lat == 0.0
    v, w, lat = unicycle_fit(np.zeros(3), np.array([0.0, 0.3, 0.0]), 1.0)  # pure sideways step: slip
    assert v == 0.0 and lat == pytest.approx(0.3)


# |w| in {0} or >= 1e-3: the references' r = v / w form loses ~1e-16 |v / w| m (1e-7 m at w = 1e-9)
_W = st.one_of(st.just(0.0), st.floats(1e-3, 1.5), st.floats(-1.5, -1e-3))


@settings(max_examples=300, deadline=None)
@given(st.floats(-3.0, 3.0), _W, st.floats(0.01, 2.0), st.floats(-10, 10), st.floats(-10, 10),
       st.floats(-math.pi, math.pi))
def test_fit_inverts_the_unicycle_step(v, w, dt, x, y, th):
    import gtsam

    p0 = np.array([x, y, th])
    p1 = unicycle_step(p0, v, w, dt)
    g = gtsam.Pose2(x, y, th).compose(gtsam.Pose2.Expmap(np.array([v * dt, 0.0, w * dt])))  # the library's arc
    assert np.allclose(p1[:2], [g.x(), g.y()], atol=1e-9)
    fv, fw, lat = unicycle_fit(p0, p1, dt)
    assert fw == pytest.approx(w, abs=1e-9)
    assert fv == pytest.approx(v, abs=1e-9)
    assert lat == pytest.approx(0.0, abs=1e-9)


# ----------------------------------------------------------------------------- noise-free odometry

@pytest.mark.parametrize(("v", "w"), [(1.2, 0.0), (0.8, 0.25), (-0.5, -0.4), (0.0, 0.3), (0.0, 0.0)])
def test_noise_free_odometry_integrates_back_to_the_truth(v, w):
    t = 0.5 * np.arange(60)
    poses = arc_track(v, w, 0.5, 60)
    log = degrade(truth_log(poses, t), DegradeConfig(odometry=OdometryNoise(0.0, 0.0, 0.0)), seed=3)
    odo = log.of("odometry")
    assert [r.t for r in odo] == t.tolist()  # one control per truth time; the last repeats the last
    dr = run_dead_reckoning(log).trajectory
    assert np.allclose(dr.t, t)
    err = dr.poses - poses
    err[:, 2] = (err[:, 2] + math.pi) % (2 * math.pi) - math.pi
    assert np.abs(err).max() < 1e-9
    assert log.meta["odometry_arc_residual_m"]["max"] < 1e-9
    assert all(r.sigma_v >= SIGMA_V_FLOOR and r.sigma_w > 0 for r in odo)


def test_irregular_times_and_a_repeated_time():
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.1, 1.0, 40))
    poses = [np.array([0.0, 0.0, 0.0])]
    for k in range(39):
        poses.append(unicycle_step(poses[-1], 1.0 + 0.1 * k, 0.3 * math.sin(k), t[k + 1] - t[k]))
    poses = np.array(poses)
    t2, p2 = np.insert(t, 10, t[10]), np.insert(poses, 10, poses[10], axis=0)  # a duplicated truth record
    log = degrade(truth_log(p2, t2, scans=False), DegradeConfig(odometry=OdometryNoise(0, 0, 0)))
    assert log.meta["odometry_skipped_steps"] == 1
    dr = run_dead_reckoning(log).trajectory
    assert np.abs(dr.poses[:, :2] - poses[:, :2]).max() < 1e-9


# ----------------------------------------------------------------------------- the noise model

def test_noise_statistics_and_stated_sigmas():
    n = 4000
    t = 0.2 * np.arange(n)
    poses = arc_track(1.5, 0.2, 0.2, n)
    cfg = DegradeConfig(odometry=OdometryNoise(0.05, 0.1, math.radians(0.5)))
    log = degrade(truth_log(poses, t, scans=False), cfg, seed=11)
    odo = log.of("odometry")[:-1]
    v = np.array([r.v for r in odo])
    w = np.array([r.w for r in odo])
    sv = np.array([r.sigma_v for r in odo])
    sw = np.array([r.sigma_w for r in odo])
    assert np.allclose(sv, 0.05 * 1.5) and np.allclose(sw, math.hypot(0.1 * 0.2, math.radians(0.5)))
    zv, zw = (v - 1.5) / sv, (w - 0.2) / sw
    for z in (zv, zw):  # standardised errors ~ N(0, 1), white
        assert abs(z.mean()) < 4 / math.sqrt(n) and abs(z.std() - 1) < 0.05
        assert abs(np.corrcoef(z[:-1], z[1:])[0, 1]) < 0.06
    again = degrade(truth_log(poses, t, scans=False), cfg, seed=11)
    other = degrade(truth_log(poses, t, scans=False), cfg, seed=12)
    assert [r.v for r in again.of("odometry")] == [r.v for r in log.of("odometry")]
    assert [r.v for r in other.of("odometry")] != [r.v for r in log.of("odometry")]


def test_constant_yaw_rate_bias():
    n = 2000
    t = 0.5 * np.arange(n)
    poses = arc_track(1.0, 0.0, 0.5, n)
    b = math.radians(0.5)
    log = degrade(truth_log(poses, t, scans=False), DegradeConfig(odometry=OdometryNoise(0.0, 0.0, 0.0, bias=b)))
    w = np.array([r.w for r in log.of("odometry")])
    assert np.allclose(w, b)
    assert {"kind": "yaw_rate_bias", "t0": 0.0, "t1": t[-1], "bias_degps": pytest.approx(0.5)} in log.meta["events"]


def test_existing_odometry_is_replaced_and_counted():
    t = np.arange(5.0)
    base = truth_log(arc_track(1.0, 0.0, 1.0, 5), t)
    base = NavLog.from_unsorted(base.records + [Odometry(0.5, 9.0, 9.0)], meta=base.meta)
    log = degrade(base, DegradeConfig(odometry=OdometryNoise(0, 0, 0)))
    assert log.meta["replaced"] == {"odometry": 1} and all(r.v != 9.0 for r in log.of("odometry"))


# ----------------------------------------------------------------------------- GNSS and compass

def test_gnss_compass_windows_and_rates():
    t = 0.1 * np.arange(2001)  # 200 s at 10 Hz
    poses = arc_track(1.0, 0.05, 0.1, 2001)
    cfg = DegradeConfig(gnss_sigma=2.0, gnss_hz=1.0, compass_sigma=math.radians(1.0), compass_bias=math.radians(4.0),
                        compass_hz=2.0, outages=(Window(50.0, 20.0),), jumps=(Window(120.0, 10.0, 30.0),))
    log = degrade(truth_log(poses, t, scans=False), cfg, seed=5)
    g = log.of(Gnss)
    assert len(g) == 201 - 20  # 1 Hz, none in [50, 70)
    assert not any(50.0 <= r.t < 70.0 for r in g) and all(r.sigma == 2.0 for r in g)
    tr = log.truth()
    err = np.array([[r.x - tr.interpolate([r.t])[0, 0], r.y - tr.interpolate([r.t])[0, 1]] for r in g])
    tg = np.array([r.t for r in g])
    jump = (tg >= 120.0) & (tg < 130.0)
    assert np.hypot(*err[jump].mean(axis=0)) == pytest.approx(30.0, abs=2.0)
    assert np.hypot(*err[~jump].mean(axis=0)) < 0.5 and abs(err[~jump].std() - 2.0) < 0.25
    h = log.of(Heading)
    assert len(h) == 401
    dyaw = np.array([(r.yaw - tr.interpolate([r.t])[0, 2] + math.pi) % (2 * math.pi) - math.pi for r in h])
    assert math.degrees(dyaw.mean()) == pytest.approx(4.0, abs=0.2)
    kinds = [e["kind"] for e in log.meta["events"]]
    assert kinds == ["gnss_outage", "gnss_jump", "compass_bias"]


# ----------------------------------------------------------------------------- marina-degraded preset

def _marina_degraded_original(base: NavLog, seed: int, jump_m: float = 20.0) -> NavLog:
    """graphnav.sim.marina_degraded.degrade as it was before it became a preset (the oracle)."""
    gnss_sigma, outage_s, jump_s = 3.0, 40.0, 10.0
    compass_sigma, compass_bias = math.radians(2.0), math.radians(3.0)
    rng = np.random.default_rng(seed)
    tr = base.truth()
    t0, t1 = float(tr.t[0]), float(tr.t[-1])
    span = t1 - t0
    o0 = t0 + rng.uniform(0.15, 0.45) * span - outage_s / 2
    j0 = t0 + rng.uniform(0.6, 0.85) * span - jump_s / 2
    ang = rng.uniform(-math.pi, math.pi)
    jump = jump_m * np.array([math.cos(ang), math.sin(ang)])
    n = len(tr)
    noise_g = rng.normal(0.0, gnss_sigma, (n, 2))
    noise_c = rng.normal(0.0, compass_sigma, n)
    recs = list(base.records)
    for i in range(n):
        t = float(tr.t[i])
        x, y, yaw = tr.poses[i]
        if not (o0 <= t < o0 + outage_s):
            off = jump if j0 <= t < j0 + jump_s else 0.0
            gx, gy = np.array([x, y]) + off + noise_g[i]
            recs.append(Gnss(t, float(gx), float(gy), gnss_sigma))
        h = yaw + compass_bias + noise_c[i]
        recs.append(Heading(t, float((h + math.pi) % (2 * math.pi) - math.pi), compass_sigma))
    return NavLog.from_unsorted(recs, base.beacons_known, {})


def _same_records(a: NavLog, b: NavLog) -> None:
    assert len(a.records) == len(b.records)
    for ra, rb in zip(a.records, b.records, strict=True):
        assert type(ra) is type(rb) and ra.t == rb.t
        if not isinstance(ra, Scan):
            assert ra == rb


@pytest.mark.parametrize(("seed", "jump_m"), [(1, 20.0), (4, 20.0), (1, 0.0)])
def test_marina_preset_reproduces_the_original_draws(seed, jump_m):
    from graphnav.sim.marina_degraded import degrade as marina_degrade

    t = np.arange(177.0)
    base = truth_log(arc_track(1.25, 0.01, 1.0, 177), t)
    _same_records(marina_degrade(base, seed, jump_m=jump_m), _marina_degraded_original(base, seed, jump_m))
    if jump_m:
        _same_records(degrade(base, PRESETS["marina-degraded"], seed), _marina_degraded_original(base, seed))


def test_marina_preset_on_the_real_marina(marina_log):
    from graphnav.sim.marina_degraded import degrade as marina_degrade

    log = marina_degrade(marina_log, 1)
    _same_records(log, _marina_degraded_original(marina_log, 1))
    assert log.meta["name"] == "marina-degraded" and [e["kind"] for e in log.meta["events"]] == [
        "gnss_outage", "gnss_jump", "compass_bias"]


# ----------------------------------------------------------------------------- CLI

def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "graphnav", *args], capture_output=True, text=True, cwd=REPO)


def test_cli_degrade(tmp_path):
    t = 0.5 * np.arange(100)
    src = tmp_path / "in.jsonl"
    save_log(truth_log(arc_track(1.0, 0.1, 0.5, 100), t), src)
    out = tmp_path / "out.jsonl.gz"
    r = _cli("simulate", "degrade", str(src), "--odometry-noise", "0.05,0.05,0.5", "--gnss", "3,1",
             "--gnss-outage", "10%..20%,5", "--gnss-jump", "30,4,15", "--compass", "2,1", "--seed", "0",
             "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    obj = json.loads(r.stdout)
    assert obj["records"]["odometry"] == 100 and obj["records"]["gnss"] > 0 and obj["records"]["heading"] == 100
    assert [e["kind"] for e in obj["events"]] == ["gnss_outage", "gnss_jump", "compass_bias"]
    back = load_log(out)
    odo = back.of("odometry")
    assert odo[0].sigma_v == pytest.approx(0.05 * abs(odo[0].v), rel=0.3)  # the simulator's sigmas are in the log
    again = tmp_path / "again.jsonl.gz"
    _cli("simulate", "degrade", str(src), "--odometry-noise", "0.05,0.05,0.5", "--gnss", "3,1", "--gnss-outage",
         "10%..20%,5", "--gnss-jump", "30,4,15", "--compass", "2,1", "--seed", "0", "--out", str(again))
    assert again.read_bytes() == out.read_bytes()  # deterministic per seed


@pytest.mark.parametrize("args", [
    ["--odometry-noise", "0.05,0.05"],
    ["--odometry-noise", "0.05,x,0.5"],
    ["--gnss-outage", "10,5"],
    ["--gnss", "3", "--gnss-outage", "50%..10%,5"],
    [],
])
def test_cli_rejects_bad_options_without_a_traceback(tmp_path, args):
    src = tmp_path / "in.jsonl"
    save_log(truth_log(arc_track(1.0, 0.1, 0.5, 10), 0.5 * np.arange(10)), src)
    r = _cli("simulate", "degrade", str(src), *args, "--out", str(tmp_path / "o.jsonl"))
    assert r.returncode == 2 and "graphnav: error:" in r.stderr and "Traceback" not in r.stderr


def test_cli_needs_truth(tmp_path):
    src = tmp_path / "in.jsonl"
    save_log(NavLog([Odometry(0.0, 1.0, 0.0), Odometry(1.0, 1.0, 0.0)]), src)
    r = _cli("simulate", "degrade", str(src), "--odometry-noise", "0.05,0.05,0.5", "--out", str(tmp_path / "o.jsonl"))
    assert r.returncode == 2 and "truth" in r.stderr


# ----------------------------------------------------------------------------- the real CARMEN logs

def _carmen() -> Path | None:
    for c in (REPO.parent / "shared" / "data" / "carmen", REPO.parent.parent / "shared" / "data" / "carmen"):
        if (c / "acapulco-corrected.log.gz").exists():
            return c
    return None


@pytest.mark.parametrize("name", ["acapulco", "belgioioso", "edmonton", "freiburg-079", "freiburg-101",
                                  "freiburg-campus", "infinite-corridor", "orebro", "seattle"])
def test_real_carmen_logs_convert_and_degrade(name):
    d = _carmen()
    if d is None:
        pytest.skip("CARMEN logs not found at ../shared/data/carmen (research data, not in the repository)")
    from graphnav.io.carmen import read_carmen

    base = read_carmen(d / f"{name}-corrected.log.gz", lenient=True)
    assert base.meta["skipped"] == 0
    c = base.counts()
    assert c["scan"] > 0 and c["truth"] > 0
    clean = degrade(base, DegradeConfig(odometry=OdometryNoise(0.0, 0.0, 0.0)))
    noisy = degrade(base, DegradeConfig(odometry=OdometryNoise(0.05, 0.05, math.radians(0.5))), seed=0)
    assert len(noisy.of("odometry")) == c["truth"] and noisy.meta["odometry_skipped_steps"] == 0
    # the corrected poses are not exact unicycle arcs: the sideways residual is reported, and small
    assert 0.0 < noisy.meta["odometry_arc_residual_m"]["rms"] < 0.2
    from graphnav.evaluation.metrics import ate

    ref = base.truth()
    e_clean = ate(run_dead_reckoning(clean).trajectory, ref)["rmse"]
    e_noisy = ate(run_dead_reckoning(noisy).trajectory, ref)["rmse"]
    assert np.isfinite(e_clean) and np.isfinite(e_noisy) and e_clean < 5.0
