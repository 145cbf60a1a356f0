"""Hypothesis fuzzing of every reader: any input gives a NavLog or a LogError (never another
exception), lenient mode never raises on record problems, and memory stays bounded.

Budget: ``max_examples`` 40-80 per reader, ``deadline=None`` (the whole file runs in well under a
minute on the 2-core CI machine). Memory: every example's peak traced allocation
(``tracemalloc``, which numpy reports to) stays under :data:`PEAK_BYTES` for inputs of at most a
few kB -- far below what one mis-sized allocation (a length field read as 2**31, a grid sized by a
1e308 coordinate) would ask for.

"""

from __future__ import annotations

import gzip
import io
import json
import string
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from graphnav.errors import LogError
from graphnav.io import load_log, save_log
from graphnav.io.nmea_out import checksum
from graphnav.log import NavLog
from tests._logfactory import every_record_log

PEAK_BYTES = 48 << 20
FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                        HealthCheck.too_slow])


def _read_bounded(fn) -> NavLog | LogError:
    """``fn()`` -> its NavLog or LogError (any other exception propagates: a failure), with the peak
    traced allocation asserted under :data:`PEAK_BYTES`."""
    tracemalloc.start()
    try:
        try:
            out = fn()
        except LogError as err:
            out = err
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < PEAK_BYTES, f"peak {peak / 2**20:.1f} MiB"
    assert isinstance(out, NavLog | LogError)
    return out


def _both(path: Path, **kw) -> None:
    """Strict: a result or a LogError naming the file; lenient: a result or (only for what cannot be
    skipped record by record: the container itself) a LogError."""
    out = _read_bounded(lambda: load_log(path, **kw))
    if isinstance(out, LogError):
        assert out.file is not None and Path(out.file).name.startswith(path.name.split(".")[0])
    _read_bounded(lambda: load_log(path, lenient=True, **kw))


# ----------------------------------------------------------------------------- JSON Lines

numbers = (st.integers(-10**400, 10**400) | st.floats(allow_nan=True, allow_infinity=True)
           | st.sampled_from([0, -1, 1e308, -1e308, 1e-320, 50.0, 51.0, 1e6, 2e6]))
json_values = st.recursive(st.none() | st.booleans() | numbers | st.text(max_size=6),
                           lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=6), c, max_size=4),
                           max_leaves=10)
record = st.fixed_dictionaries(
    {"type": st.sampled_from(["scan", "gnss", "heading", "odometry", "imu", "beacon", "truth", "pose_prior",
                              "beacon_known", "meta"])},
    optional={k: json_values | numbers for k in ["t", "x", "y", "sigma", "yaw", "v", "w", "ranges", "angles", "id",
                                                  "range", "bearing", "lat", "lon", "origin", "sigma_xy",
                                                  "sigma_yaw", "ax", "ay", "wz", "range_max", "sigma_v",
                                                  "sigma_range"]})
jsonl_line = st.one_of(record.map(lambda d: json.dumps(d)), st.text(max_size=60),
                       st.binary(max_size=40).map(lambda b: b.decode("latin-1")))


@FUZZ
@given(st.lists(jsonl_line, min_size=1, max_size=8), st.booleans())
def test_fuzz_jsonl(tmp_path, lines, gz):
    data = "\n".join(s.replace("\n", " ") for s in lines).encode("utf-8", "surrogatepass")
    p = tmp_path / ("f.jsonl.gz" if gz else "f.jsonl")
    p.write_bytes(gzip.compress(data, mtime=0) if gz else data)
    _both(p)


@FUZZ
@given(st.binary(min_size=1, max_size=64), st.integers(0, 10**6))
def test_fuzz_jsonl_gzip_bytes(tmp_path, junk, where):
    """Damaged gzip streams: random bytes spliced into a valid compressed log."""
    log = every_record_log(n=3)
    save_log(log, tmp_path / "ok.jsonl.gz")
    raw = bytearray((tmp_path / "ok.jsonl.gz").read_bytes())
    i = where % len(raw)
    raw[i:i + len(junk)] = junk
    p = tmp_path / "f.jsonl.gz"
    p.write_bytes(bytes(raw))
    _both(p)


# ----------------------------------------------------------------------------- npz

npz_keys = st.sampled_from(["order", "meta", "version", "gnss/t", "gnss/x", "gnss/y", "gnss/sigma", "scan/t",
                            "scan/offsets", "scan/ranges", "scan/angles", "scan/range_max", "odometry/t",
                            "odometry/v", "odometry/w", "odometry/sigma_v", "odometry/sigma_w",
                            "beacon_known/id", "beacon_known/x", "junk"])
npz_arrays = st.one_of(
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=6).map(np.array),
    st.lists(st.integers(-3, 12), max_size=6).map(lambda v: np.array(v, dtype=np.int64)),
    st.lists(st.integers(-128, 127), max_size=6).map(lambda v: np.array(v, dtype=np.int8)),
    st.text(max_size=20).map(np.array),
    st.lists(st.floats(-5, 5), min_size=1, max_size=4).map(lambda v: np.array(v).reshape(-1, 1)),
)


