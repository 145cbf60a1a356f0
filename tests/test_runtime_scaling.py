"""benchmarks/runtime_scaling.py runs the checkout it is given (``--code``), wherever it is started from."""

from __future__ import annotations

import json
from pathlib import Path

from _bench import REPO, load_benchmark


def test_code_runs_that_checkout_even_from_inside_another(tmp_path, monkeypatch):
    """``python -m graphnav`` puts its working directory ahead of ``PYTHONPATH``: started from this checkout, a
    ``--code`` run measured this checkout's code. A stand-in ``graphnav`` in ``--code`` answers instead."""
    fake = tmp_path / "other" / "graphnav"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("")
    (fake / "__main__.py").write_text("import json, os, sys\n"
                                      "print(json.dumps({'argv': sys.argv[1:3], 'here': os.path.abspath(__file__)}))\n")
    rs = load_benchmark("runtime_scaling")
    monkeypatch.chdir(REPO)  # where one starts it: a checkout with its own graphnav
    got = rs.run(Path("/nonexistent/log.npz"), "isam2", [], tmp_path / "other")
    assert got["here"] == str((fake / "__main__.py").resolve())
    assert got["argv"] == ["run", "/nonexistent/log.npz"]
    assert got["cpu_s"] > 0.0 and json.dumps(got)
