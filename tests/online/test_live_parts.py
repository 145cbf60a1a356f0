"""The parts of live mode on their own (issue #26): the decoder's snapshot/restore, the scan feed and
the sink; the loop over them is tests/online/test_live.py and test_live_time.py."""

from __future__ import annotations

import json
import time

import numpy as np
from _harbour import harbour_trial

from graphnav.io.nmea import DECODER_STATE, NmeaDecoder, parse_sentence
from graphnav.log import NavLog, Scan
from graphnav.online.nmea_replay import log_sentences
from graphnav.online.scan_feed import MAX_WAITING, ScanFeed
from graphnav.online.sink import Sink
from graphnav.result import Estimate


def _state(dec: NmeaDecoder) -> dict:
    """Every attribute of the decoder's parts (``"clock.t"``), the output and configuration aside."""
    return {f"{part}.{k}": v for part in ("ctx", "clock", "positions", "motion", "headings")
            for k, v in vars(getattr(dec, part)).items() if k not in ("out", "ctx", "clock")}


def test_restore_undoes_every_sentence():
    """After ``restore(snapshot())`` around any sentence the decoder is exactly as before it (every
    attribute a sentence can change is in the snapshot), and the next sentence decodes the same."""
    sents = [s for _, s in log_sentences(harbour_trial(duration=6.0, rate=10.0))]
    dec, ref = NmeaDecoder(keep=False), NmeaDecoder(keep=False)
    changed = set()
    for s in sents:
        msg = parse_sentence(s)
        before = _state(dec)
        snap = dec.snapshot()
        dec.feed(msg)
        changed |= {k for k, v in _state(dec).items() if v is not before[k] and v != before[k]}
        dec.restore(snap)
        assert _state(dec) == before
        a, b = dec.feed(msg), ref.feed(msg)  # fed for real now: the same as a decoder never rolled back
        assert a == b and _state(dec).keys() == _state(ref).keys()
    assert {"clock.t", "positions.frame", "positions.last_fix_t", "clock.clock_src"} <= changed <= set(DECODER_STATE)


def _scan(t: float) -> Scan:
    return Scan(t, np.array([1.0, 2.0]), np.array([0.0, 0.1]))


def test_scan_feed_holds_scans_for_the_stream_clock():
    feed = ScanFeed()
    for t in (3.0, 1.0, 2.0):
        feed.hold(_scan(t), 100.0 + t)
    assert feed.due(0.5) == [] and [(s.t, a) for s, a in feed.due(2.0)] == [(1.0, 101.0), (2.0, 102.0)]
    assert [s.t for s, _ in feed.due(9)] == [3.0]
    pkt = {"t": 5.0, "type": "scan", "ranges": [1.0, 2.0], "angles": [0.0, 0.1]}
    assert feed.packet(json.dumps(pkt).encode()).t == 5.0
    assert feed.packet(b"{not json") is None and feed.packet(b'{"type": "gnss"}') is None
    assert (feed.scans_in, feed.bad_scans) == (3, 2)
    for k in range(MAX_WAITING + 3):
        feed.hold(_scan(10.0 + k), 0.0)
    assert len(feed.waiting) == MAX_WAITING and feed.waiting[0][0].t == 13.0 and feed.bad_scans == 5
    assert not feed.done


def test_scan_feed_replays_a_log_on_the_stream_clock():
    log = NavLog([_scan(0.0), _scan(0.5), _scan(1.0)])
    feed = ScanFeed(log)
    assert [(s.t, a) for s, a in feed.due(1.7e9)] == [(1.7e9, None)]  # 1.7e9 s apart: shifted onto the stream
    assert [s.t for s, _ in feed.due(1.7e9 + 0.6)] == [1.7e9 + 0.5] and not feed.done
    assert len(feed.due(1.7e9 + 2)) == 1 and feed.done


def test_sink_counts_times_and_writes(tmp_path):
    sink = Sink(out_dir=tmp_path)
    sink.open()
    est = Estimate(12.5, np.array([1.0, 2.0, 0.5]), np.eye(3) * 0.01)
    sink.emit(est, time.perf_counter(), None)
    sink.emit(est, None, None)
    sink.close()
    s = sink.summary()
    assert (s["estimates"], s["published"]) == (2, 0) and s["latency_ms_median"] >= 0.0
    assert s["tum"].endswith(".tum") and len(open(s["tum"]).read().splitlines()) == 3  # header + 2


def test_sink_drops_an_estimate_older_than_one_emitted(tmp_path):
    """A keyframe solved once the stream came back, after predictions coasted past its time: dropped and
    counted, so the file's (and the bus's) times only go forward."""
    sink = Sink(out_dir=tmp_path)
    sink.open()
    for t, coasted in ((1.0, False), (2.0, False), (3.0, True), (4.0, True), (2.5, False), (4.0, False), (5.0, False)):
        sink.emit(Estimate(t, np.array([t, 0.0, 0.0]), np.eye(3) * 0.01, coasted=coasted), None, None)
    sink.close()
    s = sink.summary()
    assert (s["estimates"], s["coasted_estimates"], s["late_estimates"]) == (6, 2, 1)
    times = [float(line.split()[0]) for line in open(s["tum"]).read().splitlines()[1:]]
    assert times == [1.0, 2.0, 3.0, 4.0, 4.0, 5.0]


def test_sink_times_start_again_after_a_clock_resync(tmp_path):
    sink = Sink(out_dir=tmp_path)
    sink.open()
    sink.emit(Estimate(3600.0, np.zeros(3)), None, None)
    sink.resync()  # the stream's clock stepped back an hour: a fresh estimator's estimates are not late
    sink.emit(Estimate(1.0, np.zeros(3)), None, None)
    sink.emit(Estimate(0.5, np.zeros(3)), None, None)  # ... but one older than those is
    sink.close()
    s = sink.summary()
    assert (s["estimates"], s["late_estimates"]) == (2, 1)
