"""The report to send a colleague: report.html self-contained (checked in a real headless browser when
Debian's chromium is installed), provenance and warnings in the text, skipped estimators as rows,
truth.tum beside the estimates so evo reproduces the ATE."""

from __future__ import annotations

import base64
import contextlib
import hashlib
import io
import json
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest
from _compare_cli import run_compare
from _polyworld import synthetic_log

from graphnav import estimators
from graphnav.cli import main
from graphnav.estimators import EstimatorSpec, RunResult
from graphnav.evaluation.comparison import Entry, compare
from graphnav.evaluation.report import warnings
from graphnav.io import save_log
from graphnav.log import NavLog
from graphnav.trajectory import Trajectory


def _boom(log, *, on_estimate=None, **options):
    raise RuntimeError("deliberate failure")


def _flagging(log, *, on_estimate=None, **options):
    """Truth plus 0.2 m in y with covariances, reporting flagged scan matches as a smoother does."""
    tr = log.truth()
    cov = np.tile(np.diag([0.04, 0.04, 1e-4]), (len(tr), 1, 1))
    return RunResult(Trajectory(tr.t, tr.poses + [0.0, 0.2, 0.0], cov), info={"icp_failed": 7, "icp_pairs": 29})


FAKES = {"zz-boom": EstimatorSpec(_boom, lambda log: None, "always fails", "filter"),
         "flagging": EstimatorSpec(_flagging, lambda log: None, "truth + 0.2 m, flags 7 of 29 matches", "smoother")}
NAMES = "dead-reckoning,flagging,zz-boom,ukf"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    rc, stdout, out, path = run_compare(synthetic_log(30), tmp_path_factory.mktemp("rep"), FAKES, ["-e", NAMES])
    assert rc == 0
    return json.loads(stdout), out, path


def test_skipped_estimator_is_a_row_saying_why(run):
    obj, out, _ = run
    est = obj["estimators"]
    assert est["ukf"]["skipped"] == "needs imu records" and est["ukf"]["nees_mean"] is None
    assert "error" not in est["ukf"] and "deliberate failure" in est["zz-boom"]["error"]
    md = (out / "report.md").read_text()
    row = next(line for line in md.splitlines() if line.startswith("| – | ukf |"))
    assert row.rstrip(" |").endswith("not run: needs imu records")
    html = (out / "report.html").read_text()
    assert re.search(r"<td>ukf</td><td>filter</td><td class=\"note\" colspan=\"\d+\">not run: needs imu records", html)


def test_compare_without_names_keeps_the_estimators_it_cannot_run():
    log = synthetic_log(12).without(lambda r: r.kind == "scan")
    entries = compare(log, None, options={})  # every registered estimator: run or skipped
    assert [e.name for e in entries] == estimators.names()
    skipped = {e.name: e.skipped for e in entries if e.skipped}
    assert set(skipped) == set(estimators.names()) - set(estimators.runnable(log))
    assert skipped["scan-to-map"] and skipped["ukf"] == "needs imu records"
    assert all(e.result is None for e in entries if e.skipped)


def test_warnings_are_stated_in_the_text(run):
    _, out, _ = run
    for f in ("report.md", "report.html"):
        text = (out / f).read_text()
        assert "7 of 29 (24.1 %) weighted-ICP matches flagged" in text
        assert "was not run: needs imu records" in text
        assert "failed:" in text and "deliberate failure" in text


def test_warnings_name_every_counter():
    res = RunResult(Trajectory([0.0], [[0, 0, 0]]), info={"icp_failed": 1970, "icp_pairs": 3089, "rejected": 0,
                                                          "new_thing_rejected": 3, "forced": True})
    w = warnings([Entry("isam2", kind="smoother", result=res, summary={})], NavLog([]))
    assert w[0] == ("**isam2**: 1,970 of 3,089 (63.8 %) weighted-ICP matches flagged (degenerate geometry, too "
                    "few points or inliers, or a step beyond the limit) and left out.")
    assert "**isam2**: `new_thing_rejected` = 3." in w
    assert not any("gate" in s for s in w)  # 0 rejected, and a bool is not a count
    assert w[-1].startswith("The log has no truth")


