"""Estimator options (``-O key=value`` on the CLI, ``**options`` in Python) -> a config dataclass whose
fields carry their help (:func:`option`, :func:`describe_config`), and the declared ranges option and
argument values are checked against (:func:`number`, :class:`Range`, :class:`OptionError`;
docs/hostile-input.md)."""

from __future__ import annotations

import copy
import difflib
import functools
import math
import re
from collections.abc import Mapping
from dataclasses import MISSING, Field, dataclass, field, fields, replace
from typing import Any, ClassVar, TypeVar

from .errors import GraphnavError

T = TypeVar("T")


def option(default: Any = MISSING, help: str = "", unit: str = "", *, factory: Any = None, flat: str = "") -> Any:
    """A config dataclass field with its help: ``help`` (what it means, reST allowed) and ``unit`` (SI,
    e.g. ``"m/s"``; ``""``: none) as field metadata, read by :func:`describe_config` (``--list-options``,
    TOML and ``-O`` checks). ``factory``: a default factory instead of ``default``. ``flat``: in a
    section (:func:`section`), the field's flat name when it is not the section's ``prefix`` + its name."""
    meta = {"help": help, "unit": unit}
    if flat:
        meta["flat"] = flat
    if factory is not None:
        return field(default_factory=factory, metadata=meta)
    return field(default=default, metadata=meta)


def section(cls: type, help: str = "") -> Any:
    """A field of a config dataclass that holds a section: the dataclass ``cls`` (its defaults unless
    given). A section's class attribute ``prefix`` (e.g. ``"gnss_"``) makes its fields' flat names
    (``gnss_gate`` for ``gnss.gate``; :func:`option`'s ``flat`` for the exceptions)."""
    return field(default_factory=cls, metadata={"help": help, "section": True})


def sections(cls: type) -> dict[str, type]:
    """The sections of config dataclass ``cls``: ``{field name: section dataclass}`` (none: ``{}``)."""
    return {f.name: f.default_factory for f in fields(cls)  # type: ignore[arg-type, misc]
            if f.metadata.get("section")}


@functools.cache
def option_names(cls: type) -> dict[str, str]:
    """Every name an option of config dataclass ``cls`` answers to -> its path: a top-level field by its
    name; a section's field by its path ``SECTION.FIELD`` and its flat name (the section's ``prefix`` +
    the field's name, or the field's ``flat``): the one alias table, generated from the sections."""
    table: dict[str, str] = {}
    secs = sections(cls)
    for f in fields(cls):  # type: ignore[arg-type]
        if f.name not in secs:
            table[f.name] = f.name
            continue
        sec = secs[f.name]
        for g in fields(sec):  # type: ignore[arg-type]
            path = f"{f.name}.{g.name}"
            for name in (path, g.metadata.get("flat") or getattr(sec, "prefix", "") + g.name):
                if table.get(name, path) != path or name in secs:
                    raise TypeError(f"{cls.__name__}: option name {name!r} is both {table.get(name, name)} and {path}")
                table[name] = path
    return table


def unknown_options(what: str, bad: list[str], known: list[str], hint: str = "",
                    names: list[str] | None = None) -> str:
    """The message for unknown options ``bad``: the closest of ``names`` (default ``known``; "did you
    mean") and the known ones."""
    close = [c for b in bad for c in difflib.get_close_matches(b, names or known, n=2, cutoff=0.6)]
    mean = f"; did you mean {' or '.join(repr(c) for c in dict.fromkeys(close))}?" if close else ""
    return f"unknown {what} option(s) {sorted(bad)}{mean} (known: {', '.join(sorted(known)) or 'none'}){hint}"


def spell_options(cls: type, options: Mapping[str, Any]) -> list[tuple[str, str | None, Any]]:
    """``options`` of a config dataclass with sections as ``(name as given, path or None when unknown,
    value)``: a flat name (``gnss_gate``) or a path (``gnss.gate``) names that field; a section's name
    with a table (``gnss={"gate": 4}``, TOML ``[options.gnss]``) each of its fields (``gnss.gate``),
    with a section object the whole section (path: the section's name)."""
    table, secs = option_names(cls), sections(cls)
    out: list[tuple[str, str | None, Any]] = []
    for key, value in options.items():
        if key in secs and isinstance(value, Mapping):
            for k, v in value.items():
                path = f"{key}.{k}"
                out.append((path, path if table.get(path) == path else None, v))
        elif key in secs and isinstance(value, secs[key]):
            out.append((key, key, value))
        else:
            out.append((key, table.get(key), value))
    return out


def resolve_options(cls: type, options: Mapping[str, Any], what: str, hint: str = "") -> dict[str, Any]:
    """``options`` of a config dataclass with sections -> ``{path: value}`` (:func:`spell_options`;
    the last spelling of one option wins). An unknown name is a ``ValueError`` (:func:`unknown_options`;
    ``hint`` ends it)."""
    table = option_names(cls)
    spelled = spell_options(cls, options)
    bad = [name for name, path, _ in spelled if path is None]
    if bad:
        raise ValueError(unknown_options(what, bad, [n for n, p in table.items() if n == p], hint, list(table)))
    return {path: value for _, path, value in spelled if path is not None}


