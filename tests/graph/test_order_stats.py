"""graphnav.graph.order_stats gives numpy's median and linear quantile to the last bit."""

from __future__ import annotations

import numpy as np
import pytest

from graphnav.graph.order_stats import median, quantile


def samples() -> list[np.ndarray]:
    rng = np.random.default_rng(7)
    out = [rng.uniform(0.05, 0.15, n) for n in range(1, 40)]
    out += [rng.lognormal(0.0, 2.0, n) for n in (2, 3, 16, 17, 199, 200)]
    out += [np.array([0.1] * 5), np.array([0.1, 0.1, 0.2, 0.2]), np.array([1e-300, 1e300, -5.0])]
    return out


def test_median_is_numpys_to_the_bit():
    for x in samples():
        assert median(x.tolist()) == float(np.median(x))


@pytest.mark.parametrize("q", [0.0, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95, 1.0])
def test_quantile_is_numpys_to_the_bit(q: float):
    for x in samples():
        assert quantile(x.tolist(), q) == float(np.quantile(x, q))


def test_known_answers_and_no_values():
    assert median([3.0, 1.0, 2.0]) == 2.0
    assert median([4.0, 1.0, 2.0, 3.0]) == 2.5
    assert quantile([0.0, 10.0], 0.9) == 9.0
    with pytest.raises(ValueError):
        median([])
    with pytest.raises(ValueError):
        quantile([], 0.5)
