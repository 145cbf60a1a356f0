"""``graphnav compare`` through the CLI entry point on a log written to a temporary folder, with
fake estimators registered for the call: what the compare and report tests share."""

from __future__ import annotations

import contextlib
import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pytest

from graphnav import estimators
from graphnav.cli import main
from graphnav.io import save_log
from graphnav.log import NavLog


def run_compare(log: NavLog, d: Path, fakes: Mapping[str, Any], args: Sequence[str]) -> tuple[int, str, Path, Path]:
    """Save ``log`` as ``d/poly.jsonl`` and run ``graphnav compare LOG --out d/out --json *args`` with
    ``fakes`` in the estimator registry; returns (exit code, stdout, out folder, log path)."""
    path = d / "poly.jsonl"
    save_log(log, path)
    out = d / "out"
    with pytest.MonkeyPatch.context() as mp:
        for k, v in fakes.items():
            mp.setitem(estimators.registry(), k, v)
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            rc = main(["compare", str(path), "--out", str(out), "--json", *args])
    return rc, buf.getvalue(), out, path
