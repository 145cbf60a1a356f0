"""Signal K deltas in and out (graphnav.io.signalk): each path's record with known values, a log
round trip through record deltas, the published solution delta parsed back, the own vessel only,
errors naming file/line/field, and a hypothesis fuzz (a result or a LogError, bounded memory)."""

from __future__ import annotations

import json
import math
import tracemalloc

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from graphnav.errors import LogError
from graphnav.geodesy import LocalFrame
from graphnav.io import load_log
from graphnav.io.signalk import SignalKDecoder, iso_time, parse_time, read_signalk, record_delta, solution_delta
from graphnav.log import Attitude, Gnss, GnssVelocity, Heading, NavLog, Odometry, WaterSpeed

T = "2014-08-15T19:00:00.540Z"
POSIX = 1408129200.54


def _delta(values, t=T, src="n2k.160", context="vessels.urn:mrn:imo:mmsi:230000001", meta=None):
    upd = {"$source": src, "timestamp": t, "values": [{"path": p, "value": v} for p, v in values]}
    if meta:
        upd["meta"] = meta
    return {"context": context, "updates": [upd]}


def _file(tmp_path, objs, name="log.sk"):
    p = tmp_path / name
    p.write_text("\n".join(json.dumps(o) for o in objs) + "\n")
    return p


def test_paths_give_records_with_known_values(tmp_path):
    objs = [
        {"name": "signalk-server", "version": "2.0", "self": "vessels.urn:mrn:imo:mmsi:230000001"},
        _delta([("navigation.gnss.horizontalDilution", 0.8), ("navigation.gnss.methodQuality", "DGNSS fix")]),
        _delta([("navigation.position", {"latitude": 59.5, "longitude": 24.25})]),
        _delta([("navigation.speedOverGround", 2.0), ("navigation.courseOverGroundTrue", 0.5)]),
        _delta([("navigation.rateOfTurn", 0.01)], src="n2k.27"),
        _delta([("navigation.headingTrue", 1.0)]),
        _delta([("navigation.magneticVariation", 0.1), ("navigation.headingMagnetic", 1.0)]),
        _delta([("navigation.attitude", {"roll": 0.1, "pitch": 0.05, "yaw": None})]),
        _delta([("navigation.speedThroughWater", 3.0), ("environment.depth.belowKeel", 4.0)]),
        _delta([("navigation.position", {"latitude": 60.0, "longitude": 25.0})],
               context="vessels.urn:mrn:imo:mmsi:999999999"),  # an AIS target: not ours
    ]
    log = load_log(_file(tmp_path, objs, "log.json"))  # sniffed as Signal K
    assert log.meta["format"] == "signalk" and log.meta["contexts"] == {"vessels.urn:mrn:imo:mmsi:999999999": 1}
    g = log.of("gnss")
    assert len(g) == 1 and g[0].t == pytest.approx(POSIX) and g[0].sigma == pytest.approx(0.8)
    assert g[0].source == "n2k.160"
    v = log.of("gnss_velocity")[0]
    assert (v.vx, v.vy) == pytest.approx((2.0 * math.sin(0.5), 2.0 * math.cos(0.5)))
    o = log.of("odometry")[0]
    assert (o.v, o.w, o.source) == (2.0, -0.01, "n2k.27")
    h = log.of("heading")
    assert h[0].yaw == pytest.approx(math.pi / 2 - 1.0) and h[1].yaw == pytest.approx(math.pi / 2 - 1.1)
    a = log.of("attitude")[0]
    assert (a.roll, a.pitch) == (0.1, -0.05)
    assert log.of("water_speed")[0].v == 3.0
    assert log.meta["paths"]["environment.depth.belowKeel"] == 1


def test_log_round_trips_through_record_deltas(tmp_path):
    frame = LocalFrame(59.5, 24.25)
    recs = [Gnss(POSIX, 10.0, -5.0, 4.5, source="a"), Heading(POSIX + 0.1, 0.3, math.radians(0.5)),
            GnssVelocity(POSIX + 0.2, 1.0, -2.0, 0.1), Odometry(POSIX + 0.3, 2.236, 0.02),
            Attitude(POSIX + 0.4, 0.05, -0.02), WaterSpeed(POSIX + 0.5, 2.5, 0.2)]
    p = _file(tmp_path, [record_delta(r, frame) for r in recs])
    back = read_signalk(p, origin=(59.5, 24.25))
    assert [r.kind for r in back.records] == [r.kind for r in recs]
    g = back.of("gnss")[0]
    assert (g.x, g.y) == pytest.approx((10.0, -5.0), abs=1e-6) and g.source == "a"
    assert back.of("heading")[0].yaw == pytest.approx(0.3)
    v = back.of("gnss_velocity")[0]
    assert (v.vx, v.vy) == pytest.approx((1.0, -2.0))
    assert back.of("odometry")[0].w == pytest.approx(0.02)
    assert back.of("attitude")[0].pitch == pytest.approx(-0.02)


