"""Every capture of the real-receiver NMEA corpus through the CLI: a result or a clean error, never
a traceback; and the isam2 track of every file with >= 5 fixes against the receiver's own fixes.

For each file of ``../shared/data/nmea_corpus`` (GPSD's regression captures, 79 receivers; not ours,
read in place):

1. ``python -m graphnav info FILE --json`` strict and with ``--lenient``: exit 0 (parsed), 2 (a clean
   error: one ``{"error", "where"}`` object, no traceback) or anything else (a crash: reported);
2. when the log has >= ``--min-fixes`` GNSS fixes: ``python -m graphnav run FILE -e isam2 --json
   --out DIR`` (``--lenient`` when the strict read fails), then the distance from each fix of the
   log to the smoothed track (``DIR/trajectory.tum``, linear interpolation in time), its median per
   file against the 1.5 m target of issue #14.

    python benchmarks/nmea_corpus.py                 # the table, ~5-10 min on 2 loaded cores
    python benchmarks/nmea_corpus.py --no-run        # the parse table only
    python benchmarks/nmea_corpus.py --json          # one JSON object
    python benchmarks/nmea_corpus.py --api           # the same reading and runs in one process (minutes, not ~45)

``--api`` reads with ``graphnav.io.load_log`` (strict, then ``lenient=True``: ok, a ``GraphnavError`` =
clean, anything else = crash) and runs ``graphnav.estimators.run("isam2", log)``: the path the CLI
takes, without an interpreter per file.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from graphnav.io import load_log  # noqa: E402

TARGET_M = 1.5


def default_corpus() -> Path | None:
    for c in (REPO.parent / "shared" / "data" / "nmea_corpus", REPO.parent.parent / "shared" / "data" / "nmea_corpus"):
        if c.is_dir():
            return c
    return None


def cli(*args: str, timeout: float = 600) -> tuple[int, dict | None, str]:
    """``python -m graphnav ARGS``: (exit code, the JSON object on stdout or None, stderr)."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    try:
        p = subprocess.run([sys.executable, "-m", "graphnav", *args], capture_output=True, text=True, env=env,
                           timeout=timeout, cwd=str(REPO))
    except subprocess.TimeoutExpired:
        return -1, None, f"timeout after {timeout:.0f} s"
    try:
        obj = json.loads(p.stdout) if p.stdout.strip() else None
    except json.JSONDecodeError:
        obj = None
    return p.returncode, obj, p.stderr


def outcome(rc: int, obj: dict | None, err: str) -> str:
    """ok, clean (a clean error: exit 2, one JSON error object, no traceback) or crash."""
    if rc == 0 and obj is not None and "error" not in obj:
        return "ok"
    if rc == 2 and obj is not None and set(obj) == {"error", "where"} and "Traceback" not in err:
        return "clean"
    return "crash"


def fix_distances(log_path: Path, tum: Path, lenient: bool) -> np.ndarray:
    """Distance [m] from each GNSS fix of the log to the track of ``tum`` at the fix's time."""
    log = load_log(log_path, lenient=lenient)
    g = log.columns("gnss")
    est = np.loadtxt(tum, comments="#", ndmin=2)
    t, x, y = est[:, 0], est[:, 1], est[:, 2]
    inside = (g["t"] >= t[0]) & (g["t"] <= t[-1])
    ex = np.interp(g["t"][inside], t, x)
    ey = np.interp(g["t"][inside], t, y)
    return np.hypot(ex - g["x"][inside], ey - g["y"][inside])


def _api_read(f: Path, lenient: bool) -> tuple[str, object, str | None]:
    from graphnav.errors import GraphnavError

    try:
        return "ok", load_log(f, lenient=lenient), None
    except GraphnavError as e:
        return "clean", None, str(e)
    except Exception as e:  # noqa: BLE001 -- a crash is what the benchmark reports
        return "crash", None, f"{type(e).__name__}: {e}"


def study_api(corpus: Path, min_fixes: int, run: bool, options: list[str] | None = None) -> list[dict]:
    """:func:`study`'s rows, in this process."""
    from graphnav import estimators
    from graphnav.commands._common import parse_options

    opts = parse_options(options)
    rows = []
    for f in sorted(p for p in corpus.iterdir() if p.is_file() and p.name != "README.md"):
        row: dict = {"file": f.name}
        row["strict"], log, err = _api_read(f, False)
        row["strict_error"] = err if row["strict"] == "clean" else None
        if row["strict"] == "crash":
            row["crash"] = [err]
        row["lenient"], llog, _ = _api_read(f, True)
        log = log if log is not None else llog
        row["fixes"] = len(log.columns("gnss")["t"]) if log is not None else 0
        if run and row["fixes"] >= min_fixes:
            lenient = row["strict"] != "ok"
            try:
                r = estimators.run("isam2", log, **opts)
                row["isam2"] = "ok" + (" (--lenient)" if lenient else "")
                g, tj = log.columns("gnss"), r.trajectory
                inside = (g["t"] >= tj.t[0]) & (g["t"] <= tj.t[-1])
                d = np.hypot(np.interp(g["t"][inside], tj.t, tj.x) - g["x"][inside],
                             np.interp(g["t"][inside], tj.t, tj.y) - g["y"][inside])
                row["median_m"] = float(np.median(d)) if d.size else None
                row["p95_m"] = float(np.percentile(d, 95)) if d.size else None
                row["n_scored"] = int(d.size)
            except Exception as e:  # noqa: BLE001 -- a failed run is a row of the table
                row["isam2"] = "crash"
                row["isam2_error"] = f"{type(e).__name__}: {e}"[:200]
        rows.append(row)
        print(f"  {f.name}: {row['strict']}/{row['lenient']} {row['fixes']} fixes", file=sys.stderr, flush=True)
    return rows


