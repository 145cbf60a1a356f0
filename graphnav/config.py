"""Estimator options (``-O key=value`` on the CLI, ``**options`` in Python) -> a config dataclass whose
fields carry their help (:func:`option`, :func:`describe_config`), and the declared ranges option and
argument values are checked against (:func:`number`, :class:`Range`, :class:`OptionError`;
docs/hostile-input.md)."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import MISSING, Field, dataclass, field, fields
from typing import Any, TypeVar

from .errors import GraphnavError

T = TypeVar("T")


def option(default: Any = MISSING, help: str = "", unit: str = "", *, factory: Any = None) -> Any:
    """A config dataclass field with its help: ``help`` (what it means, reST allowed) and ``unit`` (SI,
    e.g. ``"m/s"``; ``""``: none) as field metadata, read by :func:`describe_config` (``--list-options``,
    TOML and ``-O`` checks). ``factory``: a default factory instead of ``default``."""
    meta = {"help": help, "unit": unit}
    if factory is not None:
        return field(default_factory=factory, metadata=meta)
    return field(default=default, metadata=meta)


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
    the class's own fields first, then each base's."""
    out = []
    for f in fields(cls):  # type: ignore[arg-type]
        if f.name in skip:
            continue
        unit = f.metadata.get("unit", "")
        meaning = plain_text(f.metadata.get("help", ""))
        depth, owner = next((i, k) for i, k in enumerate(cls.__mro__)
                            if f.name in k.__dict__.get("__annotations__", {}))
        out.append({"name": f.name, "type": str(f.type), "default": field_default(f), "unit": unit,
                    "meaning": f"[{unit}] {meaning}" if unit else meaning,
                    "group": owner.__dict__.get("group") or owner.__name__, "_depth": depth})
    out.sort(key=lambda o: o["_depth"])  # the class's own fields first, then its bases'
    for o in out:
        del o["_depth"]
    return out


def config_from_options(cls: type[T], options: Mapping[str, Any], what: str) -> T:
    """``cls(**options)`` for a dataclass ``cls``; an unknown option is a ``ValueError`` naming it
    and the known ones (``what``: e.g. ``"smoother"``)."""
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