def given_option(cls: type, options: Mapping[str, Any], path: str, default: Any = None) -> Any:
    """The value ``options`` give the option ``path`` of config dataclass ``cls`` (by any of its names,
    in its section's table or object; the last one given wins), else ``default``; other keys are ignored."""
    table, secs = option_names(cls), sections(cls)
    head, _, tail = path.partition(".")
    value = default
    for key, v in options.items():
        if table.get(key) == path:
            value = v
        elif key == head and head in secs and isinstance(v, Mapping) and tail in v:
            value = v[tail]
        elif key == head and head in secs and isinstance(v, secs[head]):
            value = getattr(v, tail)
    return value


class Sectioned:
    """Base of a config dataclass made of sections (declare it ``@dataclass(init=False)``): its
    constructor takes any option name (:func:`resolve_options`: ``gnss_gate=4``, ``**{"gnss.gate": 4}``,
    ``gnss={"gate": 4}``, ``gnss=GnssConfig(...)``), each section built with its fields given;
    :meth:`value` reads one by any name, :meth:`flat` gives them all by their flat names."""

    what: ClassVar[str] = "config"

    def __init__(self, **options: Any) -> None:
        given = resolve_options(type(self), options, self.what)
        secs = sections(type(self))
        for f in fields(self):  # type: ignore[arg-type]
            if f.name in secs:
                sub = {p.partition(".")[2]: v for p, v in given.items() if p.startswith(f.name + ".")}
                base = given.get(f.name)
                value = secs[f.name](**sub) if base is None else (replace(base, **sub) if sub else base)
            else:
                value = given[f.name] if f.name in given else field_default(f)
            setattr(self, f.name, value)
        post = getattr(self, "__post_init__", None)
        if post is not None:
            post()

    def __getattr__(self, name: str) -> Any:  # only for names that are not attributes: a flat name's hint
        path = option_names(type(self)).get(name) if not name.startswith("__") else None
        hint = f"; the options are in sections: read .{path} (or .value({name!r}))" if path else ""
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}{hint}")

    def value(self, name: str) -> Any:
        """The value of the option ``name`` (a flat name or a path; a ``KeyError`` for an unknown one)."""
        path = option_names(type(self))[name]
        head, _, tail = path.partition(".")
        return getattr(getattr(self, head), tail) if tail else getattr(self, head)

    def flat(self) -> dict[str, Any]:
        """Every option by its flat name (``gnss_gate``), in declaration order (a copy)."""
        table = option_names(type(self))
        return {name: copy.deepcopy(self.value(path)) for name, path in table.items() if "." not in name}


def field_default(f: Field) -> Any:
    """A dataclass field's default (its factory's value; ``None`` when it has none)."""
    if f.default is not MISSING:
        return f.default
    if f.default_factory is not MISSING:
        return f.default_factory()
    return None


def describe_config(cls: type, skip: tuple[str, ...] = ()) -> list[dict[str, Any]]:
    """The fields of config dataclass ``cls`` as options: ``{"name", "type", "default", "unit", "meaning",
    "group"}`` (``meaning``: the field's help as plain text, the unit in front as ``[unit]``; ``group``: the
    ``group`` class attribute of the dataclass that declares the field, else that dataclass's name);
    the class's own fields first, then each base's. A class with sections (:func:`section`) gives its
    top-level fields (group ``general``), then each section's, with ``"path"`` (``gnss.gate``), ``name``
    the flat name (``gnss_gate``), ``group`` the section's name and ``group_help`` its help."""
    if sections(cls):
        return _describe_sections(cls, skip)
    out = []
    for f in fields(cls):  # type: ignore[arg-type]
        if f.name in skip:
            continue
        depth, owner = next((i, k) for i, k in enumerate(cls.__mro__)
                            if f.name in k.__dict__.get("__annotations__", {}))
        out.append({**_describe_field(f, f.name), "group": owner.__dict__.get("group") or owner.__name__,
                    "_depth": depth})
    out.sort(key=lambda o: o["_depth"])  # the class's own fields first, then its bases'
    for o in out:
        del o["_depth"]
    return out


def _describe_field(f: Field, name: str) -> dict[str, Any]:
    unit = f.metadata.get("unit", "")
    meaning = plain_text(f.metadata.get("help", ""))
    return {"name": name, "type": str(f.type), "default": field_default(f), "unit": unit,
            "meaning": f"[{unit}] {meaning}" if unit else meaning}


