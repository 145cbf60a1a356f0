"""The column-wise record check (graphnav.log.suspect_rows) a reader uses before the scalar one:
every record check_record rejects must be flagged, whatever the values, for every record type; and
valid columns flag nothing (else the fast path would be no faster)."""

from __future__ import annotations

import math
from dataclasses import MISSING, fields
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from graphnav.errors import LogError
from graphnav.io import load_log
from graphnav.log import ARRAY_FIELDS, RECORD_TYPES, KnownBeacon, Limits, check_record, suspect_rows
from graphnav.sim.heel import heeled
from tests._logfactory import every_record_log

TYPES = [c for c in (*RECORD_TYPES.values(), KnownBeacon) if not set(f.name for f in fields(c)) & set(ARRAY_FIELDS)]
EDGES = [0.0, -0.0, 1e-9, 1e-10, -1.0, 1.0, math.pi / 2, math.pi / 2 + 1e-12, 1e4, 1e4 + 1, 1e6, 1e7, 1e10, 1e11,
         1e300, -1e300, math.inf, -math.inf, math.nan, 55.0, 60.0]
VALUE = st.one_of(st.sampled_from(EDGES), st.floats(allow_nan=True, allow_infinity=True))
TEXT = st.one_of(st.sampled_from(["", "B1", "gps2", "x" * 64, "x" * 65, "a\nb", "\x00"]), st.text(max_size=70))


def _rejected(cls, row: dict, lim: Limits) -> bool:
    try:
        check_record(cls(**row), lim)
    except LogError:
        return True
    return False


@settings(max_examples=400, deadline=None)
@given(cls=st.sampled_from(TYPES), data=st.data(), n=st.integers(1, 4),
       lim=st.sampled_from([Limits(), Limits(max_speed=math.inf, max_beacon_range=math.inf)]))
def test_every_rejected_record_is_flagged(cls, data, n, lim):
    """Valid records (every number 0.5, names "B1") with one or two fields set to an edge value or
    any float: a single fault must not slip through among valid fields."""
    names = [f.name for f in fields(cls)]
    omit = {f.name for f in fields(cls) if f.default is not MISSING and data.draw(st.booleans())}
    rows = []
    for _ in range(n):
        row = {k: ("B1" if k in ("id", "source") else 0.5) for k in names if k not in omit}
        for k in data.draw(st.lists(st.sampled_from(names), min_size=0, max_size=2)):
            row[k] = data.draw(TEXT if k in ("id", "source") else VALUE)
        rows.append(row)
    keys = [k for k in names if all(k in r for r in rows)]
    cols = {k: ([r[k] for r in rows] if k in ("id", "source") else np.array([r[k] for r in rows], dtype=float))
            for k in keys}
    rows = [{k: r[k] for k in keys} for r in rows]
    flagged = suspect_rows(cls, cols, lim)
    for i, row in enumerate(rows):
        if _rejected(cls, row, lim):
            assert flagged[i], (cls.__name__, row)


@pytest.mark.parametrize("cls", TYPES, ids=lambda c: c.__name__)
def test_every_single_fault_at_every_edge_is_flagged(cls):
    """Exhaustive: each field of each type set to each edge value (text fields to each edge text),
    the others valid, under the default and the API limits."""
    names = [f.name for f in fields(cls)]
    texts = ["", "B1", "x" * 64, "x" * 65, "a\nb", "\x00", 3.0]
    for lim in (Limits(), Limits(max_speed=math.inf, max_beacon_range=math.inf)):
        for k in names:
            rows = [{n: ("B1" if n in ("id", "source") else 0.5) for n in names} for _ in
                    (texts if k in ("id", "source") else EDGES)]
            for row, v in zip(rows, texts if k in ("id", "source") else EDGES, strict=True):
                row[k] = v
            cols = {n: ([r[n] for r in rows] if n in ("id", "source") else np.array([r[n] for r in rows], dtype=float))
                    for n in names}
            flagged = suspect_rows(cls, cols, lim)
            rejected = [_rejected(cls, r, lim) for r in rows]
            assert any(rejected) or k in ("id", "source")
            for i, row in enumerate(rows):
                if rejected[i]:
                    assert flagged[i], (cls.__name__, k, row[k])


def test_non_float_values_are_flagged():
    cls = RECORD_TYPES["gnss"]
    cols = {"t": [1.0, 2], "x": np.zeros(2), "y": np.zeros(2), "sigma": np.ones(2)}
    assert _rejected(cls, {"t": 2, "x": 0.0, "y": 0.0, "sigma": 1.0}, Limits())
    assert suspect_rows(cls, cols).tolist() == [False, True]


_HARBOUR = load_log(Path(__file__).resolve().parents[2] / "data" / "harbour.npz")
_ATTITUDE = heeled(_HARBOUR.sliced(0.0, 20.0), attitude_hz=5.0).of("attitude")  # AHRS roll and pitch records


@pytest.mark.parametrize("kind", sorted(k for k, c in RECORD_TYPES.items() if c in TYPES))
def test_valid_records_flag_nothing(kind):
    recs = [r for r in [*every_record_log().records, *_HARBOUR.records, *_ATTITUDE] if type(r) is RECORD_TYPES[kind]]
    if not recs:
        pytest.skip(f"the factory log has no {kind} record")
    cls = RECORD_TYPES[kind]
    for r in recs:
        check_record(r)
    cols = {f.name: ([getattr(r, f.name) for r in recs] if f.name in ("id", "source")
                     else np.array([getattr(r, f.name) for r in recs], dtype=float)) for f in fields(cls)}
    assert not suspect_rows(cls, cols).any()
