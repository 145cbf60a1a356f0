"""Write a comparison to a directory: ``report.md`` (one table, configurations, figures), the PNGs
of :mod:`graphnav.evaluation.plots`, and ``<estimator>.tum`` per estimator (evo-readable)."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..io.jsonsafe import jsonable
from ..io.outputs import OutDir, write_text_atomic
from ..log import NavLog
from . import plots
from .compare import Entry, ranked

# (summary key, column header, format)
COLUMNS: list[tuple[str, str, str]] = [
    ("ate_rmse_m", "ATE RMSE [m]", "{:.3f}"),
    ("ate_mean_m", "ATE mean [m]", "{:.3f}"),
    ("ate_median_m", "ATE median [m]", "{:.3f}"),
    ("ate_max_m", "ATE max [m]", "{:.3f}"),
    ("online_ate_rmse_m", "online ATE RMSE [m]", "{:.3f}"),
    ("rpe_rmse_m", "RPE 1 [m]", "{:.3f}"),
    ("rpe10_rmse_m", "RPE 10 [m]", "{:.3f}"),
    ("sog_rmse_mps", "SOG RMSE [m/s]", "{:.3f}"),
    ("cog_rmse_deg", "COG RMSE [deg]", "{:.2f}"),
    ("rot_rmse_degps", "ROT RMSE [deg/s]", "{:.2f}"),
    ("runtime_s", "runtime [s]", "{:.2f}"),
    ("step_ms_median", "step [ms] (median)", "{:.2f}"),
    ("icp_ms_median", "scan match [ms] (median)", "{:.2f}"),
    ("icp_cache_hits", "shared matches", "{:d}"),
]
SHARED_NOTE = (" *shared matches*: weighted-ICP matches taken from an earlier estimator of this run (same "
               "scans, configuration and initial guess; `--no-icp-cache` turns the sharing off); an "
               "estimator's runtime excludes its shared matches, its *scan match* time is their computation "
               "time (by the estimator that computed them first).")
# the keys every estimator gets in the --json object (issue #7), plus the rest of summarize()
JSON_KEYS = ("ate_rmse_m", "rpe_rmse_m", "runtime_s", "step_ms_median")


def file_stem(name: str) -> str:
    """An estimator name (or label) as a safe file name stem."""
    return re.sub(r"[^A-Za-z0-9_.+-]", "_", name).lstrip(".") or "estimator"


def _fmt(v: Any, f: str) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    try:
        return f.format(v)
    except (ValueError, TypeError):
        return str(v)


def to_json(entries: Sequence[Entry], log_name: str, **extra: Any) -> dict[str, Any]:
    """``{"log": ..., "estimators": {name: {"ate_rmse_m", "rpe_rmse_m", "runtime_s",
    "step_ms_median", ...}}}``; a failed estimator carries ``"error"`` (and null figures)."""
    est: dict[str, Any] = {}
    for e in entries:
        if e.ok:
            d = {k: e.summary.get(k) for k in JSON_KEYS}
            d.update({k: v for k, v in e.summary.items() if k not in d and k != "estimator"})
            d["kind"] = e.kind
        else:
            d = {k: None for k in JSON_KEYS}
            d["error"] = e.error
        if e.options:
            d["options"] = e.options
        est[e.name] = d
    return jsonable({"log": log_name, "estimators": est, **extra})


def markdown_table(entries: Sequence[Entry]) -> str:
    def present(v: Any) -> bool:
        return v is not None and not (isinstance(v, float) and not math.isfinite(v))

    cols = [c for c in COLUMNS if any(e.ok and present((e.summary or {}).get(c[0])) for e in entries)]
    head = "| rank | estimator | kind | " + " | ".join(h for _, h, _ in cols) + " |"
    sep = "|---:|---|---|" + "|".join("---:" for _ in cols) + "|"
    rows = [head, sep]
    for i, e in enumerate(ranked(entries), 1):
        if e.ok:
            vals = [_fmt(e.summary.get(k), f) for k, _, f in cols]
            rows.append(f"| {i} | {e.name} | {e.kind} | " + " | ".join(vals) + " |")
        else:
            rows.append(f"| – | {e.name} | {e.kind or '?'} | " + " | ".join("–" for _ in cols) + " |")
    return "\n".join(rows)


def _brief(v: Any, max_len: int = 20) -> Any:
    """``v`` with long sequences (at any depth) replaced by a note of their length."""
    if isinstance(v, dict):
        return {k: _brief(x, max_len) for k, x in v.items()}
    if isinstance(v, list | tuple | np.ndarray):
        if len(v) > max_len:
            return f"<{len(v)} values>"
        return [_brief(x, max_len) for x in v]
    return v


def _config(e: Entry) -> dict[str, Any]:
    """The options and ``RunResult.info`` of an estimator, long arrays summarised."""
    info = e.result.info if e.result is not None else {}
    cfg = {"options": e.options} if e.options else {}
    cfg.update(info)
    return jsonable(_brief(cfg))


def write_report(entries: Sequence[Entry], log: NavLog, out: Path | OutDir, *, log_name: str = "") -> dict[str, Path]:
    """Write report.md, the PNGs and one TUM file per estimator into ``out`` (each atomically; an
    :class:`~graphnav.io.outputs.OutDir` records every name in its manifest before writing it);
    returns the paths."""
    log_name = log_name or str(log.meta.get("name", "log"))
    if not isinstance(out, OutDir):
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
    files: dict[str, Path] = {}
    ok = [e for e in entries if e.ok and e.result is not None]
    trajs = {e.name: e.result.trajectory for e in ok}
    for e in ok:
        p = out / f"{file_stem(e.name)}.tum"
        e.result.trajectory.to_tum(p)
        files[p.name] = p
        onl = e.result.online
        if onl is not None and onl is not e.result.trajectory and len(onl):
            p = out / f"{file_stem(e.name)}.online.tum"
            onl.to_tum(p)
            files[p.name] = p
    truth = log.truth() if log.has_truth else None
    events = log.meta.get("events", []) or []
    gnss = None
    if log.of("gnss"):
        c = log.columns("gnss")
        gnss = np.column_stack([c["x"], c["y"]])
    figs: list[tuple[str, str]] = []
    if trajs:
        title = f"Trajectories over the truth — {Path(log_name).name or log_name}"
        files["trajectories.png"] = plots.plot_trajectories(trajs, truth, out / "trajectories.png", gnss, title=title)
        figs.append(("Trajectories", "trajectories.png"))
        if truth is not None:
            online = {e.name: e.result.online for e in ok
                      if e.result.online is not None and e.result.online is not e.result.trajectory}
            files["position_error.png"] = plots.plot_position_error(trajs, truth, out / "position_error.png",
                                                                    events, online)
            files["error_cdf.png"] = plots.plot_error_cdf(trajs, truth, out / "error_cdf.png")
            files["sog_cog.png"] = plots.plot_sog_cog(trajs, truth, out / "sog_cog.png", events)
            figs += [("Position error versus time (smoothers: online estimate dashed)", "position_error.png"),
                     ("Error CDF", "error_cdf.png"),
                     ("SOG, COG and ΔCOG errors (weighted-ICP paper, Figs. 12-15 style)", "sog_cog.png")]
        cov = plots.plot_covariance(trajs, truth, out / "covariance.png")
        if cov is not None:
            files["covariance.png"] = cov
            figs.append(("Covariance ellipses (2σ)", "covariance.png"))

    lines = [f"# Estimator comparison — {log_name}", ""]
    counts = ", ".join(f"{k}: {v}" for k, v in log.counts().items())
    span = f"{log.t1 - log.t0:.1f} s" if log.records else "empty"
    lines += [f"Log: {counts}; duration {span}.", ""]
    if events:
        listed = "; ".join(f"{ev.get('kind')} {ev.get('t0'):.1f}–{ev.get('t1'):.1f} s" for ev in events)
        lines += [f"Events (GNSS outages/jumps and shorter conditions shaded in the plots): {listed}", ""]
    lines += ["## Results", "",
              "Ranked by ATE RMSE. ATE is unaligned (in the log's frame), over poses time-associated with "
              "the truth; RPE over 1 and 10 associated poses; SOG/COG/ROT errors between consecutive "
              "associated poses (COG only while the truth moves faster than 0.2 m/s). For smoothers ATE is "
              "the smoothed trajectory and *online ATE* the estimate available at each time. *step* is "
              "solver/filter time per step excluding scan matching; *scan match* is per registration."
              + (SHARED_NOTE if any((e.summary or {}).get("icp_cache_hits") for e in entries) else ""),
              "", markdown_table(entries), ""]
    if truth is None:
        lines += ["The log has no truth: only timing is reported.", ""]
    failed = [e for e in entries if not e.ok]
    if failed:
        lines += ["## Failed or not runnable", ""]
        lines += [f"- **{e.name}**: `{e.error}`" for e in failed]
        lines.append("")
    lines += ["## Configuration", ""]
    for e in entries:
        if not e.ok:
            continue
        lines += [f"### {e.name} ({e.kind})", "", e.description, "",
                  "```json", json.dumps(_config(e), indent=2, sort_keys=True), "```", ""]
    if figs:
        lines += ["## Figures", ""]
        for title, f in figs:
            lines += [f"### {title}", "", f"![{title}]({f})", ""]
    tums = ", ".join(f"`{file_stem(e.name)}.tum`" for e in ok)
    lines += [f"Trajectories: {tums} (TUM, evo-readable).", ""]
    p = write_text_atomic(out / "report.md", "\n".join(lines))
    files["report.md"] = p
    return files
