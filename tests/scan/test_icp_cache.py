"""The shared weighted-ICP match cache: a hit is exactly the match it replaces, and `compare` gives
the same table with and without it."""

from __future__ import annotations

import numpy as np
import pytest
from _polyworld import synthetic_log

from graphnav.evaluation.comparison import compare
from graphnav.scan import icp_cache
from graphnav.scan import weighted_icp as icp


@pytest.fixture(scope="module")
def log():
    return synthetic_log(12)


def test_a_hit_is_the_computed_match_and_other_guesses_miss(log):
    a, b = log.of("scan")[1], log.of("scan")[0]
    cfg = icp.IcpConfig()
    ref = icp.match_scans(a, b, cfg, init=[0.7, 0.0, 0.0])
    cache = icp_cache.MatchCache()
    with icp_cache.active(cache):
        first = icp_cache.match_scans(a, b, cfg, init=[0.7, 0.0, 0.0])
        first.pose[:] = 99.0  # a caller mutating its copy does not touch the cache
        again = icp_cache.match_scans(a, b, cfg, init=[0.7, 0.0, 0.0])
        assert (cache.hits, cache.misses) == (1, 1)
        icp_cache.match_scans(a, b, cfg, init=[0.0, 0.0, 0.0])  # another guess: computed
        icp_cache.match_scans(a, b, icp.IcpConfig(variant="HD"), init=[0.7, 0.0, 0.0])  # another config
        assert (cache.hits, cache.misses) == (1, 3) and len(cache) == 3
    np.testing.assert_array_equal(again.pose, ref.pose)
    np.testing.assert_array_equal(again.cov, ref.cov)
    assert again.ok == ref.ok
    assert len(cache.ms) == 4 and cache.ms[1] == cache.ms[0]  # a hit reports its first computation's time
    icp_cache.match_scans(a, b, cfg, init=[0.7, 0.0, 0.0])  # outside `active`: not cached
    assert cache.hits == 1 and icp_cache.current() is None


def test_compare_with_the_cache_gives_the_same_results(log):
    names = ["batch", "isam2", "icp-dr"]
    plain = compare(log, names)
    cache = icp_cache.MatchCache()
    shared = compare(log, names, cache=cache)
    n_pairs = len(log.of("scan")) - 1
    by = {e.name: e for e in shared}
    assert by["batch"].summary["icp_cache_hits"] == 0
    assert by["isam2"].summary["icp_cache_hits"] == n_pairs  # the same GraphBuilder sequence as batch
    assert cache.hits == sum(e.summary["icp_cache_hits"] for e in shared)
    for p, s in zip(plain, shared, strict=True):
        assert p.ok and s.ok
        assert "icp_cache_hits" not in p.summary
        np.testing.assert_array_equal(p.result.trajectory.poses, s.result.trajectory.poses)
        assert s.summary["ate_rmse_m"] == p.summary["ate_rmse_m"]
    assert icp_cache.current() is None  # compare leaves no cache active


def test_the_library_compare_shares_matches_by_default(log, tmp_path):
    """`graphnav demo` calls the library with default options: the cache is on, and counted."""
    from graphnav.evaluation.pipeline import CompareOptions, run_compare
    from graphnav.io import save_log
    from graphnav.io.outputs import OutDir

    path = tmp_path / "l.jsonl"
    save_log(log, path)
    opts = CompareOptions(log=str(path), out=tmp_path / "o", estimators=["dead-reckoning"], workers=1)
    outcome = run_compare(opts, OutDir(opts.out, command="compare"))
    assert outcome.json["icp_cache_hits"] == 0 and outcome.json["estimators"]["dead-reckoning"]["ate_rmse_m"] > 0
