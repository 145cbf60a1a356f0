"""``graphnav compare`` as a library call: one typed :class:`CompareOptions` -> read the log ->
:func:`~graphnav.evaluation.comparison.compare` -> :func:`~graphnav.evaluation.report.render` -> one
writer. The command (and ``demo``) only parse arguments into the options and print the outcome."""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .. import estimators
from ..errors import GraphnavError
from ..estimators.options import check as check_options
from ..io import load_log
from ..io.drop import drop_kinds
from ..io.outputs import OutDir
from ..log import NavLog
from .comparison import Comparison, compare
from .holdout import HoldoutSpec

log_ = logging.getLogger("graphnav.compare")


@dataclass(frozen=True)
class CompareOptions:
    """Everything a comparison run takes. ``estimators``: names (``LABEL=NAME`` allowed; ``None``: every
    registered one); ``options``: ``{estimator or label: {key: value}}``; ``dropped``: record kinds left
    out; ``workers``: processes (0: one per core); ``icp_cache``: share weighted-ICP matches;
    ``tiles``: map tile URL template; ``holdout``: GNSS hold-out; ``read``: the log reader's options
    (``date``, ``max_speed``, ...); ``command``: the command line, for the report's provenance."""

    log: str
    out: Path
    estimators: list[str] | None = None
    options: dict[str, dict[str, Any]] = field(default_factory=dict)
    dropped: list[str] = field(default_factory=list)
    workers: int = 0
    icp_cache: bool = True
    tiles: str | None = None
    holdout: HoldoutSpec | None = None
    lenient: bool = False
    read: dict[str, Any] = field(default_factory=dict)
    command: str | None = None

    def check(self) -> None:
        """Fail before anything is read or written: an unknown estimator (with "did you mean"), an
        ``-O`` scope or key no compared estimator knows, workers out of range."""
        for name in self.estimators or []:
            est = (name.partition("=")[2] if "=" in name else name).strip()
            if est not in estimators.registry():
                raise KeyError(f"-e {name}: " + estimators.unknown_name(est))
        labels = {}
        for name in self.estimators if self.estimators is not None else estimators.names():
            label, _, est = name.partition("=") if "=" in name else (name, "", name)
            labels[label.strip()] = est.strip()
        for scope, given in self.options.items():
            if scope not in labels:
                if scope not in estimators.registry():
                    raise KeyError(f"-O {scope}.KEY=VALUE: " + estimators.unknown_name(
                        scope, {*estimators.names(), *labels}))
                raise ValueError(f"-O {scope}.KEY=VALUE: {scope!r} is not one of the estimators compared "
                                 f"({', '.join(labels)})")
            if labels[scope] in estimators.registry():
                check_options(labels[scope], given)
        if not 0 <= self.workers <= 256:
            raise ValueError(f"--workers must be in [0, 256] (0: one per CPU), got {self.workers}")


def runnable(log: NavLog, names: list[str] | None) -> int:
    """How many of ``names`` (``LABEL=NAME`` allowed) the log can feed: a progress bar's total."""
    n = 0
    for name in names if names is not None else estimators.names():
        try:
            n += estimators.get(name.partition("=")[2] or name).unmet(log) is None
        except KeyError:
            pass
    return n


@dataclass
class Outcome:
    """What a comparison run gives back: the comparison, the files written, the one JSON object and
    the plain-text summary."""

    comparison: Comparison
    files: dict[str, Path]
    json: dict[str, Any]
    text: str


def _import_figures() -> None:
    """Import the figures' modules (matplotlib: ~0.8 s of CPU) while the estimators run, not after."""
    from .report import writer  # noqa: F401  (writer -> assemble -> figures -> plots)


def run_compare(opts: CompareOptions, out: OutDir,
                progress: Callable[[str, int], None] | None = None) -> Outcome:
    """Read the log, compare, render and write into ``out``. ``progress(name, total)`` is called as each
    estimator starts (``total``: how many will run). A comparison in which no estimator ran is a
    :class:`GraphnavError` (nothing is written)."""
    from ..scan.icp_cache import MatchCache
    from .report import summary_lines, to_json

    opts.check()
    log = drop_kinds(load_log(opts.log, lenient=opts.lenient, **opts.read), opts.dropped)
    t0 = time.perf_counter()
    workers = opts.workers if opts.workers > 0 else (os.cpu_count() or 1)
    total = runnable(log, opts.estimators)

    def started(name: str) -> None:
        if progress is not None:
            progress(name, total)
        else:
            log_.info("running %s on %s", name, opts.log)

    cache = MatchCache() if opts.icp_cache else None
    comp = compare(log, opts.estimators, options=opts.options, progress=started, workers=workers, cache=cache,
                   holdout=opts.holdout, log_name=str(opts.log), dropped=opts.dropped, meanwhile=_import_figures)
    if not comp.ran:
        why = "; ".join(f"{e.name}: " + (f"failed: {e.error}" if e.error is not None else f"not run: {e.skipped}")
                        for e in comp)
        after = f" (after --drop {','.join(opts.dropped)})" if opts.dropped else ""
        raise GraphnavError(f"no estimator ran on this log{after}: {why or 'none given'}", where=str(opts.log))
    from .report.assemble import start
    from .report.writer import write_drawing

    rep, files = write_drawing(start(comp, command=opts.command, workers=workers, tiles=opts.tiles), out)
    total_s = time.perf_counter() - t0
    for e in comp:
        if e.error is not None:
            log_.warning("%s failed: %s", e.name, e.error)
        elif e.skipped is not None:
            log_.info("%s not run: %s", e.name, e.skipped)
    hits = comp.icp_cache_hits
    extra: dict[str, Any] = {}
    if comp.holdout is not None:
        extra["holdout"] = {**comp.holdout.describe(), "ranking": comp.holdout_ranking()}
    obj = to_json(comp, str(opts.log), out=str(opts.out), total_runtime_s=total_s, workers=workers,
                  icp_cache_hits=hits, map="map.html", dropped=opts.dropped, **(rep.wgs84 or {}), **extra,
                  data_checks=comp.checks)
    cached = f"; {hits} weighted-ICP matches shared between estimators" if hits else ""
    lines = summary_lines(comp) + [f"wrote {len(files)} files to {opts.out} (report.md) in {total_s:.1f} s{cached}"]
    return Outcome(comp, files, obj, "\n".join(lines))
