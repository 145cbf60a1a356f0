"""Live mode chooses the motion model from the stream as an offline run chooses it from its log
(graphnav/online/warmup.py, docs/live.md "The motion model"): a warm-up holds the first records, the
navigator is built with the offline rule on them, and every held record is replayed into it."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from graphnav.geodesy import LocalFrame
from graphnav.graph.navigator import Navigator
from graphnav.graph.smoother_config import SmootherConfig
from graphnav.io.nmea_out import gga, hdt, rmc, rot, vtg, zda
from graphnav.log import NavLog, Record
from graphnav.online.live_runner import LiveRunner
from graphnav.online.warmup import MIN_PERIOD_S, WARMUP_PERIODS, WarmUp, WarmUpRule, live_estimator
from graphnav.result import Estimate

T0 = 1.7e9  # POSIX seconds: dated sentences
FRAME = LocalFrame(43.5, 16.4)


def vessel_sentences(n: int = 40, *, odometry: bool = False, seed: int = 0) -> list[tuple[float, str]]:
    """A boat crabbing in a current, 1 Hz: heading 0.5 rad off its course; GGA + RMC (SOG/COG) + VTG + HDT
    (+ ROT when ``odometry``: the decoder's rate of turn + SOG records), fixes with 1.5 m noise."""
    rng = np.random.default_rng(seed)
    out = []
    x = y = 0.0
    for k in range(n):
        t = T0 + k
        course = 0.3 * math.sin(2 * math.pi * k / 120.0)
        sog = 2.0
        x, y = x + sog * math.cos(course), y + sog * math.sin(course)
        lat, lon = FRAME.to_geodetic(x + rng.normal(0, 1.5), y + rng.normal(0, 1.5))
        heading = course + 0.5 + rng.normal(0, 0.01)
        out += [(t, zda(t)), (t, gga(t, float(lat), float(lon), hdop=1.5 / 3.0)),
                (t, rmc(t, float(lat), float(lon), sog, course)), (t, vtg(sog, course)), (t, hdt(heading))]
        if odometry:
            out.append((t, rot(0.3 * 2 * math.pi / 120.0 * math.cos(2 * math.pi * k / 120.0))))
    return out


class Taped(LiveRunner):
    """The live loop without sockets, keeping every record handed over and every estimate emitted."""

    def __init__(self, estimator, **kw) -> None:
        super().__init__(["udp://127.0.0.1:9"], estimator, origin=(FRAME.lat0, FRAME.lon0), **kw)
        self.taped: list[Record] = []
        self.out: list[Estimate] = []
        emit = self.sink.emit

        def keep(est, arrival, frame, kind=""):
            self.out.append(est)
            emit(est, arrival, frame, kind)

        self.sink.emit = keep  # type: ignore[method-assign]

    def _record(self, rec, arrival):
        self.taped.append(rec)
        super()._record(rec, arrival)

    def play(self, sents: list[tuple[float, str]]) -> dict:
        a0 = time.perf_counter()
        for i, (_, s) in enumerate(sents):
            self.feed_sentence(s.encode(), a0 + i)  # arrivals never ahead of the stream: no time outliers
        flush = self.estimator.flush()
        for e in getattr(self.estimator, "replayed_out", ()):
            self.sink.emit(e, None, None)
        if flush is not None:
            self.sink.emit(flush, None, None)
        return self.summary()


def offline(records: list[Record], solver: str = "isam2", **kw) -> tuple[Navigator, list[Estimate]]:
    """The offline navigator (``Navigator.for_log``, motion auto) on the same records, record by record."""
    nav = Navigator.for_log(NavLog(records), SmootherConfig.from_options({"solver": solver, **kw}))
    out = []
    for r in records:
        e = nav.add(r)
        out += [*nav.coasted_out, *([e] if e is not None else [])]
    f = nav.flush()
    return nav, out + ([f] if f is not None else [])


@pytest.mark.parametrize("solver", ["isam2", "fixed-lag"])
def test_a_vessel_stream_gets_the_vessel_graph_and_the_offline_estimates(solver):
    r = Taped(live_estimator(solver, {})())
    summary = r.play(vessel_sentences())
    assert summary["motion"] == "vessel" and "heading" in summary["motion_reason"]
    assert summary["warmup"]["records"] > 0
    nav, off = offline(r.taped, solver)
    assert nav.builder.nav and nav.cfg.motion == "vessel"
    # nothing lost: every record reached the navigator, and as many estimates came out, at the same times
    assert r.estimator.nav.n_records == len(r.taped) == summary["records"]
    assert summary["estimates"] == len(off) == len(r.out)
    assert [e.t for e in r.out] == [e.t for e in off]
    live_xy = np.array([e.vec[:2] for e in r.out])
    off_xy = np.array([e.vec[:2] for e in off])
    assert np.max(np.linalg.norm(live_xy - off_xy, axis=1)) < 1e-6


def test_without_the_warm_up_the_same_stream_gets_the_pose2_graph():
    """The defect being fixed: the navigator made before any record (make_online) is the Pose2 graph."""
    from graphnav.online.runner import make_online

    r = Taped(make_online("isam2"))
    r.play(vessel_sentences())
    assert not r.estimator.builder.nav


def test_an_explicit_motion_skips_the_warm_up():
    make = live_estimator("isam2", {"motion": "odometry"})
    assert isinstance(make(), Navigator)
    r = Taped(make())
    summary = r.play(vessel_sentences())
    assert "warmup" not in summary and not r.estimator.builder.nav
    assert summary["motion"] == "odometry" and summary["motion_reason"] == "given (motion=odometry)"
    vessel = Taped(live_estimator("isam2", {"motion": "vessel", "imu": {"vessel_position_walk": 0.2}})())
    vessel.play(vessel_sentences())
    assert isinstance(vessel.estimator, Navigator) and vessel.estimator.builder.nav
    assert vessel.estimator.builder.motion.imu.vessel_walk == pytest.approx(0.2)  # the config's imu section


def test_the_ekf_has_no_warm_up():
    assert not isinstance(live_estimator("ekf", {})(), WarmUp)


def test_rate_of_turn_odometry_keeps_the_offline_choice():
    """ROT + SOG odometry is no odometer (auto_motion): vessel, as offline with meta["odometry"]."""
    r = Taped(live_estimator("isam2", {})())
    summary = r.play(vessel_sentences(odometry=True))
    assert any(x.kind == "odometry" for x in r.taped)
    assert summary["motion"] == "vessel" and "rate of turn" in summary["motion_reason"]


def _records_with(extra) -> list[Record]:
    from graphnav.log import Gnss, GnssVelocity, Heading

    recs: list[Record] = []
    for k in range(12):
        t = float(k)
        recs += [Gnss(t, 2.0 * t, 0.0, 1.0), GnssVelocity(t, 2.0, 0.0, 0.1), Heading(t, 0.0, 0.02), *extra(t)]
    return recs


def _choice(recs: list[Record], **kw) -> str | None:
    w = WarmUp("isam2", {}, **kw)
    for rec in recs:
        w.add(rec)
    w.flush()
    assert w.nav is not None and w.nav.n_records == len(recs)  # every record held reached the navigator
    return w.motion


def test_an_odometer_or_a_lidar_keeps_the_pose2_graph():
    """Odometry that is an odometer (``rot_odometry=False``: not a decoder's rate of turn + SOG) or LiDAR
    scans: the Pose2 graph, as offline; the same records without them: the vessel graph."""
    from graphnav.log import Odometry, Scan

    angles = np.linspace(-math.pi, math.pi, 90, endpoint=False)
    scan = lambda t: [Scan(t, 10.0 + np.cos(3 * angles), angles)]  # noqa: E731
    odo = lambda t: [Odometry(t, 2.0, 0.0)]  # noqa: E731
    assert _choice(_records_with(lambda t: [])) == "vessel"
    assert _choice(_records_with(scan)) == "odometry"
    assert _choice(_records_with(odo), rot_odometry=False) == "odometry"
    assert _choice(_records_with(odo)) == "vessel"  # live decoders' odometry: rate of turn + SOG


def test_warm_up_rule_lengths():
    """Default: every kind seen twice and WARMUP_PERIODS x the slowest interval after the first fix."""
    from graphnav.log import Gnss, Heading, WaterSpeed

    rule = WarmUpRule()
    ended = None
    for k in range(40):
        t = 0.1 * k
        recs = [Heading(t, 0.0, 0.02)] + ([Gnss(t, 0.0, 0.0, 1.0)] if k % 10 == 3 else [])
        recs += [WaterSpeed(t, 1.0, 0.1)] if k % 5 == 0 else []
        for rec in recs:
            if ended is None and rule.add(rec) is not None:
                ended = rec.t
    # the slowest kind: the fixes, every 1 s from t = 0.3: the warm-up ends 2 s after the first fix
    assert ended == pytest.approx(0.3 + WARMUP_PERIODS * 1.0)
    fast = WarmUpRule()  # a 10 Hz bus: its slowest kind's interval taken as 1 s (MIN_PERIOD_S)
    ended = next(k * 0.1 for k in range(100) if fast.add(Gnss(k * 0.1, 0.0, 0.0, 1.0)) is not None)
    assert ended == pytest.approx(WARMUP_PERIODS * MIN_PERIOD_S)
    given = WarmUpRule(0.0)
    assert given.add(Heading(0.0, 0.0, 0.02)) is None and given.add(Gnss(0.5, 0.0, 0.0, 1.0)) is not None


def test_a_stream_that_ends_inside_the_warm_up_loses_nothing():
    """Two seconds of stream (the warm-up needs 2 s after the first fix and each kind twice): the end of
    input ends it, every record is replayed and every estimate published, as offline."""
    r = Taped(live_estimator("isam2", {})())
    summary = r.play(vessel_sentences(2))
    assert summary["warmup"]["ended_by"] == "the end of the input" and summary["motion"] == "vessel"
    _, off = offline(r.taped)
    assert summary["records"] == len(r.taped) == r.estimator.nav.n_records
    assert summary["estimates"] == len(off) > 0


def test_the_vessel_position_walk_is_estimated_from_the_stream():
    """A receiver whose fixes wander 0.4 m/sqrt(s) from its exact SOG/COG (as tests/graph/test_position_walk.py):
    live, the walk starts at the default and is estimated from the stream; by the end it is the one the
    offline run estimates from the whole log (within 15 %: the last estimate, at 184 s, misses the last 16 s)."""
    from _logfactory import wandering_fixes

    from graphnav.graph.imu_chain import ImuConfig
    from graphnav.graph.position_walk import position_walk

    recs = wandering_fixes()
    w = WarmUp("fixed-lag", {"keyframe_period": 1.0})
    for rec in recs:
        w.add(rec)
    w.flush()
    imu = w.nav.builder.motion.imu
    assert w.motion == "vessel" and w.walker is not None and w.walker.updates >= 3
    whole = position_walk(NavLog(recs))["walk"]
    print(f"walk: live {imu.vessel_walk:.3f}, whole log {whole:.3f}, true 0.4")
    assert imu.vessel_walk == pytest.approx(whole, rel=0.15) and imu.vessel_walk > 10 * ImuConfig().integration_sigma
    assert w.motion_choice()["position_walk_live"]["walk"] == imu.vessel_walk
    given = WarmUp("fixed-lag", {"keyframe_period": 1.0, "imu": {"vessel_position_walk": 0.1}})  # given: kept
    for rec in recs[:300]:
        given.add(rec)
    assert given.walker is None and given.nav.builder.motion.imu.vessel_walk == pytest.approx(0.1)


def test_graphnav_live_cli_says_which_motion_and_why(tmp_path):
    """``graphnav live`` (motion auto) over UDP: the summary JSON names the vessel graph and why."""
    import json
    import socket

    from _live import send_and_wait, start_live

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    p = start_live(tmp_path / "o", "--nmea", f"udp://127.0.0.1:{port}", "--idle-exit", "1.5", "--duration", "60",
                   "--json", "--origin", f"{FRAME.lat0},{FRAME.lon0}")
    out, err = send_and_wait(p, port, [line for _, line in vessel_sentences(20)], pause_s=0.002, timeout_s=30)
    assert p.returncode == 0, err
    obj = json.loads(out)
    assert obj["motion"] == "vessel" and obj["warmup"]["records"] > 0 and "motion vessel" in err
    assert obj["records"] == 60 and obj["estimates"] > 0
