"""Failures the environment causes (a port in use, an address that is not ours, an output path of the
wrong kind, an unreachable scheduler, Ctrl-C) end in one ``graphnav: error:`` line naming the
address or path, exit 2 (130 for Ctrl-C), never a traceback."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from graphnav import cli
from graphnav.evaluation.sweep import SCHEDULER_TIMEOUT_S, load_done

REPO = Path(__file__).resolve().parents[1]


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def call(capsys, *argv: str) -> tuple[int, str, dict | None]:
    """``graphnav ARGV --json`` in this process: (exit code, stderr, the JSON object on stdout)."""
    rc = cli.main([*argv, "--json"])
    cap = capsys.readouterr()
    lines = [ln for ln in cap.out.splitlines() if ln.strip()]
    return rc, cap.err, json.loads(lines[-1]) if lines else None


def tiny_log(tmp_path: Path) -> Path:
    p = tmp_path / "tiny.jsonl"
    recs = [{"t": 0.0, "type": "pose_prior", "x": 0, "y": 0, "yaw": 0, "sigma_xy": 1, "sigma_yaw": 0.1}]
    for k in range(1, 30):
        t = 0.1 * k
        recs += [{"t": t, "type": "odometry", "v": 1.0, "w": 0.0},
                 {"t": t, "type": "truth", "x": t, "y": 0.0, "yaw": 0.0}]
    p.write_text("".join(json.dumps(r) + "\n" for r in recs))
    return p


def test_live_port_in_use_names_the_address(capsys):
    port = free_port()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as blocker:  # no SO_REUSEADDR: exclusive
        blocker.bind(("127.0.0.1", port))
        rc, err, obj = call(capsys, "live", "--nmea", f"udp://127.0.0.1:{port}", "--duration", "1")
    addr = f"udp://127.0.0.1:{port}"
    assert rc == 2
    assert err.startswith("graphnav: error:") and addr in err and "Traceback" not in err
    assert obj == {"error": obj["error"], "where": addr} and "in use" in obj["error"]


@pytest.mark.parametrize("url, says", [
    ("udp://192.0.2.1:{port}", "cannot listen"),            # TEST-NET-1: not an address of this machine
    ("udp://127.0.0.1:99999", "port out of range"),
    ("udp://no-such-host.invalid:{port}", "cannot resolve"),
    ("serial:///dev/ttyUSB0", "expected udp://HOST:PORT"),
])
def test_live_bad_bind_address_names_it(capsys, url, says):
    url = url.format(port=free_port())
    rc, err, obj = call(capsys, "live", "--nmea", url, "--duration", "1")
    assert rc == 2 and err.startswith("graphnav: error:") and url in err, err
    assert obj["where"] == url and says in obj["error"]


def test_live_publish_address_that_does_not_resolve(capsys):
    url = "udp://no-such-host.invalid:10111"
    rc, err, obj = call(capsys, "live", "--nmea", f"udp://127.0.0.1:{free_port()}", "--publish", url,
                        "--duration", "1")
    assert rc == 2 and obj["where"] == url


@pytest.mark.parametrize("command", ["run", "compare", "icp", "live"])
def test_out_pointing_at_a_file_is_a_clean_error(capsys, tmp_path, command):
    log = tiny_log(tmp_path)
    target = tmp_path / "a-file"
    target.write_text("precious\n")
    argv = {"run": ["run", str(log), "-e", "dead-reckoning"], "compare": ["compare", str(log)],
            "icp": ["icp", str(log)], "live": ["live", "--nmea", f"udp://127.0.0.1:{free_port()}",
                                                "--duration", "0.5"]}[command]
    rc, err, obj = call(capsys, *argv, "--out", str(target))
    assert rc == 2 and "not a directory" in err and str(target) in err, err
    assert obj["where"] == str(target)
    assert target.read_text() == "precious\n"  # untouched


def test_results_pointing_at_a_directory_is_a_clean_error(capsys, tmp_path):
    rc, err, obj = call(capsys, "beacons", "search", "--beacons", "1", "--limit", "100", "--scheduler",
                        "serial", "--no-progress", "--results", str(tmp_path))
    assert rc == 2 and "results file must be a file" in err and obj["where"] == str(tmp_path)


def test_unreachable_scheduler_is_a_clean_error_after_the_short_timeout(capsys):
    addr = f"tcp://127.0.0.1:{free_port(socket.SOCK_STREAM)}"  # nothing listens there
    rc, err, obj = call(capsys, "beacons", "search", "--beacons", "1", "--limit", "100", "--scheduler", addr,
                        "--no-progress")
    assert rc == 2 and obj["where"] == addr
    assert f"within {SCHEDULER_TIMEOUT_S:g} s" in obj["error"] and "Traceback" not in err
    assert SCHEDULER_TIMEOUT_S <= 10


def test_not_a_scheduler_address(capsys):
    rc, err, obj = call(capsys, "beacons", "search", "--beacons", "1", "--limit", "100", "--scheduler", "nowhere",
                        "--no-progress")
    assert rc == 2 and obj["where"] == "nowhere" and "not a Dask scheduler address" in obj["error"]


def test_ctrl_c_during_beacons_search_exits_130_keeps_results_and_resumes(tmp_path):
    """SIGINT to the whole process group (what Ctrl-C does) while the LocalCluster works: exit 130,
    one line, no worker tracebacks; the finished chunks stay in --results and the same command resumes."""
    results = tmp_path / "r.jsonl"
    argv = [sys.executable, "-m", "graphnav", "beacons", "search", "--beacons", "1", "--chunk", "1",
            "--results", str(results), "--no-progress"]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    # the child starts with SIGINT at its default, as from a shell (an ignored SIGINT is inherited, and Python
    # then installs no KeyboardInterrupt handler: whatever left it ignored in this process must not decide)
    p = subprocess.Popen([*argv, "--scheduler", "local", "--workers", "2"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=env, start_new_session=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and p.poll() is None and not (results.exists() and load_done(results)):
            time.sleep(0.05)
        time.sleep(0.5)
        assert p.poll() is None, "the search ended before it could be interrupted"
        os.killpg(p.pid, signal.SIGINT)
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    assert p.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert err.strip().splitlines()[-1] == "graphnav: error: interrupted"
    kept = len(load_done(results))
    assert 0 < kept < 4000
    r = subprocess.run([*argv, "--scheduler", "serial", "--json"], capture_output=True, text=True, env=env,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    assert f"resuming: {kept} of 4000 tasks" in r.stderr
    assert json.loads(r.stdout)["configs"] == 4000
