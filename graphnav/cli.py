"""The ``graphnav`` command line. Each sub-command lives in ``graphnav/commands/<name>.py``
with a ``register(subparsers)`` function; this module only discovers and dispatches.

Contract: with ``--json`` a command prints exactly one JSON object on stdout; logs and
progress go to stderr.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
import sys

from . import commands
from .errors import LogError


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command, or (``only``) of the one in ``graphnav/commands/<only>.py``:
    importing every command costs ~2 s CPU (plotting, scipy.stats), so ``main`` loads only the
    command it runs."""
    parser = argparse.ArgumentParser(
        prog="graphnav", description="Factor-graph navigation for unmanned surface vessels."
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging (stderr)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for mod in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if not mod.name.startswith("_") and only in (None, mod.name):
            importlib.import_module(f"{commands.__name__}.{mod.name}").register(sub)
    return parser


def _parser_for(argv: list[str]) -> argparse.ArgumentParser:
    """Only the named command's module when the first argument names one that registers it;
    otherwise (help, options first, a typo) all of them."""
    name = argv[0] if argv else ""
    if name.isidentifier() and any(m.name == name for m in pkgutil.iter_modules(commands.__path__)):
        parser = build_parser(only=name)
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        if name in sub.choices:
            return parser
    return build_parser()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = _parser_for(argv)
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        return int(args.func(args) or 0)
    except LogError as err:
        print(f"graphnav: error: {err}", file=sys.stderr)
        return 2
    except (ValueError, KeyError, FileNotFoundError) as err:
        print(f"graphnav: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
