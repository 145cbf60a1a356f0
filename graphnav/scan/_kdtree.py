"""scipy's k-d tree, :class:`cKDTree`, without importing the rest of ``scipy.spatial``.

``from scipy.spatial import cKDTree`` runs ``scipy/spatial/__init__.py``, which imports the distance
functions, Delaunay/Voronoi (qhull), ``Rotation`` and with them ``scipy.linalg`` and ``scipy.special``:
0.15 s of CPU at start-up (``python -X importtime``; a 10 min harbour run is ~4.7 s), none of it used by
the loop closer's place index or the degeneracy analysis. The tree is one compiled module of its own,
``scipy.spatial._ckdtree``, which imports nothing of ``scipy.spatial``: it is loaded here by itself and
registered under its own name, so a later ``import scipy.spatial`` takes this module (one ``cKDTree``
class). Where that cannot be done (another scipy layout, an error), the ordinary import.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import os
import sys
from typing import Any

NAME = "scipy.spatial._ckdtree"


def _load() -> Any:
    """The ``cKDTree`` class: from the module loaded by itself where possible, else from ``scipy.spatial``."""
    mod = sys.modules.get(NAME)
    if mod is None and "scipy.spatial" not in sys.modules:
        try:
            import scipy

            spec = importlib.machinery.PathFinder.find_spec(NAME, [os.path.join(os.path.dirname(scipy.__file__),
                                                                                "spatial")])
            if spec is not None and spec.loader is not None:
                mod = importlib.util.module_from_spec(spec)
                sys.modules[NAME] = mod
                try:
                    spec.loader.exec_module(mod)
                except BaseException:
                    del sys.modules[NAME]
                    raise
        except Exception:  # noqa: BLE001  (anything: the ordinary import below)
            mod = None
    tree = getattr(mod, "cKDTree", None)
    if tree is None:
        from scipy.spatial import cKDTree as tree
    return tree


cKDTree = _load()
