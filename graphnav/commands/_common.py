"""Helpers shared by the sub-commands: the one-JSON-object output contract, option parsing."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from ..io.jsonsafe import jsonable

__all__ = ["add_json_flag", "add_log_args", "emit", "jsonable", "parse_options"]


def add_json_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")


def add_overwrite_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument("--overwrite", action="store_true",
                   help="--out may be a non-empty directory: the files a previous graphnav run wrote there "
                        "(listed in its .graphnav-outputs.json) are deleted first, other files are left alone")


def add_dashboard_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dashboard", nargs="?", const="127.0.0.1:8787", default=None, metavar="HOST:PORT",
                   help="serve the embedded Dask LocalCluster's dashboard (default off; bare --dashboard: "
                        "127.0.0.1:8787, loopback only)")


def add_log_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("log", help="log: marina directory, .jsonl[.gz], .npz, .nmea, a CARMEN .log[.gz], or a ROS bag")
    p.add_argument("--lenient", action="store_true",
                   help="skip malformed or physically invalid records (and count them)")
    p.add_argument("--max-speed", type=float, metavar="M/S",
                   help="the vessel's plausible speed limit; faster odometry is invalid (default 50 m/s)")


def emit(args: argparse.Namespace, obj: dict[str, Any], human: str | None = None) -> None:
    """With ``--json``: the object on stdout, alone. Otherwise a readable text (or the JSON, indented)."""
    if getattr(args, "json", False):
        sys.stdout.write(json.dumps(jsonable(obj), allow_nan=False) + "\n")
    else:
        sys.stdout.write((human if human is not None else json.dumps(jsonable(obj), indent=2)) + "\n")
    sys.stdout.flush()


def parse_options(pairs: list[str] | None) -> dict[str, Any]:
    """``["lag=10", "robust=\\"huber\\"", "keyframe_dt=0.5"]`` -> dict (values parsed as JSON when possible)."""
    out: dict[str, Any] = {}
    for item in pairs or []:
        if "=" not in item:
            raise ValueError(f"option {item!r} is not KEY=VALUE")
        k, v = item.split("=", 1)
        try:
            out[k.strip().replace("-", "_")] = json.loads(v)
        except json.JSONDecodeError:
            out[k.strip().replace("-", "_")] = v
    return out