@FUZZ
@given(st.dictionaries(npz_keys, npz_arrays, min_size=1, max_size=8))
def test_fuzz_npz_members(tmp_path, arrays):
    p = tmp_path / "f.npz"
    np.savez(p, **arrays)
    _both(p)


@FUZZ
@given(st.lists(st.tuples(st.integers(0, 10**6), st.binary(min_size=1, max_size=8)), min_size=1, max_size=4))
def test_fuzz_npz_bytes(tmp_path, edits):
    """Byte edits of a valid archive: zip headers, npy headers (lengths, shapes) and data."""
    save_log(every_record_log(n=3), tmp_path / "ok.npz")
    raw = bytearray((tmp_path / "ok.npz").read_bytes())
    for where, b in edits:
        i = where % len(raw)
        raw[i:i + len(b)] = b
    p = tmp_path / "f.npz"
    p.write_bytes(bytes(raw))
    _both(p)


@FUZZ
@given(st.sampled_from(["order", "gnss/t", "scan/ranges", "scan/offsets", "meta"]),
       st.lists(st.integers(0, 2**40), min_size=0, max_size=3), st.sampled_from(["<f8", "<i8", "|i1", "<U4"]))
def test_fuzz_npz_lying_headers(tmp_path, key, shape, dtype):
    """A member whose array header states any shape, over a few bytes of data."""
    save_log(every_record_log(n=3), tmp_path / "ok.npz")
    p = tmp_path / "f.npz"
    with zipfile.ZipFile(tmp_path / "ok.npz") as src, zipfile.ZipFile(p, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            if info.filename != key + ".npy":
                dst.writestr(info, src.read(info))
        hdr = io.BytesIO()
        np.lib.format.write_array_header_2_0(hdr, {"descr": dtype, "fortran_order": False, "shape": tuple(shape)})
        dst.writestr(key + ".npy", hdr.getvalue() + bytes(64))
    _both(p)


# ----------------------------------------------------------------------------- NMEA

def _s(body: str) -> str:
    return f"${body}*{checksum(body)}"


NMEA_VALID = [
    "GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
    "GPRMC,123520,A,4807.038,N,01131.000,E,22.4,84.4,230394,003.1,W,A",
    "GPZDA,123521.00,23,03,1994,00,00", "HEHDT,45.0,T", "HCHDG,100.0,2.0,E,3.0,W", "TIROT,60.0,A",
    "GPVTG,90.0,T,,M,1.0,N,1.8,K,A", "HETHS,270.0,A",
    # the instrument sentences of #21/#23: velocity, water speed, magnetic heading, GLL/GNS/GST, attitude
    "IIVHW,,T,,M,06.11,N,11.31,K", "IIHDM,100.0,M", "GPGLL,6005.071,N,02332.346,E,123522,A,D",
    "GNGNS,123523.00,4332.69262,S,17235.48549,E,RR,13,0.9,25.63,11.24,,", "GPZDA,123524,,,,00,",
    "GPGST,123523.00,0.006,0.023,0.020,273.6,0.023,0.020,0.031", "YXXDR,A,-1.5,D,PTCH,A,2.5,D,ROLL",
    "PASHR,123525.000,224.19,T,-01.26,+00.83,+00.00,0.101,0.113,0.267,1,0", "GPZDA,123526.00,23,03,94,00,00",
]
field_junk = st.one_of(st.text(alphabet=string.ascii_letters + string.digits + ".-+ ", max_size=10),
                       st.sampled_from(["999.9", "1e308", "nan", "inf", "-0", "", "235960", "9" * 40]))


@st.composite
def nmea_line(draw):
    body = draw(st.sampled_from(NMEA_VALID))
    fields = body.split(",")
    for _ in range(draw(st.integers(0, 3))):
        fields[draw(st.integers(1, len(fields) - 1))] = draw(field_junk)
    if draw(st.booleans()):
        fields = fields[: draw(st.integers(1, len(fields)))]
    line = _s(",".join(fields))
    if draw(st.integers(0, 9)) == 0:  # a broken checksum or raw garbage now and then
        line = draw(st.sampled_from([line[:-1] + "0", draw(st.text(max_size=40))]))
    return line


@FUZZ
@given(st.lists(nmea_line(), min_size=1, max_size=12), st.booleans())
def test_fuzz_nmea(tmp_path, lines, gz):
    data = ("\r\n".join(s.replace("\n", " ").replace("\r", " ") for s in lines) + "\r\n").encode("latin-1", "replace")
    p = tmp_path / ("f.nmea.gz" if gz else "f.nmea")
    p.write_bytes(gzip.compress(data, mtime=0) if gz else data)
    _both(p)


# ----------------------------------------------------------------------------- marina

@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.integers(0, 5), st.integers(0, 5), st.integers(0, 6), st.integers(1, 4),
       st.lists(st.sampled_from([np.nan, 0.0, -1.0, 1e5, 1e308, -1e308, np.inf]), max_size=4))
