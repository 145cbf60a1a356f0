"""Live time sanity: a sentence far from the stream's clock is an outlier (counted, warned once, never
moving the clock); a sustained step of the clock is accepted as a re-sync (docs/live.md)."""

from __future__ import annotations

import json
import logging
import socket
import time

import pytest
from _harbour import harbour_trial
from _live import send_and_wait, start_live

from graphnav.io.nmea_out import _hhmmss, sentence
from graphnav.log import NavLog
from graphnav.online.live_runner import RESYNC_STAMPS, TIME_TOLERANCE_S, LiveRunner, StreamClock
from graphnav.online.nmea_replay import log_sentences
from graphnav.online.runner import make_online

HOUR = 3600.0


def retimed(s: str, t: float) -> str:
    """The sentence with its UTC time field set to ``t`` (GGA, RMC, ZDA: field 1), checksum redone."""
    f = s[1:s.index("*")].split(",")
    f[1] = _hhmmss(t)
    return sentence(",".join(f))


def stream(duration: float = 12.1) -> tuple[NavLog, list[tuple[float, str]]]:
    log = harbour_trial(duration=duration, rate=10.0)
    return log, list(log_sentences(log))


def feed(sents: list[tuple[float, str]], estimator: str = "ekf", speed: float = 1.0, **kw) -> LiveRunner:
    """Every sentence through the live path (decode, clock, estimator), arriving ``speed`` x real time."""
    r = LiveRunner(["udp://127.0.0.1:9"], make_online(estimator), restart=lambda: make_online(estimator), **kw)
    a0, t0 = time.perf_counter(), sents[0][0]
    for t, s in sents:
        r.feed_sentence(s.encode(), a0 + ((t - t0) / speed if speed else 0.0))
    return r


def clean(estimator: str, duration: float = 12.1) -> int:
    """Estimates from the undamaged stream: the ekf makes one per fix (the first epoch starts it),
    the navigation graph (fixed-lag) one per keyframe of its 0.5 s grid."""
    return feed(stream(duration)[1], estimator).summary()["estimates"]


def gga_indices(sents: list[tuple[float, str]]) -> list[int]:
    return [i for i, (_, s) in enumerate(sents) if s[3:6] == "GGA"]


# -- the clock alone
def test_clock_rule():
    c = StreamClock(tol=10.0, resync=3)
    assert c.check(1000.0, 0.0) == "ok"
    assert c.check(1000.1, 0.1) == "ok"
    assert c.check(1000.1 + 11 * HOUR, 0.2) == "outlier" and c.t0 == 1000.1   # never moves the clock
    assert c.check(995.0, 0.3) == "ok" and c.t0 == 1000.1                      # a little late: the estimator's business
    assert c.check(980.0, 0.3) == "outlier"                                     # 20 s back
    assert c.check(1000.1 + 600.0, 600.3) == "ok"                               # a 10-min gap that the wall clock saw
    assert c.check(1000.1 + 620.0, 600.4) == "outlier"                          # 20 s ahead of the wall clock
    # a replay at 10x: 0.1 s of stream per 0.01 s of wall time, for 10 000 steps
    c2, ok = StreamClock(), 0
    for k in range(10_000):
        ok += c2.check(1.7e9 + 0.1 * k, 0.01 * k) == "ok"
    assert ok == 10_000
    # as fast as possible (no wall time at all): steps of 1 s are fine
    c3 = StreamClock()
    assert all(c3.check(1.7e9 + k, 5.0) == "ok" for k in range(1000))


def test_clock_step_needs_distinct_consistent_stamps():
    c = StreamClock(tol=10.0, resync=3)
    c.check(0.0, 0.0)
    assert [c.check(t, 0.1) for t in (HOUR, HOUR, HOUR)] == ["outlier"] * 3  # one stamp repeated is not a step
    assert c.check(HOUR + 0.1, 0.2) == "outlier"
    assert c.check(-5 * HOUR, 0.2) == "outlier"          # disagrees with the run: a new run starts
    assert c.check(HOUR + 0.2, 0.3) == "outlier"         # ... and again
    assert c.check(HOUR + 0.3, 0.4) == "outlier"
    assert c.check(HOUR + 0.4, 0.5) == "resync" and c.t0 == HOUR + 0.4 and c.resyncs == 1
    assert c.step == pytest.approx(HOUR + 0.4)
    assert c.check(0.5, 0.6) == "outlier"                # the old time base is the outlier now


# -- through the live path
@pytest.mark.parametrize("estimator", ["ekf", "fixed-lag"])
def test_one_sentence_eleven_hours_ahead_is_an_outlier(estimator, caplog):
    """The issue's case: one GGA with a valid checksum 11 h ahead used to leave 5 estimates for 121
    fixes (every later record 'late')."""
    _, sents = stream()
    ggas = gga_indices(sents)
    assert len(ggas) == 121
    t, s = sents[ggas[5]]
    sents[ggas[5]] = (t, retimed(s, t + 11 * HOUR))
    with caplog.at_level(logging.WARNING, logger="graphnav.live"):
        r = feed(sents, estimator)
    summary = r.summary()
    assert summary["time_outliers"] == 1 and summary["clock_resyncs"] == 0
    assert sum("time outlier" in m for m in caplog.messages) == 1
    info = r.estimator.info()
    assert info["late"] == 0 and info["gnss"] == 120          # every other fix reached the estimator
    assert summary["estimates"] >= clean(estimator) - 2      # (fixed-lag: one per 0.5 s keyframe)


