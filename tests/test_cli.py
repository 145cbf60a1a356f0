import json
import subprocess
import sys

import pytest
from _logfactory import every_record_log

from graphnav.io import save_log


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "graphnav", *args], capture_output=True, text=True)


def test_info_json_is_one_object(tmp_path):
    save_log(every_record_log(), tmp_path / "l.jsonl")
    r = _cli("info", str(tmp_path / "l.jsonl"), "--json")
    assert r.returncode == 0, r.stderr
    obj = json.loads(r.stdout)
    assert obj["records"] == {"scan": 20, "gnss": 20, "heading": 20, "odometry": 20, "imu": 20, "beacon": 20,
                              "truth": 20, "pose_prior": 1, "beacon_known": 2}
    assert obj["t0"] == 0.0 and obj["t1"] == 9.5 and obj["has_truth"] is True


def test_bad_input_exit_code_and_message(tmp_path):
    p = tmp_path / "bad.jsonl"
    p.write_text('{"t": 0, "type": "gnss", "x": 1, "y": "north", "sigma": 1}\n')
    r = _cli("info", str(p), "--json")
    assert r.returncode == 2
    assert f"{p}:1: field 'y'" in r.stderr and "Traceback" not in r.stderr
    err = json.loads(r.stdout)  # --json: the error is the one JSON object on stdout
    assert set(err) == {"error", "where"} and err["where"] == f"{p}, line 1, field 'y'"
    assert _cli("info", str(p)).stdout == ""  # without --json, stdout stays empty


def test_missing_file_is_an_input_error_naming_it(tmp_path):
    r = _cli("info", str(tmp_path / "absent.jsonl"), "--json")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert json.loads(r.stdout)["where"] == str(tmp_path / "absent.jsonl")


def test_run_dead_reckoning_writes_outputs(tmp_path):
    save_log(every_record_log(), tmp_path / "l.npz")
    r = _cli("run", str(tmp_path / "l.npz"), "--estimator", "dead-reckoning", "--out", str(tmp_path / "o"), "--json")
    assert r.returncode == 0, r.stderr
    obj = json.loads(r.stdout)
    for k in ("estimator", "steps", "ate_rmse_m", "ate_aligned_rmse_m", "rpe_rmse_m", "runtime_s", "step_ms_median",
              "heading_rmse_deg", "nees_mean"):
        assert k in obj
    assert obj["heading_rmse_deg"] >= 0 and (obj["nees_mean"] is None or obj["nees_mean"] >= 0)
    assert obj["steps"] == 20 and obj["anchor"] == "pose_prior"
    online = (tmp_path / "o" / "online.tum").read_text().splitlines()
    assert len([ln for ln in online if not ln.startswith("#")]) == 20
    assert (tmp_path / "o" / "trajectory.tum").exists() and (tmp_path / "o" / "trajectory.csv").exists()


def test_unknown_estimator_is_a_clear_error(tmp_path):
    save_log(every_record_log(), tmp_path / "l.jsonl")
    r = _cli("run", str(tmp_path / "l.jsonl"), "--estimator", "nope", "--json")
    assert r.returncode == 2 and "unknown estimator" in r.stderr
    assert "unknown estimator" in json.loads(r.stdout)["error"]


def test_main_loads_only_the_command_it_runs():
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from graphnav import cli\n"
        "p = cli.build_parser('beacons')\n"
        "loaded = sorted(m for m in sys.modules if m.startswith('graphnav.commands.') and '._' not in m)\n"
        "try:\n"
        "    cli.main(['--help'])\n"
        "except SystemExit:\n"
        "    pass\n"
        "print(loaded, 'gtsam' in sys.modules)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    *help_lines, last = r.stdout.strip().splitlines()
    assert last == "['graphnav.commands.beacons'] False"  # only the invoked command, no GTSAM for --help
    helptext = "\n".join(help_lines)
    from graphnav.cli import command_names

    names = command_names()
    assert {"beacons", "info", "run", "simulate", "live", "compare"} <= set(names)
    assert all(n in helptext for n in names)


def test_a_named_command_reads_no_other_commands_source(monkeypatch):
    """The placeholders' help (each command's source parsed, 0.04 s CPU) is read only when it can be shown: with no
    command named (``graphnav --help``) or a name that is none (the error lists the commands)."""
    import argparse

    from graphnav import cli

    want = {n: cli.command_help(n) for n in cli.command_names()}

    def helps(parser):
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        return {c.dest: c.help for c in sub._choices_actions}

    assert helps(cli.build_parser("")) == want
    assert helps(cli.build_parser("nope")) == want
    monkeypatch.setattr(cli, "command_help", lambda name: pytest.fail(f"read {name}'s source"))
    got = helps(cli.build_parser("info"))
    assert set(got) == set(want) and all(got[n] is None for n in got if n != "info")


def test_a_command_runs_openblas_on_one_thread_unless_the_environment_says():
    """cli.main sets OPENBLAS_NUM_THREADS=1 before a command imports numpy (its idle BLAS workers spun ~0.2 s of
    a 4 s run): numpy's and scipy's OpenBLAS then report one thread; a value in the environment wins."""
    import os
    import subprocess
    import sys

    code = (
        "import ctypes, glob, os, sys\n"
        "from graphnav import cli\n"
        "early = 'numpy' in sys.modules\n"
        "try:\n"
        "    cli.main(['run', '--help'])\n"
        "except SystemExit:\n"
        "    pass\n"
        "import numpy, scipy.sparse.linalg\n"
        "site = os.path.dirname(os.path.dirname(numpy.__file__))\n"
        "n = []\n"
        "for pat, fn in (('numpy.libs/libscipy_openblas64_*.so', 'scipy_openblas_get_num_threads64_'),\n"
        "                ('scipy.libs/libscipy_openblas-*.so', 'scipy_openblas_get_num_threads')):\n"
        "    paths = glob.glob(os.path.join(site, pat))\n"
        "    n.append(getattr(ctypes.CDLL(paths[0]), fn)() if paths else None)\n"
        "print(early, os.environ['OPENBLAS_NUM_THREADS'], *n, file=sys.stderr)\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    early, value, *threads = r.stderr.split("\n")[-2].split()
    assert early == "False" and value == "1"
    assert all(t in ("1", "None") for t in threads)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**env, "OPENBLAS_NUM_THREADS": "2"}, check=True)
    assert r.stderr.split("\n")[-2].split()[:2] == ["False", "2"]


def test_a_run_with_json_makes_no_tqdm_bar(tmp_path):
    """``--json`` (no progress bar): :class:`NoBar` answers for tqdm, which is not imported; the output is the
    run's JSON either way."""
    from _logfactory import every_record_log

    from graphnav.commands._common import NoBar, progress_bar

    path = tmp_path / "log.npz"
    save_log(every_record_log(), path)
    code = ("import sys\nfrom graphnav import cli\n"
            f"rc = cli.main(['run', {str(path)!r}, '-e', 'dead-reckoning', '--json'])\n"
            "print('tqdm' in sys.modules, file=sys.stderr)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stderr.strip().splitlines()[-1] == "False" and json.loads(r.stdout)["estimator"] == "dead-reckoning"

    class Args:
        json = True

    bar = progress_bar(Args(), total=12.5, unit="s")
    assert isinstance(bar, NoBar) and bar.disable and bar.total == 12.5 and bar.n == 0
    with bar as b:
        b.update(2.5)
        b.set_postfix_str("x")
    assert bar.n == 2.5
