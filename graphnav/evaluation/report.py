"""Write a comparison to a directory: ``report.md`` and ``report.html`` (provenance, warnings, one
table, skipped and failed estimators, configurations, figures), the PNGs of
:mod:`graphnav.evaluation.plots`, ``<estimator>.tum`` per estimator and ``truth.tum`` (evo-readable).

``report.html`` is self-contained, to send to a colleague: the figures are inlined as base64 PNG,
the style sheet is inline, there is no script, and its Content-Security-Policy forbids any network
load. Both reports are rendered from one list of blocks, so they say the same thing.
"""

from __future__ import annotations

import base64
import datetime as _dt
import hashlib
import html
import json
import math
import os
import re
import shlex
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..io.jsonsafe import jsonable
from ..io.outputs import OutDir, write_text_atomic
from ..io.tum import write_truth, write_tum
from ..log import NavLog
from . import plots
from .comparison import Entry, ranked

# (summary key, column header, format)
COLUMNS: list[tuple[str, str, str]] = [
    ("ate_rmse_m", "ATE RMSE [m]", "{:.3f}"),
    ("ate_mean_m", "ATE mean [m]", "{:.3f}"),
    ("ate_median_m", "ATE median [m]", "{:.3f}"),
    ("ate_max_m", "ATE max [m]", "{:.3f}"),
    ("online_ate_rmse_m", "online ATE RMSE [m]", "{:.3f}"),
    ("heading_rmse_deg", "heading RMSE [deg]", "{:.3f}"),
    ("nees_mean", "NEES mean", "{:.2f}"),
    ("nees_in95", "NEES in 95 % band", "{:.0%}"),
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
NEES_NOTE = (" *NEES*: the position NEES of the estimator's own covariance against the truth (2 degrees of "
             "freedom), averaged over the same pairs as ATE: a consistent estimator gives 2, a larger value "
             "means an over-confident covariance, a smaller one a pessimistic covariance; *in 95 % band*: "
             "the fraction of samples inside the two-sided 95 % chi-square interval (0.05-7.38); – when the "
             "estimator gives no covariance.")
# the keys every estimator gets in the --json object (issue #7, #17), plus the rest of summarize()
JSON_KEYS = ("ate_rmse_m", "rpe_rmse_m", "runtime_s", "step_ms_median", "heading_rmse_deg", "nees_mean")

# RunResult.info counters worth a warning: (key, key of the total or None, what was counted)
WARN_COUNTERS: list[tuple[str, str | None, str]] = [
    ("icp_failed", "icp_pairs", "weighted-ICP matches flagged (degenerate geometry, too few points or inliers, or "
                                "a step beyond the limit) and left out"),
    ("failed_matches", "matches", "weighted-ICP matches flagged and bridged by odometry or a constant-velocity guess"),
    ("degenerate_registrations", "registrations", "registrations degenerate along some direction (the prediction "
                                                  "kept along the weak directions)"),
    ("failed_registrations", "registrations", "registrations rejected (fitness or correction limits; the "
                                              "prediction kept)"),
    ("gnss_rejected", None, "GNSS fixes rejected by the gate"),
    ("gnss_dropped_after_lm", None, "GNSS fixes dropped after the batch solve"),
    ("rejected", None, "measurements rejected by the innovation gate"),
    ("forced", None, "measurements forced in after persistent gate rejections (covariance inflated)"),
    ("scans_skipped_before_anchor", "scans", "scans skipped before the start pose was known"),
]
_WARN_WORDS = ("failed", "rejected", "degenerate", "dropped", "skipped", "diverged")


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
    "step_ms_median", "heading_rmse_deg", "nees_mean", ...}}}``; a failed estimator carries ``"error"``,
    one the log cannot feed ``"skipped"`` (the reason), both with null figures."""
    est: dict[str, Any] = {}
    for e in entries:
        if e.ok:
            d = {k: e.summary.get(k) for k in JSON_KEYS}
            d.update({k: v for k, v in e.summary.items() if k not in d and k != "estimator"})
            d["kind"] = e.kind
        else:
            d = {k: None for k in JSON_KEYS}
            if e.error is not None:
                d["error"] = e.error
            else:
                d["skipped"] = e.skipped
            if e.kind:
                d["kind"] = e.kind
        if e.options:
            d["options"] = e.options
        est[e.name] = d
    return jsonable({"log": log_name, "estimators": est, **extra})


def _present(v: Any) -> bool:
    return v is not None and not (isinstance(v, float) and not math.isfinite(v))


def results_table(entries: Sequence[Entry]) -> tuple[list[str], list[list[str]]]:
    """The ranked table: header and rows of text cells; a failed or skipped estimator has a row
    whose last cell (*note*) says why."""
    cols = [c for c in COLUMNS if any(e.ok and _present((e.summary or {}).get(c[0])) for e in entries)]
    head = ["rank", "estimator", "kind", *(h for _, h, _ in cols), "note"]
    rows = []
    for i, e in enumerate(ranked(entries), 1):
        if e.ok:
            rows.append([str(i), e.name, e.kind, *(_fmt(e.summary.get(k), f) for k, _, f in cols), ""])
        else:
            note = f"failed: {e.error}" if e.error is not None else f"not run: {e.skipped}"
            rows.append(["–", e.name, e.kind or "?", *("–" for _ in cols), note])
    return head, rows


def event_table(entries: Sequence[Entry]) -> tuple[list[str], list[list[str]]] | None:
    """Position errors inside the log's event windows (``errors_by_event``), one row per estimator
    in the ranking's order and a smoothed / online column pair per event kind; ``None`` when no
    estimator has any."""
    kinds: list[str] = []
    for e in entries:
        for k in (e.summary or {}).get("errors_by_event") or {}:
            if k not in kinds:
                kinds.append(k)
    if not kinds:
        return None
    head = ["estimator", *(f"{k} {w} [m]" for k in kinds for w in ("RMSE", "max", "online RMSE"))]
    rows = []
    for e in ranked(entries):
        ev = (e.summary or {}).get("errors_by_event") or {}
        if e.ok:
            rows.append([e.name, *(_fmt((ev.get(k) or {}).get(f), "{:.3f}") for k in kinds
                                   for f in ("rmse_m", "max_m", "online_rmse_m"))])
    return head, rows


def markdown_table(entries: Sequence[Entry]) -> str:
    head, rows = results_table(entries)
    return _md_table(head, rows, ["---:", "---", "---"] + ["---:"] * (len(head) - 4) + ["---"])


def _md_table(head: list[str], rows: list[list[str]], align: list[str] | None = None) -> str:
    def cell(s: str) -> str:
        return s.replace("|", "\\|").replace("\n", " ")

    align = align or ["---"] * len(head)
    out = ["| " + " | ".join(cell(h) for h in head) + " |", "|" + "|".join(align) + "|"]
    out += ["| " + " | ".join(cell(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


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


# -- provenance and warnings ---------------------------------------------------------------------------

def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        v = version("graphnav")
    except PackageNotFoundError:
        v = "unknown"
    src = Path(__file__).resolve().parents[2]
    if not (src / "pyproject.toml").exists() or not (src / ".git").exists():
        return v  # an installed package: no checkout to describe
    try:
        rev = subprocess.run(["git", "-C", str(src), "describe", "--always", "--dirty"], capture_output=True,
                             text=True, timeout=10)
        if rev.returncode == 0 and rev.stdout.strip():
            v += f" (git {rev.stdout.strip()})"
    except (OSError, subprocess.SubprocessError):
        pass
    return v


def _digest(path: Path) -> tuple[int, str]:
    """Size in bytes and SHA-256 of a file, or of a directory's files (relative names and contents,
    in sorted order)."""
    h = hashlib.sha256()
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    size = 0
    for f in files:
        if f is not path:
            h.update(str(f.relative_to(path)).encode() + b"\0")
        with open(f, "rb") as fh:
            for chunk in iter(lambda fh=fh: fh.read(1 << 20), b""):
                h.update(chunk)
                size += len(chunk)
    return size, h.hexdigest()


def provenance(log_path: str | Path | None, command: str | None = None) -> dict[str, str]:
    """Where a report came from: date (UTC), graphnav version (and git revision when run from a
    checkout), Python, the command line, and the log with its size and SHA-256."""
    out = {"date": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC"),
           "graphnav": _version(),
           "python": sys.version.split()[0],
           "command": command or f"(not given; the process: {shlex.join(sys.argv)})"}
    if log_path is not None:
        p = Path(log_path)
        out["log"] = str(log_path)
        if p.exists():
            size, sha = _digest(p)
            out["log size"] = f"{size:,} bytes" + (" (directory)" if p.is_dir() else "")
            out["log SHA-256"] = sha
    return out


def warnings(entries: Sequence[Entry], log: NavLog) -> list[str]:
    """What a reader must know before trusting the table, as sentences: estimators skipped (and why)
    or failed, scan matches flagged or rejected (from each ``RunResult.info``), a log without truth."""
    out = []
    for e in entries:
        if e.skipped is not None and e.error is None:
            out.append(f"**{e.name}** was not run: {e.skipped}.")
        elif e.error is not None:
            out.append(f"**{e.name}** failed: `{e.error}`.")
    for e in entries:
        if not e.ok or e.result is None:
            continue
        info = e.result.info
        said = set()
        for key, total, what in WARN_COUNTERS:
            n = info.get(key)
            if not isinstance(n, int | np.integer) or isinstance(n, bool) or n <= 0:
                continue
            said.add(key)
            tot = info.get(total) if total else None
            if isinstance(tot, int | np.integer) and tot > 0:
                out.append(f"**{e.name}**: {n:,} of {tot:,} ({100.0 * n / tot:.1f} %) {what}.")
            else:
                out.append(f"**{e.name}**: {n:,} {what}.")
        for key, n in info.items():  # counters this list does not know yet: stated as they are
            if (key not in said and isinstance(n, int | np.integer) and not isinstance(n, bool) and n > 0
                    and any(w in key for w in _WARN_WORDS)):
                out.append(f"**{e.name}**: `{key}` = {n:,}.")
    if not log.has_truth:
        out.append("The log has no truth: no accuracy figure can be computed, only timing.")
    return out


# -- one report, two renderings ----------------------------------------------------------------------
# blocks: ("h", level, text) ("p", text) ("ul", [text]) ("kv", [(key, value)]) ("warn", [text])
#         ("table", head, rows) ("code", lang, text) ("fig", title, file name)

def _blocks(entries: Sequence[Entry], log: NavLog, log_name: str, prov: dict[str, str], warns: list[str],
            figs: list[tuple[str, str]], truth_file: str | None) -> list[tuple]:
    b: list[tuple] = [("h", 1, f"Estimator comparison — {log_name}"), ("kv", list(prov.items()))]
    counts = ", ".join(f"{k}: {v}" for k, v in log.counts().items())
    span = f"{log.t1 - log.t0:.1f} s" if log.records else "empty"
    b.append(("p", f"Log: {counts}; duration {span}."))
    events = log.meta.get("events", []) or []
    if events:
        listed = "; ".join(f"{ev.get('kind')} {ev.get('t0'):.1f}–{ev.get('t1'):.1f} s" for ev in events)
        b.append(("p", f"Events (GNSS outages/jumps and shorter conditions shaded in the plots): {listed}"))
    b += [("h", 2, "Warnings"), ("warn", warns or ["None: every estimator ran, and none flagged a measurement."])]
    head, rows = results_table(entries)
    b += [("h", 2, "Results"),
          ("p", "Ranked by ATE RMSE. ATE is unaligned (in the log's frame), over poses time-associated with "
                "the truth; RPE over 1 and 10 associated poses; SOG/COG/ROT errors between consecutive "
                "associated poses (COG only while the truth moves faster than 0.2 m/s). For smoothers ATE is "
                "the smoothed trajectory and *online ATE* the estimate available at each time. *step* is "
                "solver/filter time per step excluding scan matching; *scan match* is per registration."
                + NEES_NOTE
                + (SHARED_NOTE if any((e.summary or {}).get("icp_cache_hits") for e in entries) else "")),
          ("table", head, rows)]
    ev_table = event_table(entries)
    if ev_table is not None:
        b += [("h", 3, "Errors inside events"),
              ("p", "Position error (unaligned, the pairs of the ATE) inside the log's event windows, pooled per "
                    "kind; *online*: the estimate available at each time."),
              ("table", *ev_table)]
    if not log.has_truth:
        b.append(("p", "The log has no truth: only timing is reported."))
    if figs:
        b.append(("h", 2, "Figures"))
        b += [("fig", title, f) for title, f in figs]
    b.append(("h", 2, "Configuration"))
    for e in entries:
        if e.ok:
            used = (e.summary or {}).get("inputs")
            uses = f" Inputs (record kinds it used): {', '.join(used) if used else 'none'}." if used is not None else ""
            b += [("h", 3, f"{e.name} ({e.kind})"), ("p", e.description + uses),
                  ("code", "json", json.dumps(_config(e), indent=2, sort_keys=True))]
    tums = ", ".join(f"`{file_stem(e.name)}.tum`" for e in entries if e.ok and e.result is not None)
    files = f"Trajectories: {tums} (TUM, evo-readable)"
    if truth_file:
        files += f"; the truth: `{truth_file}` (`evo_ape tum {truth_file} <estimator>.tum` gives the ATE above)"
    b.append(("p", files + "."))
    return b


def render_markdown(blocks: Sequence[tuple]) -> str:
    out: list[str] = []
    for blk in blocks:
        kind = blk[0]
        if kind == "h":
            out += ["#" * blk[1] + " " + blk[2], ""]
        elif kind == "p":
            out += [blk[1], ""]
        elif kind in ("ul", "warn"):
            out += [f"- {t}" for t in blk[1]] + [""]
        elif kind == "kv":
            out += [f"- **{k}**: {v if k != 'command' else '`' + v + '`'}" for k, v in blk[1]] + [""]
        elif kind == "table":
            head, rows = blk[1], blk[2]
            align = ["---:", "---", "---"] + ["---:"] * (len(head) - 4) + ["---"] if head[0] == "rank" else None
            out += [_md_table(head, rows, align), ""]
        elif kind == "code":
            out += [f"```{blk[1]}", blk[2], "```", ""]
        elif kind == "fig":
            out += [f"### {blk[1]}", "", f"![{blk[1]}]({blk[2]})", ""]
    return "\n".join(out)


def _inline(text: str) -> str:
    """The markdown inline marks used in the blocks (`code`, **bold**, *em*) as HTML, escaped."""
    parts = re.split(r"(`[^`]*`)", text)
    out = []
    for p in parts:
        if p.startswith("`") and p.endswith("`") and len(p) >= 2:
            out.append(f"<code>{html.escape(p[1:-1])}</code>")
        else:
            s = html.escape(p, quote=False)
            s = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", s)
            s = re.sub(r"(?<![\w*])\*(?!\s)(.+?)(?<!\s)\*(?![\w*])", r"<em>\1</em>", s)
            out.append(s)
    return "".join(out)


CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:1.5em auto;max-width:1500px;padding:0 1em;
color:#222;line-height:1.4}
h1{font-size:1.5em;margin-bottom:.3em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}
h3{font-size:1.05em}
table{border-collapse:collapse;font-size:.85em;margin:.5em 0}
th,td{border:1px solid #ccc;padding:.25em .5em;text-align:right;vertical-align:top}
th{background:#f0f0f0}td:nth-child(2),td:nth-child(3),td.note{text-align:left}td.note{font-style:italic}
table.kv th{text-align:left;width:9em}table.kv td{text-align:left;font-family:monospace;word-break:break-all}
.scroll{overflow-x:auto}
.warn{background:#fff6d6;border:1px solid #e0c060;border-radius:4px;padding:.4em 1em}
.warn li{margin:.2em 0}
figure{margin:1em 0}figure img{max-width:100%;height:auto;border:1px solid #ddd}
figcaption{font-weight:bold;margin-bottom:.3em}
pre{background:#f7f7f7;border:1px solid #ddd;padding:.5em;overflow-x:auto;font-size:.8em;max-height:30em}
code{background:#f3f3f3;padding:0 .2em}
details{margin:.3em 0 1em}summary{cursor:pointer}
"""


