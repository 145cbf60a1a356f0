"""A shared weighted-ICP match cache: estimators that match the same scan pairs compute each once.

``graphnav compare`` runs several estimators on one log; isam2, batch and fixed-lag (one shared
:class:`~graphnav.graph.builder.GraphBuilder` sequence), the EKF with ICP increments and ``icp-dr``
all call :func:`graphnav.scan.weighted_icp.match_points` on the same consecutive scans. Inside
``with active(MatchCache()):`` the call sites that go through :func:`match_points` /
:func:`match_scans` of this module look the match up first. The key is the exact content of
both point sets, the whole :class:`~graphnav.scan.weighted_icp.IcpConfig` and the initial guess, so a hit
returns exactly what the call would have computed (ICP is deterministic); an estimator with
another guess or config computes its own match. Outside ``active`` nothing is cached.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from . import weighted_icp as icp

_active: MatchCache | None = None  # a module global, not a ContextVar: forked workers inherit it


def _digest(a: Any) -> bytes:
    if a is None:
        return b"none"
    arr = np.ascontiguousarray(np.asarray(a, dtype=float))
    return hashlib.blake2b(arr.tobytes() + str(arr.shape).encode(), digest_size=16).digest()


class MatchCache:
    """Weighted-ICP results keyed by (source points, target points, config, initial guess).

    ``hits``/``misses`` count lookups, ``ms`` holds each lookup's computation time (that of the
    first computation for a hit); ``max_entries`` bounds memory (oldest dropped first; a
    marina compare needs ~180 entries of a few hundred bytes each).
    """

    def __init__(self, max_entries: int = 100_000) -> None:
        self.max_entries = max_entries
        self._store: dict[tuple, tuple[icp.MatchResult, float]] = {}
        self.hits = 0
        self.misses = 0
        self.ms: list[float] = []  # per lookup: the computation time [ms] of the match returned

    def __len__(self) -> int:
        return len(self._store)

    @staticmethod
    def key(src_xy: ArrayLike, tgt_xy: ArrayLike, cfg: icp.IcpConfig, init: ArrayLike | None,
            init_cov: ArrayLike | None = None) -> tuple:
        # repr(cfg): every field, without astuple's deep copy on each lookup
        return (_digest(src_xy), _digest(tgt_xy), repr(cfg), _digest(init), _digest(init_cov))

    def match_points(self, src_xy: ArrayLike, tgt_xy: ArrayLike, cfg: icp.IcpConfig | None = None,
                     init: ArrayLike | None = None, init_cov: ArrayLike | None = None) -> icp.MatchResult:
        """:func:`graphnav.scan.weighted_icp.match_points`, computed once per key (a copy is returned)."""
        cfg = cfg or icp.IcpConfig()
        k = self.key(src_xy, tgt_xy, cfg, init, init_cov)
        got = self._store.get(k)
        if got is None:
            self.misses += 1
            t0 = time.perf_counter()
            hit = icp.match_points(src_xy, tgt_xy, cfg, init, init_cov=init_cov)
            got = (hit, (time.perf_counter() - t0) * 1e3)
            if len(self._store) >= self.max_entries:
                self._store.pop(next(iter(self._store)))
            self._store[k] = got
        else:
            self.hits += 1
        hit, ms = got
        self.ms.append(ms)
        return icp.MatchResult(hit.pose.copy(), hit.cov.copy(), hit.ok, copy.deepcopy(hit.quality))

    def stats(self) -> dict[str, int]:
        return {"icp_cache_hits": self.hits, "icp_cache_misses": self.misses}


@contextlib.contextmanager
def active(cache: MatchCache | None) -> Iterator[MatchCache | None]:
    """Route this module's :func:`match_points`/:func:`match_scans` through ``cache`` (``None``: off)."""
    global _active
    before, _active = _active, cache
    try:
        yield cache
    finally:
        _active = before


def current() -> MatchCache | None:
    """The active cache, if any."""
    return _active


def match_points(src_xy: ArrayLike, tgt_xy: ArrayLike, config: icp.IcpConfig | None = None,
                 init: ArrayLike | None = None, init_cov: ArrayLike | None = None) -> icp.MatchResult:
    """:func:`graphnav.scan.weighted_icp.match_points` through the active cache (plain call when none is active)."""
    cache = _active
    if cache is None:
        return icp.match_points(src_xy, tgt_xy, config, init, init_cov=init_cov)
    return cache.match_points(src_xy, tgt_xy, config, init, init_cov)


def match_scans(source: Any, target: Any, config: icp.IcpConfig | None = None,
                init: ArrayLike | None = None) -> icp.MatchResult:
    """:func:`graphnav.scan.weighted_icp.match_scans` through the active cache."""
    cfg = config or icp.IcpConfig()
    return match_points(icp.scan_points(source, cfg), icp.scan_points(target, cfg), cfg, init)
