"""Every estimator reads a :class:`NavLog` and returns a :class:`~graphnav.result.RunResult`.

Estimator modules in this package declare ``ESTIMATORS = {"name": EstimatorSpec(...)}``;
they are discovered here, so adding an estimator is adding a module. Comparing estimators is
one loop over :func:`names`.
"""

from __future__ import annotations

import difflib
import importlib
import pkgutil
import re
from collections.abc import Callable, Iterable
from typing import Any, NamedTuple, Protocol

from ..log import NavLog
from ..result import OnEstimate, RunResult  # re-exported: estimator modules import them from here

__all__ = ["EstimatorSpec", "OnEstimate", "RunFn", "RunResult", "get", "inputs", "names", "registry", "run", "runnable",
           "unknown_name"]


class RunFn(Protocol):
    def __call__(self, log: NavLog, *, on_estimate: OnEstimate | None = None, **options: Any) -> RunResult: ...


class EstimatorSpec(NamedTuple):
    """``run(log, on_estimate=None, **options)``; ``unmet(log)`` returns why the log cannot feed
    the estimator (``None`` if it can); a one-line ``description``; ``kind`` is
    ``"smoother"``, ``"filter"`` or ``"odometry"``. ``inputs(log, options)``: the record kinds
    ``run(log, **options)`` reads (measurements, controls, its start pose; :func:`inputs` keeps those
    the log holds), ``None``: not declared."""

    run: RunFn
    unmet: Callable[[NavLog], str | None]
    description: str
    kind: str = "filter"
    inputs: Callable[[NavLog, dict[str, Any]], Iterable[str]] | None = None


_REGISTRY: dict[str, EstimatorSpec] | None = None


def registry() -> dict[str, EstimatorSpec]:
    """All estimators, discovered from the modules of this package."""
    global _REGISTRY
    if _REGISTRY is None:
        reg: dict[str, EstimatorSpec] = {}
        for mod in pkgutil.iter_modules(__path__):
            m = importlib.import_module(f"{__name__}.{mod.name}")
            for name, spec in getattr(m, "ESTIMATORS", {}).items():
                if name in reg:
                    raise RuntimeError(f"estimator {name!r} declared twice")
                reg[name] = spec
        _REGISTRY = reg
    return _REGISTRY


def names() -> list[str]:
    return sorted(registry())


def unknown_name(name: str, known: Iterable[str] | None = None) -> str:
    """The message for an unknown estimator ``name``: the closest known names (difflib) and all of them."""
    known = sorted(registry() if known is None else known)
    close = difflib.get_close_matches(name, known, n=2, cutoff=0.6)
    hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
    return f"unknown estimator {name!r}{hint} (known: {', '.join(known)})"


def get(name: str) -> EstimatorSpec:
    reg = registry()
    if name not in reg:
        raise KeyError(unknown_name(name, reg))
    return reg[name]


#: what an estimator's ``info["anchor"]`` (where its start pose came from) names -> the record kinds read
_ANCHOR_WORDS = {"truth": ("truth",), "gnss": ("gnss",), "pose_prior": ("pose_prior",), "compass": ("heading",),
                 "beacons": ("beacon", "beacon_known")}


def inputs(name: str, log: NavLog, options: dict[str, Any] | None = None,
           info: dict[str, Any] | None = None) -> list[str] | None:
    """The record kinds estimator ``name`` used on ``log`` with ``options``: the kinds its spec
    declares (``EstimatorSpec.inputs``) that the log holds, plus the kinds its start pose came from
    (``info["anchor"]`` of its result, e.g. ``truth`` when nothing else gave one), in
    :data:`graphnav.io.drop.KINDS` order. ``None`` when the spec declares nothing."""
    from ..io.drop import KINDS

    spec = get(name)
    if spec.inputs is None:
        return None
    used = set(spec.inputs(log, dict(options or {})))
    anchor = (info or {}).get("anchor")
    if isinstance(anchor, str):
        for word in re.split(r"[^a-z_]+", anchor.lower()):
            used.update(_ANCHOR_WORDS.get(word, ()))
    have = log.counts()
    return [k for k in KINDS if k in used and have.get(k)]


def run(name: str, log: NavLog, *, on_estimate: OnEstimate | None = None, **options: Any) -> RunResult:
    """Run one estimator by name."""
    spec = get(name)
    why = spec.unmet(log)
    if why:
        raise ValueError(f"estimator {name!r} cannot run on this log: {why}")
    return spec.run(log, on_estimate=on_estimate, **options)


def runnable(log: NavLog) -> list[str]:
    """Names of the estimators the log's records can feed."""
    return [n for n in names() if registry()[n].unmet(log) is None]
