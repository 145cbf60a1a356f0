"""The report's text: the results and event tables, warnings, the per-estimator sentences, the JSON
object, and the list of blocks that :mod:`.render` turns into Markdown and HTML."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from typing import Any

import numpy as np

from ...io.jsonsafe import jsonable
from ...log import NavLog
from ..comparison import Comparison, Entry, ranked
from .render import md_table
from .verdicts import data_lines, holdout_table, verdicts

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
    ("rpe_1s_rmse_m", "RPE 1 s [m]", "{:.3f}"),
    ("sog_rmse_mps", "SOG RMSE [m/s]", "{:.3f}"),
    ("cog_rmse_deg", "COG RMSE [deg]", "{:.2f}"),
    ("rot_rmse_degps", "ROT RMSE [deg/s]", "{:.2f}"),
    ("runtime_s", "runtime [s]", "{:.2f}"),
    ("step_ms_median", "step [ms] (median)", "{:.2f}"),
    ("icp_ms_median", "scan match [ms] (median)", "{:.2f}"),
    ("icp_cache_hits", "shared matches", "{:d}"),
]
# without truth: what can be judged (GNSS residuals of every estimate, the hold-out error when asked)
NO_TRUTH_COLUMNS: list[tuple[str, str, str]] = [
    ("holdout_rmse_m", "hold-out end error RMSE [m]", "{:.2f}"),
    ("gnss_residual_rms_m", "GNSS residual RMS [m]", "{:.2f}"),
    ("gnss_residual_median_m", "GNSS residual median [m]", "{:.2f}"),
    ("gnss_nis_mean", "GNSS NIS mean", "{:.2f}"),
]
TRUTH_NOTE = ("Ranked by ATE RMSE. ATE is unaligned (in the log's frame), over poses time-associated with "
              "the truth; RPE over 1 and 10 associated poses (an estimator's own output spacing: a filter's "
              "every record, a smoother's keyframes) and over about 1 s (*RPE 1 s*, the same span for "
              "every estimator); SOG/COG/ROT errors between the estimate's own poses about "
              "1 s apart, the truth's over the same intervals, so a 100 Hz filter and a smoother's keyframes "
              "are scored on comparable intervals (COG only while the truth moves faster than 0.2 m/s). "
              "For smoothers ATE is "
              "the smoothed trajectory and *online ATE* the estimate available at each time. *step* is "
              "solver/filter time per step excluding scan matching; *scan match* is per registration.")
NO_TRUTH_NOTE = ("The log has no truth: no accuracy figure can be computed. What can be judged: *GNSS residual*, "
                 "the distance between each GNSS fix and the estimate at its time (an estimator that used the "
                 "fixes is pulled onto them, so this shows fit, not accuracy); *GNSS NIS*, the residual normalised "
                 "by the estimate's covariance plus the fix's (2 when both are honest and independent, lower for "
                 "an estimator that used the fixes); and with `--holdout-gnss EVERY,LENGTH` the error against GNSS "
                 "fixes withheld from every estimator, by which the table is then ranked.")
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


def rank_key(entries: Sequence[Entry]) -> str:
    """What the table ranks by: ATE RMSE, else (no truth) the hold-out error when there is one."""
    if any(_present((e.summary or {}).get("ate_rmse_m")) for e in entries):
        return "ate_rmse_m"
    return "holdout_rmse_m" if any(_present((e.summary or {}).get("holdout_rmse_m")) for e in entries) else "ate_rmse_m"


def results_table(entries: Sequence[Entry]) -> tuple[list[str], list[list[str]]]:
    """The ranked table: header and rows of text cells; a failed or skipped estimator has a row
    whose last cell (*note*) says why. Without truth the GNSS residual and hold-out columns stand in
    for the errors."""
    truth = any(_present((e.summary or {}).get("ate_rmse_m")) for e in entries)
    cols = [c for c in COLUMNS + ([] if truth else NO_TRUTH_COLUMNS)
            if any(e.ok and _present((e.summary or {}).get(c[0])) for e in entries)]
    head = ["rank", "estimator", "kind", *(h for _, h, _ in cols), "note"]
    rows = []
    for i, e in enumerate(ranked(entries, rank_key(entries)), 1):
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
    return md_table(head, rows, ["---:", "---", "---"] + ["---:"] * (len(head) - 4) + ["---"])


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
        out.append("The log has no truth: no accuracy figure can be computed; see the GNSS residuals (and the "
                   "hold-out, with --holdout-gnss).")
    return out


# -- the blocks ---------------------------------------------------------------------------------------

def blocks(comp: Comparison, prov: dict[str, str], figs: list[tuple[str, str]], truth_file: str | None) -> list[tuple]:
    """The report as blocks (:mod:`.render`): provenance, the log, warnings, the ranked table, events,
    figures (``(caption, file name)``), configuration."""
    entries, log, log_name = comp.entries, comp.log, comp.log_name
    warns = warnings(entries, log)
    truth = log.has_truth
    b: list[tuple] = [("h", 1, f"Estimator comparison{'' if truth else ' (no truth)'} — {log_name}"),
                      ("kv", list(prov.items()))]
    counts = ", ".join(f"{k}: {v}" for k, v in log.counts().items())
    span = f"{log.t1 - log.t0:.1f} s" if log.records else "empty"
    b.append(("p", f"Log: {counts}; duration {span}."))
    events = log.meta.get("events", []) or []
    if events:
        listed = "; ".join(f"{ev.get('kind')} {ev.get('t0'):.1f}–{ev.get('t1'):.1f} s" for ev in events)
        b.append(("p", f"Events (GNSS outages/jumps and shorter conditions shaded in the plots): {listed}"))
    b += [("h", 2, "Gaps and jumps in the data"), ("ul", data_lines(comp))]
    b += [("h", 2, "Warnings"), ("warn", warns or ["None: every estimator ran, and none flagged a measurement."])]
    b += [("h", 2, "What each estimator did"), ("ul", verdicts(comp))]
    head, rows = results_table(entries)
    b += [("h", 2, "Results"),
          ("p", TRUTH_NOTE + NEES_NOTE
                + (SHARED_NOTE if any((e.summary or {}).get("icp_cache_hits") for e in entries) else "")
                if truth else NO_TRUTH_NOTE),
          ("table", head, rows)]
    ho = holdout_table(comp)
    if ho is not None:
        b += [("h", 3, "GNSS hold-out"), ("p", ho[0]), ("table", ho[1], ho[2])]
    ev_table = event_table(entries)
    if ev_table is not None:
        b += [("h", 3, "Errors inside events"),
              ("p", "Position error (unaligned, the pairs of the ATE) inside the log's event windows, pooled per "
                    "kind; *online*: the estimate available at each time."),
              ("table", *ev_table)]
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


def summary_lines(comp: Comparison) -> list[str]:
    """The ranked table as plain text lines (what ``graphnav compare`` prints without ``--json``)."""
    lines = [f"{'estimator':16s} {'ATE RMSE [m]':>12s} {'RPE [m]':>9s} {'runtime [s]':>11s}  note"]
    for e in ranked(comp.entries, rank_key(comp.entries)):
        s = e.summary or {}
        a, r, t = (f"{s[k]:.3f}" if isinstance(s.get(k), float) else "–"
                   for k in ("ate_rmse_m", "rpe_rmse_m", "runtime_s"))
        note = "" if e.ok else f"failed: {e.error}" if e.error is not None else f"not run: {e.skipped}"
        lines.append(f"{e.name:16s} {a:>12s} {r:>9s} {t:>11s}  " + note)
    return lines
