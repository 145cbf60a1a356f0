"""Leave-one-out for the graph's defaults (issue #25 item 2): does a value chosen without a log hold on it?

For every parameter of a grid (one at a time, every other option at its default) the estimator runs on
every log at every value of the parameter. Then, for each log held out in turn, the value that does best
on the *other* logs (the mean over them of the metric relative to each log's own default run, so a long
log does not outweigh a short one) is applied to the held-out log and compared with the value chosen on
all logs, the best value for that log alone, and the default. With logs of two kinds (CARMEN, MRCLAM) the
same is done per kind: the value chosen on one kind applied to the other (a parameter both kinds use).

    python benchmarks/leave_one_out.py LOG... [-p NAME=v1,v2,...]... [--metric ate,online] [--results F.jsonl]
    python benchmarks/leave_one_out.py /tmp/logs/mrclam6-r*.jsonl.gz --results loo.jsonl   # the built-in grid
    python benchmarks/leave_one_out.py LOGS --results loo.jsonl --table-only                 # print from the cache

The logs are the converted ones of issue #12 (docs/smoother.md, "Real logs"; never in the repository).
Without ``-p`` the grid is the defaults of docs/defaults.md that a log of the kind can feed: x0.5 and x2
around each default. ``--results`` caches every run (JSON lines, keyed by log, estimator and options), so
an interrupted sweep resumes and the table can be re-printed. ``--base key=value`` options apply to every
run (e.g. ``covariances=false``: the marginals change no estimate, only the time).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

METRICS = {"ate": "ate_rmse_m", "aligned": "ate_aligned_rmse_m", "online": "online_ate_rmse_m", "rpe1": "rpe_rmse_m"}

#: the defaults of docs/defaults.md a kind of log can feed, each at x0.5 and x2 (the default is the middle)
GRIDS: dict[str, dict[str, list[Any]]] = {
    "isam2:mrclam6": {  # the most suspect first (chosen on MRCLAM robots 1, 2, 5; CARMEN)
        "beacon_sigma_range": [0.05, 0.1, 0.2],
        "beacon_sigma_bearing_deg": [0.5, 1.0, 2.0],
        "relinearize_threshold_landmarks": [0.025, 0.05, 0.1],
        "odo_lateral": [0.05, 0.1, 0.2],
        "odo_sigma_v": [0.01, 0.02, 0.04],
        "odo_sigma_w_deg": [0.5, 1.0, 2.0],
    },
    "isam2:carmen": {  # the loop closer's thresholds chosen on CARMEN (docs/defaults.md), then its rules
        "odo_lateral": [0.05, 0.1, 0.2],
        "icp_gate": [2.0, 4.0, 8.0],
        "loop.descriptor_max": [0.175, 0.35, 0.7],
        "loop.min_hits": [0.2, 0.4, 0.8],
        "loop.max_ambiguity": [0.8, 0.9, 0.95],  # a ratio <= 1: its margin 1 - x doubled and halved
        "loop.kernel_k": [0.5, 1.0, 2.0],
        "loop.min_sigma": [0.25, 0.5, 1.0],
    },
    "ekf-slam:mrclam6": {  # EkfSlamConfig's None = SENSOR_DEFAULTS (graphnav/estimators/ekf_slam.py)
        "sigma_v": [0.05, 0.1, 0.2],
        "sigma_rot": [math.radians(2.5), math.radians(5.0), math.radians(10.0)],
        "sigma_range": [0.25, 0.5, 1.0],
        "sigma_bearing": [math.radians(1.0), math.radians(2.0), math.radians(4.0)],
        "adaptive": [False, True],
        "window": [10, 20, 40],
    },
}


def kind(log: str) -> str:
    return log.split("-")[0]


def options_of(name: str, value: Any) -> dict[str, Any]:
    """``loop.kernel_k=2`` -> ``{"loop": {"kernel_k": 2}}``; a plain name as it is."""
    if "." in name:
        outer, inner = name.split(".", 1)
        return {outer: {inner: value}}
    return {name: value}


def key(log: str, estimator: str, options: dict[str, Any]) -> str:
    return json.dumps([log, estimator, options], sort_keys=True)


def measure(path: Path, estimator: str, options: dict[str, Any]) -> dict[str, Any]:
    """One run: the summary's metrics (``error`` when it fails)."""
    from graphnav import estimators
    from graphnav.evaluation.evaluate import summarize
    from graphnav.io import load_log

    log = load_log(path)
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        r = estimators.run(estimator, log, **options)
    except Exception as e:  # noqa: BLE001 -- a failed setting is a result of the sweep, not its end
        return {"error": f"{type(e).__name__}: {e}"[:300]}
    s = summarize(estimator, r, log, runtime_s=time.perf_counter() - t0)
    out = {m: s.get(k) for m, k in METRICS.items()}
    out["cpu_s"] = time.process_time() - c0
    return out