def _html_table(head: list[str], rows: list[list[str]]) -> str:
    """A table; in the results table (last column *note*) a failed or skipped estimator's note spans
    the figures it does not have."""
    noted = head[-1] == "note"
    cols = head[:-1] if noted else head
    out = []
    for r in rows:
        if noted and r[-1]:
            out.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r[:3])
                       + f'<td class="note" colspan="{len(cols) - 3}">{html.escape(r[-1])}</td></tr>')
        else:
            out.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in (r[:-1] if noted else r)) + "</tr>")
    th = "".join(f"<th>{html.escape(h)}</th>" for h in cols)
    return (f'<div class="scroll"><table class="results"><thead><tr>{th}</tr></thead>'
            f"<tbody>{''.join(out)}</tbody></table></div>")


def render_html(blocks: Sequence[tuple], images: dict[str, bytes]) -> str:
    """One self-contained page: inline CSS, figures as ``data:image/png;base64`` URIs, no script; the
    Content-Security-Policy forbids loading anything from anywhere else."""
    title = next((b[2] for b in blocks if b[0] == "h" and b[1] == 1), "graphnav report")
    body: list[str] = []
    for blk in blocks:
        kind = blk[0]
        if kind == "h":
            body.append(f"<h{blk[1]}>{_inline(blk[2])}</h{blk[1]}>")
        elif kind == "p":
            body.append(f"<p>{_inline(blk[1])}</p>")
        elif kind == "ul":
            body.append("<ul>" + "".join(f"<li>{_inline(t)}</li>" for t in blk[1]) + "</ul>")
        elif kind == "warn":
            body.append('<div class="warn"><ul>' + "".join(f"<li>{_inline(t)}</li>" for t in blk[1]) + "</ul></div>")
        elif kind == "kv":
            rows = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(v)}</td></tr>" for k, v in blk[1])
            body.append(f'<table class="kv">{rows}</table>')
        elif kind == "table":
            body.append(_html_table(blk[1], blk[2]))
        elif kind == "code":
            body.append(f"<details><summary>{html.escape(blk[1])}</summary><pre>{html.escape(blk[2])}</pre></details>")
        elif kind == "fig":
            data = images.get(blk[2])
            if data is None:
                continue
            uri = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
            body.append(f'<figure id="{html.escape(blk[2])}"><figcaption>{_inline(blk[1])}</figcaption>'
                        f'<img src="{uri}" alt="{html.escape(blk[1])}"></figure>')
    csp = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f'<meta http-equiv="Content-Security-Policy" content="{csp}">'
            '<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{html.escape(title)}</title><style>{CSS}</style></head>\n<body>\n"
            + "\n".join(body) + "\n</body></html>\n")