def study(corpus: Path, min_fixes: int, run: bool, options: list[str] | None = None, api: bool = False) -> dict:
    rows = study_api(corpus, min_fixes, run, options) if api else []
    for f in [] if api else sorted(p for p in corpus.iterdir() if p.is_file() and p.name != "README.md"):
        row: dict = {"file": f.name}
        rc, obj, err = cli("info", str(f), "--json")
        row["strict"] = outcome(rc, obj, err)
        row["strict_error"] = obj.get("error") if obj and row["strict"] == "clean" else None
        if row["strict"] == "crash":
            row["crash"] = err.strip().splitlines()[-1:] if err.strip() else [f"exit {rc}"]
        rc, obj, err = cli("info", str(f), "--json", "--lenient")
        row["lenient"] = outcome(rc, obj, err)
        row["fixes"] = int(obj.get("records", {}).get("gnss", 0)) if row["lenient"] == "ok" else 0
        if row["lenient"] == "ok":
            row["skipped"] = obj.get("skipped", 0)
            row["dropped_fields"] = sum((obj.get("dropped_fields") or {}).values())
        if run and row["fixes"] >= min_fixes:
            lenient = row["strict"] != "ok"
            with tempfile.TemporaryDirectory() as tmp:
                args = ["run", str(f), "-e", "isam2", "--json", "--out", tmp] + (["--lenient"] if lenient else [])
                args += [a for o in options or () for a in ("-O", o)]
                rc, obj, err = cli(*args)
                row["isam2"] = outcome(rc, obj, err) + (" (--lenient)" if lenient else "")
                if rc == 0:
                    d = fix_distances(f, Path(tmp) / "trajectory.tum", lenient)
                    row["median_m"] = float(np.median(d)) if d.size else None
                    row["p95_m"] = float(np.percentile(d, 95)) if d.size else None
                    row["n_scored"] = int(d.size)
                else:
                    row["isam2_error"] = (obj or {}).get("error") or err.strip()[-200:]
        rows.append(row)
        print(f"  {f.name}: {row['strict']}/{row['lenient']} {row['fixes']} fixes", file=sys.stderr, flush=True)
    ran = [r for r in rows if "isam2" in r]
    scored = [r for r in ran if r.get("median_m") is not None]
    summary = {
        "files": len(rows),
        "strict": {k: sum(r["strict"] == k for r in rows) for k in ("ok", "clean", "crash")},
        "lenient": {k: sum(r["lenient"] == k for r in rows) for k in ("ok", "clean", "crash")},
        "files_with_min_fixes": sum(r["fixes"] >= min_fixes for r in rows),
        "isam2_ran": len(ran),
        "isam2_failed": [r["file"] for r in ran if r.get("median_m") is None],
        "median_within_target": sum(r["median_m"] <= TARGET_M for r in scored),
        "median_over_target": [(r["file"], round(r["median_m"], 2)) for r in scored if r["median_m"] > TARGET_M],
        "median_of_medians_m": float(np.median([r["median_m"] for r in scored])) if scored else None,
    }
    return {"corpus": str(corpus), "min_fixes": min_fixes, "target_m": TARGET_M, "summary": summary, "files": rows}


def table(res: dict) -> str:
    out = [f"{'file':36s} {'strict':7s} {'lenient':7s} {'fixes':>5s} {'skip':>5s} {'drop':>5s} "
           f"{'isam2':18s} {'median m':>9s} {'p95 m':>8s}  error / note"]
    for r in res["files"]:
        med = f"{r['median_m']:.3f}" if r.get("median_m") is not None else ""
        p95 = f"{r['p95_m']:.3f}" if r.get("p95_m") is not None else ""
        note = r.get("isam2_error") or r.get("strict_error") or " ".join(r.get("crash", []))
        out.append(f"{r['file']:36s} {r['strict']:7s} {r['lenient']:7s} {r['fixes']:5d} {r.get('skipped', ''):>5} "
                   f"{r.get('dropped_fields', ''):>5} {r.get('isam2', ''):18s} {med:>9s} {p95:>8s}  "
                   f"{(note or '')[:90]}")
    s = res["summary"]
    st, le = s["strict"], s["lenient"]
    out += ["", f"{s['files']} files. strict info: {st['ok']} parsed, {st['clean']} clean errors, {st['crash']} "
                f"crashes; --lenient: {le['ok']} parsed, {le['clean']} clean errors, {le['crash']} crashes",
            f"{s['files_with_min_fixes']} files with >= {res['min_fixes']} fixes; isam2 ran on {s['isam2_ran']}, "
            f"failed on {len(s['isam2_failed'])} {s['isam2_failed']}",
            f"median fix-to-track distance <= {res['target_m']} m: {s['median_within_target']} files; over: "
            f"{s['median_over_target']}; median of the medians {s['median_of_medians_m']}"]
    return "\n".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--corpus", type=Path, default=default_corpus())
    ap.add_argument("--min-fixes", type=int, default=5)
    ap.add_argument("--no-run", action="store_true", help="only the info table (no isam2 runs)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--api", action="store_true", help="read and run in this process (the CLI's path, faster)")
    ap.add_argument("-O", dest="options", action="append", default=[], metavar="KEY=VALUE",
                    help="an isam2 option for every run (e.g. -O motion=vessel)")
    args = ap.parse_args()
    if args.corpus is None or not args.corpus.is_dir():
        print("nmea_corpus not found (../shared/data/nmea_corpus or --corpus DIR)", file=sys.stderr)
        return 2
    res = study(args.corpus, args.min_fixes, not args.no_run, args.options, api=args.api)
    print(json.dumps(res) if args.json else table(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
