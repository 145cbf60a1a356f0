"""A ``graphnav compare`` as a timeline: each estimator, figure and file step with its process, start and end
(wall seconds from the start) and CPU seconds, to see which core is idle when.

    python benchmarks/compare_timeline.py data/harbour.npz [--out DIR] [-e isam2,ekf]

Each step is wrapped (in the parent and in the forked workers, which inherit the wrappers) and appends one
JSON line to a file; the lines are printed sorted by start. On a shared machine, wall beside CPU says how
much of a step was waiting for a core.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

T0 = time.time()
LINES = Path(tempfile.gettempdir()) / f"compare_timeline-{os.getpid()}.jsonl"


def wrap(mod: Any, attr: str, label: Any) -> None:
    """Replace ``mod.attr`` by a copy that logs its span (``label(args)``: the step's name)."""
    f = getattr(mod, attr)

    @functools.wraps(f)  # (the same qualified name: a forked worker's task still pickles by reference)
    def timed(*a: Any, **k: Any) -> Any:
        w0, c0 = time.time(), time.process_time()
        try:
            return f(*a, **k)
        finally:
            with LINES.open("a") as fh:
                fh.write(json.dumps({"pid": os.getpid(), "name": label(a), "start": w0 - T0, "end": time.time() - T0,
                                     "cpu": time.process_time() - c0}) + "\n")

    setattr(mod, attr, timed)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log")
    ap.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "compare_timeline")
    ap.add_argument("-e", "--estimators", help="comma-separated (default: every one)")
    a = ap.parse_args(argv)
    import graphnav.evaluation.comparison as comparison
    import graphnav.evaluation.pipeline as pipeline
    import graphnav.evaluation.report.assemble as assemble
    import graphnav.evaluation.report.figures as figures
    import graphnav.evaluation.report.writer as writer
    from graphnav.io.outputs import OutDir

    wrap(comparison, "_run", lambda args: "estimator " + args[1])
    wrap(figures, "_render", lambda args: "figure " + figures._FIG_JOBS[args[0]][3])
    wrap(pipeline, "load_log", lambda args: "read the log")
    wrap(assemble, "start", lambda args: "report: start")
    wrap(writer, "_write_tracks", lambda args: "files: TUM")
    wrap(writer, "wgs84_texts", lambda args: "files: WGS84 texts")
    wrap(writer, "finish", lambda args: "report: finish (waits for the figures)")
    wrap(writer, "_write_pages", lambda args: "files: PNG, report, WGS84, map")
    opts = pipeline.CompareOptions(log=a.log, out=a.out, workers=2,
                                   estimators=a.estimators.split(",") if a.estimators else None)
    c0 = time.process_time()
    pipeline.run_compare(opts, OutDir(a.out, command="compare", overwrite=True))
    rows = sorted((json.loads(x) for x in LINES.read_text().splitlines()), key=lambda r: r["start"])
    LINES.unlink()
    for r in rows:
        print(f"{r['pid']:>7} {r['name']:<42} {r['start']:6.2f} -> {r['end']:6.2f}  wall {r['end'] - r['start']:5.2f}"
              f"  CPU {r['cpu']:5.2f}")
    print(f"total: wall {time.time() - T0:.2f} s from the start, this process's CPU {time.process_time() - c0:.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
