"""graph.chi2 against scipy.stats (the library it stands in for without its start-up cost)."""

import numpy as np
import pytest
from scipy.stats import chi2

from graphnav.graph.chi2 import chi2_median, chi2_ppf


@pytest.mark.parametrize("p", [0.5, 0.9, 0.95, 0.99, 0.999])
@pytest.mark.parametrize("dof", [1, 2, 3, 6, 15])
def test_ppf_equals_scipy(p, dof):
    assert chi2_ppf(p, dof) == float(chi2.ppf(p, dof))


def test_median_equals_scipy():
    d = np.array([1, 2, 3, 3, 6, 9])
    assert np.array_equal(chi2_median(d), chi2.median(d))
