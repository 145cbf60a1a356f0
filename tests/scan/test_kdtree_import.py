"""graphnav.scan._kdtree: scipy's cKDTree without scipy.spatial's other modules (start-up), one class either way."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]


def _run(code: str) -> str:
    return subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True, cwd=REPO,
                          env={**os.environ, "PYTHONPATH": str(REPO)}, timeout=300).stdout.strip()


def test_the_place_index_and_degeneracy_do_not_import_scipy_spatial():
    out = _run("import sys, graphnav.graph.loop_places, graphnav.scan.degeneracy\n"
               "print('scipy.spatial' in sys.modules, 'scipy.special' in sys.modules)")
    assert out == "False False"


def test_a_later_scipy_spatial_import_has_the_same_tree_class():
    out = _run("from graphnav.scan._kdtree import cKDTree\nimport scipy.spatial\n"
               "from scipy.spatial import KDTree\n"
               "print(scipy.spatial.cKDTree is cKDTree, issubclass(KDTree, cKDTree))")
    assert out == "True True"


def test_after_scipy_spatial_the_tree_is_its_own():
    out = _run("import scipy.spatial\nfrom graphnav.scan._kdtree import cKDTree\n"
               "print(scipy.spatial.cKDTree is cKDTree)")
    assert out == "True"


def test_the_tree_answers():
    from graphnav.scan._kdtree import cKDTree

    pts = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]])
    d, i = cKDTree(pts).query([0.9, 0.1], k=2)
    assert i.tolist() == [1, 0] and d[0] == np.hypot(0.1, 0.1)