def default_of(name: str, estimator: str = "isam2") -> Any:
    """The value a run without the option uses (EKF-SLAM's ``None``: its mode's sensor default)."""
    from graphnav.graph.loops import LoopConfig
    from graphnav.graph.smoother_config import SmootherConfig

    if estimator == "ekf-slam":
        from graphnav.estimators.ekf_slam import SENSOR_DEFAULTS, EkfSlamConfig

        v = getattr(EkfSlamConfig(), name)
        if name == "adaptive" and v is None:
            return True
        return SENSOR_DEFAULTS[name] if v is None else v
    if name.startswith("loop."):
        return getattr(LoopConfig(), name.split(".", 1)[1])
    return SmootherConfig().value(name)


def sweep(paths: list[Path], grid: dict[str, dict[str, list[Any]]], estimator: str, base: dict[str, Any],
          cache: dict[str, dict], results: Path | None, run: bool) -> None:
    """Every (log, parameter, value) not yet in ``cache``: run it, append it to ``results``. Parameter
    by parameter over all logs (the default runs first), so an interrupted sweep leaves whole parameters."""
    names = {path: path.name.split(".")[0] for path in paths}
    todo = [(path, dict(base)) for path in paths]
    params: dict[str, list[Any]] = {}
    for path in paths:
        for p, vals in grid.get(f"{estimator}:{kind(names[path])}", {}).items():
            params.setdefault(p, vals)
    for p, vals in params.items():
        for v in vals:
            if v != default_of(p, estimator):
                todo += [(path, {**base, **options_of(p, v)}) for path in paths
                         if p in grid.get(f"{estimator}:{kind(names[path])}", {})]
    for path, opts in todo:
        k = key(names[path], estimator, opts)
        if k in cache or not run:
            continue
        cache[k] = measure(path, estimator, opts)
        print(json.dumps({"log": names[path], "options": opts, **cache[k]}), file=sys.stderr, flush=True)
        if results is not None:
            with results.open("a", encoding="utf-8") as fh:
                fh.write(json.dumps({"key": k, "result": cache[k]}) + "\n")


def value_table(logs: list[str], param: str, values: list[Any], estimator: str, base: dict[str, Any],
                cache: dict[str, dict], metric: str) -> dict[str, dict[Any, float]]:
    """{log: {value: metric}} (the default value's entry is the base run)."""
    d = default_of(param, estimator)
    out: dict[str, dict[Any, float]] = {}
    for log in logs:
        row = {}
        for v in values:
            opts = dict(base) if v == d else {**base, **options_of(param, v)}
            r = cache.get(key(log, estimator, opts))
            if r and r.get(metric) is not None:
                row[v] = float(r[metric])
        if len(row) == len(values):
            out[log] = row
    return out


def choose(table: dict[str, dict[Any, float]], logs: list[str], values: list[Any], default: Any) -> Any:
    """The value with the lowest mean of metric / (metric at the default) over ``logs`` (ties: the default)."""
    score = {v: float(np.mean([table[g][v] / table[g][default] for g in logs])) for v in values}
    best = min(score.values())
    return default if score[default] <= best + 1e-12 else min(values, key=lambda v: score[v])


def analyse(table: dict[str, dict[Any, float]], values: list[Any], default: Any) -> dict[str, Any]:
    """Leave-one-out over the logs of ``table`` and, with two kinds, across kinds."""
    logs = sorted(table)
    rows = []
    on_all = choose(table, logs, values, default)
    for g in logs:
        others = [o for o in logs if o != g]
        held = choose(table, others, values, default) if others else default
        own = min(values, key=lambda v: table[g][v])
        rows.append({"log": g, "chosen_without": held, "chosen_on_all": on_all, "best_own": own,
                     "m_default": table[g][default], "m_without": table[g][held], "m_all": table[g][on_all],
                     "m_best": table[g][own]})
    kinds = sorted({kind(g) for g in logs})
    across = []
    if len(kinds) == 2:
        for a, b in (kinds, kinds[::-1]):
            la = [g for g in logs if kind(g) == a]
            lb = [g for g in logs if kind(g) == b]
            va, vb = choose(table, la, values, default), choose(table, lb, values, default)
            across.append({"chosen_on": a, "value": va, "applied_to": b, "own_value": vb,
                           "mean_rel": float(np.mean([table[g][va] / table[g][vb] for g in lb]))})
    return {"default": default, "chosen_on_all": on_all, "rows": rows, "across": across,
            "mean_without_over_all": float(np.mean([r["m_without"] / r["m_all"] for r in rows])),
            "mean_default_over_all": float(np.mean([r["m_default"] / r["m_all"] for r in rows])),
            "worst_without_over_all": float(max(r["m_without"] / r["m_all"] for r in rows)),
            # the held-out regret against the default: < 1, the value chosen on the other logs beats it
            "mean_without_over_default": float(np.mean([r["m_without"] / r["m_default"] for r in rows])),
            "min_without_over_default": float(min(r["m_without"] / r["m_default"] for r in rows)),
            "max_without_over_default": float(max(r["m_without"] / r["m_default"] for r in rows))}