def _describe_sections(cls: type, skip: tuple[str, ...]) -> list[dict[str, Any]]:
    flat_of = {p: n for n, p in option_names(cls).items() if "." not in n}
    secs = sections(cls)
    top, out = [], []
    for f in fields(cls):  # type: ignore[arg-type]
        if f.name in skip:
            continue
        if f.name not in secs:
            top.append({**_describe_field(f, f.name), "path": f.name, "group": "general", "group_help": ""})
            continue
        for g in fields(secs[f.name]):  # type: ignore[arg-type]
            path = f"{f.name}.{g.name}"
            out.append({**_describe_field(g, flat_of[path]), "path": path, "group": f.name,
                        "group_help": plain_text(f.metadata.get("help", ""))})
    return top + out


def config_from_options(cls: type[T], options: Mapping[str, Any], what: str) -> T:
    """``cls(**options)`` for a dataclass ``cls``; an unknown option is a ``ValueError`` naming it
    and the known ones (``what``: e.g. ``"smoother"``)."""
    if sections(cls):
        resolve_options(cls, options, what)  # an unknown name: the error names this config (what)
        return cls(**options)
    known = {f.name for f in fields(cls)}  # type: ignore[arg-type]
    bad = sorted(set(options) - known)
    if bad:
        raise ValueError(f"unknown {what} option(s) {bad}; known: {sorted(known)}")
    return cls(**options)


_ROLE = re.compile(r":[a-z]+(?::[a-z]+)?:`(~?)([^`<]*?)(?:\s*<[^>]*>)?`")


def plain_text(text: str) -> str:
    """reST inline markup -> plain text (help and option descriptions): ````x```` -> x,
    ``:class:`~a.B``` -> B, ``:func:`f``` -> f, ``**b**`` -> b."""
    text = _ROLE.sub(lambda m: m.group(2).strip().rsplit(".", 1)[-1] if m.group(1) else m.group(2).strip(), text)
    return text.replace("``", "").replace("**", "")


# -- declared ranges of option and argument values (docs/hostile-input.md) -------------------------
# number() checks one value (a real number, not true; finite; an integer when asked; within [lo, hi],
# lo excluded when lo_open) and returns it; check_fields() checks the fields of a config dataclass
# against a table of Range. A bad value is an OptionError (exit 2) naming the option and the allowed
# range, so that no value reaches a C++ library (small_gicp, open3d, GTSAM) unchecked: threads=0 or
# knn=0 there is a crash, not an error.

MAX_THREADS = 256
"""The most threads an option may ask a native library for."""


class OptionError(GraphnavError, ValueError):
    """An option or argument value outside its declared type or range; ``where`` names the option."""

    def __init__(self, name: str, message: str) -> None:
        super().__init__(message, where=name)


@dataclass(frozen=True)
class Range:
    """A numeric option's declared range: ``lo <= v <= hi`` (``lo < v`` when ``lo_open``), an integer
    when ``integer``, ``None`` allowed when ``optional``."""

    lo: float = -math.inf
    hi: float = math.inf
    integer: bool = False
    lo_open: bool = False
    optional: bool = False

    def describe(self) -> str:
        kind = "an integer" if self.integer else "a finite number"
        lo = "" if self.lo == -math.inf else f"{'>' if self.lo_open else '>='} {self.lo:g}"
        hi = "" if self.hi == math.inf else f"<= {self.hi:g}"
        bounds = " and ".join(b for b in (lo, hi) if b)
        return kind + (f" {bounds}" if bounds else "") + (" (or null)" if self.optional else "")


def number(name: str, value: Any, rng: Range) -> Any:
    """``value`` if it is a number in ``rng``, else an :class:`OptionError` naming ``name`` and the range."""
    if value is None and rng.optional:
        return value
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    if ok:
        if isinstance(value, float) and not math.isfinite(value):
            ok = False
        elif rng.integer and not (isinstance(value, int) or float(value).is_integer()):
            ok = False
        elif value < rng.lo or value > rng.hi or (rng.lo_open and value == rng.lo):
            ok = False
    if not ok:
        raise OptionError(name, f"must be {rng.describe()}, got {_show(value)}")
    return int(value) if rng.integer else value


def _show(value: Any) -> str:
    """The value as the user wrote it (JSON: true, null, [1, 2]) when it can be, else its repr, cut to 60."""
    import json

    try:
        text = json.dumps(value) if not isinstance(value, float) or math.isfinite(value) else repr(value)
    except (TypeError, ValueError, RecursionError):
        text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def check_fields(obj: Any, ranges: dict[str, Range], what: str = "") -> None:
    """Every field of the dataclass ``obj`` named in ``ranges`` checked (:func:`number`; an integral
    float of an integer field becomes an ``int``, frozen dataclasses too); the error names
    ``WHAT FIELD``."""
    for name, rng in ranges.items():
        value = number(f"{what} {name}".strip(), getattr(obj, name), rng)
        object.__setattr__(obj, name, value)


POSITIVE = Range(lo=0.0, lo_open=True)
NON_NEGATIVE = Range(lo=0.0)
COUNT = Range(lo=1, hi=1_000_000, integer=True)
THREADS = Range(lo=1, hi=MAX_THREADS, integer=True)
KNN = Range(lo=1, hi=1000, integer=True)
FRACTION = Range(lo=0.0, hi=1.0)
