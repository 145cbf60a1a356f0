"""``graphnav simulate SCENARIO ... --out LOG``: write a simulated log.

Scenarios are the modules of :mod:`graphnav.sim`; each declares
``register(subparsers)`` adding its own sub-parser (with ``set_defaults(func=...)``).
``degrade`` (simulated sensors added to an existing log) has its CLI glue here, in
:mod:`graphnav.commands._simulate_degrade`.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil

from .. import sim


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="simulate a scenario into a log", description=__doc__)
    scen = p.add_subparsers(dest="scenario", metavar="SCENARIO", required=True)
    for mod in sorted(pkgutil.iter_modules(sim.__path__), key=lambda m: m.name):
        if not mod.name.startswith("_"):
            m = importlib.import_module(f"{sim.__name__}.{mod.name}")
            if hasattr(m, "register"):
                m.register(scen)
    from ._simulate_degrade import register as register_degrade

    register_degrade(scen)
