"""Issue #25's "yaw bias on small steps": the weighted ICP's yaw on CARMEN-geometry scans with a known
rotation, and benchmarks/icp_yaw_slope.py's statistics on sequences with a known scale, offset and
per-pose noise (docs/defaults.md, "What was fitted")."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _scan_sim import raycast, room

from graphnav.geometry import se2_compose
from graphnav.io.carmen import flaser_angles
from graphnav.scan.weighted_icp import IcpConfig, match_points
from tests._bench import load_benchmark

BENCH = load_benchmark("icp_yaw_slope")


def carmen_pairs(n_beams: int, n_pairs: int, seed: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(source points, target points, true increment) of ray-cast pairs with a CARMEN FLASER's beams
    (:func:`flaser_angles`), 1 cm range noise and ranges written to 1 cm as in the logs; steps of
    ~0.1 m and N(0, 3 deg) of yaw, the size of freiburg-079's 0.24 s steps."""
    rng = np.random.default_rng(seed)
    segs, ang = room(), flaser_angles(n_beams)

    def scan(pose: np.ndarray) -> np.ndarray:
        r = np.round((raycast(segs, pose, ang) + rng.normal(0.0, 0.01, ang.size)) / 0.01) * 0.01
        ok = np.isfinite(r)
        return np.column_stack([r[ok] * np.cos(ang[ok]), r[ok] * np.sin(ang[ok])])

    out = []
    for _ in range(n_pairs):
        p0 = np.array([rng.uniform(-6, 6), rng.uniform(-3, 3), rng.uniform(-math.pi, math.pi)])
        inc = np.array([rng.normal(0.1, 0.05), rng.normal(0.0, 0.01), rng.normal(0.0, math.radians(3.0))])
        out.append((scan(se2_compose(p0, inc)), scan(p0), inc))
    return out


@pytest.mark.parametrize("n_beams", [360, 181])
def test_hdl_yaw_is_not_short_on_small_steps(n_beams):
    """Known answer: over small rotations the match's yaw regresses on the true one with slope 1 (a
    shrinkage toward zero motion of 1 %, the issue's figure, would be 10 standard errors here)."""
    est, true = [], []
    for src, tgt, inc in carmen_pairs(n_beams, 80, seed=n_beams):
        r = match_points(src, tgt, IcpConfig(), init=inc)
        est.append(r.quality["icp_pose"][2])
        true.append(inc[2])
    est, true = np.array(est), np.array(true)
    err = est - true
    keep = np.abs(err) < math.radians(1.0)  # a pose facing one wall may be degenerate in yaw
    assert keep.sum() >= 75
    slope = est[keep] @ true[keep] / (true[keep] @ true[keep])
    assert slope == pytest.approx(1.0, abs=0.003)
    assert abs(np.degrees(err[keep].mean())) < 0.02
    assert np.degrees(np.sqrt(np.mean(err[keep] ** 2))) < 0.1


def test_textbook_point_to_line_recovers_the_rotation():
    """The benchmark's independent matcher recovers the known rotation too (from a guess 1 deg and 5 cm off)."""
    est, true = [], []
    for src, tgt, inc in carmen_pairs(360, 40, seed=7):
        pose, converged = BENCH.p2l_match(src, tgt, inc + np.array([0.05, -0.05, math.radians(1.0)]))
        if converged:
            est.append(pose[2])
            true.append(inc[2])
    est, true = np.array(est), np.array(true)
    keep = np.abs(est - true) < math.radians(1.0)
    assert keep.sum() >= 35
    assert est[keep] @ true[keep] / (true[keep] @ true[keep]) == pytest.approx(1.0, abs=0.003)


