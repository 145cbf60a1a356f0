"""Shared fixtures. The marina dataset is not part of the project: it is looked up at
``$GRAPHNAV_MARINA``, then ``../shared/data/icp_data_marina`` beside the repository (and one
level further up, for git worktrees), and tests that need it skip with the reason when absent."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

# CI (CI=true) runs hypothesis derandomized: the same examples every run, so a red CI is a real
# regression, not a new random draw; developers' runs explore new examples each time.
# No deadline anywhere: tests never assert wall-clock times (a loaded 2-core machine made first calls slow).
settings.register_profile("ci", derandomize=True, deadline=None)
settings.register_profile("dev", deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")

REPO = Path(__file__).resolve().parents[1]


def find_marina() -> Path | None:
    cands = []
    if os.environ.get("GRAPHNAV_MARINA"):
        cands.append(Path(os.environ["GRAPHNAV_MARINA"]))
    cands += [REPO.parent / "shared" / "data" / "icp_data_marina",
              REPO.parent.parent / "shared" / "data" / "icp_data_marina"]
    for c in cands:
        if (c / "ranges.mat").exists() and (c / "gps.mat").exists() and (c / "angles.mat").exists():
            return c
    return None


@pytest.fixture(scope="session")
def marina_dir() -> Path:
    d = find_marina()
    if d is None:
        pytest.skip("marina dataset not found (set GRAPHNAV_MARINA or place it at ../shared/data/icp_data_marina)")
    return d


@pytest.fixture(scope="session")
def marina_log(marina_dir):
    from graphnav.io.marina import read_marina

    return read_marina(marina_dir)


@pytest.fixture(autouse=True)
def _run_writes_no_report_by_default(monkeypatch):
    """``graphnav run --out`` draws compare's figures for its estimator (~3 s each run); the suite runs
    it some 70 times, so here it does so only when a test asks (``--report``)."""
    import graphnav.commands.run as run_command

    monkeypatch.setattr(run_command, "REPORT_DEFAULT", False)


@pytest.fixture(scope="session")
def legacy_harbour():
    """The robot-style harbour log (seed 0, ``--profile legacy``: 10 Hz odometry, 1 Hz IMU, 5 Hz scans),
    ``data/harbour.npz`` before issue 21, for the tests whose known answers are about that log."""
    from graphnav.sim.harbour import HarbourConfig, simulate_harbour

    return simulate_harbour(0, HarbourConfig.legacy())