_FIG_JOBS: list[tuple[Any, tuple, dict, Path]] = []  # what forked figure workers render (set before forking)


def _render(i: int) -> bool:
    """Draw and save figure ``i`` of :data:`_FIG_JOBS`; whether there was one to save."""
    fn, args, kw, path = _FIG_JOBS[i]
    fig = fn(*args, **kw)
    if fig is None:
        return False
    plots.save(fig, path)
    return True


def render_figures(jobs: Sequence[tuple[Any, tuple, dict, str, str]], directory: Path, workers: int = 1) -> list[bool]:
    """Draw and save each ``(plot function, args, kwargs, file name, title)`` into ``directory``;
    ``workers > 1`` draws them in that many forked processes (the figures are independent; the
    PNGs are the same). Returns, per job, whether a figure was written."""
    global _FIG_JOBS
    _FIG_JOBS = [(fn, args, kw, directory / fname) for fn, args, kw, fname, _ in jobs]
    try:
        if workers > 1 and len(jobs) > 1:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            with ProcessPoolExecutor(max_workers=min(workers, len(jobs)),
                                     mp_context=multiprocessing.get_context("fork")) as pool:
                return list(pool.map(_render, range(len(jobs))))
        return [_render(i) for i in range(len(jobs))]
    finally:
        _FIG_JOBS = []


