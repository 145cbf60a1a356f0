"""A slow IMU (records further apart than the keyframes): each record is the mean over its interval, so
the preintegration is exact over whole records; the keyframes wait for a record's time
(graphnav.graph.keyframes.Keyframes.at_imu_record) and a share of a record adds the variance of the
rate's variation within it (graphnav.graph.imu_chain.ImuChain.hold_variance). Known answers."""

from __future__ import annotations

import bisect
import math

import gtsam
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from graphnav.graph.imu_chain import ImuChain, ImuConfig, _hold, _window
from graphnav.graph.keyframes import Keyframes
from graphnav.graph.smoother_config import KeyframeConfig
from graphnav.log import Gnss, Imu


def _ramp_chain(slope: float, n: int = 6) -> ImuChain:
    """1 Hz records of a yaw rate rising linearly, ``w(t) = slope t``: record ``i`` (at ``t = i``) is its
    mean over ``(i - 1, i]``, ``slope (i - 1/2)``."""
    chain = ImuChain(ImuConfig())
    for i in range(1, n + 1):
        chain.add(Imu(float(i), 0.0, 0.0, slope * (i - 0.5)))
    return chain


@settings(max_examples=40, deadline=None)
@given(lo=st.floats(1.01, 1.99), hi=st.floats(3.01, 3.99), slope=st.floats(-0.05, 0.05))
def test_a_share_of_a_record_is_off_by_the_rate_change_within_it(lo: float, hi: float, slope: float):
    """A linear rate: the held mean over a share ``f`` at either end of a record misses ``v T f (1 - f) / 2``
    of the integral (``v`` = the step between records = ``slope T``), the sigma ``hold_variance`` states."""
    chain = _ramp_chain(slope)
    yaw = chain.preintegrate(gtsam.imuBias.ConstantBias(), lo, hi).deltaRij().yaw()
    exact = slope * (hi**2 - lo**2) / 2.0
    f_start, f_end = 2.0 - lo, hi - 3.0  # the shares of records 2 and 4; record 3 whole
    # the end of record 2 (the rate above its mean there) and the start of record 4 (below it)
    e_start, e_end = slope * f_start * (1 - f_start) / 2.0, -slope * f_end * (1 - f_end) / 2.0
    assert exact - yaw == pytest.approx(e_start + e_end, abs=1e-9)
    _, vg, _ = chain.hold_variance(lo, hi)
    assert vg[2] == pytest.approx(e_start**2 + e_end**2, rel=1e-9, abs=1e-18)
    assert vg[0] == vg[1] == 0.0


def test_whole_records_add_nothing_and_a_held_tail_grows_with_its_square():
    chain = _ramp_chain(0.02, n=4)
    va, vg, vp = chain.hold_variance(1.0, 4.0)  # records 2, 3, 4 whole
    assert not va.any() and not vg.any() and vp == 0.0  # (no specific force)
    _, vg, _ = chain.hold_variance(3.5, 5.0)  # half of the newest record, then held 1 s beyond it
    v = 0.02
    assert vg[2] == pytest.approx((v * 0.25 / 2) ** 2 + (v * 1.0**2 / 2) ** 2)
    const = ImuChain(ImuConfig())
    for i in range(1, 5):
        const.add(Imu(float(i), 0.1, 0.2, 0.01))
    va, vg, vp = const.hold_variance(1.3, 6.0)
    assert not va.any() and not vg.any() and vp == 0.0


def test_whole_records_of_a_changing_force_leave_the_position_off_by_its_spread():
    """A specific force rising linearly (``a = s t``, 1 Hz records of its means): over whole records the
    velocity is exact and the position misses ``s T^3 / 12`` per record, the sigma ``hold_variance`` states."""
    s_ = 0.04
    chain = ImuChain(ImuConfig())
    for i in range(1, 6):
        chain.add(Imu(float(i), s_ * (i - 0.5), 0.0, 0.0))
    bias = gtsam.imuBias.ConstantBias()
    pim = chain.preintegrate(bias, 1.0, 3.0)
    exact_v = s_ * (3.0**2 - 1.0**2) / 2.0
    exact_p = s_ * (3.0**3 - 1.0**3) / 6.0 - s_ * 1.0**2 / 2.0 * 2.0  # from rest at t = 1
    assert pim.deltaVij()[0] == pytest.approx(exact_v, abs=1e-12)
    assert exact_p - pim.deltaPij()[0] == pytest.approx(-2 * s_ / 12.0, abs=1e-12)
    _, _, vp = chain.hold_variance(1.0, 3.0)
    assert vp == pytest.approx(2 * (s_ / 12.0) ** 2, rel=1e-9)


