"""A whole log fed at once (``Estimator.feed``: runs of IMU samples and truth poses into the graph
together, ``graphnav.graph.navigator.feed``) gives what ``add`` of each record gives: the same online estimates,
in the same order, and the same smoothed result and counts -- also with a late IMU sample and with
records no reader checked."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from graphnav import estimators
from graphnav.graph.navigator import Navigator, feed
from graphnav.io import load_log
from graphnav.log import NavLog

HARBOUR = Path(__file__).resolve().parents[2] / "data" / "harbour.npz"


@pytest.fixture(scope="module")
def harbour() -> NavLog:
    if not HARBOUR.exists():
        pytest.skip("data/harbour.npz not generated")
    log = load_log(HARBOUR).sliced(None, 25.0)
    assert log.counts()["imu"] > 1000 and log.counts()["scan"] > 100
    return log


def _run(log: NavLog, whole: bool) -> tuple[list[tuple[float, np.ndarray, np.ndarray]], object]:
    out: list[tuple[float, np.ndarray, np.ndarray]] = []
    est = estimators.get("isam2")(log, on_estimate=lambda t, p, c: out.append((t, np.array(p), np.array(c))))
    if whole:
        est.feed(log.records)
    else:
        for rec in log.records:
            est.add(rec)
    return out, est.finish()


def _same(log: NavLog) -> None:
    a, ra = _run(log, whole=False)
    b, rb = _run(log, whole=True)
    assert len(a) == len(b) > 20
    for (ta, pa, ca), (tb, pb, cb) in zip(a, b, strict=True):
        assert ta == tb
        np.testing.assert_array_equal(pa, pb)
        np.testing.assert_array_equal(ca, cb)
    np.testing.assert_array_equal(ra.trajectory.poses, rb.trajectory.poses)
    np.testing.assert_array_equal(ra.online.poses, rb.online.poses)
    for key in ("records", "imu", "truth", "late", "ignored", "keyframes"):
        assert ra.info.get(key) == rb.info.get(key), key


def test_feeding_the_log_equals_adding_each_record(harbour):
    _same(harbour)


def test_a_late_imu_sample_and_unchecked_records_are_taken_alike(harbour):
    """The navigator's feed (records out of order, as two sockets may bring them; some not checked)."""
    recs = list(harbour.records)
    imu = [i for i, r in enumerate(recs) if r.kind == "imu"]
    recs.insert(imu[len(imu) // 2] + 40, recs.pop(imu[len(imu) // 2]))  # 0.4 s late: behind a keyframe's batch
    flags = [i % 50 != 7 for i in range(len(recs))]
    out: dict[bool, list] = {False: [], True: []}
    navs = {}
    for whole in (False, True):
        nav = navs[whole] = Navigator.for_log(harbour, on_estimate=lambda t, p, c, w=whole: out[w].append((t, p, c)))
        if whole:
            feed(nav, recs, flags)
        else:
            for rec, ok in zip(recs, flags, strict=True):
                nav.add(rec, checked=ok)
    assert len(out[False]) == len(out[True]) > 20
    for (ta, pa, ca), (tb, pb, cb) in zip(out[False], out[True], strict=True):
        assert ta == tb
        np.testing.assert_array_equal(pa, pb)
        np.testing.assert_array_equal(ca, cb)
    a, b = navs[False].result(), navs[True].result()
    assert a.info["late"] >= 1
    assert [a.info[k] for k in ("records", "imu", "truth", "late", "ignored")] == [
        b.info[k] for k in ("records", "imu", "truth", "late", "ignored")]
    np.testing.assert_array_equal(a.trajectory.poses, b.trajectory.poses)
