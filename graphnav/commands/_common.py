"""Helpers shared by the sub-commands: the one-JSON-object output contract, option parsing."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from ..errors import GraphnavError
from ..io.jsonsafe import jsonable

__all__ = ["OPTION_FORM", "add_drop_flag", "add_json_flag", "add_log_args", "dropped_kinds", "emit", "jsonable",
           "log_options", "options_by_estimator", "options_for", "parse_option", "parse_options", "plain_options",
           "progress_enabled", "scoped_options", "seed_arg"]


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


def add_holdout_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument("--holdout-gnss", metavar="EVERY,LENGTH", default=None,
                   help="score without truth: every EVERY s of log time withhold the last LENGTH s of GNSS (fixes "
                        "and velocity) from the estimators and score them against the withheld fixes, e.g. 300,60")


def add_compare_flags(p: argparse.ArgumentParser) -> None:
    """``compare``'s flags beyond the log, the estimators and their options."""
    p.add_argument("--workers", "-j", type=int, default=0,
                   help="processes for the estimators and the figures (the smoothers share one, with their "
                        "weighted-ICP matches; runtimes then include contention); default 0: one per core, "
                        "1: everything in this process")
    p.add_argument("--no-icp-cache", dest="icp_cache", action="store_false",
                   help="every estimator computes its own weighted-ICP matches (default: a match shared by "
                        "several estimators is computed once; their runtimes then exclude it)")
    p.add_argument("--tiles", metavar="URL", default=None,
                   help="map.html draws map tiles from this {z}/{x}/{y} URL template under the tracks (loaded "
                        "over the network when the page is opened; default: none, the page is self-contained)")
    add_holdout_flag(p)


@contextlib.contextmanager
def progress_callback(args: argparse.Namespace, desc: str) -> Iterator[Callable[[str, int], None]]:
    """A progress bar over estimators for :func:`graphnav.evaluation.pipeline.run_compare`: the callback
    ``(name, total)`` advances it as each estimator starts; closed (and completed) when the block ends."""
    state: dict[str, Any] = {}

    def started(name: str, total: int) -> None:
        bar = state.get("bar")
        if bar is None:
            bar = state["bar"] = progress_bar(args, total=total, desc=desc, unit="estimator")
        else:
            bar.update(1)
        bar.set_postfix_str(name)
        if bar.disable:
            import logging

            logging.getLogger(f"graphnav.{desc}").info("running %s", name)

    try:
        yield started
        if "bar" in state:
            state["bar"].update(1)
    finally:
        if "bar" in state:
            state["bar"].close()


def add_log_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("log", help="log: marina directory, .jsonl[.gz], .npz, .nmea, a CARMEN .log[.gz], or a ROS bag")
    p.add_argument("--lenient", action="store_true",
                   help="skip malformed or physically invalid records (and count them)")
    p.add_argument("--max-speed", type=float, metavar="M/S",
                   help="the vessel's plausible speed limit; faster odometry is invalid (default 50 m/s)")
    add_date_flag(p)
    p.add_argument("--columns", metavar="FIELD=COLUMN[:UNIT],...",
                   help="a CSV/TSV log's column mapping, e.g. t=time,lat=Latitude,lon=Longitude,sigma=2.5,"
                        "heading=HDG:deg,sog=SOG:kn,cog=COG (a number is a constant; units and fields: docs/csv.md)")


def add_date_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument("--date", type=log_date, metavar="YYYY-MM-DD",
                   help="NMEA logs without a date (no RMC, ZDA without date): the UTC day of the first time of "
                        "day (t becomes POSIX time); a log's own date wins (docs/nmea.md)")


MAX_SEED = 2**63 - 1
"""The largest ``--seed`` (NumPy takes any non-negative integer; a seed is a count, not a size)."""


def seed_arg(text: str) -> int:
    """``--seed``'s value: an integer in ``[0, 2^63 - 1]`` (argparse names the flag otherwise, exit 2);
    NumPy's own message for a negative seed named no argument."""
    try:
        value = int(text.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text[:30]!r}") from None
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"must be in [0, 2^63 - 1], got {text[:30]}")
    return value


def log_date(text: str) -> str:
    """``--date``'s value: a ``YYYY-MM-DD`` calendar date (argparse reports anything else, exit 2)."""
    from datetime import date

    try:
        return date.fromisoformat(text.strip()).isoformat()
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected YYYY-MM-DD, got {text[:30]!r}") from None


def log_options(args: argparse.Namespace) -> dict[str, Any]:
    """The reader options that :func:`add_log_args` flags give (``date``, ``columns``), for ``load_log(**...)``."""
    out: dict[str, Any] = {"date": args.date} if getattr(args, "date", None) else {}
    if getattr(args, "columns", None) is not None:
        out["columns"] = args.columns
    return out