def test_provenance_header(run):
    _, out, path = run
    sha = hashlib.sha256(path.read_bytes()).hexdigest()
    for f in ("report.md", "report.html"):
        text = (out / f).read_text()
        assert sha in text and f"{path.stat().st_size:,} bytes" in text
        assert f"graphnav compare {path} --out {out} --json -e {NAMES}" in text
        assert re.search(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d UTC", text)
        assert "graphnav" in text and str(path) in text


def test_html_is_self_contained(run):
    """No network: figures inlined as data: URIs, no script, no external style sheet, font or link."""
    _, out, _ = run
    html = (out / "report.html").read_text()
    assert not re.search(r"https?://", html)
    assert not re.search(r"<script|<link|<iframe|<object|<embed|@import|url\(", html, re.I)
    refs = re.findall(r"""(?:src|href)\s*=\s*["']?([^"'\s>]+)""", html, re.I)
    assert refs and all(r.startswith("data:image/png;base64,") for r in refs)
    assert "default-src 'none'" in html  # the page's CSP forbids loading anything else
    md = (out / "report.md").read_text()
    figures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert len(figures) >= 8 and len(refs) == len(figures)
    for f, uri in zip(figures, refs, strict=True):
        assert base64.b64decode(uri.split(",", 1)[1]) == (out / f).read_bytes()


def _ape(out: Path, name: str) -> float:
    """evo_ape tum truth.tum NAME.tum, as the command line does it (evo's defaults: t_max_diff 0.01 s)."""
    from evo.core.metrics import PoseRelation
    from evo.main_ape import ape
    from evo.tools import file_interface

    ref = file_interface.read_tum_trajectory_file(str(out / "truth.tum"))
    est = file_interface.read_tum_trajectory_file(str(out / f"{name}.tum"))
    ref, est = ref.sync_with(est, max_diff=0.01)
    return ape(ref, est, pose_relation=PoseRelation.translation_part).stats["rmse"]


def test_truth_tum_lets_evo_reproduce_the_ate(run):
    obj, out, _ = run
    for name in ("dead-reckoning", "flagging"):
        assert _ape(out, name) == pytest.approx(obj["estimators"][name]["ate_rmse_m"], abs=1e-4)
    assert obj["estimators"]["flagging"]["ate_rmse_m"] == pytest.approx(0.2)


def test_run_writes_truth_tum_beside_the_estimate(tmp_path):
    save_log(synthetic_log(20), tmp_path / "l.jsonl")
    out = tmp_path / "o"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["run", str(tmp_path / "l.jsonl"), "-e", "dead-reckoning", "--out", str(out), "--json"]) == 0
    obj = json.loads(buf.getvalue())
    (out / "dead-reckoning.tum").write_bytes((out / "trajectory.tum").read_bytes())
    assert _ape(out, "dead-reckoning") == pytest.approx(obj["ate_rmse_m"], abs=1e-4)


# -- a real browser ---------------------------------------------------------------------------------

CHROMIUM = shutil.which("chromium")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", "--hide-scrollbars"]


def _chromium(*args: str) -> subprocess.CompletedProcess:
    with tempfile.TemporaryDirectory() as profile:
        return subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={profile}", *args], capture_output=True,
                              text=True, timeout=180)


def _colours(png: Path) -> tuple[int, float]:
    """Distinct colours in a screenshot, and the fraction of pixels that are not white."""
    from PIL import Image

    with Image.open(png) as im:
        rgb = im.convert("RGB")
        counts = rgb.getcolors(maxcolors=rgb.width * rgb.height)  # counted in C: no large arrays
    inked = sum(n for n, c in counts if min(c) < 250)
    return len(counts), inked / (rgb.width * rgb.height)


@pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed (.ci/run installs it as root; "
                                             "apt-get install chromium)")
def test_report_renders_in_headless_chromium(run, tmp_path):
    obj, out, _ = run
    url = (out / "report.html").resolve().as_uri()
    dom = _chromium("--dump-dom", url)
    assert dom.returncode == 0, dom.stderr[-2000:]
    page = dom.stdout
    # the browser's DOM: the provenance and results tables with a row per estimator, the images
    assert page.count("<table") >= 2
    for name in obj["estimators"]:
        assert re.search(rf"<tr><td>[^<]*</td><td>{re.escape(name)}</td>", page), name
    assert page.count('<img src="data:image/png;base64,') >= 8
    shot = tmp_path / "shot.png"
    r = _chromium("--window-size=1400,5000", f"--screenshot={shot}", url)
    assert r.returncode == 0 and shot.exists(), r.stderr[-2000:]
    colours, inked = _colours(shot)
    assert inked > 0.05  # not blank
    # the figures are drawn: the same page without its images renders with far fewer colours
    bare = tmp_path / "bare.html"
    bare.write_text(re.sub(r'<img src="data:[^"]*"', '<img src=""', (out / "report.html").read_text()))
    shot2 = tmp_path / "bare.png"
    r = _chromium("--window-size=1400,5000", f"--screenshot={shot2}", bare.resolve().as_uri())
    assert r.returncode == 0, r.stderr[-2000:]
    colours_bare, _ = _colours(shot2)
    assert colours > 3 * colours_bare and colours > 1000, (colours, colours_bare)
