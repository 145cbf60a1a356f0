"""Every estimator's options (``-O KEY=VALUE``, ``[options]`` in ``--config`` TOML) with their types,
defaults, units and meanings, read from the estimator's ``Config`` dataclass (its fields' metadata:
:func:`graphnav.config.option`), and the check of given values against them. ``graphnav run
--list-options NAME`` prints :func:`describe`."""

from __future__ import annotations

import re
from typing import Any

from ..config import describe_config

__all__ = ["Option", "check", "describe"]

Option = dict[str, Any]  # {"name", "type", "default", "unit", "meaning", "group"}


def describe(name: str) -> list[Option]:
    """The options estimator ``name`` accepts, each ``{"name", "type", "default", "unit", "meaning",
    "group"}`` (a ``KeyError`` naming the known estimators for an unknown name)."""
    from . import get

    cls = get(name)
    if cls.Config is None:
        return []
    return describe_config(cls.Config, skip=("solver",) if cls.kind == "smoother" else ())


MAX_INT_OPTION = 2**31 - 1  # an integer option reaches C++ (GTSAM) as a C int
MAX_FLOAT_OPTION = 1e15  # a numeric option's magnitude: its square stays far from overflow
_SIGNED = {"kappa", "water_margin"}
"""Numeric options that may be negative (every other numeric option is >= 0)."""


def check_value(option: str, value: Any, default: Any) -> None:
    """An :class:`~graphnav.config.OptionError` naming ``option`` when ``value`` is not of the kind of
    its ``default``: a number (finite; an integer when the default is one; >= 0 unless the option is
    signed) for a numeric default, ``true``/``false`` for a flag, a table for a table; a choice (text
    default) or an option without a default (None) takes null, a flag, text or a finite number
    (never a list or a table); the estimator checks the choice itself."""
    from ..config import OptionError, Range, number

    name = f"option {option}"
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise OptionError(name, f"must be true or false, got {value!r:.60}")
    elif isinstance(default, int | float):
        integer = isinstance(default, int)
        hi = MAX_INT_OPTION if integer else MAX_FLOAT_OPTION
        number(name, value, Range(lo=-hi if option.rpartition(".")[2] in _SIGNED else 0.0, hi=hi, integer=integer))
    elif isinstance(default, dict):
        if not isinstance(value, dict):
            raise OptionError(name, f"must be a table of options, got {value!r:.60}")
    elif (default is None or isinstance(default, str)) and not (value is None or isinstance(value, bool | str)):
        # a choice (text) or an option without a default: some also take a number (ekf-slam's gate)
        if isinstance(value, list | dict):
            raise OptionError(name, f"must be a single value (default {default!r}), got {value!r:.60}")
        number(name, value, Range(lo=-MAX_FLOAT_OPTION, hi=MAX_FLOAT_OPTION))


def _by_annotation(option: str, value: Any, ann: str) -> bool:
    """True when ``value`` is of a kind the annotation ``ann`` admits (None, a flag, text, a number);
    an annotation that names none of them (or none given) admits anything."""
    kinds = {"None": value is None, "bool": isinstance(value, bool),
             "str": isinstance(value, str), "Literal": isinstance(value, str),
             "float": isinstance(value, int | float) and not isinstance(value, bool),
             "int": isinstance(value, int) and not isinstance(value, bool)}
    tokens = set(re.findall(r"[A-Za-z_]+", ann))
    if tokens & {"dict", "list", "tuple", "Mapping", "Sequence", "Any", "object"}:
        return True
    named = [k for k in kinds if k in tokens]
    return not named or any(kinds[k] for k in named)


def check(name: str, options: dict[str, Any]) -> None:
    """A ``ValueError`` naming the unknown option(s) of estimator ``name`` ("did you mean") and the known
    ones; an :class:`~graphnav.config.OptionError` naming an option whose value is not of its kind
    (:func:`check_value` against its default, and its type), and a ``cloud`` table checked as the
    cloud matcher's options. An estimator without a ``Config`` takes any option. A config in sections
    (the smoother's) takes each option by its flat name, its path (``gnss.gate``) or in its section's
    table (``gnss = {gate = 4}``, :func:`graphnav.config.spell_options`)."""
    from ..config import OptionError, sections, spell_options, unknown_options
    from . import get

    cls = get(name).Config
    if not options or cls is None:
        return
    opts = describe(name)
    hint = f" (graphnav run --list-options {name})"
    if sections(cls):
        by_path = {o["path"]: o for o in opts}
        names = [n for o in opts for n in (o["name"], o["path"])]
        spelled = [(key, path, value) for key, path, value in spell_options(cls, options)
                   if path not in sections(cls)]  # a section object (Python) is checked as it is built
        bad = [key for key, path, _ in spelled if path not in by_path]
        if bad:
            raise ValueError(unknown_options(name, bad, list(by_path), hint, names))
        items = [(key, value, by_path[str(path)]) for key, path, value in spelled]
    else:
        described = {o["name"]: o for o in opts}
        bad = sorted(set(options) - set(described))
        if bad:
            raise ValueError(unknown_options(name, bad, list(described), hint))
        items = [(key, value, described[key]) for key, value in options.items()]
    for key, value, o in items:
        ann = o["type"]
        if value is None and "None" in ann:
            continue
        if not (isinstance(value, list | tuple) and re.search(r"\b(list|tuple)\b", ann)):
            check_value(key, value, o["default"])
        if ann and not _by_annotation(key, value, ann):
            raise OptionError(f"option {key}", f"must be of type {ann}, got {value!r:.60}")
    cloud = next((value for _, value, o in items if o.get("path", o["name"]) in ("cloud", "scan.cloud")), None)
    if isinstance(cloud, dict) and get(name).kind == "smoother":
        from ..scan.cloud_match import CloudMatchConfig

        CloudMatchConfig.from_options(dict(cloud))