def add_drop_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument("--drop", action="append", metavar="KIND[,KIND]",
                   help="leave these record kinds out of the log before any estimator sees it, e.g. "
                        "--drop odometry,beacon (repeatable; beacon_known: the charted beacons; KIND@SOURCE: "
                        "only that source's, e.g. --drop gnss@52 keeps the other GNSS); the JSON "
                        "output lists them as 'dropped'")


def dropped_kinds(args: argparse.Namespace) -> list[str]:
    """The kinds of ``--drop`` (checked: an unknown kind is a ``ValueError`` naming the known ones)."""
    from ..io.drop import parse_kinds

    return parse_kinds(getattr(args, "drop", None))


def emit(args: argparse.Namespace, obj: dict[str, Any], human: str | None = None) -> None:
    """With ``--json``: the object on stdout, alone. Otherwise a readable text (or the JSON, indented)."""
    if getattr(args, "json", False):
        sys.stdout.write(json.dumps(jsonable(obj), allow_nan=False) + "\n")
    else:
        sys.stdout.write((human if human is not None else json.dumps(jsonable(obj), indent=2)) + "\n")
    sys.stdout.flush()


OPTION_FORM = "[ESTIMATOR.]KEY=VALUE"


MAX_CONFIG_BYTES = 1 << 20
"""The largest ``--config`` file read."""
MAX_OPTION_DEPTH = 32
"""The deepest nesting of lists and tables an option value (``-O``, ``[options]``) may have."""


def _value(text: str, item: str | None = None) -> Any:
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        return text
    except RecursionError:
        raise ValueError(f"option {(item or text)[:40]!r}...: nested deeper than {MAX_OPTION_DEPTH} levels") from None
    if depth(value) > MAX_OPTION_DEPTH:
        raise ValueError(f"option {(item or text)[:40]!r}...: nested deeper than {MAX_OPTION_DEPTH} levels")
    return value