def test_fuzz_marina(tmp_path, nb, ns, nr, nc, hostile):
    from scipy.io import savemat

    rng = np.random.default_rng(nb * 100 + ns * 10 + nr)
    ranges = rng.uniform(0, 40, (nb, ns))
    pose = rng.normal(size=(nr, nc))
    targets = [a for a in (pose, ranges) if a.size]
    for k, v in enumerate(hostile if targets else []):
        arr = targets[k % len(targets)]
        arr.flat[k % arr.size] = v
    savemat(tmp_path / "ranges.mat", {"ranges_baza": ranges})
    savemat(tmp_path / "angles.mat", {"angles_baza": rng.uniform(0, 6.3, (nb, ns))})
    savemat(tmp_path / "gps.mat", {"slam_pose": pose})
    _read_bounded(lambda: load_log(tmp_path))


# ----------------------------------------------------------------------------- ROS bags

@pytest.fixture(scope="module")
def bag_bytes(tmp_path_factory):
    pytest.importorskip("rosbags")
    from graphnav.io.nmea_out import gga
    from graphnav.io.rosbag import write_bag

    d = tmp_path_factory.mktemp("bag")
    log = every_record_log(n=4)
    keep = NavLog([r for r in log.records if r.kind in ("scan", "gnss", "heading", "odometry", "imu")],
                  meta={"origin": {"lat": 43.5, "lon": 16.4, "h": 0.0}})
    write_bag(keep, d / "b.bag", nmea_sentences=[(1.0, gga(1.0, 43.5, 16.4))])
    return (d / "b.bag").read_bytes()


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.integers(0, 10**7), st.binary(min_size=1, max_size=8)), min_size=1, max_size=4))
def test_fuzz_rosbag(tmp_path, bag_bytes, edits):
    """Byte edits of a valid ROS 1 bag (record headers, lengths, connection data, messages)."""
    raw = bytearray(bag_bytes)
    for where, b in edits:
        i = where % len(raw)
        raw[i:i + len(b)] = b
    p = tmp_path / "f.bag"
    p.write_bytes(bytes(raw))
    _both(p)


def test_rosbag_damaged_length_is_refused_before_allocating(tmp_path, bag_bytes):
    """Every top-level record length of a ROS 1 bag set to 96 MiB (hypothesis found one): a LogError
    naming the field, and no allocation of the declared size (rosbags read it in one call: 103 MiB)."""
    raw0, pos, n = bytes(bag_bytes), 13, 0
    while pos < len(raw0):
        hl = int.from_bytes(raw0[pos:pos + 4], "little")
        dpos = pos + 4 + hl
        for at in (pos, dpos):
            raw = bytearray(raw0)
            raw[at:at + 4] = (96 << 20).to_bytes(4, "little")
            p = tmp_path / "g.bag"
            p.write_bytes(bytes(raw))
            out = _read_bounded(lambda p=p: load_log(p))
            assert isinstance(out, LogError)
            n += 1
        pos = dpos + 4 + int.from_bytes(raw0[dpos:dpos + 4], "little")
    assert n >= 10


# ----------------------------------------------------------------------------- CARMEN, MRCLAM

carmen_line = st.one_of(
    st.builds(lambda n, vals, tail: "FLASER " + " ".join([str(n)] + [str(v) for v in vals + tail]),
              st.integers(-2, 400), st.lists(numbers, max_size=12), st.lists(numbers, min_size=9, max_size=9)),
    st.builds(lambda vals: "ROBOTLASER1 " + " ".join(str(v) for v in vals), st.lists(numbers, max_size=30)),
    st.builds(lambda vals: "ODOM " + " ".join(str(v) for v in vals), st.lists(numbers, max_size=9)),
    st.text(max_size=60))


@FUZZ
@given(st.lists(carmen_line, min_size=1, max_size=8), st.booleans())
def test_fuzz_carmen(tmp_path, lines, gz):
    data = ("\n".join(s.replace("\n", " ") for s in lines) + "\n").encode("utf-8", "surrogatepass")
    p = tmp_path / ("f.clf.gz" if gz else "f.clf")
    p.write_bytes(gzip.compress(data, mtime=0) if gz else data)
    _both(p)


mrclam_row = st.lists(numbers, min_size=2, max_size=6).map(lambda v: " ".join(str(x) for x in v))


@FUZZ
@given(st.dictionaries(st.sampled_from(["Barcodes", "Landmark_Groundtruth", "Robot1_Odometry", "Robot1_Measurement",
                                        "Robot1_Groundtruth"]),
                       st.lists(mrclam_row, max_size=6), min_size=2))
def test_fuzz_mrclam(tmp_path, tables):
    for stem, rows in tables.items():
        (tmp_path / f"{stem}.dat").write_text("\n".join(rows) + "\n")
    for kw in ({"robot": 1}, {}):  # an MRCLAM directory without robot= is a clean error too
        out = _read_bounded(lambda kw=kw: load_log(tmp_path, **kw))
        _read_bounded(lambda kw=kw: load_log(tmp_path, lenient=True, **kw))
        assert isinstance(out, NavLog | LogError)
