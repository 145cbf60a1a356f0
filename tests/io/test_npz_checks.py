"""The npz reader's whole-array checks: a scan is checked record by record only when a scalar field or
a beam's angle could fail (every beam with a return needs a finite angle; a beam without one may have
none), and the record order must take each kind's arrays exactly (records interleaved as written,
those a lenient read skips left out)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from graphnav.errors import LogError
from graphnav.io.npz import KINDS, read_npz, write_npz
from graphnav.log import Gnss, NavLog, Scan


def _log() -> NavLog:
    recs = []
    for i in range(6):
        t = 0.1 * i
        recs.append(Scan(t, np.array([1.0, 2.0, math.nan]), np.array([-0.1, 0.0, 0.1]), 30.0))
        recs.append(Gnss(t + 0.05, float(i), 0.0, 1.0))
    return NavLog(recs, [], {})


def _rewrite(src, dst, **changes) -> None:
    with np.load(src) as z:
        arrays = {k: z[k] for k in z.files}
    arrays.update(changes)
    np.savez_compressed(dst, **arrays)


def test_a_scan_beam_with_a_return_needs_a_finite_angle(tmp_path):
    write_npz(_log(), tmp_path / "a.npz")
    with np.load(tmp_path / "a.npz") as z:
        ang = z["scan/angles"].copy()
    no_return = ang.copy()
    no_return[3 * 2 + 2] = np.nan  # scan 2's third beam: no return (NaN range)
    _rewrite(tmp_path / "a.npz", tmp_path / "b.npz", **{"scan/angles": no_return})
    assert len(read_npz(tmp_path / "b.npz").of("scan")) == 6
    with_return = ang.copy()
    with_return[3 * 4 + 1] = np.nan  # scan 4's second beam: a return at 2 m
    _rewrite(tmp_path / "a.npz", tmp_path / "c.npz", **{"scan/angles": with_return})
    with pytest.raises(LogError, match="finite angle"):
        read_npz(tmp_path / "c.npz")
    log = read_npz(tmp_path / "c.npz", lenient=True)
    assert log.meta["skipped"] == 1 and "record 4" in log.meta["skipped_errors"][0]
    assert [r.t for r in log.of("scan")] == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.5])
    assert [r.kind for r in log.records[:4]] == ["scan", "gnss", "scan", "gnss"]  # still interleaved
    assert len(log.of("gnss")) == 6


def test_the_order_must_take_each_kinds_records_exactly(tmp_path):
    write_npz(_log(), tmp_path / "a.npz")
    with np.load(tmp_path / "a.npz") as z:
        order = z["order"].copy()
    assert [r.t for r in read_npz(tmp_path / "a.npz").records] == pytest.approx(
        [0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.55])
    imu = KINDS.index("imu")  # a kind without arrays in this file
    for extra in (-1, len(KINDS), 100, imu):
        _rewrite(tmp_path / "a.npz", tmp_path / "b.npz", order=np.append(order, extra).astype(np.int16))
        with pytest.raises(LogError, match="record order does not match"):
            read_npz(tmp_path / "b.npz")
    _rewrite(tmp_path / "a.npz", tmp_path / "b.npz", order=order[:-1])  # one record short: its kind's arrays say so
    with pytest.raises(LogError, match="expected 5 values, got 6"):
        read_npz(tmp_path / "b.npz")
