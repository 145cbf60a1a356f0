"""Every estimator, in one registry for batch runs and live mode.

An estimator is a class (:class:`~graphnav.estimators.base.Estimator`): a ``Config`` dataclass whose fields
are its ``-O`` options with their help, ``add(record) -> Estimate | None`` and ``finish() -> RunResult``;
``online(**options)`` gives its live form. Estimator modules in this package declare
``ESTIMATORS = {"name": EstimatorClass}``; they are discovered here, so adding an estimator is adding a
module. A batch run is one loop (:func:`run`); comparing estimators is one loop over :func:`names`.

The names are read from the modules' source (:func:`declared`) and :func:`get` imports only the module
that declares the estimator asked for: ``graphnav run -e isam2`` does not import the filters' numba
kernels nor the scan matchers' SciPy (0.18 s CPU of its start-up); :func:`registry` imports them all.
"""

from __future__ import annotations

import ast
import difflib
import importlib
import pkgutil
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from ..log import NavLog
from ..result import OnEstimate, OnlineEstimator, RunResult  # re-exported: estimator modules import them from here
from .base import BatchEstimator, Estimator, EstimatorSpec, RunFn

__all__ = ["BatchEstimator", "Estimator", "EstimatorSpec", "OnEstimate", "RunFn", "RunResult", "get", "inputs",
           "make_online", "names", "registry", "run", "runnable", "unknown_name"]


_REGISTRY: dict[str, type[Estimator]] | None = None
_DECLARED: dict[str, str] | None = None
#: a module's declaration at the start of a line: ``ESTIMATORS = {"name": Class, ...}``
_DECLARATION = re.compile(r"^ESTIMATORS\s*=", re.MULTILINE)


def _module_estimators(module: str) -> dict[str, type[Estimator]]:
    """The ``ESTIMATORS`` of module ``module`` of this package (imported), each class named."""
    found = getattr(importlib.import_module(f"{__name__}.{module}"), "ESTIMATORS", {})
    for name, cls in found.items():
        cls.name = name
    return found


def _declared_names(module: str, ispkg: bool) -> list[str]:
    """The names module ``module`` declares, from its source when its one mention of ``ESTIMATORS`` is a dict
    literal with string keys at the start of a line; else (no source, another form, a later change to it) by
    importing it."""
    path = Path(__path__[0], f"{module}.py")
    text = None if ispkg else path.read_text(encoding="utf-8") if path.is_file() else None
    if text is not None:
        if "ESTIMATORS" not in text:
            return []
        m = _DECLARATION.search(text) if text.count("ESTIMATORS") == 1 else None
        try:  # (the module's rest: its statements from there; a line of a string starting so is no declaration)
            node = ast.parse(text[m.start():]).body[0] if m is not None else None
        except SyntaxError:
            node = None
        if node is not None:
            value = node.value if isinstance(node, ast.Assign) and len(node.targets) == 1 else None
            if isinstance(value, ast.Dict) and all(isinstance(k, ast.Constant) and isinstance(k.value, str)
                                                   for k in value.keys):
                return [k.value for k in value.keys]
    return list(_module_estimators(module))


def declared() -> dict[str, str]:
    """Estimator name -> the module of this package that declares it (:func:`_declared_names`: read from
    the source, not imported)."""
    global _DECLARED
    if _DECLARED is None:
        out: dict[str, str] = {}
        for mod in pkgutil.iter_modules(__path__):
            for name in _declared_names(mod.name, mod.ispkg):
                if name in out:
                    raise RuntimeError(f"estimator {name!r} declared twice")
                out[name] = mod.name
        _DECLARED = out
    return _DECLARED


def registry() -> dict[str, type[Estimator]]:
    """All estimators, discovered from the modules of this package (every one imported)."""
    global _REGISTRY
    if _REGISTRY is None:
        reg: dict[str, EstimatorSpec] = {}
        for mod in pkgutil.iter_modules(__path__):
            for name, cls in _module_estimators(mod.name).items():
                if name in reg:
                    raise RuntimeError(f"estimator {name!r} declared twice")
                reg[name] = cls
        _REGISTRY = reg
    return _REGISTRY


