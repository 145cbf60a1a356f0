"""The Dask sweep runner: a real LocalCluster equals the serial run exactly; resume skips work."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from graphnav.beacons.layout import chunk_tasks, grid, score_chunk
from graphnav.evaluation.sweep import CLUSTER_STARTUP_S, load_done, resolve_scheduler, run_sweep, task_key


def record_call(task: dict) -> dict:
    """A task that leaves a trace of every call (to prove finished work is not redone)."""
    with open(task["trace"], "a") as f:
        f.write(task["key"] + "\n")
    return {"square": task["n"] ** 2, "third": task["n"] / 3.0}


def traced_score(task: dict) -> dict:
    with open(task["trace"], "a") as f:
        f.write(task["key"] + "\n")
    return score_chunk(task)


def test_local_cluster_equals_serial_exactly_and_resumes(tmp_path: Path):
    trace, out = tmp_path / "trace.txt", tmp_path / "results.jsonl"
    tasks = chunk_tasks(grid(1)[::200], 4, extra={"trace": str(trace)})   # 20 layouts in 5 tasks
    serial = run_sweep(score_chunk, tasks, scheduler="serial", progress=False)
    direct = np.concatenate([score_chunk(t)["scores"] for t in tasks])
    assert np.array_equal(np.concatenate([r["scores"] for r in serial]), direct)
    # two tasks are already on disk (an interrupted sweep): the cluster computes only the other three
    run_sweep(score_chunk, tasks[:2], out=out, scheduler="serial", progress=False)
    dask = run_sweep(traced_score, tasks, out=out, workers=2, progress=False)
    assert dask == serial
    assert sorted(trace.read_text().split()) == sorted(t["key"] for t in tasks[2:])
    assert load_done(out) == {task_key(t): r for t, r in zip(tasks, serial, strict=True)}


def test_resume_skips_finished_tasks(tmp_path: Path):
    trace, out = tmp_path / "trace.txt", tmp_path / "results.jsonl"
    tasks = [{"key": f"t{n}", "n": n, "trace": str(trace)} for n in range(8)]
    first = run_sweep(record_call, tasks[:5], out=out, scheduler="serial", progress=False)
    with open(out, "a") as f:
        f.write('{"key": "t7", "res')          # torn line of an interrupted write: ignored
    full = run_sweep(record_call, tasks, out=out, scheduler="serial", progress=False)
    calls = trace.read_text().split()
    assert calls == [f"t{n}" for n in range(5)] + ["t5", "t6", "t7"]
    assert full[:5] == first
    assert full == [{"square": n * n, "third": n / 3.0} for n in range(8)]
    assert set(load_done(out)) == {task_key(t) for t in tasks}
    # a third run computes nothing
    run_sweep(record_call, tasks, out=out, scheduler="serial", progress=False)
    assert trace.read_text().split() == calls


def test_keys_must_be_unique_and_present():
    with pytest.raises(ValueError):
        run_sweep(record_call, [{"key": "a"}, {"key": "a"}], scheduler="serial")
    with pytest.raises(ValueError):
        run_sweep(record_call, [{"n": 1}], scheduler="serial")


def test_auto_scheduler_runs_in_process_unless_a_cluster_pays_off():
    cheap, dear = CLUSTER_STARTUP_S / 100, CLUSTER_STARTUP_S
    assert resolve_scheduler("auto", 40, cheap, 2) == "serial"       # 1.2 s of work: a cluster costs more
    assert resolve_scheduler("auto", 40, dear, 2) == "local"         # 120 s of work: it saves ~60 s
    assert resolve_scheduler("auto", 1, 1e3, 2) == "serial"          # one task cannot run in parallel
    assert resolve_scheduler("auto", 40, dear, 1) == "serial"        # nor on one worker
    assert resolve_scheduler("auto", 40, None, 2) == "local"         # unknown cost: the cluster
    assert resolve_scheduler(None, 40, cheap, 2) == "local"          # the library default is unchanged
    assert resolve_scheduler("tcp://h:8786", 40, cheap, 2) == "tcp://h:8786"
    # the decision counts only the tasks still to do (a resumed sweep)
    assert resolve_scheduler("auto", 2, dear, 2) == "serial"


def test_beacons_search_json_keys(capsys, tmp_path):
    from graphnav.cli import main

    assert main(["beacons", "search", "--beacons", "1", "--limit", "100", "--chunk", "8",
                 "--no-progress", "--json", "--results", str(tmp_path / "r.jsonl")]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"beacons", "configs", "criterion", "best", "worst_mean_mxy", "mean_over_configs_mxy",
                        "wall_s", "configs_per_s", "scheduler", "backend"}
    assert set(out["best"]) == {"layout", "mean_mxy", "mean_mx", "mean_my"}
    assert out["configs"] == 40 and out["criterion"] == "ekf"
    assert out["scheduler"] == "serial"                                # auto: 5 small tasks run in-process
    assert out["configs_per_s"] == pytest.approx(40 / out["wall_s"])
    assert out["best"]["mean_mxy"] <= out["mean_over_configs_mxy"] <= out["worst_mean_mxy"]
    assert os.path.getsize(tmp_path / "r.jsonl") > 0