def sequence(n: int, scale: float, offset_deg: float, pose_noise_deg: float, match_noise_deg: float,
             seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Yaw increments (N,) of a robot that drives straight half the time and turns, mostly left, in
    between (turns lasting ~10 steps): the truth's (true increments + per-pose noise, which telescopes)
    and a matcher's (``scale`` x true + ``offset`` + independent per-pair noise)."""
    rng = np.random.default_rng(seed)
    rate = np.convolve(rng.normal(0.0, 1.0, n + 9), np.ones(10) / math.sqrt(10), mode="valid")
    turning = np.repeat(rng.random(n // 20 + 1) < 0.5, 20)[:n]
    x = np.where(turning, np.radians(4.0) * rate + np.radians(1.0), 0.0)
    j = np.radians(pose_noise_deg) * rng.normal(0.0, 1.0, n + 1)
    ref = x + np.diff(j)
    est = scale * x + np.radians(offset_deg) + np.radians(match_noise_deg) * rng.normal(0.0, 1.0, n)
    return est, ref


def test_per_pose_noise_of_the_truth_is_not_a_scale():
    """No scale, noise in the truth's poses: the one-pair slope is pulled below 1 and the error is
    anticorrelated between consecutive pairs and pulled toward zero binned by the truth's increment,
    not by the match's; over windows, and in the scale/offset fit, the scale is 1."""
    est, ref = sequence(4000, 1.0, 0.0, 0.35, 0.15, seed=1)
    ok = np.ones(est.size, dtype=bool)
    err, good = BENCH.yaw_errors(est, ref, ok)
    w1, w1_rev = BENCH.window_slopes(est, ref, good, 1)
    assert w1 < 0.985 and w1_rev == pytest.approx(1.0, abs=0.01)  # matches nearly clean: the reverse is ~1
    assert BENCH.window_slopes(est, ref, good, 100)[0] == pytest.approx(1.0, abs=0.003)
    fit = BENCH.scale_offset(est, ref, good)
    assert abs(fit["scale_pct"]) < 3 * fit["scale_se_pct"] + 0.05
    assert abs(fit["offset_deg"]) < 3 * fit["offset_se_deg"] + 1e-3
    assert BENCH.lag1(err, good) < -0.3
    by_truth = {tuple(b["bin_deg"]): b for b in BENCH.binned(est, ref, err, good, "truth")}
    by_match = {tuple(b["bin_deg"]): b for b in BENCH.binned(est, ref, err, good, "match")}
    small = (0.3, 1.0)
    assert by_truth[small]["mean_err_deg"] < -5 * by_truth[small]["se_deg"]  # regression to the mean
    assert abs(by_match[small]["mean_err_deg"]) < abs(by_truth[small]["mean_err_deg"]) / 2


@pytest.mark.parametrize(("scale", "offset_deg"), [(0.99, 0.0), (1.0, -0.01), (1.005, 0.01)])
def test_scale_and_offset_are_recovered(scale, offset_deg):
    """A matcher's yaw scale and a constant per-pair offset, under the same truth noise, come back
    from the windowed fit within 3 standard errors (and the standard errors are small enough to tell
    them apart)."""
    est, ref = sequence(4000, scale, offset_deg, 0.35, 0.15, seed=2)
    _, good = BENCH.yaw_errors(est, ref, np.ones(est.size, dtype=bool))
    fit = BENCH.scale_offset(est, ref, good)
    assert fit["scale_pct"] == pytest.approx(100 * (scale - 1.0), abs=3 * fit["scale_se_pct"])
    assert fit["offset_deg"] == pytest.approx(offset_deg, abs=3 * fit["offset_se_deg"])
    assert fit["scale_se_pct"] < 0.3 and fit["offset_se_deg"] < 0.004


@pytest.mark.parametrize("wz_deg", [30.0, -30.0])
def test_an_unmodelled_counter_clockwise_sweep_turns_matches_clockwise(wz_deg):
    """Known answer for the clockwise drift of benchmarks/icp_yaw_slope.py's ``--sweep``: scans whose
    beams are taken one after the other from -90 to +90 deg over ``S`` seconds while the robot turns
    at ``w``, matched as if instantaneous, come out turned by ``-dyaw w S / pi`` (clockwise whichever
    way the robot turns: the scan is stretched or squeezed in bearing by ``1 + w S / pi``)."""
    from graphnav.scan.deskew import beam_times, se2_exp

    segs, ang, sweep, dt = room(), flaser_angles(181), 0.1, 0.25
    twist = np.array([0.4, 0.0, math.radians(wz_deg)])
    rel = np.array([*se2_exp(twist, np.array([dt]))]).ravel()

    def swept(pose: np.ndarray) -> np.ndarray:
        x, y, th = se2_exp(twist, beam_times(ang.size, sweep * ang.size / (ang.size - 1)))  # -90..+90 in S
        r = np.array([raycast(segs, se2_compose(pose, np.array([x[i], y[i], th[i]])), ang[i:i + 1])[0]
                      for i in range(ang.size)])
        ok = np.isfinite(r)
        return np.column_stack([r[ok] * np.cos(ang[ok]), r[ok] * np.sin(ang[ok])])

    errs = []
    for p0 in ([-3.0, -1.0, 0.3], [2.0, 1.0, 2.5], [0.0, -2.0, -1.2]):
        p0 = np.array(p0)
        r = match_points(swept(se2_compose(p0, rel)), swept(p0), IcpConfig(), init=rel)
        errs.append(r.quality["icp_pose"][2] - rel[2])
    want = -rel[2] * twist[2] * sweep / math.pi
    assert want < 0
    assert np.mean(errs) == pytest.approx(want, rel=0.15)