def test_many_outliers_are_counted_and_warned_once(caplog):
    _, sents = stream()
    for i in gga_indices(sents)[3::10]:  # every 10th fix 11 h ahead or 5 h back, alternating
        t, s = sents[i]
        sents[i] = (t, retimed(s, t + (11 * HOUR if i % 2 else -5 * HOUR)))
    with caplog.at_level(logging.WARNING, logger="graphnav.live"):
        r = feed(sents, "fixed-lag")
    assert r.summary()["time_outliers"] == 12 and sum("time outlier" in m for m in caplog.messages) == 1
    assert r.estimator.info()["late"] == 0 and r.summary()["estimates"] == clean("fixed-lag")  # one per keyframe


@pytest.mark.parametrize("step", [HOUR, -HOUR])
def test_a_sustained_clock_step_is_accepted_as_a_resync(step, caplog):
    """From fix 40 on, every time stamp is ``step`` away and stays there: after RESYNC_STAMPS distinct
    stamps the stream clock re-syncs, the run's sentences are decoded again, nothing is lost (a
    step back starts a fresh estimator, whose first epoch yields no estimate)."""
    log, sents = stream()
    k = 40
    t_cut = log.of("gnss")[k].t
    assert _hhmmss(t_cut + step)[:2] != "00"  # the step stays inside the day (ZDA dates unchanged)
    timed = ("GGA", "ZDA", "RMC")
    sents = [(t, retimed(x, t + step) if t >= t_cut - 1e-9 and x[3:6] in timed else x) for t, x in sents]
    with caplog.at_level(logging.WARNING, logger="graphnav.live"):
        r = feed(sents, "ekf")
    summary = r.summary()
    assert summary["clock_resyncs"] == 1 and summary["time_outliers"] == 0
    assert any("clock step" in m for m in caplog.messages)
    est = r.estimator.info()
    assert est["late"] == 0
    if step > 0:  # every fix reached the filter; it saw a 1-hour gap
        assert est["gnss"] == 121 and summary["estimates"] >= 121 - 1
    else:
        assert est["gnss"] == 121 - k and summary["estimates"] >= 121 - 2  # the restarted filter's first epoch


def test_the_first_date_rebases_the_clock_without_an_outlier():
    """A stream whose first fix comes before any date: seconds of the day, then POSIX time once a
    ZDA arrives -- a jump of whole days that is the decoder's, not the stream's."""
    _, sents = stream(3.05)
    first_zda = next(i for i, (_, s) in enumerate(sents) if s[3:6] == "ZDA")
    del sents[first_zda]
    r = feed(sents, "fixed-lag")
    assert r.summary()["time_outliers"] == 0 and r.summary()["clock_resyncs"] == 0
    assert r.estimator.info()["late"] == 0


def test_a_replay_as_fast_as_possible_has_no_outliers():
    _, sents = stream(30.0)
    r = feed(sents, "fixed-lag", speed=0.0)
    assert r.summary()["time_outliers"] == 0 and r.summary()["estimates"] == clean("fixed-lag", 30.0) == 60


def test_scan_far_from_the_clock_is_an_outlier():
    _, sents = stream(2.0)
    r = feed(sents, "fixed-lag")
    t_now = r.nmea.clock.t0
    packet = {"t": t_now + 11 * HOUR, "type": "scan", "ranges": [10.0, 11.0, 12.0], "angles": [0.0, 0.1, 0.2]}
    r.feed_scan(json.dumps(packet).encode(), r.nmea.clock.a0)
    assert r.summary()["time_outliers"] == 1 and not r.scans.waiting


def test_constants_are_the_documented_ones():
    assert TIME_TOLERANCE_S == 10.0 and RESYNC_STAMPS == 10


def test_graphnav_live_cli_with_an_eleven_hour_sentence(tmp_path):
    """End to end over UDP, as the issue ran it."""
    _, sents = stream()
    ggas = gga_indices(sents)
    t, s = sents[ggas[5]]
    sents[ggas[5]] = (t, retimed(s, t + 11 * HOUR))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    p = start_live(tmp_path / "o", "--nmea", f"udp://127.0.0.1:{port}", "--estimator", "ekf", "--idle-exit", "2",
                   "--duration", "60", "--json")
    epochs = ["\r\n".join(x for _, x in sents[k:k + 6]) for k in range(0, len(sents), 6)]  # one per datagram
    out, err = send_and_wait(p, port, epochs, pause_s=0.01, timeout_s=60)  # (ZDA, GGA, HDT, VTG, ROT) at 100 Hz
    assert p.returncode == 0, err
    obj = json.loads(out)
    assert obj["time_outliers"] == 1 and obj["estimates"] >= 119 and obj["estimator"]["late"] == 0
    assert err.count("time outlier") == 1
