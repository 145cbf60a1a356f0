"""Real-data benchmark (issue #12, item 8): every estimator on every real log, one table.

    python benchmarks/real_data.py                          # all datasets, local Dask cluster, writes docs/real-data.md
    python benchmarks/real_data.py --json                   # the same, one JSON object on stdout
    python benchmarks/real_data.py --datasets mrclam,harbour --estimators ekf-slam,isam2 --no-doc
    python benchmarks/real_data.py --logs /work/cache/logs  # CARMEN/MRCLAM read pre-converted (*.jsonl.gz)

Datasets (graphnav/evaluation/real_data.py): the 9 CARMEN logs (converted, then wheel odometry
simulated with the issue's recipe ``--odometry-noise 0.05,0.05,0.5 --seed 0``), MRCLAM Dataset 6
robots 1-5, marina, marina-degraded (seed 1) and the harbour scenario. A dataset whose raw data is
absent (``../shared/data``) is skipped with the reason printed. Each log is one task on Dask
(``--scheduler``, as the sweeps: ``local`` (default) an embedded LocalCluster of ``--workers``
processes on 127.0.0.1 without dashboard, ``auto``, ``serial`` or ``tcp://host:8786``); every
estimator the log can feed (``graphnav.estimators.runnable``) runs on it with its defaults.

Columns: ATE RMSE [m] (the smoothed/final trajectory, unaligned, log frame), SE(2)-aligned ATE,
online ATE (the estimate available at each record's time; = ATE for filters), RPE1 (translation
RMSE over consecutive associated poses) and the estimator's runtime [s] (wall, on a shared machine).
"""

from __future__ import annotations

import argparse
import datetime
import json
import logging
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from graphnav.commands._common import add_dashboard_flag  # noqa: E402
from graphnav.evaluation.real_data import DATASETS, _cost, find_data, plan, run_log  # noqa: E402
from graphnav.evaluation.sweep import run_sweep  # noqa: E402

DOC = ROOT / "docs" / "real-data.md"


def _csv(text: str | None) -> list[str] | None:
    return [s.strip() for s in text.split(",") if s.strip()] if text else None


def _f(x: float | None, nd: int = 3) -> str:
    return "–" if x is None else f"{x:.{nd}f}"


def table(results: list[dict[str, Any]]) -> tuple[list[str], list[str]]:
    """Markdown table lines and failure lines."""
    lines = ["| log | estimator | ATE [m] | aligned ATE [m] | online ATE [m] | RPE1 [m] | runtime [s] |",
             "|---|---|---:|---:|---:|---:|---:|"]
    fails = []
    for r in results:
        if "error" in r:
            fails.append(f"{r['log']}: (log) {r['error']}")
            continue
        for row in r["rows"]:
            if "error" in row:
                fails.append(f"{r['log']} / {row['estimator']}: {row['error']}")
                lines.append(f"| {r['log']} | {row['estimator']} | failed | | | | {_f(row['runtime_s'], 1)} |")
                continue
            lines.append(f"| {r['log']} | {row['estimator']} | {_f(row['ate'])} | {_f(row['ate_aligned'])} | "
                         f"{_f(row['ate_online'])} | {_f(row['rpe1'], 4)} | {_f(row['runtime_s'], 1)} |")
    return lines, fails