def test_the_preintegration_of_a_share_carries_that_variance():
    """The factor's rotation variance: the white noise's density x dt plus ``hold_variance``."""
    chain = _ramp_chain(0.05)
    bias = gtsam.imuBias.ConstantBias()
    whole = chain.preintegrate(bias, 1.0, 3.0).preintMeasCov()[2, 2]
    share = chain.preintegrate(bias, 1.5, 3.5).preintMeasCov()[2, 2]
    gyro_density = math.radians(ImuConfig().gyro_sigma_deg) ** 2 / ImuConfig().hz
    assert whole == pytest.approx(gyro_density * 2.0, rel=1e-6)
    assert share == pytest.approx(gyro_density * 2.0 + 2 * (0.05 * 0.25 / 2) ** 2, rel=1e-6)


def _keyframe_times(imu_hz: float, scan_hz: float = 5.0, speed: float = 1.43, T: float = 12.0) -> list[float]:
    """The keyframes the motion rule (1 m) picks among ``scan_hz`` scans with an IMU at ``imu_hz``."""
    kf = Keyframes(KeyframeConfig(), scans=True)
    chain = ImuChain(ImuConfig())
    n_imu = 0
    for j in range(int(T * scan_hz) + 1):
        t = j / scan_hz
        while (n_imu + 1) / imu_hz <= t + 1e-9:  # the records up to the scan have arrived
            n_imu += 1
            chain.add(Imu(n_imu / imu_hz, 0.0, 0.0, 0.0))
        if kf.scan_is_keyframe(t, lambda: speed, chain):
            kf.add(t, None)
        kf.n_scans += 1
    return kf.t


def test_keyframes_wait_for_a_slow_imus_record():
    slow = np.array(_keyframe_times(1.0))
    slow = slow[slow >= 2.0]  # from the second record on (the first two give the period)
    assert len(slow) >= 10
    np.testing.assert_allclose(slow, np.round(slow), atol=1e-9)  # at the 1 Hz records' times
    fast = np.array(_keyframe_times(100.0))  # a fast IMU: the motion rule alone (1 m at 1.43 m/s: every 0.8 s)
    np.testing.assert_allclose(np.diff(fast), 0.8, atol=1e-9)


def test_the_grid_skips_the_slots_between_a_slow_imus_records():
    kf = Keyframes(KeyframeConfig(period=0.5), scans=False)
    chain = ImuChain(ImuConfig())
    kf.imu = chain
    for i in range(0, 21):  # 1 Hz IMU and 2 Hz GNSS, 0.5 s grid
        t = i * 0.5
        if i % 2 == 0:
            chain.add(Imu(t, 0.0, 0.0, 0.0))
        kf.clock(Gnss(t, 0.0, 0.0, 3.0))
    later = np.array(kf.t)[np.array(kf.t) >= 2.0]
    assert len(later) >= 8
    np.testing.assert_allclose(later, np.round(later), atol=1e-9)


def _pieces_loop(t: list[float], ta: float, tb: float) -> list[tuple[int, float, float]]:
    """The record pieces of ``[ta, tb]`` walked one record at a time (the reference)."""
    out: list[tuple[int, float, float]] = []
    if not t or tb <= ta:
        return out
    i, lo, n = bisect.bisect_right(t, ta), ta, len(t)
    while lo < tb - 1e-12:
        j, hi = (i, min(t[i], tb)) if i < n else (n - 1, tb)
        if hi > lo:
            out.append((j, lo, hi))
        lo, i = hi, i + 1
    return out


@settings(max_examples=150, deadline=None)
@given(gaps=st.lists(st.floats(0.001, 2.0), min_size=1, max_size=30), ta=st.floats(-1.0, 40.0),
       width=st.floats(0.01, 20.0), at_record=st.booleans())
def test_the_pieces_are_the_records_walked_one_at_a_time(gaps: list[float], ta: float, width: float,
                                                         at_record: bool):
    t = list(np.cumsum(gaps))
    if at_record:  # interval ends exactly on record times
        ta = t[len(t) // 3]
    chain = ImuChain(ImuConfig())
    for i, ti in enumerate(t):
        chain.add(Imu(float(ti), 0.01 * i, -0.02 * i, 0.001 * i))
    tb = ta + width
    idx, lo, hi = chain._pieces(ta, tb)
    ref = _pieces_loop(chain.t, ta, tb)
    assert [int(i) for i in idx] == [r[0] for r in ref]
    np.testing.assert_allclose(lo, [r[1] for r in ref], atol=1e-12)
    np.testing.assert_allclose(hi, [r[2] for r in ref], atol=1e-12)
    acc, omega, dt = chain._arrays((idx, lo, hi))
    np.testing.assert_allclose(dt, [r[2] - r[1] for r in ref], atol=1e-12)
    np.testing.assert_allclose(omega[:, 2], [chain.rows[r[0]][5] for r in ref])


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(2, 40), ta=st.floats(-0.5, 3.0), span=st.floats(0.0, 4.0),
       six=st.booleans())
