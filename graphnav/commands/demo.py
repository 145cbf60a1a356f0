"""``graphnav demo --out DIR``: the main job on the project's embedded data.

Runs ``graphnav compare`` on the embedded harbour log (``data/harbour.npz``: seed 0 of
``graphnav simulate harbour``, every sensor, exact truth) and says where the report went. When the
repository's ``data/`` is not beside the installed package, the same log is simulated first.

Unlike ``compare``, the demo replaces its own previous output without ``--overwrite``: a directory
that holds only files graphnav wrote (its ``.graphnav-outputs.json`` lists them; by default
``out/demo``) is cleared of them and rewritten. A directory with any other file in it is refused
unless ``--overwrite`` is given (and even then only graphnav's files are deleted).
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from ..evaluation.pipeline import CompareOptions, run_compare
from ..io.outputs import OutDir, atomic_path
from ._common import add_overwrite_flag, emit, progress_callback

log_ = logging.getLogger("graphnav.demo")
EMBEDDED = Path(__file__).resolve().parents[2] / "data" / "harbour.npz"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="compare every estimator on the embedded harbour log", description=__doc__)
    p.add_argument("--out", type=Path, default=Path("out/demo"),
                   help="output directory (default out/demo; a previous demo's files there are replaced)")
    add_overwrite_flag(p)
    p.add_argument("--log", type=Path, default=None, help="another log instead of the embedded one")
    p.add_argument("--workers", "-j", type=int, default=0,
                   help="processes for the estimators and figures (default 0: one per core; 1: none)")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.set_defaults(func=run)


def embedded_log(out_dir: OutDir) -> Path:
    """The embedded harbour log, or a freshly simulated identical one (in ``out_dir``) when ``data/`` is absent."""
    if EMBEDDED.exists():
        return EMBEDDED
    from ..io import save_log
    from ..sim.harbour import EMBEDDED_PROFILE, HarbourConfig, simulate_harbour

    path = out_dir.file("harbour-seed0.npz")
    log_.info("data/harbour.npz not found beside the package: simulating harbour seed 0 into %s", path)
    with atomic_path(path) as tmp:
        save_log(simulate_harbour(seed=0, cfg=HarbourConfig.for_profile(EMBEDDED_PROFILE)), tmp)
    return path


def run(args: argparse.Namespace) -> int:
    out = OutDir(args.out, command="demo", overwrite=args.overwrite, own_ok=True)
    log_path = args.log or embedded_log(out)
    log_.info("graphnav demo: comparing every estimator on %s", log_path)
    opts = CompareOptions(log=str(log_path), out=args.out, workers=args.workers)
    with progress_callback(args, "compare") as progress:
        outcome = run_compare(opts, out, progress)
    emit(args, outcome.json, outcome.text)
    log_.info("report: %s (self-contained, to send: %s)", (args.out / "report.md").resolve(),
              (args.out / "report.html").resolve())
    return 0