def _commit() -> str:
    try:
        return subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def write_doc(path: Path, out: dict[str, Any], lines: list[str], fails: list[str], command: str) -> None:
    text = [
        "# Real-data benchmark",
        "",
        "Every estimator that a log can feed, with its defaults, on the real logs of issue #12 (item 8):",
        "the 9 CARMEN logs (converted, wheel odometry simulated with `--odometry-noise 0.05,0.05,0.5 --seed 0`),",
        "MRCLAM Dataset 6 robots 1-5, the marina log, marina-degraded (seed 1) and the harbour scenario.",
        "Written by `benchmarks/real_data.py` (module `graphnav/evaluation/real_data.py`); the raw data",
        "is not part of the project (`../shared/data`).",
        "",
        f"Command: `{command}`  ",
        f"Commit {out['commit']}, {out['date']}; scheduler {out['scheduler']}, {out['workers']} workers; "
        f"wall {out['wall_s']:.0f} s.",
        "",
        "ATE: RMSE of the final (smoothed) trajectory in the log's frame; aligned: after the best SE(2)",
        "fit; online: the estimate available at each record's time (= ATE for filters); RPE1: translation",
        "RMSE between consecutive associated poses; runtime: the estimator's wall time on a shared 2-core",
        "machine (not a benchmark of speed; within a log the estimators share weighted-ICP matches, as",
        "`graphnav compare`, so a later estimator's runtime excludes the matches an earlier one computed).",
        "Every estimator runs with its defaults; `failed` rows are listed with their error below.",
        "",
        *lines,
        "",
        "## Failures",
        "",
        *([f"- {f}" for f in fails] or ["none"]),
        "",
    ]
    if out["skipped"]:
        text += ["## Skipped", "", *[f"- {s['dataset']}: {s['reason']}" for s in out["skipped"]], ""]
    path.write_text("\n".join(text), encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--datasets", default=",".join(DATASETS), help=f"comma list of {', '.join(DATASETS)}")
    ap.add_argument("--carmen", help="comma list of CARMEN log names (default: all 9)")
    ap.add_argument("--robots", help="comma list of MRCLAM robots (default: 1-5)")
    ap.add_argument("--estimators", "-e", help="comma list of estimators (default: every one a log can feed)")
    ap.add_argument("--data", type=Path, default=None, help="the raw data directory (default: ../shared/data)")
    ap.add_argument("--logs", type=Path, default=None,
                    help="read CARMEN/MRCLAM pre-converted from DIR/carmen-NAME.jsonl.gz, DIR/mrclam6-rN.jsonl.gz")
    ap.add_argument("--scheduler", default="local",
                    help="local (default): an embedded Dask LocalCluster; auto: in-process when a cluster "
                         "would cost more to start than it saves; 'tcp://host:8786': an existing cluster; "
                         "serial: in-process")
    ap.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes (default 2)")
    add_dashboard_flag(ap)
    ap.add_argument("--no-icp-cache", action="store_true",
                    help="each estimator computes its own ICP matches (default: shared within a log, as "
                         "'graphnav compare'; later estimators' runtimes then exclude the shared matches)")
    ap.add_argument("--results", type=Path, default=None,
                    help="JSON-lines file of finished logs: an interrupted run resumes from it (a log is "
                         "reused only if its task is the same; a file written by other code is refused)")
    ap.add_argument("--overwrite", action="store_true", help="discard what --results holds and start it afresh")
    ap.add_argument("--doc", type=Path, default=DOC, help=f"markdown file to write (default {DOC.relative_to(ROOT)})")
    ap.add_argument("--no-doc", action="store_true", help="do not write the markdown file")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr)

    datasets = _csv(args.datasets) or []
    robots = [int(r) for r in _csv(args.robots) or []] or None
    data_dir = args.data if args.data is not None else find_data(ROOT)
    tasks, skipped = plan(datasets, repo=ROOT, data_dir=data_dir, logs_dir=args.logs, carmen=_csv(args.carmen),
                          robots=robots, estimators=_csv(args.estimators), icp_cache=not args.no_icp_cache)
    for s in skipped:
        print(f"skipped {s['dataset']}: {s['reason']}", file=sys.stderr)
    report: dict[str, Any] = {}
    t0 = time.perf_counter()
    cost = sum(_cost(t) for t in tasks) / max(1, len(tasks))
    results = run_sweep(run_log, tasks, out=args.results, scheduler=args.scheduler, workers=args.workers,
                        progress=not args.no_progress, desc="real data", task_cost_s=cost, report=report,
                        dashboard=args.dashboard, overwrite=args.overwrite)
    wall = time.perf_counter() - t0
    lines, fails = table(results)
    out = {"commit": _commit(), "date": datetime.date.today().isoformat(), "scheduler": report.get("scheduler"),
           "workers": args.workers, "wall_s": wall, "logs": results, "failures": fails, "skipped": skipped}
    if not args.no_doc:
        command = "python benchmarks/real_data.py " + " ".join(argv if argv is not None else sys.argv[1:])
        write_doc(args.doc, out, lines, fails, command.strip())
    if args.json:
        print(json.dumps(out, allow_nan=False))
    else:
        print("\n".join(lines))
        print("\nfailures:" if fails else "\nfailures: none")
        for f in fails:
            print(f"  {f}")
        print(f"\nwall {wall:.0f} s, scheduler {report.get('scheduler')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