def names() -> list[str]:
    """The estimators' names (those of :func:`registry` once it is built, else :func:`declared`'s)."""
    return sorted(_REGISTRY if _REGISTRY is not None else declared())


def unknown_name(name: str, known: Iterable[str] | None = None) -> str:
    """The message for an unknown estimator ``name``: the closest known names (difflib) and all of them."""
    known = sorted(names() if known is None else known)
    close = difflib.get_close_matches(name, known, n=2, cutoff=0.6)
    hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
    return f"unknown estimator {name!r}{hint} (known: {', '.join(known)})"


def get(name: str) -> type[Estimator]:
    """The estimator ``name`` (a ``KeyError`` naming the known ones): from :func:`registry` once it is built,
    else from the one module that declares it."""
    if _REGISTRY is not None:
        if name not in _REGISTRY:
            raise KeyError(unknown_name(name, _REGISTRY))
        return _REGISTRY[name]
    module = declared().get(name)
    if module is None:
        raise KeyError(unknown_name(name))
    found = _module_estimators(module)
    if name not in found:
        raise RuntimeError(f"estimator {name!r}: module {module!r} does not declare it in ESTIMATORS")
    return found[name]


#: what an estimator's ``info["anchor"]`` (where its start pose came from) names -> the record kinds read
_ANCHOR_WORDS = {"truth": ("truth",), "gnss": ("gnss",), "pose_prior": ("pose_prior",), "compass": ("heading",),
                 "beacons": ("beacon", "beacon_known")}


def inputs(name: str, log: NavLog, options: dict[str, Any] | None = None,
           info: dict[str, Any] | None = None) -> list[str] | None:
    """The record kinds estimator ``name`` used on ``log`` with ``options``: the kinds its class
    declares (``Estimator.inputs``) that the log holds, plus the kinds its start pose came from
    (``info["anchor"]`` of its result, e.g. ``truth`` when nothing else gave one), in
    :data:`graphnav.io.drop.KINDS` order. ``None`` when the spec declares nothing."""
    from ..io.drop import KINDS

    declared = get(name).inputs(log, dict(options or {}))
    if declared is None:
        return None
    used = set(declared)
    anchor = (info or {}).get("anchor")
    if isinstance(anchor, str):
        for word in re.split(r"[^a-z_]+", anchor.lower()):
            used.update(_ANCHOR_WORDS.get(word, ()))
    have = log.counts()
    return [k for k in KINDS if k in used and have.get(k)]


def run(name: str, log: NavLog, *, on_estimate: OnEstimate | None = None, **options: Any) -> RunResult:
    """Run one estimator by name on a whole log: every record through ``add``, then ``finish``."""
    cls = get(name)
    why = cls.unmet(log)
    if why:
        raise ValueError(f"estimator {name!r} cannot run on this log: {why}")
    est = cls(log, on_estimate=on_estimate, **options)
    est.feed(log.records)
    return est.finish()


def online_names() -> list[str]:
    """The estimators with a live (record-by-record) form."""
    return [n for n in names() if registry()[n].live]


def make_online(name: str, **options: Any) -> OnlineEstimator:
    """The live form of estimator ``name`` (:meth:`Estimator.online`); a ``ValueError`` naming the
    estimators that have one when it has none."""
    have = online_names()
    if name not in have:
        close = difflib.get_close_matches(name, have, n=2, cutoff=0.6)
        hint = f"did you mean {' or '.join(repr(c) for c in close)}? " if close else ""
        raise ValueError(f"no online form of estimator {name!r} ({hint}have: {', '.join(have)})")
    try:
        est = get(name).online(**options)
    except TypeError as exc:  # an unknown -O option
        raise ValueError(f"estimator {name!r}: {exc}") from None
    assert est is not None
    return est


def runnable(log: NavLog) -> list[str]:
    """Names of the estimators the log's records can feed."""
    return [n for n in names() if registry()[n].unmet(log) is None]
