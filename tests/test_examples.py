"""The scripts in examples/ run (with their quick options) and print what they promise.

Each script is loaded as a module and its ``main(argv)`` called in-process (the imports are shared,
so the whole file costs ~15 s CPU); one subprocess run checks the script entry point and its exit
code when the marina dataset is absent. The marina examples skip with the reason when
``../shared/data/icp_data_marina`` is not there.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"


def load(name: str):
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def run(name: str, argv: list[str], capsys) -> str:
    rc = load(name).main(argv)
    assert rc in (0, None)
    return capsys.readouterr().out


def table_rows(out: str) -> list[list[str]]:
    """Rows of the markdown tables in ``out`` (cells stripped; header and separator rows dropped)."""
    rows = []
    for line in out.splitlines():
        if line.startswith("|") and not line.startswith("|---") and not line.startswith("| rank"):
            rows.append([c.strip() for c in line.strip().strip("|").split("|")])
    return [r for r in rows if r and r[0] not in ("beacons", "estimator")]


def test_every_example_is_tested():
    tested = {"marina_graph", "online_smoothing", "marina_degraded_filters_vs_smoothers", "fairway_beacons",
              "solent_filters_vs_smoothers"}
    assert {p.stem for p in EXAMPLES.glob("*.py")} == tested


@pytest.mark.marina
def test_marina_graph_beats_chained_icp(marina_dir, capsys):
    out = run("marina_graph", [str(marina_dir), "--scans", "60", "--json"], capsys)
    d = json.loads(out)
    assert d["scans"] == 60 and d["factors"] == 1 + 59 + 2 * 60  # anchor, ICP chain, a GNSS + a compass per pose
    assert d["ate_rmse_m"] < 1.0  # 0.50 m measured; simulated GNSS is 3 m per axis
    assert d["ate_rmse_m"] < 0.5 * d["dead_reckoning_ate_rmse_m"]  # the fixes correct the ICP drift
    cov = np.array(d["last_pose_cov"])
    assert np.allclose(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) > 0)
    # tighter than one GNSS fix (3 m), looser than the ICP floor
    assert 0.05 < d["last_pose_sigma"][0] < 3.0 and 0.05 < d["last_pose_sigma"][1] < 3.0


@pytest.mark.marina
def test_marina_graph_text_output(marina_dir, capsys):
    out = run("marina_graph", [str(marina_dir), "--scans", "20", "--no-gnss"], capsys)
    assert "graph: 20 poses, 20 factors (19 ICP" in out
    assert re.search(r"ATE RMSE vs the reference: \d+\.\d{3} m", out)
    assert "marginal covariance" in out


def test_marina_graph_without_data_exits_2(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    p = subprocess.run([sys.executable, str(EXAMPLES / "marina_graph.py"), str(tmp_path / "nope")],
                       capture_output=True, text=True, cwd=REPO, env=env, timeout=120)
    assert p.returncode == 2 and p.stdout == ""
    assert "marina dataset not found" in p.stderr


def test_online_smoothing_prints_live_estimates(capsys):
    out = run("online_smoothing", ["--duration", "30", "--every", "10"], capsys)
    lines = [ln for ln in out.splitlines() if re.match(r"\s*\d+\.\d\s", ln)]
    m = re.search(r"(\d+) live estimates \(fixed-lag 10 s\); online ATE RMSE (\d+\.\d+) m", out)
    assert m and int(m.group(1)) in (150, 151)  # one per scan keyframe (5 Hz)
    assert len(lines) == -(-int(m.group(1)) // 10)  # every 10th printed
    t = [float(ln.split()[0]) for ln in lines]
    assert t == sorted(t) and t[0] == 0.0
    sog = [float(ln.split()[4]) for ln in lines]
    assert all(1.0 < v < 2.0 for v in sog)  # the simulated vessel runs at about 1.5 m/s
    assert float(m.group(2)) < 0.5  # 0.19 m measured (GNSS sigma 3 m; odometry, weighted ICP, beacons)


@pytest.mark.marina
def test_marina_degraded_table_ranks_the_smoother_first(marina_dir, capsys):
    out = run("marina_degraded_filters_vs_smoothers",
              [str(marina_dir), "-e", "isam2,ekf,scan-to-map", "--seconds", "60"], capsys)
    rows = table_rows(out)
    assert [r[1] for r in rows][0] == "isam2"
    assert {r[1] for r in rows} == {"isam2", "ekf", "scan-to-map"}
    ate = {r[1]: float(r[3]) for r in rows}
    assert ate["isam2"] < 0.7 * ate["ekf"]
    assert "vs 0.7 x best filter (ekf" in out and "met" in out


def test_fairway_charted_beacons_help_every_estimator(capsys):
    out = run("fairway_beacons", ["--steps", "60"], capsys)
    rows = table_rows(out)
    ate = {(r[0], r[1]): float(r[3]) for r in rows}
    assert set(ate) == {(c, e) for c in ("unknown", "charted")
                        for e in ("ekf-slam", "ekf-slam-paper", "isam2", "batch", "dead-reckoning")}
    for e in ("ekf-slam", "ekf-slam-paper", "isam2", "batch"):
        assert ate[("charted", e)] < ate[("unknown", e)]  # the chart removes the beacons' uncertainty
        assert ate[("unknown", e)] < 0.5 * ate[("unknown", "dead-reckoning")]
    assert ate[("charted", "dead-reckoning")] == ate[("unknown", "dead-reckoning")]  # beacons unused


def test_solent_quick(tmp_path, capsys):
    load("solent_filters_vs_smoothers").main(["--quick", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    for sc in (1, 2, 3):
        assert f"### Scenario {sc} (1 run, seed 0)" in out
        for f in (f"solent_rhat_s{sc}.png", f"solent_track_s{sc}.png"):
            assert (tmp_path / f).stat().st_size > 10_000
    rows = table_rows(out)
    assert {r[0] for r in rows} >= {"ukf", "fuzzy-ukf", "ekf", "isam2", "batch"}
    assert len(rows) == 3 * len({r[0] for r in rows})
    assert all(0.0 < float(r[1]) < 50.0 for r in rows)  # position RMSE [m]


# -- examples/config.toml (#23 item 6): every section, commented, loadable -------------------------------------

CONFIG = EXAMPLES / "config.toml"


def _config(path: Path, estimator: str = "isam2"):
    import argparse

    from graphnav.cli import build_parser, leaf_parsers
    from graphnav.commands._common import config_defaults

    run_parser = next(p for p in leaf_parsers(build_parser()) if p.prog == "graphnav run")
    return config_defaults(run_parser, path, argparse.Namespace(estimator=estimator, estimators=None))


def _all_uncommented(tmp_path: Path) -> Path:
    """The example with every commented ``# key = value`` line (one with a TOML value) switched on."""
    out = []
    for line in CONFIG.read_text().splitlines():
        m = re.match(r"^# ([a-z][a-z_-]*) = (.+?)(\s{2,}#.*)?$", line)
        out.append(f"{m.group(1)} = {m.group(2)}" if m and not m.group(2).startswith("...") else line)
    p = tmp_path / "all.toml"
    p.write_text("\n".join(out) + "\n")
    return p


