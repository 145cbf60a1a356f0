"""Peak RSS of each reader against the size of what it decodes (issue #14: under 2x).

Each reader runs in a fresh interpreter: the reader's modules are imported first, then the kernel's
RSS high-water mark is reset (``echo 5 > /proc/self/clear_refs``, Linux >= 4.0) and the current RSS
taken, the log is read, and the high-water mark (``VmHWM``) read again. ``peak`` = that mark minus
the RSS before the read; ``decoded`` = the bytes of the NavLog it returns (records, their floats and
strings, scan arrays; objects counted once, ``sys.getsizeof``); ``retained`` = RSS after the read
minus before (the log kept). Target: ``peak / decoded < 2``.

Inputs: the embedded harbour log (data/harbour.npz: 618 s, 3090 scans of 360 beams) written as
JSON Lines, gzipped JSON Lines, npz, NMEA (its GNSS/heading/odometry records) and a ROS 1 bag;
and, when present in ../shared/data, the marina directory, the largest CARMEN log and MRCLAM
Dataset 6 robot 1 (read in place, never copied).

    python benchmarks/reader_memory.py            # the table
    python benchmarks/reader_memory.py --json
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

TARGET = 2.0

MEASURE = textwrap.dedent('''
    import gc, json, sys
    import numpy as np
    from graphnav.io import load_log
    import graphnav.io.{module}  # the reader's own imports happen before the baseline ...
    for name in {warm!r}:  # ... and those it makes lazily
        __import__(name)

    def status(key):
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) * 1024

    def deep_size(log):
        seen, total = set(), sys.getsizeof(log.records)
        def add(o):
            nonlocal total
            if id(o) in seen:
                return
            seen.add(id(o))
            total += sys.getsizeof(o)
            if isinstance(o, np.ndarray) and o.base is not None:
                add(o.base)
        for r in log.records:
            add(r)
            for name in r.__slots__ if hasattr(r, "__slots__") else ():
                add(getattr(r, name))
        return total

    gc.collect()
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")  # reset VmHWM to the current RSS
    before = status("VmRSS")
    log = load_log({path!r}, **{kw})
    peak = status("VmHWM")
    after = status("VmRSS")
    print(json.dumps({{"records": len(log), "before": before, "peak": peak, "after": after,
                      "decoded": deep_size(log)}}))
''')


WARM = {"marina": ["scipy.io"], "rosbag": ["rosbags.highlevel", "rosbags.typesys", "rosbags.rosbag1",
                                            "rosbags.rosbag2"]}


def measure(path: Path, module: str, **kw) -> dict:
    code = MEASURE.format(module=module, path=str(path), kw=repr(kw), warm=WARM.get(module, []))
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=1800)
    if p.returncode != 0:
        return {"error": p.stderr.strip().splitlines()[-1] if p.stderr.strip() else f"exit {p.returncode}"}
    m = json.loads(p.stdout.strip().splitlines()[-1])
    inc = m["peak"] - m["before"]
    m["peak_inc"] = inc
    m["retained"] = m["after"] - m["before"]
    m["ratio"] = inc / m["decoded"] if m["decoded"] else None
    m["file_bytes"] = (sum(f.stat().st_size for f in path.rglob("*") if f.is_file()) if path.is_dir()
                       else path.stat().st_size)
    return m


def shared(name: str) -> Path | None:
    for c in (REPO.parent / "shared" / "data" / name, REPO.parent.parent / "shared" / "data" / name):
        if c.exists():
            return c
    return None


def inputs(tmp: Path) -> list[tuple[str, Path, str, dict]]:
    from graphnav.io import load_log, save_log
    from graphnav.io.nmea_out import log_to_nmea

    log = load_log(REPO / "data" / "harbour.npz")
    out = []
    for name in ("harbour.jsonl", "harbour.jsonl.gz", "harbour.npz"):
        save_log(log, tmp / name)
        out.append((name, tmp / name, {"npz": "npz"}.get(name.rsplit(".", 1)[-1], "jsonl"), {}))
    with open(tmp / "harbour.nmea", "w") as fh:
        for _t, s in log_to_nmea(log, with_rmc=True):
            fh.write(s + "\r\n")
    out.append(("harbour.nmea", tmp / "harbour.nmea", "nmea", {}))
    try:
        from graphnav.io.rosbag import write_bag

        write_bag(log.without(lambda r: r.kind not in ("scan", "gnss", "heading", "odometry", "imu")),
                  tmp / "harbour.bag")
        out.append(("harbour.bag (ROS 1)", tmp / "harbour.bag", "rosbag", {}))
    except ImportError:
        pass
    if (m := shared("icp_data_marina")) is not None:
        out.append(("marina (dir)", m, "marina", {}))
    if (c := shared("carmen")) is not None and (c / "freiburg-079-corrected.log.gz").exists():
        out.append(("carmen freiburg-079 .log.gz", c / "freiburg-079-corrected.log.gz", "carmen", {}))
    if (d := shared("mrclam")) is not None and (d / "MRCLAM_Dataset6").is_dir():
        out.append(("mrclam Dataset6 robot 1", d / "MRCLAM_Dataset6", "mrclam", {"robot": 1}))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, path, module, kw in inputs(Path(tmp)):
            m = measure(path, module, **kw)
            m["input"] = name
            rows.append(m)
            print(f"  {name}: {m.get('ratio')}", file=sys.stderr, flush=True)
    if args.json:
        print(json.dumps({"target_ratio": TARGET, "rows": rows}))
        return 0
    mb = 2 ** 20
    print(f"{'input':30s} {'records':>8s} {'file MB':>8s} {'decoded MB':>10s} {'peak MB':>8s} {'retained MB':>11s} "
          f"{'peak/decoded':>12s}")
    for m in rows:
        if "error" in m:
            print(f"{m['input']:30s} error: {m['error']}")
            continue
        print(f"{m['input']:30s} {m['records']:8d} {m['file_bytes'] / mb:8.1f} {m['decoded'] / mb:10.1f} "
              f"{m['peak_inc'] / mb:8.1f} {m['retained'] / mb:11.1f} {m['ratio']:12.2f}")
    over = [m["input"] for m in rows if m.get("ratio") is not None and m["ratio"] >= TARGET]
    print(f"\ntarget peak/decoded < {TARGET}: {'all readers meet it' if not over else 'over: ' + ', '.join(over)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
