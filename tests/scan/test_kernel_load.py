"""The ICP kernels loaded from numba's cache without numba's target-context refresh
(graphnav.scan._jit.load_cached), checked in fresh processes: the same numbers as the dispatcher's own first
call, none of numba's lowering modules imported, and the dispatcher's own path where the loader cannot help."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("numba")

REPO = Path(__file__).resolve().parents[2]

MATCH = """
import json, sys
import numpy as np
from graphnav.scan import weighted_icp as w
if sys.argv[1] == "own":  # the dispatcher's own first call (numba's refresh, its cache)
    w._load = lambda *a: None
rng = np.random.default_rng(3)
tgt = rng.normal(size=(400, 2)) * 8.0
c, s = np.cos(0.05), np.sin(0.05)
src = (tgt - [0.3, -0.2]) @ np.array([[c, -s], [s, c]]) + rng.normal(size=(400, 2)) * 0.01
out = []
for cfg in (w.IcpConfig(), w.IcpConfig(variant="HD"), w.IcpConfig(matching="delaunay")):
    r = w.match_points(src, tgt, cfg, init=(0.25, -0.15, 0.04))
    out.append([r.pose.tolist(), r.cov.tolist(), r.ok, r.quality["iterations"]])
f = w._KERNELS[0]
print(json.dumps({"out": out, "lowering": "numba.np.polynomial.polynomial_functions" in sys.modules,
                  "signatures": [len(f.bounded.signatures), len(f.match_xy.signatures)]}))
"""


def _match(mode: str) -> dict:
    r = subprocess.run([sys.executable, "-c", MATCH, mode], capture_output=True, text=True, cwd=REPO,
                       env={**os.environ, "PYTHONPATH": str(REPO)}, timeout=600, check=True)
    return json.loads(r.stdout)


def test_the_cached_kernels_load_without_numbas_lowering_and_match_alike():
    own = _match("own")  # (also fills the cache on a fresh checkout)
    assert own["lowering"]  # the dispatcher's first call refreshed numba's target context
    loaded = _match("load")
    assert not loaded["lowering"]
    assert loaded["signatures"] == own["signatures"] == [1, 1]  # one signature each: the one a match passes
    assert loaded["out"] == own["out"]  # bit for bit


def test_the_loader_leaves_what_it_cannot_load_to_the_dispatcher():
    import numpy as np

    from graphnav.scan import _icp_fast
    from graphnav.scan._jit import load_cached

    a = np.zeros((3, 2), dtype=np.float32)  # a signature no match passes: not in the cache, not loaded
    before = len(_icp_fast.bounded.signatures)
    assert not load_cached(_icp_fast.bounded, (a, a, 1.0)) or len(_icp_fast.bounded.signatures) == before + 1
    assert _icp_fast.bounded(a, a, 1.0)  # the dispatcher compiles it as ever
    assert not load_cached(lambda x: x, (1.0,))  # not a dispatcher: nothing done
