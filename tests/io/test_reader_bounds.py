"""Readers decompress and allocate only what they use; damaged streams and out-of-range numbers are
LogErrors naming the file, line and field (issue #14).

Memory is measured with ``tracemalloc`` (numpy reports its array allocations to it); the bound
:data:`NPZ_PEAK_BYTES` is far below the members the hostile archives declare.
"""

from __future__ import annotations

import gzip
import io
import json
import logging
import tracemalloc
import zipfile

import numpy as np
import pytest

from graphnav.errors import LogError
from graphnav.io import load_log, save_log
from graphnav.io.jsonl import read_jsonl
from graphnav.io.nmea import read_nmea
from graphnav.io.nmea_out import gga, zda
from graphnav.io.npz import read_npz
from tests._logfactory import every_record_log

NPZ_PEAK_BYTES = 32 << 20  # a 20-record log reads in well under 1 MB; the hostile members declare >= 256 MiB
BIG = 256 << 20


def _peak(fn):
    tracemalloc.start()
    try:
        try:
            out = fn()
        except LogError as err:
            out = err
        return out, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def _add_member(path, name: str, header_shape: tuple[int, ...], dtype: str, data_bytes: int) -> None:
    """Append ``name`` (.npy) to a zip: an array header for ``header_shape`` and ``data_bytes`` zero
    bytes of data, streamed (so writing it allocates nothing large)."""
    hdr = io.BytesIO()
    np.lib.format.write_array_header_2_0(hdr, {"descr": np.dtype(dtype).str, "fortran_order": False,
                                                "shape": header_shape})
    with zipfile.ZipFile(path, "a", compression=zipfile.ZIP_DEFLATED) as zf:
        with zf.open(name, "w", force_zip64=True) as fh:
            fh.write(hdr.getvalue())
            chunk = bytes(1 << 20)
            left = data_bytes
            while left > 0:
                fh.write(chunk[:min(left, len(chunk))])
                left -= len(chunk)


@pytest.fixture(scope="module")
def small_npz(tmp_path_factory):
    p = tmp_path_factory.mktemp("npz") / "log.npz"
    save_log(every_record_log(n=20), p)
    return p


def test_npz_unused_large_member_is_never_decompressed(small_npz, tmp_path):
    """A ~0.3 MB archive with a 256 MiB unused member: the reader used to load every member."""
    p = tmp_path / "junk.npz"
    p.write_bytes(small_npz.read_bytes())
    _add_member(p, "junk.npy", (BIG,), "u1", BIG)
    assert p.stat().st_size < 2 << 20
    log, peak = _peak(lambda: read_npz(p))
    assert not isinstance(log, LogError) and len(log) == len(read_npz(small_npz))
    assert peak < NPZ_PEAK_BYTES, peak


