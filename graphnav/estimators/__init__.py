"""Every estimator reads a :class:`NavLog` and returns a :class:`~graphnav.result.RunResult`.

Estimator modules in this package declare ``ESTIMATORS = {"name": EstimatorSpec(...)}``;
they are discovered here, so adding an estimator is adding a module. Comparing estimators is
one loop over :func:`names`.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from typing import Any, NamedTuple, Protocol

from ..log import NavLog
from ..result import OnEstimate, RunResult  # re-exported: estimator modules import them from here

__all__ = ["EstimatorSpec", "OnEstimate", "RunFn", "RunResult", "get", "names", "registry", "run", "runnable"]


class RunFn(Protocol):
    def __call__(self, log: NavLog, *, on_estimate: OnEstimate | None = None, **options: Any) -> RunResult: ...


class EstimatorSpec(NamedTuple):
    """``run(log, on_estimate=None, **options)``; ``unmet(log)`` returns why the log cannot feed
    the estimator (``None`` if it can); a one-line ``description``; ``kind`` is
    ``"smoother"``, ``"filter"`` or ``"odometry"``."""

    run: RunFn
    unmet: Callable[[NavLog], str | None]
    description: str
    kind: str = "filter"


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


def get(name: str) -> EstimatorSpec:
    reg = registry()
    if name not in reg:
        raise KeyError(f"unknown estimator {name!r}; known: {', '.join(sorted(reg))}")
    return reg[name]


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
