"""graph.chi2 against scipy.stats / scipy.special (the libraries it stands in for without their start-up cost)."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.special as sc
from scipy.stats import chi2

from graphnav.graph.chi2 import KNOWN, chi2_median, chi2_ppf, ndtri, significant_scale, special

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("p", [0.5, 0.9, 0.95, 0.99, 0.999])
@pytest.mark.parametrize("dof", [1, 2, 3, 6, 15])
def test_ppf_equals_scipy(p, dof):
    assert chi2_ppf(p, dof) == float(chi2.ppf(p, dof))


def test_median_equals_scipy():
    d = np.array([1, 2, 3, 3, 6, 9])
    assert np.array_equal(chi2_median(d), chi2.median(d))
    two = np.array([[2.0, 1.0], [2.0, 7.0]])
    assert np.array_equal(chi2_median(two), chi2.median(two))
    assert chi2_median(np.zeros(0)).shape == (0,)


@pytest.mark.parametrize("key", sorted(KNOWN))
def test_known_values_are_scipy_special_to_the_bit(key):
    name, *args = key
    assert KNOWN[key] == float(getattr(sc, name)(*args))


def test_unknown_arguments_go_to_scipy():
    assert special("gammaincinv", 3.5, 0.9) == float(sc.gammaincinv(3.5, 0.9))
    assert ndtri(0.975) == float(sc.ndtri(0.975))
    dim, prob, n = 2, 0.99, 37
    m = float(chi2.median(dim))
    f = float(chi2.pdf(m, dim))
    expected = 1.0 + sc.ndtri(prob) / (2.0 * f * np.sqrt(n)) / m
    assert significant_scale(dim, prob, n) == pytest.approx(expected, rel=1e-12)


def _imported(code: str, names: list[str]) -> list[bool]:
    """Whether each module of ``names`` is in ``sys.modules`` after ``code`` runs in a fresh interpreter."""
    code = f"import sys\n{code}print(*[n in sys.modules for n in {names!r}])\n"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO,
                       env={**os.environ, "PYTHONPATH": str(REPO)}, timeout=300)
    assert r.returncode == 0, r.stderr
    return [w == "True" for w in r.stdout.split()[-len(names):]]


def test_a_vessel_run_imports_neither_scipy_special_nor_scipy_optimize():
    """The 5 Hz NMEA log's path (the vessel graph, its position walk, GNC, the noise estimation): the values
    of KNOWN and the walk's own fit, no scipy.special (~0.05 s) or scipy.optimize (~0.1 s) import."""
    code = ("from graphnav.graph.log_runs import run_isam2\n"
            "from tests.graph.test_position_walk import wandering_boat\n"
            "res = run_isam2(wandering_boat(0.2, n=240))\n")
    assert _imported(code, ["scipy.special", "scipy.optimize", "scipy.sparse"]) == [False, False, True]


def test_the_graph_modules_import_no_sparse_solver_nor_ndimage():
    """scipy.sparse.linalg (0.01 s to import) is imported by the noise estimation and the odometry-scale step when
    they factorise, scipy.ndimage (0.04 s) by the correlative matcher's grid when it builds one, not by the modules a
    run imports (the harbour's isam2 run does neither)."""
    code = ("import graphnav.graph.log_runs, graphnav.graph.solution, graphnav.graph.noise\n"
            "import graphnav.graph.odometry_scale, graphnav.graph.loops, graphnav.scan.correlative\n")
    assert _imported(code, ["scipy.sparse.linalg", "scipy.ndimage"]) == [False, False]