def markdown(report: dict[str, Any]) -> str:
    f = lambda x: f"{x:.3f}"  # noqa: E731
    out = []
    for metric, params in report["tables"].items():
        out += [f"**{metric}** ({report['estimator']}; m = {METRICS[metric]})", "",
                "| parameter | default | chosen on all | held-out log | chosen without it | m default | "
                "m without | m all | m best own |", "|---|---|---|---|---|---|---|---|---|"]
        for p, a in params.items():
            for r in a["rows"]:
                out.append(f"| {p} | {a['default']} | {a['chosen_on_all']} | {r['log']} | {r['chosen_without']} | "
                           f"{f(r['m_default'])} | {f(r['m_without'])} | {f(r['m_all'])} | {f(r['m_best'])} |")
            out.append(f"| {p} | | | **mean m/m(all)** | | {a['mean_default_over_all']:.3f} | "
                       f"{a['mean_without_over_all']:.3f} (worst {a['worst_without_over_all']:.3f}) | 1 | |")
            for c in a["across"]:
                out.append(f"| {p} | | | chosen on {c['chosen_on']} ({c['value']}) -> {c['applied_to']} "
                           f"(own {c['own_value']}) | | | x{c['mean_rel']:.3f} | | |")
        out.append("")
    return "\n".join(out)


def _v(x: Any) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def summary(report: dict[str, Any]) -> str:
    """One row per parameter: the values chosen with each log held out, and what they cost."""
    out = []
    for metric, params in report["tables"].items():
        out += [f"**{metric}** ({report['estimator']}, {len(report['logs'])} logs)", "",
                "| parameter | default | chosen on all | chosen without each log | m(default) / m(all) | "
                "m(without) / m(all): mean, worst | m(without) / m(default): mean (min-max) | across kinds |",
                "|---|---|---|---|---|---|---|---|"]
        for p, a in params.items():
            held = ", ".join(_v(r["chosen_without"]) for r in a["rows"])
            across = "; ".join(f"{c['chosen_on']} -> {c['applied_to']} x{c['mean_rel']:.3f}" for c in a["across"])
            out.append(f"| {p} | {_v(a['default'])} | {_v(a['chosen_on_all'])} | {held} | "
                       f"{a['mean_default_over_all']:.3f} | {a['mean_without_over_all']:.3f}, "
                       f"{a['worst_without_over_all']:.3f} | {a['mean_without_over_default']:.3f} "
                       f"({a['min_without_over_default']:.3f}-{a['max_without_over_default']:.3f}) | {across or '-'} |")
        out.append("")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("logs", nargs="+", type=Path)
    ap.add_argument("-p", "--param", action="append", default=[], metavar="NAME=v1,v2,...",
                    help="a parameter and its values (the default among them); default: the built-in grid")
    ap.add_argument("-e", "--estimator", default="isam2")
    ap.add_argument("--metric", default="ate,online", help=f"comma list of {', '.join(METRICS)}")
    ap.add_argument("--base", action="append", default=[], metavar="KEY=VALUE", help="an option for every run")
    ap.add_argument("--results", type=Path, help="JSON-lines cache of runs (resumes; --table-only reads it)")
    ap.add_argument("--table-only", action="store_true", help="no runs: the table from --results")
    ap.add_argument("--json", action="store_true", help="one JSON object on stdout")
    ap.add_argument("--summary", action="store_true", help="one row per parameter (the per-log rows left out)")
    args = ap.parse_args(argv)
    from graphnav.commands._common import parse_options

    base = parse_options(args.base)
    names = [p.name.split(".")[0] for p in args.logs]
    if args.param:
        custom = {}
        for item in args.param:
            n, vals = item.split("=", 1)
            custom[n] = [json.loads(v) for v in vals.split(",")]
        grid = {f"{args.estimator}:{kind(n)}": custom for n in names}
    else:
        grid = GRIDS
    cache: dict[str, dict] = {}
    if args.results is not None and args.results.exists():
        for line in args.results.read_text(encoding="utf-8").splitlines():
            if line.strip():
                row = json.loads(line)
                cache[row["key"]] = row["result"]
    sweep(args.logs, grid, args.estimator, base, cache, args.results, run=not args.table_only)
    params: dict[str, list[Any]] = {}
    for n in names:
        for p, vals in grid.get(f"{args.estimator}:{kind(n)}", {}).items():
            params.setdefault(p, vals)
    report: dict[str, Any] = {"estimator": args.estimator, "base": base, "logs": names, "tables": {}}
    for metric in [m.strip() for m in args.metric.split(",") if m.strip()]:
        report["tables"][metric] = {}
        for p, vals in params.items():
            logs = [n for n in names if p in grid.get(f"{args.estimator}:{kind(n)}", {})]
            table = value_table(logs, p, vals, args.estimator, base, cache, metric)
            if table:
                report["tables"][metric][p] = analyse(table, vals, default_of(p, args.estimator))
    print(json.dumps(report, allow_nan=False) if args.json else summary(report) if args.summary else markdown(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
