"""Every capture of the real-receiver NMEA corpus (../shared/data/nmea_corpus, GPSD's regression
captures; not ours, skipped when absent) gives a result or a clean error through the CLI, strict and
lenient: exit 0 or 2 with one JSON object, never 1 (an internal error) or a traceback.
``benchmarks/nmea_corpus.py`` prints the full table and the isam2 comparison."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from graphnav import cli

REPO = Path(__file__).resolve().parents[2]
CORPUS = next((c for c in (REPO.parent / "shared" / "data" / "nmea_corpus",
                           REPO.parent.parent / "shared" / "data" / "nmea_corpus") if c.is_dir()), None)
FILES = sorted(p for p in CORPUS.iterdir() if p.is_file() and p.name != "README.md") if CORPUS else []

pytestmark = pytest.mark.skipif(CORPUS is None, reason="nmea_corpus not found at ../shared/data/nmea_corpus "
                                                       "(real captures, not in the repository)")


def test_corpus_is_there():
    assert len(FILES) >= 70


@pytest.mark.parametrize("lenient", [False, True], ids=["strict", "lenient"])
def test_every_file_gives_a_result_or_a_clean_error(capsys, lenient):
    bad = []
    parsed = 0
    for f in FILES:
        rc = cli.main(["info", str(f), "--json"] + (["--lenient"] if lenient else []))
        out = capsys.readouterr().out.strip().splitlines()
        obj = json.loads(out[0]) if len(out) == 1 else None
        if rc == 0 and obj is not None and "records" in obj:
            parsed += 1
        elif not (rc == 2 and obj is not None and set(obj) == {"error", "where"}):
            bad.append((f.name, rc, out[:2]))
    assert not bad, bad
    if lenient:  # lenient reads every capture (binary and AIS files give empty or partial logs)
        assert parsed == len(FILES)


@pytest.mark.parametrize("name", ["cat-ms352.log", "garmin18x-bin.log", "ais-nmea.log", "ac12.log"])
def test_cli_process_never_prints_a_traceback(name):
    f = CORPUS / name
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    p = subprocess.run([sys.executable, "-m", "graphnav", "info", str(f), "--json"], capture_output=True, text=True,
                       env=env, timeout=300, cwd=str(REPO))
    assert p.returncode in (0, 2) and "Traceback" not in p.stderr
    assert len(p.stdout.strip().splitlines()) == 1