def test_config_example_names_every_option_and_every_value_is_valid(tmp_path):
    """Every field of the graph's configs appears (set or commented); with every commented value
    switched on the file still loads, and each table builds its config (so no comment lies)."""
    from dataclasses import fields

    from graphnav.config import sections
    from graphnav.estimators.options import check
    from graphnav.graph.imu_chain import ImuConfig
    from graphnav.graph.loops import LoopConfig
    from graphnav.graph.mounts import parse_mounts
    from graphnav.graph.smoother_config import SmootherConfig
    from graphnav.scan.cloud_match import CloudMatchConfig
    from graphnav.scan.weighted_icp import IcpConfig

    text = CONFIG.read_text()
    tables = dict(re.findall(r"^\[options\.?([^\]]*)\][^\n]*\n(.*?)(?=^\[|\Z)", text, re.M | re.S))
    secs = sections(SmootherConfig)
    wanted = {"": [f.name for f in fields(SmootherConfig) if f.name not in ("solver", "imu", "mounts", *secs)],
              **{n: [f.name for f in fields(c) if f.name not in ("icp", "loop", "cloud")] for n, c in secs.items()},
              "imu": ImuConfig, "scan.icp": IcpConfig, "scan.loop": LoopConfig, "scan.cloud": CloudMatchConfig}
    for name, want in wanted.items():  # each field in its own table
        names = want if isinstance(want, list) else [f.name for f in fields(want)]
        missing = [n for n in names if not re.search(rf"^#? ?{n} =", tables.get(name, ""), re.M)]
        assert not missing, (f"examples/config.toml [options.{name}] lacks {missing}: regenerate it "
                             "(PYTHONPATH=. python tools/config_example.py)")
    for path in (CONFIG, _all_uncommented(tmp_path)):
        pairs, options = _config(path)
        assert {a.dest for a, _ in pairs} >= {"estimator", "out"}
        graph = {**options[None], **options.get("isam2", {})}
        cfg = SmootherConfig.from_options(graph)
        assert cfg.gnss.gate == 4.0 and cfg.robust.noise_estimation == "defaulted"  # the two set
        ImuConfig(**cfg.imu)
        IcpConfig(**cfg.scan.icp)
        LoopConfig(**cfg.scan.loop)
        CloudMatchConfig.from_options(dict(cfg.scan.cloud))
        assert set(parse_mounts(cfg.mounts)) >= {"gnss"}
        check("isam2", graph)
        check("ekf", options.get("ekf", {}))


def test_config_example_runs(tmp_path, capsys):
    from graphnav.cli import main

    log = tmp_path / "h.jsonl"
    assert main(["simulate", "harbour", "--duration", "4", "--lidar-hz", "0", "--out", str(log)]) == 0
    capsys.readouterr()
    assert main(["run", str(log), "--config", str(CONFIG), "--out", str(tmp_path / "o"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["estimator"] == "isam2" and (tmp_path / "o" / "trajectory.csv").is_file()
