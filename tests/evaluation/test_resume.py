"""Resume is keyed by everything that changes a result: every parameter of a task (its hash is in
its results line) and the code (the results file's header); other code is refused with the flag."""

from __future__ import annotations

import json
import logging
import tomllib
from pathlib import Path

import numpy as np
import pytest

import graphnav
from graphnav import cli
from graphnav.evaluation import sweep
from graphnav.evaluation.monte_carlo_trials import solent_trial
from graphnav.evaluation.sweep import code_version, load_done, read_header, run_sweep, task_key

REPO = Path(__file__).resolve().parents[2]


def search(capsys, results: Path | None, *extra: str) -> tuple[int, dict, str]:
    argv = ["beacons", "search", "--beacons", "1", "--limit", "100", "--chunk", "2", "--scheduler", "serial",
            "--no-progress", "--json", *extra]  # 40 layouts in 20 tasks
    if results is not None:
        argv += ["--results", str(results)]
    rc = cli.main(argv)
    cap = capsys.readouterr()
    return rc, json.loads(cap.out), cap.err


def same(a: dict, b: dict) -> bool:
    keys = ("configs", "best", "worst_mean_mxy", "mean_over_configs_mxy")
    return all(a[k] == b[k] for k in keys)


def test_a_changed_parameter_is_recomputed_not_taken_from_the_file(capsys, caplog, tmp_path):
    caplog.set_level(logging.INFO, logger="graphnav.sweep")
    r = tmp_path / "r.jsonl"
    assert search(capsys, r)[0] == 0
    caplog.clear()
    rc, resumed, _ = search(capsys, r, "--p0-beacon", "1.0")
    assert "20 result(s) computed with other parameters: not used" in caplog.text
    fresh = search(capsys, None, "--p0-beacon", "1.0")[1]
    assert rc == 0 and same(resumed, fresh), (resumed["best"], fresh["best"])
    # and back: both parameter sets are in the file now, so this run computes nothing new
    lines = len(r.read_text().splitlines())
    caplog.clear()
    rc, again, _ = search(capsys, r)
    assert rc == 0 and "resuming: 20 of 20 tasks" in caplog.text and len(r.read_text().splitlines()) == lines


@pytest.mark.parametrize("extra", [("--limit", "50"), ("--limit", "150"), ("--beacons", "2", "--limit", "400"),
                                   ("--chunk", "7")])
def test_changing_limit_beacons_or_chunk_resumes_without_error(capsys, tmp_path, extra):
    r = tmp_path / "r.jsonl"
    assert search(capsys, r)[0] == 0
    rc, resumed, _ = search(capsys, r, *extra)
    assert rc == 0 and same(resumed, search(capsys, None, *extra)[1])


def test_results_of_other_code_are_refused_with_the_flag_to_use(capsys, caplog, tmp_path, monkeypatch):
    caplog.set_level(logging.INFO, logger="graphnav.sweep")
    r = tmp_path / "r.jsonl"
    assert search(capsys, r)[0] == 0
    assert read_header(r)["code"] == code_version()
    monkeypatch.setattr(sweep, "code_version", lambda: "0.1.0+0123456789ab")  # as if the sources changed
    rc, obj, err = search(capsys, r)
    assert rc == 2 and obj["where"] == str(r) and "--overwrite" in obj["error"] and "0.1.0+0123456789ab" in err
    caplog.clear()
    rc, obj, err = search(capsys, r, "--overwrite")
    assert rc == 0 and read_header(r)["code"] == "0.1.0+0123456789ab" and "resuming" not in caplog.text
    assert len(load_done(r)) == 20


def test_a_results_file_without_header_is_refused(capsys, tmp_path):
    r = tmp_path / "r.jsonl"
    r.write_text('{"key": "0", "result": {"scores": [[1.0, 1.0, 1.0]]}}\n')  # the format before the header
    rc, obj, _ = search(capsys, r)
    assert rc == 2 and "no header" in obj["error"] and "--overwrite" in obj["error"]


def test_task_key_covers_every_parameter():
    t = {"key": "0", "layouts": [[1.0, 2.0]], "choices": {"p0_beacon": 1e6}, "fn": solent_trial}
    k = task_key(t)
    assert k.startswith("0#") and task_key(dict(t)) == k
    assert task_key({**t, "choices": {"p0_beacon": 1.0}}) != k
    assert task_key({**t, "layouts": [[1.0, 2.0000000001]]}) != k
    assert task_key({**t, "layouts": np.array([[1.0, 2.0]])}) == k  # numpy and lists alike
    assert task_key({**t, "key": "1"}).split("#")[1] == k.split("#")[1]


def test_montecarlo_keeps_finished_runs_when_more_are_asked(tmp_path):
    """The Monte Carlo runner's tasks carry their seed and options: 3 runs, then 4, computes one more."""
    out = tmp_path / "mc.jsonl"
    calls = []

    def trial(task):
        calls.append(task["kwargs"]["seed"])
        return {"seed": task["kwargs"]["seed"]}

    mk = lambda n: [{"key": f"s{i}", "fn": "solent", "kwargs": {"seed": i}} for i in range(n)]  # noqa: E731
    run_sweep(trial, mk(3), out=out, scheduler="serial", progress=False)
    assert run_sweep(trial, mk(4), out=out, scheduler="serial", progress=False) == [{"seed": i} for i in range(4)]
    assert calls == [0, 1, 2, 3]


def test_version_is_the_packages():
    meta = tomllib.loads((REPO / "pyproject.toml").read_text())
    assert graphnav.__version__ == meta["project"]["version"]
    assert code_version().startswith(graphnav.__version__ + "+")