def test_solution_delta_parses_back():
    frame = LocalFrame(59.5, 24.25)
    cov = np.diag([4.0, 1.0, 0.01])
    d = solution_delta(POSIX, (30.0, 40.0, 0.2), frame, cov=cov, sog=3.0, cog_yaw=0.25, w=-0.05)
    vals = {v["path"]: v["value"] for v in d["updates"][0]["values"]}
    assert vals["navigation.headingTrue"] == pytest.approx(math.pi / 2 - 0.2)
    assert vals["navigation.courseOverGroundTrue"] == pytest.approx(math.pi / 2 - 0.25)
    assert vals["navigation.rateOfTurn"] == pytest.approx(0.05)  # to starboard
    assert d["updates"][0]["timestamp"] == iso_time(POSIX) and parse_time(iso_time(POSIX)) == pytest.approx(POSIX)
    meta = {m["path"]: m["value"]["uncertainty"] for m in d["updates"][0]["meta"]}
    assert meta["navigation.position"] == pytest.approx(math.sqrt(2.5)) and meta["navigation.headingTrue"] == 0.1
    dec = SignalKDecoder(frame)
    recs = dec.feed(json.loads(json.dumps(d)))
    g = next(r for r in recs if r.kind == "gnss")
    assert (g.x, g.y) == pytest.approx((30.0, 40.0), abs=1e-6) and g.sigma == pytest.approx(math.sqrt(2.5))
    h = next(r for r in recs if r.kind == "heading")
    assert h.yaw == pytest.approx(0.2) and h.sigma == pytest.approx(0.1)


@pytest.mark.parametrize(("obj", "field"), [
    ("not json", "delta"),
    (_delta([("navigation.position", {"latitude": 95.0, "longitude": 0.0})]), "navigation.position.latitude"),
    (_delta([("navigation.headingTrue", "north")]), "navigation.headingTrue"),
    (_delta([("navigation.speedThroughWater", 1.0)], t="yesterday"), "timestamp"),
    ({"context": "vessels.self", "updates": {"values": []}}, "updates"),
])
def test_bad_deltas_name_file_line_and_field(tmp_path, obj, field):
    good = _delta([("navigation.speedThroughWater", 1.0)])
    p = tmp_path / "bad.sk"
    p.write_text(json.dumps(good) + "\n" + (obj if isinstance(obj, str) else json.dumps(obj)) + "\n")
    with pytest.raises(LogError) as ei:
        read_signalk(p)
    assert ei.value.file == str(p) and ei.value.line == 2 and ei.value.field == field
    assert read_signalk(p, lenient=True).meta["skipped"] == 1


_JSON = st.recursive(st.none() | st.booleans() | st.floats(allow_nan=True) | st.integers(-10**30, 10**30)
                     | st.text(max_size=8),
                     lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=6), c, max_size=4),
                     max_leaves=12)
_PATHS = st.sampled_from(["navigation.position", "navigation.headingTrue", "navigation.speedOverGround",
                          "navigation.courseOverGroundTrue", "navigation.rateOfTurn", "navigation.attitude",
                          "navigation.speedThroughWater", "navigation.gnss.horizontalDilution", "x.y"])


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(items=st.lists(st.one_of(
    st.builds(lambda p, v, t: _delta([(p, v)], t=t), _PATHS, _JSON,
              st.sampled_from([T, "2014-08-15T19:00:01Z", "2014-02-30T00:00:00Z", 5, None])),
    _JSON, st.text(max_size=30)), min_size=1, max_size=6), lenient=st.booleans())
def test_fuzz_result_or_logerror_bounded(tmp_path, items, lenient):
    p = tmp_path / "fuzz.sk"
    p.write_text("\n".join(s if isinstance(s, str) else json.dumps(s) for s in items) + "\n")
    tracemalloc.start()
    try:
        try:
            out = read_signalk(p, lenient=lenient)
        except LogError as err:
            assert not lenient and err.file == str(p) and err.line is not None and err.field
            out = None
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 32 << 20
    assert out is None or isinstance(out, NavLog)