def depth(value: Any, limit: int = 10_000) -> int:
    """How deep lists and tables nest in ``value`` (a scalar: 0), iteratively (no recursion limit)."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        v, d = stack.pop()
        if isinstance(v, dict | list | tuple):
            deepest = max(deepest, d + 1)
            if deepest > limit:
                return deepest
            stack.extend((c, d + 1) for c in (v.values() if isinstance(v, dict) else v))
    return deepest


def parse_option(item: str) -> tuple[str | None, str, Any]:
    """The one ``-O`` grammar, ``[ESTIMATOR.]KEY=VALUE``: ``"fuzzy-ukf.window=50"`` ->
    ``("fuzzy-ukf", "window", 50)``, ``"lag=10"`` -> ``(None, "lag", 10)``; KEY may be a path
    (``"isam2.gnss.gate=4"`` -> ``("isam2", "gnss.gate", 4)``; ``"gnss.gate=4"`` -> ``("gnss", "gate", 4)``,
    which :func:`options_for` reads as the path when ``gnss`` is a section of the estimator's options).
    VALUE is parsed as JSON when it can be (``true``, ``null``, ``0.5``, ``'{"tol": 1e-3}'``), else kept
    as text; dashes in KEY become underscores. The old ``ESTIMATOR:KEY=VALUE`` form is an error naming the new one."""
    head, sep, value = item.partition("=")
    head = head.strip()
    if ":" in head:
        scope, _, key = head.partition(":")
        raise ValueError(f"option {item!r}: the ESTIMATOR:KEY form is gone; write "
                         f"{scope.strip()}.{key.strip()}={value} ({OPTION_FORM})")
    scope, dot, key = head.partition(".")
    if not dot:
        scope, key = "", scope
    key = ".".join(k.strip().replace("-", "_") for k in key.split("."))
    if not sep or not key or (dot and not scope.strip()) or not all(k.isidentifier() for k in key.split(".")):
        raise ValueError(f"option {item!r} is not {OPTION_FORM}")
    return (scope.strip() or None), key, _value(value, item)


def scoped_options(items: list[str] | None, sections: Iterable[str | None] = ()) -> dict[str | None, dict[str, Any]]:
    """``-O`` items -> ``{ESTIMATOR or None: {KEY: VALUE}}`` (later items win, last in order);
    ``SECTION.KEY=VALUE`` for one of ``sections`` is the unscoped path ``SECTION.KEY``."""
    out: dict[str | None, dict[str, Any]] = {}
    for item in items or []:
        scope, key, value = parse_option(item)
        if scope in sections:
            scope, key = None, f"{scope}.{key}"
        opts = out.setdefault(scope, {})
        opts.pop(key, None)
        opts[key] = value
    return out


def _file_options(args: argparse.Namespace) -> dict[str | None, dict[str, Any]]:
    return getattr(args, "config_options", None) or {}


def options_for(args: argparse.Namespace, name: str) -> dict[str, Any]:
    """The options of a one-estimator command (``run -e NAME``, ``live``): ``KEY=VALUE`` and
    ``NAME.KEY=VALUE``. A ``-O`` scoped to another estimator is an error; a ``--config`` file's
    ``[options.OTHER]`` tables are ignored (one file can serve several commands)."""
    given = scoped_options(getattr(args, "option", None), _sections(name) - {name})
    other = sorted(s for s in given if s not in (None, name))
    if other:
        from .. import estimators

        if other[0] not in estimators.names():
            raise KeyError(f"-O {other[0]}.KEY=VALUE: " + estimators.unknown_name(other[0]))
        raise ValueError(f"-O {other[0]}.KEY=VALUE: this command runs {name!r}; write KEY=VALUE or "
                         f"{name}.KEY=VALUE")
    files = _file_options(args)
    out: dict[str, Any] = {}
    for src in (files.get(None, {}), files.get(name, {}), given.get(None, {}), given.get(name, {})):
        for key, value in src.items():  # (a later spelling of one option, gnss_gate after gnss.gate, wins)
            out.pop(key, None)
            out[key] = value
    return out


def _sections(name: str) -> set[str | None]:
    """The sections of estimator ``name``'s options (:func:`graphnav.config.sections`), not estimator names."""
    from .. import estimators
    from ..config import sections

    if name not in estimators.names() or estimators.get(name).Config is None:
        return set()
    return set(sections(estimators.get(name).Config)) - set(estimators.names())


def options_by_estimator(args: argparse.Namespace) -> dict[str, dict[str, Any]]:
    """The options of a several-estimator command (``compare``, ``montecarlo``): ``ESTIMATOR.KEY=VALUE``
    only (a bare ``KEY=VALUE`` would not say which estimator it is for)."""
    out: dict[str, dict[str, Any]] = {}
    for src, what in ((_file_options(args), "--config [options]"), (scoped_options(getattr(args, "option", None)),
                                                                     "-O")):
        if src.get(None):
            key, value = next(iter(src[None].items()))
            raise ValueError(f"{what} {key}={json.dumps(value)}: this command runs several estimators; "
                             f"name one: ESTIMATOR.{key}=... ({OPTION_FORM})")
        for scope, opts in src.items():
            out.setdefault(str(scope), {}).update(opts)
    return out


def parse_options(pairs: list[str] | None, what: str = "option") -> dict[str, Any]:
    """Plain ``KEY=VALUE`` items (no estimator to name: ``icp``, ``register``, ``--sim``) -> dict."""
    opts = scoped_options(pairs)
    scoped = sorted(str(s) for s in opts if s is not None)
    if scoped:
        raise ValueError(f"{what} {scoped[0]}.KEY=VALUE: no estimator to name here; write KEY=VALUE")
    return opts.get(None, {})


def plain_options(args: argparse.Namespace, what: str = "-O") -> dict[str, Any]:
    """``parse_options`` of ``args.option`` after a ``--config`` file's ``[options]`` table."""
    files = _file_options(args)
    scoped = sorted(str(s) for s in files if s is not None)
    if scoped:
        raise ValueError(f"{getattr(args, 'config', '--config')}: [options.{scoped[0]}]: no estimator to name "
                         "here; use [options]")
    return {**files.get(None, {}), **parse_options(getattr(args, "option", None), what)}


def progress_enabled(args: argparse.Namespace) -> bool:
    """Progress bars (tqdm, stderr) unless ``--json``, ``--quiet`` (or ``--no-progress``)."""
    return not (getattr(args, "json", False) or getattr(args, "quiet", False) or getattr(args, "no_progress", False))


class NoBar:
    """What a disabled tqdm bar answers (``--json``, ``--quiet``), without importing tqdm (and the
    ``multiprocessing`` lock its constructor makes): ~0.03 s of a command's start-up."""

    disable = True

    def __init__(self, total: float | None = None, **_: Any) -> None:
        self.total, self.n = total, 0

    def update(self, n: float = 1) -> None:
        self.n += n

    def set_postfix_str(self, *_: Any, **__: Any) -> None:
        pass

    def close(self) -> None:
        pass

    def __enter__(self) -> NoBar:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def progress_bar(args: argparse.Namespace, **kwargs: Any) -> Any:
    """A tqdm bar on stderr, or a :class:`NoBar` where :func:`progress_enabled` says none."""
    if not progress_enabled(args):
        return NoBar(**kwargs)
    from tqdm import tqdm

    return tqdm(file=sys.stderr, disable=False, dynamic_ncols=True, **kwargs)


def _config_value(action: argparse.Action, value: Any, where: str) -> Any:
    """A TOML value for ``action`` -> what the command line would have given (type, choices checked)."""
    name = action.option_strings[-1] if action.option_strings else action.dest

    def bad(expected: str) -> GraphnavError:
        return GraphnavError(f"{name}: expected {expected}, got {value!r}", where=where)

    if isinstance(action, argparse._StoreConstAction | argparse._StoreTrueAction | argparse._StoreFalseAction):
        if not isinstance(value, bool):
            raise bad("true or false")
        return action.const if value else action.default
    if isinstance(action, argparse._AppendAction):
        items = value if isinstance(value, list) else [value]
        return [_config_value(argparse.Action([], action.dest, type=action.type, choices=action.choices), v, where)
                for v in items]
    if action.nargs == "?" and action.const is not None and value is True:  # e.g. a bare --dashboard
        return action.const
    if isinstance(value, dict | list) or (isinstance(value, bool) and action.type is not None):
        raise bad("a single value")
    typ = action.type
    try:
        if typ is not None and not (typ is float and isinstance(value, int | float)) and not (
                typ is int and isinstance(value, int)):
            value = typ(str(value))
        elif typ is float:
            value = float(value)
    except (ValueError, TypeError, argparse.ArgumentTypeError) as exc:
        raise GraphnavError(f"{name}: {exc}", where=where) from None
    if action.choices is not None and value not in action.choices:
        raise bad("one of " + ", ".join(map(str, action.choices)))
    return value


def config_defaults(parser: argparse.ArgumentParser, path: Path,
                    args: argparse.Namespace) -> tuple[list[tuple[argparse.Action, Any]], dict[str | None, dict]]:
    """Read ``--config FILE.toml`` for the command ``parser``: top-level keys are its long options
    (``out``, ``no-icp-cache``; ``_`` or ``-``) or positionals (``log``), each with the value the
    command line would give; ``[options]`` holds ``-O`` values (``lag = 10``) and
    ``[options.ESTIMATOR]`` tables the options of one estimator. Returns the (action, value) pairs
    and ``{ESTIMATOR or None: {KEY: VALUE}}``. An unknown key is a :class:`GraphnavError` naming the
    file and the key."""
    import tomllib

    where = str(path)
    try:
        with open(path, "rb") as fh:
            raw = fh.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise GraphnavError(exc.strerror or str(exc), where=where) from None
    if len(raw) > MAX_CONFIG_BYTES:
        raise GraphnavError(f"larger than {MAX_CONFIG_BYTES} bytes: not a configuration file", where=where)
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise GraphnavError(f"not UTF-8 text (byte {exc.start}); a --config file is UTF-8 TOML", where=where) from None
    except tomllib.TOMLDecodeError as exc:
        raise GraphnavError(f"not valid TOML: {exc}", where=where) from None
    except RecursionError:
        raise GraphnavError(f"nested deeper than {MAX_OPTION_DEPTH} levels", where=where) from None
    if depth(data) > MAX_OPTION_DEPTH:
        raise GraphnavError(f"nested deeper than {MAX_OPTION_DEPTH} levels", where=where)
    by_name: dict[str, argparse.Action] = {}
    for action in parser._actions:
        if action.dest in ("help", "config", "option") or isinstance(action, argparse._SubParsersAction):
            continue
        longs = [o[2:] for o in action.option_strings if o.startswith("--")]
        for n in longs or ([] if action.option_strings else [action.dest]):
            by_name[n.replace("_", "-")] = action
    known_opts = "option" in {a.dest for a in parser._actions}
    pairs: list[tuple[argparse.Action, Any]] = []
    options: dict[str | None, dict[str, Any]] = {}
    for key, value in data.items():
        if key == "options" and known_opts:
            if not isinstance(value, dict):
                raise GraphnavError("options: expected a table ([options])", where=where)
            scopes = _option_scopes(args)
            for k, v in value.items():
                if isinstance(v, dict) and k in scopes:
                    options.setdefault(k, {}).update({kk.replace("-", "_"): vv for kk, vv in v.items()})
                else:
                    options.setdefault(None, {})[k.replace("-", "_")] = v
            continue
        action = by_name.get(key.replace("_", "-"))
        if action is None:
            known = sorted(by_name) + (["options"] if known_opts else [])
            raise GraphnavError(f"unknown key {key!r} for 'graphnav {' '.join(parser.prog.split()[1:])}'; "
                                f"known: {', '.join(known)}", where=where)
        pairs.append((action, _config_value(action, value, where)))
    return pairs, options


def _option_scopes(args: argparse.Namespace) -> set[str]:
    """Names an ``[options.NAME]`` table may scope: the estimators, and ``compare``'s labels."""
    from .. import estimators

    scopes = set(estimators.names())
    for item in str(getattr(args, "estimators", None) or "").split(","):
        scopes.add(item.partition("=")[0].strip())
    if getattr(args, "estimator", None):
        scopes.add(args.estimator)
    return scopes