def test_one_conversion_of_the_records_reads_as_each_did_alone(seed: int, n: int, ta: float, span: float, six: bool):
    """preintegrate converts the records an interval reads once (``_window``) for the samples and the hold variance:
    the same floats, bit for bit, as each converting its own, at any interval (inside, across the start, held
    beyond the newest record, empty), uneven records, planar or six-axis."""
    rng = np.random.default_rng(seed)
    chain = ImuChain(ImuConfig())
    t = np.cumsum(rng.uniform(0.005, 0.3, n))
    for tk, r in zip(t, rng.normal(size=(n, 6)), strict=True):
        chain.add(Imu(float(tk), *r) if six else Imu(float(tk), r[0], r[1], r[5]))
    pieces = chain._pieces(ta, ta + span)
    window = _window(chain.rows, pieces)
    for a, b in zip(chain._arrays(pieces), chain._arrays(pieces, window), strict=True):
        assert a.tobytes() == b.tobytes()
    va, vg, vp = _hold(chain.t, chain.rows, pieces)
    wa, wg, wp = _hold(chain.t, chain.rows, pieces, window)
    assert va.tobytes() == wa.tobytes() and vg.tobytes() == wg.tobytes() and vp == wp


def test_the_densities_are_read_from_the_parameters_in_use():
    """_held_params reads the noise densities once per parameters object, and again when the chain gets others."""
    chain = _ramp_chain(0.5, n=6)
    chain.preintegrate(gtsam.imuBias.ConstantBias(), 1.0, 4.0)  # (makes the shared parameters)
    first = chain._densities
    assert first[0] is chain.params
    loud = gtsam.PreintegrationParams.MakeSharedU(0.0)
    for name in ("Accelerometer", "Gyroscope", "Integration"):
        getattr(loud, f"set{name}Covariance")(np.eye(3) * 7.0)
    chain.params = loud
    pieces = chain._pieces(1.5, 3.5)
    assert chain._held_params(pieces, 2.0) is loud  # 7 per unit time: the shares' variance is negligible beside it
    assert chain._densities[0] is loud and chain._densities[3] == 7.0 and list(chain._densities[1]) == [7.0] * 3


def _hold_reference(t_all, rows_all, pieces):  # noqa: ANN001, ANN202
    """The hold variance as first written (every mask applied), the reference of the one with shortcuts."""
    idx, lo, hi = pieces
    first = idx > 0
    idx, lo, hi = idx[first], lo[first], hi[first]
    if not len(idx):
        return np.zeros(3), np.zeros(3), 0.0
    k0, k1 = int(idx[0]) - 1, min(int(idx[-1]) + 2, len(t_all))
    t = np.asarray(t_all[k0:k1], dtype=float)
    rows = np.asarray(rows_all[k0:k1], dtype=float)
    j = idx - k0
    T = t[j] - t[j - 1]
    ok = T > 0.0
    j, lo, hi, T, ti = j[ok], lo[ok], hi[ok], T[ok], t[j[ok]]
    v = np.abs(rows[j] - rows[j - 1])
    has_next = j + 1 < len(t)
    v[has_next] = np.maximum(v[has_next], np.abs(rows[j[has_next] + 1] - rows[j[has_next]]))
    f_all = np.minimum((hi - lo) / T, 1.0)
    vp = float(np.sum((v[:, :3] * (T * T * f_all**3 / 12.0)[:, None]) ** 2))
    beyond = hi > ti + 1e-12
    d = np.where(beyond, hi - np.maximum(lo, ti), 0.0)
    f = np.where(beyond, np.clip((ti - lo) / T, 0.0, 1.0), (hi - lo) / T)
    share = np.where(f >= 1.0 - 1e-9, 0.0, T * f * (1.0 - f) / 2.0)
    e2 = v**2 * ((d * d / (2.0 * T)) ** 2 + share**2)[:, None]
    return e2[:, :3].sum(axis=0), e2[:, 3:].sum(axis=0), vp


@settings(max_examples=300, deadline=None)
@given(gaps=st.lists(st.sampled_from([0.0, 0.01, 0.01, 0.01, 0.013, 0.5]), min_size=1, max_size=60),
       seed=st.integers(0, 2**31), a=st.floats(-0.1, 1.0), b=st.floats(0.0, 1.2), six=st.booleans())
def test_the_hold_variance_is_the_reference_arithmetic_to_the_bit(gaps, seed, a, b, six):  # noqa: ANN001
    """Every interval -- before the first record, over records at one time, shares at both ends, held beyond
    the newest -- gives the reference's three values to the bit, with the window or without."""
    rng = np.random.default_rng(seed)
    chain = ImuChain(ImuConfig())
    t = 0.05
    for g in gaps:
        t += g
        r = rng.normal(size=6)
        chain.add(Imu(t, r[0], r[1], r[5], *((r[2], r[3], r[4]) if six else ())))
    ta = 0.05 + a * (t - 0.05)
    tb = ta + b * (t - 0.05) + 1e-3
    pieces = chain._pieces(ta, tb)
    want = _hold_reference(chain.t, chain.rows, pieces)
    for got in (_hold(chain.t, chain.rows, pieces), _hold(chain.t, chain.rows, pieces, _window(chain.rows, pieces))):
        assert got[0].tobytes() == want[0].tobytes() and got[1].tobytes() == want[1].tobytes()
        assert got[2] == want[2] or (math.isnan(got[2]) and math.isnan(want[2]))