def write_report(entries: Sequence[Entry], log: NavLog, out: Path | OutDir, *, log_name: str = "",
                 command: str | None = None, log_path: str | Path | None = None, workers: int = 1) -> dict[str, Path]:
    """Write report.md, report.html, the PNGs, one TUM file per estimator and truth.tum into ``out``
    (each atomically; an :class:`~graphnav.io.outputs.OutDir` records every name in its manifest
    before writing it, a figure once it is written); returns the paths. ``command`` (the command
    line) and ``log_path`` (default ``log_name`` when it names a file) go into the provenance
    header. ``workers > 1`` draws the figures in that many processes (0: one per core)."""
    if workers <= 0:
        workers = os.cpu_count() or 1
    log_name = log_name or str(log.meta.get("name", "log"))
    if not isinstance(out, OutDir):
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
    files: dict[str, Path] = {}
    ok = [e for e in entries if e.ok and e.result is not None]
    trajs = {e.name: e.result.trajectory for e in ok}
    for e in ok:
        p = out / f"{file_stem(e.name)}.tum"
        write_tum(e.result.trajectory, p)
        files[p.name] = p
        onl = e.result.online
        if onl is not None and onl is not e.result.trajectory and len(onl):
            p = out / f"{file_stem(e.name)}.online.tum"
            write_tum(onl, p)
            files[p.name] = p
    truth_path = write_truth(log, out)
    if truth_path is not None:
        files[truth_path.name] = truth_path
    truth = log.truth() if log.has_truth else None
    events = log.meta.get("events", []) or []
    gnss = None
    if log.of("gnss"):
        c = log.columns("gnss")
        gnss = np.column_stack([c["x"], c["y"]])
    jobs: list[tuple[Any, tuple, dict, str, str]] = []  # (plot function, args, kwargs, file name, title)

    def put(fn: Any, args: tuple, fname: str, caption: str, **kw: Any) -> None:
        jobs.append((fn, args, kw, fname, caption))

    if trajs:
        title = f"Trajectories over the truth — {Path(log_name).name or log_name}"
        put(plots.plot_trajectories, (trajs, truth, gnss), "trajectories.png", "Trajectories", title=title)
        loops = {e.name: e.result.info["loop_edge_times"] for e in ok if e.result.info.get("loop_edge_times")}
        put(plots.plot_trajectory_panels, (trajs, truth), "trajectory_panels.png",
            "Each estimator over the truth (coloured by position error) and its largest error close up"
            + (" (orange: accepted loop closures)" if loops else ""), loops=loops)
        if truth is not None:
            online = {e.name: e.result.online for e in ok
                      if e.result.online is not None and e.result.online is not e.result.trajectory}
            put(plots.plot_position_error, (trajs, truth, events, online), "position_error.png",
                "Position error versus time (smoothers: online estimate dashed)")
            put(plots.plot_heading_error, (trajs, truth, events), "heading_error.png", "Heading error versus time")
            put(plots.plot_error_cdf, (trajs, truth), "error_cdf.png", "Error CDF")
            put(plots.plot_sog_cog, (trajs, truth, events), "sog_cog.png",
                "SOG, COG and ΔCOG errors (weighted-ICP paper, Figs. 12-15 style)")
            put(plots.plot_error_bounds, (trajs, truth, events), "error_bounds.png",
                "Errors in x, y and yaw with the estimators' own ±3σ bounds")
            put(plots.plot_nees, (trajs, truth, events), "nees.png",
                "Position NEES over time with its 95 % chi-square band (2 dof)")
        put(plots.plot_covariance, (trajs, truth), "covariance.png",
            "Covariance ellipses (2σ, each panel its own scale)")
    figs: list[tuple[str, str]] = []
    for (_, _, _, fname, title), written in zip(jobs, render_figures(jobs, Path(str(out)), workers), strict=True):
        if written:
            files[fname] = out / fname  # (recorded in the manifest once written)
            figs.append((title, fname))

    if log_path is None and log_name and Path(log_name).exists():
        log_path = log_name
    prov = provenance(log_path, command)
    blocks = _blocks(entries, log, log_name, prov, warnings(entries, log), figs,
                     truth_path.name if truth_path is not None else None)
    files["report.md"] = write_text_atomic(out / "report.md", render_markdown(blocks))
    images = {f: files[f].read_bytes() for _, f in figs}
    files["report.html"] = write_text_atomic(out / "report.html", render_html(blocks, images))
    return files