def test_npz_declared_size_beyond_bound_is_rejected_before_reading(small_npz, tmp_path):
    p = tmp_path / "big.npz"
    with zipfile.ZipFile(small_npz) as src, zipfile.ZipFile(p, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            if info.filename != "order.npy":
                dst.writestr(info, src.read(info))
    _add_member(p, "order.npy", (BIG,), "i1", BIG)
    err, peak = _peak(lambda: read_npz(p, max_bytes=64 << 20))
    assert isinstance(err, LogError) and err.file == str(p) and "max_bytes" in str(err)
    assert peak < NPZ_PEAK_BYTES, peak


def test_npz_array_header_larger_than_member_is_rejected(small_npz, tmp_path):
    """A header claiming 2**34 values in a member of a few bytes: no allocation of the claimed size."""
    p = tmp_path / "lie.npz"
    with zipfile.ZipFile(small_npz) as src, zipfile.ZipFile(p, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            if info.filename != "order.npy":
                dst.writestr(info, src.read(info))
    _add_member(p, "order.npy", (1 << 34,), "i1", 16)
    err, peak = _peak(lambda: read_npz(p))
    assert isinstance(err, LogError) and err.field == "order"
    assert peak < NPZ_PEAK_BYTES, peak


def _heading_lines(n: int, seed: int = 0) -> bytes:
    rng = np.random.default_rng(seed)
    return "".join(json.dumps({"t": float(i), "type": "heading", "yaw": float(rng.uniform(-3, 3)), "sigma": 0.05})
                   + "\n" for i in range(n)).encode()


def _damage(kind: str, comp: bytes) -> bytes:
    if kind == "truncated":  # cut mid-stream: EOFError
        return comp[: len(comp) // 2]
    b = bytearray(comp)
    if kind == "early":  # the first deflate block header: zlib.error at once
        for k in range(8):
            b[30 + k] ^= 0xFF
    else:  # "crc": the stored CRC-32 at the end (gzip.BadGzipFile after all the data)
        b[-8] ^= 0xFF
    return bytes(b)


@pytest.mark.parametrize("kind", ["truncated", "early", "crc"])
def test_damaged_gzip_jsonl_strict_and_lenient(tmp_path, caplog, kind):
    raw = _heading_lines(20000)
    p = tmp_path / "d.jsonl.gz"
    p.write_bytes(_damage(kind, gzip.compress(raw, mtime=0)))
    with pytest.raises(LogError) as ei:
        read_jsonl(p)
    assert ei.value.file == str(p) and ei.value.line is not None and ei.value.line >= 1
    with caplog.at_level(logging.WARNING):
        log = read_jsonl(p, lenient=True)
    assert "truncated" in log.meta and log.meta["skipped"] >= 1
    assert any("corrupt or truncated" in r.message for r in caplog.records)
    assert [r.t for r in log.records] == [float(i) for i in range(len(log))]  # the lines read, in order
    if kind == "crc":
        assert len(log) == 20000
    if kind == "truncated":
        assert 0 < len(log) < 20000 and f":{len(log) + 1}:" in log.meta["truncated"]


@pytest.mark.parametrize("kind", ["truncated", "early", "crc"])
def test_damaged_gzip_nmea_strict_and_lenient(tmp_path, kind):
    t0 = 1_700_000_000.0
    text = "".join(f"{zda(t0 + k)}\r\n{gga(t0 + k, 43.5 + 1e-5 * k, 16.4)}\r\n" for k in range(3000)).encode()
    p = tmp_path / "d.nmea.gz"
    p.write_bytes(_damage(kind, gzip.compress(text, mtime=0)))
    with pytest.raises(LogError) as ei:
        read_nmea(p)
    assert ei.value.file == str(p) and ei.value.line is not None
    log = read_nmea(p, lenient=True)
    assert "truncated" in log.meta and log.meta["skipped"] >= 1


@pytest.mark.parametrize("line,field", [
    ('{"t": 1%s, "type": "heading", "yaw": 0, "sigma": 0.1}' % ("0" * 400), "t"),
    ('{"t": 0, "type": "odometry", "v": -1%s, "w": 0}' % ("0" * 400), "v"),
    ('{"t": 0, "type": "scan", "ranges": [1, 2%s], "angles": [0, 1]}' % ("0" * 400), "ranges"),
])
def test_huge_integer_is_a_log_error_naming_the_field(tmp_path, line, field):
    p = tmp_path / "big.jsonl"
    p.write_text('{"t": 0, "type": "truth", "x": 0, "y": 0, "yaw": 0}\n' + line + "\n")
    with pytest.raises(LogError) as ei:
        read_jsonl(p)
    assert (ei.value.file, ei.value.line, ei.value.field) == (str(p), 2, field)
    assert read_jsonl(p, lenient=True).meta["skipped"] == 1


def test_integer_beyond_json_digit_limit_is_a_log_error(tmp_path):
    p = tmp_path / "huge.jsonl"
    p.write_text('{"t": 1%s, "type": "heading", "yaw": 0, "sigma": 0.1}\n' % ("0" * 5000))
    with pytest.raises(LogError) as ei:
        read_jsonl(p)
    assert ei.value.line == 1 and "JSON" in ei.value.message


def test_non_utf8_line_is_one_bad_line(tmp_path):
    p = tmp_path / "u.jsonl"
    p.write_bytes(b'{"t": 0, "type": "heading", "yaw": 0, "sigma": 0.1}\n{"t": 1, "ty\xff\n'
                  b'{"t": 2, "type": "heading", "yaw": 0, "sigma": 0.1}\n')
    with pytest.raises(LogError) as ei:
        read_jsonl(p)
    assert ei.value.line == 2
    assert len(read_jsonl(p, lenient=True)) == 2


def test_load_log_routes_npz_max_bytes(small_npz):
    with pytest.raises(LogError):
        load_log(small_npz, max_bytes=100)
