"""graphnav: factor-graph navigation for unmanned surface vessels.

The public API, imported lazily (``import graphnav`` stays cheap; GTSAM loads on first use)::

    log = graphnav.load_log(path)
    nav = graphnav.Navigator(config=None)     # isam2 by default; SmootherConfig(solver="fixed-lag")
    for rec in log:
        est = nav.add(rec)                    # Estimate | None: est.t, est.pose (gtsam.Pose2), est.cov
    traj = nav.smoothed()                     # the smoothed Trajectory with covariances

See README.md.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"  # = pyproject.toml's [project] version (tests/test_resume.py checks)

_LAZY = {
    "load_log": ("graphnav.io", "load_log"),
    "save_log": ("graphnav.io", "save_log"),
    "Navigator": ("graphnav.graph.navigator", "Navigator"),
    "SmootherConfig": ("graphnav.graph.smoother_config", "SmootherConfig"),
    "Estimate": ("graphnav.result", "Estimate"),
    "RunResult": ("graphnav.result", "RunResult"),
    "Trajectory": ("graphnav.trajectory", "Trajectory"),
    "NavLog": ("graphnav.log", "NavLog"),
    "GraphnavError": ("graphnav.errors", "GraphnavError"),
    "LogError": ("graphnav.errors", "LogError"),
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        mod, attr = _LAZY[name]
        value = getattr(importlib.import_module(mod), attr)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'graphnav' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
