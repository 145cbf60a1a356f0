"""The ``graphnav`` command line. Each sub-command lives in ``graphnav/commands/<name>.py``
with a ``register(subparsers)`` function; this module only discovers and dispatches.

Discovery is lazy: only the invoked command's module is imported (commands pull in GTSAM,
Open3D, Dask...); the others are listed by name with the ``help=`` of their ``add_parser`` call,
read from the source without importing it. ``graphnav --help`` therefore imports no command.

Contract: with ``--json`` a command prints exactly one JSON object on stdout; logs and
progress go to stderr.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import logging
import pkgutil
import sys
from pathlib import Path

from . import commands
from .errors import EXIT_BUG, EXIT_INPUT, EXIT_INTERRUPTED, GraphnavError


def command_names() -> list[str]:
    """The sub-commands: the public modules of :mod:`graphnav.commands` (``_`` in a module's name is
    ``-`` in the command's: ``scan_matching.py`` is ``graphnav scan-matching``)."""
    return sorted(m.name.replace("_", "-") for m in pkgutil.iter_modules(commands.__path__)
                  if not m.name.startswith("_"))


def command_help(name: str) -> str | None:
    """The ``help=`` string of the command's ``add_parser`` call (else its docstring's first line),
    read from the module source without importing it."""
    try:
        tree = ast.parse(Path(commands.__path__[0], f"{name.replace('-', '_')}.py").read_text(encoding="utf-8"))
    except (OSError, SyntaxError):
        return None
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "add_parser":
            for kw in node.keywords:
                if kw.arg == "help" and isinstance(kw.value, ast.Constant) and isinstance(kw.value.value, str):
                    return kw.value.value
            break
    doc = ast.get_docstring(tree)
    return doc.strip().splitlines()[0] if doc else None


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser. ``command``: register only that command for real (the others are named
    placeholders, not imported); ``None``: import and register every command."""
    parser = argparse.ArgumentParser(
        prog="graphnav", description="Factor-graph navigation for unmanned surface vessels."
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging (stderr)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in command_names():
        if command is None or name == command:
            importlib.import_module(f"{commands.__name__}.{name.replace('-', '_')}").register(sub)
        else:
            sub.add_parser(name, help=command_help(name))
    return parser


def _invoked(argv: list[str]) -> str:
    """The command named on the command line ('' if none): the first non-option argument."""
    return next((a for a in argv if not a.startswith("-")), "")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser(_invoked(argv))
    args = parser.parse_args(argv)
    args.argv = list(argv)  # the command line as given, for reports' provenance
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        if getattr(args, "max_speed", None) is not None:  # --max-speed: the readers' validity bound
            from dataclasses import replace

            from .log import default_limits, set_default_limits

            if not args.max_speed > 0:
                raise ValueError(f"--max-speed must be > 0, got {args.max_speed}")
            set_default_limits(replace(default_limits(), max_speed=args.max_speed))
        return int(args.func(args) or 0)
    except GraphnavError as err:
        return _fail(args, str(err), err.where, EXIT_INPUT, message=err.message)
    except OSError as err:  # a file, directory, port or address the user named
        where = None if err.filename is None else str(err.filename)
        message = err.strerror or str(err)
        return _fail(args, message if where is None else f"{where}: {message}", where, EXIT_INPUT, message=message)
    except (ValueError, KeyError) as err:  # bad arguments or options (the message names them)
        return _fail(args, str(err).strip("'\""), None, EXIT_INPUT)
    except KeyboardInterrupt:
        return _fail(args, "interrupted", None, EXIT_INTERRUPTED)
    except Exception as err:  # noqa: BLE001 - a bug: one line, the traceback with -v
        logging.getLogger("graphnav").debug("internal error", exc_info=True)
        return _fail(args, f"internal error ({type(err).__name__}: {err}); run with -v for the traceback",
                     None, EXIT_BUG)


def _fail(args: argparse.Namespace, text: str, where: str | None, code: int, *, message: str | None = None) -> int:
    """``graphnav: error: TEXT`` on stderr; with ``--json`` also ``{"error": MESSAGE, "where": WHERE}``
    on stdout (the one JSON object of the contract)."""
    print(f"graphnav: error: {text}", file=sys.stderr)
    if getattr(args, "json", False):
        import json

        sys.stdout.write(json.dumps({"error": message if message is not None else text, "where": where}) + "\n")
    return code


if __name__ == "__main__":
    sys.exit(main())
