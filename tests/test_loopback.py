"""Nothing listens beyond loopback unless asked: the embedded Dask LocalCluster binds 127.0.0.1 and
has no dashboard by default; the live examples bind 127.0.0.1."""

from __future__ import annotations

from pathlib import Path

import pytest

from graphnav import cli
from graphnav.evaluation import sweep

REPO = Path(__file__).resolve().parents[1]


class Captured(Exception):
    pass


@pytest.fixture
def cluster_kwargs(monkeypatch):
    """Replace distributed.LocalCluster by a recorder (no cluster is started)."""
    import distributed

    seen: dict = {}

    def fake(*args, **kwargs):
        seen.update(kwargs)
        raise Captured

    monkeypatch.setattr(distributed, "LocalCluster", fake)
    return seen


def test_local_cluster_binds_loopback_without_dashboard(cluster_kwargs):
    with pytest.raises(Captured):
        sweep.run_sweep(len, [{"key": "a"}, {"key": "b"}], scheduler="local", progress=False)
    assert cluster_kwargs["host"] == "127.0.0.1"
    assert cluster_kwargs["dashboard_address"] is None
    assert cluster_kwargs["scheduler_kwargs"] == {"dashboard_address": "127.0.0.1:0"}  # its health-check server


def test_a_real_local_cluster_listens_on_loopback_only():
    """Every TCP port the sweep's LocalCluster (scheduler, nannies, workers, HTTP) listens on is 127.0.0.1."""
    psutil = pytest.importorskip("psutil")
    seen: set[str] = set()

    def probe(task):
        return task["n"]

    import distributed

    real = distributed.LocalCluster

    def spy(*args, **kwargs):
        cluster = real(*args, **kwargs)
        procs = [psutil.Process()] + psutil.Process().children(recursive=True)
        for p in procs:
            for c in p.net_connections(kind="tcp"):
                if c.status == psutil.CONN_LISTEN:
                    seen.add(c.laddr.ip)
        return cluster

    distributed.LocalCluster = spy
    try:
        assert sweep.run_sweep(probe, [{"key": "a", "n": 1}, {"key": "b", "n": 2}], scheduler="local",
                               progress=False) == [1, 2]
    finally:
        distributed.LocalCluster = real
    assert seen and seen <= {"127.0.0.1"}, seen


def test_dashboard_only_when_asked_and_on_loopback(cluster_kwargs, monkeypatch, capsys):
    monkeypatch.setattr(sweep.importlib.util, "find_spec", lambda name: object())  # as if bokeh were there
    rc = cli.main(["beacons", "search", "--beacons", "1", "--limit", "10", "--scheduler", "local", "--dashboard",
                   "--no-progress"])
    capsys.readouterr()
    assert rc == 1  # the recorder's exception, reported as an internal error
    assert cluster_kwargs["dashboard_address"] == "127.0.0.1:8787" and cluster_kwargs["host"] == "127.0.0.1"


def test_live_help_shows_a_loopback_example(capsys):
    with pytest.raises(SystemExit):
        cli.main(["live", "--help"])
    text = capsys.readouterr().out
    assert "udp://127.0.0.1:" in text and "0.0.0.0" not in text


def test_no_wildcard_address_in_code_docs_or_examples():
    files = [REPO / "README.md", *(REPO / "docs").glob("*.md")]
    for d in ("graphnav", "examples", "benchmarks", "tools"):
        files += (REPO / d).rglob("*.py")
    hits = [f"{p.relative_to(REPO)}:{i}" for p in files
            for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
            if "0.0.0.0" in line or 'dashboard_address=":' in line]
    assert hits == []
