"""The ``graphnav`` command line. Each sub-command lives in ``graphnav/commands/<name>.py``
with a ``register(subparsers)`` function; this module only discovers and dispatches.

Discovery is lazy: only the invoked command's module is imported (commands pull in GTSAM,
Open3D, Dask...); the others are listed by name with the ``help=`` of their ``add_parser`` call,
read from the source without importing it. ``graphnav --help`` therefore imports no command.

Contract: with ``--json`` a command prints exactly one JSON object on stdout; logs and
progress go to stderr.

Every command (each leaf parser) also gets, here in one place, ``--config FILE.toml`` (its long
options as top-level keys, ``[options]`` / ``[options.ESTIMATOR]`` tables for ``-O``; the command
line wins) and ``--quiet``; all help text is rendered as plain text (reST markup stripped).
"""

from __future__ import annotations

import argparse
import ast
import gc
import importlib
import logging
import os
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
    placeholders, not imported, their help read from their source only when no command is named: then the
    top-level help lists them; a named command never shows it, and parsing 13 sources took 0.04 s CPU of every
    run); ``None``: import and register every command."""
    names = command_names()
    listed = command not in names  # the placeholders' help can be shown (``graphnav --help``, a bad name)
    parser = argparse.ArgumentParser(
        prog="graphnav", description="Factor-graph navigation for unmanned surface vessels."
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging (stderr)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in names:
        if command is None or name == command:
            importlib.import_module(f"{commands.__name__}.{name.replace('-', '_')}").register(sub)
        else:
            sub.add_parser(name, help=command_help(name) if listed else None)
    for leaf in leaf_parsers(parser):
        if leaf is not parser and (command is None or leaf.prog.split()[1:2] == [command]):
            _add_common_flags(leaf)
    _plain_help(parser)
    return parser


def leaf_parsers(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    """The parsers without sub-commands under ``parser`` (every command a user can run)."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        return [parser]
    return [leaf for a in subs for p in dict.fromkeys(a.choices.values()) for leaf in leaf_parsers(p)]


def _add_common_flags(p: argparse.ArgumentParser) -> None:
    if "--config" not in p._option_string_actions:
        p.add_argument("--config", metavar="FILE.toml",
                       help="read options from a TOML file: top-level keys are this command's long options "
                            "(out = \"D\", runs = 5), [options] and [options.ESTIMATOR] tables give -O values; "
                            "the command line wins")
    if "--quiet" not in p._option_string_actions:
        flags = ["--quiet"] + ([] if "-q" in p._option_string_actions else ["-q"])
        p.add_argument(*flags, action="store_true", help="no progress bars (also off with --json)")


def plain(text: str | None) -> str | None:
    """reST inline markup -> plain text (:func:`graphnav.config.plain_text`)."""
    from .config import plain_text

    return plain_text(text) if text else text


def _plain_help(parser: argparse.ArgumentParser) -> None:
    """Strip reST markup from every description, help and sub-command help under ``parser``."""
    parser.description = plain(parser.description)
    parser.epilog = plain(parser.epilog)
    for action in parser._actions:
        if isinstance(action.help, str):
            action.help = plain(action.help)
        if isinstance(action, argparse._SubParsersAction):
            for choice in action._choices_actions:
                choice.help = plain(choice.help)
            for sub in dict.fromkeys(action.choices.values()):
                _plain_help(sub)


def _invoked(argv: list[str]) -> str:
    """The command named on the command line ('' if none): the first non-option argument."""
    return next((a for a in argv if not a.startswith("-")), "")


#: the cyclic garbage collector's first-generation threshold while a command runs (CPython: 700). A run
#: allocates millions of short-lived objects and few cycles: collecting after every 700 took 0.23 s CPU of
#: the harbour run (3 %, 0.12 s of it three full collections during the imports), 0.09 s at 10 000
GC_THRESHOLD = 10_000


#: OpenBLAS threads of a command's process (numpy's and scipy's libraries each keep a pool): on a run's small
#: matrices their idle workers spin between calls -- ~0.2 s CPU of the 5 Hz NMEA log's ~4 s, and its wall time no
#: shorter (docs/performance.md, Session 9). The environment's own ``OPENBLAS_NUM_THREADS`` wins.
BLAS_THREADS = "1"


def main(argv: list[str] | None = None) -> int:
    """Run the command ``argv`` (default ``sys.argv[1:]``); returns the exit status."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", BLAS_THREADS)  # (read as numpy loads: before a command imports it)
    thresholds = gc.get_threshold()
    gc.set_threshold(GC_THRESHOLD, *thresholds[1:])
    try:
        return _main(sys.argv[1:] if argv is None else argv)
    finally:
        gc.set_threshold(*thresholds)


def _main(argv: list[str]) -> int:
    parser = build_parser(_invoked(argv))
    if any(a == "--config" or a.startswith("--config=") for a in argv):
        relaxed = _relax_required(parser)  # what the file may give is not required on the command line yet
        args = parser.parse_args(argv)
        try:
            args = _with_config(parser, argv, args, relaxed)
        except GraphnavError as err:
            return _fail(args, str(err), err.where, EXIT_INPUT, message=err.message)
    else:
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

            from .config import Range, number
            from .log import default_limits, set_default_limits

            number("--max-speed", args.max_speed, Range(lo=0.0, hi=3e8, lo_open=True))
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


def _leaf(parser: argparse.ArgumentParser, args: argparse.Namespace) -> argparse.ArgumentParser:
    """The (sub-)sub-command parser ``args`` came from."""
    while True:
        sub = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
        if sub is None:
            return parser
        parser = sub.choices[getattr(args, sub.dest)]


def _relax_required(parser: argparse.ArgumentParser) -> dict[argparse.Action, tuple[bool, object]]:
    """Make every required option and positional of every command optional; returns what they were."""
    relaxed: dict[argparse.Action, tuple[bool, object]] = {}
    stack = [parser]
    while stack:
        p = stack.pop()
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                stack += list(dict.fromkeys(a.choices.values()))
            elif a.required or (not a.option_strings and a.nargs is None):
                relaxed[a] = (a.required, a.nargs)
                a.required = False
                if not a.option_strings:
                    a.nargs = "?"
    return relaxed


def _with_config(parser: argparse.ArgumentParser, argv: list[str], args: argparse.Namespace,
                 relaxed: dict[argparse.Action, tuple[bool, object]]) -> argparse.Namespace:
    """``--config FILE.toml``: its values become the command's defaults; what it does not give and
    the command needs is required again (``relaxed``); then the command line is parsed again (so a
    flag given there wins). ``[options]`` goes to ``args.config_options``."""
    from .commands._common import config_defaults

    leaf = _leaf(parser, args)
    defaults, options = config_defaults(leaf, Path(args.config), args)
    given = {action for action, _ in defaults}
    for action, value in defaults:
        action.default = value
    for action, (required, nargs) in relaxed.items():
        if action not in given:
            action.required, action.nargs = required, nargs
    new = parser.parse_args(argv)
    new.config_options = options
    return new


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
