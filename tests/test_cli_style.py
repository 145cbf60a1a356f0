"""Issue #17's one CLI style: one -O grammar ([ESTIMATOR.]KEY=VALUE), --seed, defaults that run,
--config FILE.toml on every command, run --list-options, plain-text --help with help on every flag,
progress on stderr silenced by --json/--quiet, and importing graphnav leaves matplotlib's backend
alone."""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from _logfactory import every_record_log
from hypothesis import given
from hypothesis import strategies as st

from graphnav.cli import build_parser, leaf_parsers, main
from graphnav.commands._common import options_by_estimator, options_for, parse_option, parse_options
from graphnav.io import save_log

REPO = Path(__file__).resolve().parents[1]
MARKUP = re.compile(r"``|:[a-z]+:`|\*\*")


def _all_parsers(p: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    out = [p]
    for a in p._actions:
        if isinstance(a, argparse._SubParsersAction):
            for sub in dict.fromkeys(a.choices.values()):
                out += _all_parsers(sub)
    return out


@pytest.fixture(scope="module")
def parser() -> argparse.ArgumentParser:
    return build_parser()  # every command imported and registered


def test_every_help_is_plain_text_and_every_flag_has_help(parser):
    parsers = _all_parsers(parser)
    assert len(parsers) > 15
    for p in parsers:
        text = p.format_help()
        assert not MARKUP.search(text), (p.prog, MARKUP.search(text).group(0))
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                assert all(c.help for c in a._choices_actions), p.prog
            elif a.dest != "help":
                assert a.help and a.help.strip(), (p.prog, a.option_strings or a.dest)
    for named in ("run", ""):
        lazy = build_parser(named).format_help()  # the commands listed without importing them
        assert not MARKUP.search(lazy)


def test_every_command_takes_config_and_quiet(parser):
    for leaf in leaf_parsers(parser):
        assert {"--config", "--quiet"} <= set(leaf._option_string_actions), leaf.prog


def test_beacons_search_flags_have_help(parser):
    text = subprocess.run([sys.executable, "-m", "graphnav", "beacons", "search", "--help"], capture_output=True,
                          text=True, check=True).stdout
    for flag in ("--linearize", "--beacon-init", "--p0-cross", "--w-second", "--seed", "--no-progress"):
        assert re.search(re.escape(flag) + r"[^\n]*\n?\s+\S", text), flag


@pytest.mark.parametrize(("item", "want"), [
    ("lag=10", (None, "lag", 10)),
    ("fuzzy-ukf.window=50", ("fuzzy-ukf", "window", 50)),
    ("scan-to-map.backend=gicp", ("scan-to-map", "backend", "gicp")),
    ("gate=null", (None, "gate", None)),
    ('icp={"tol": 1e-3}', (None, "icp", {"tol": 1e-3})),
    ("max-speed=0.5", (None, "max_speed", 0.5)),
    ("s2m-gicp.voxel=2.5", ("s2m-gicp", "voxel", 2.5)),
])
def test_one_option_grammar(item, want):
    assert parse_option(item) == want


@pytest.mark.parametrize("item", ["lag", "=3", ".lag=3", "lag x=3", "a.=3"])
def test_malformed_options_name_the_form(item):
    with pytest.raises(ValueError, match=r"\[ESTIMATOR\.\]KEY=VALUE"):
        parse_option(item)


def test_old_colon_form_names_the_new_one():
    with pytest.raises(ValueError, match=r"write fuzzy-ukf\.window=50"):
        parse_option("fuzzy-ukf:window=50")


@given(st.sampled_from(["isam2", "fuzzy-ukf", "scan-to-map", None]),
       st.from_regex(r"[a-z][a-z0-9_]{0,12}", fullmatch=True),
       st.one_of(st.integers(-10**6, 10**6), st.booleans(), st.none(), st.text("abcxyz_.", min_size=1, max_size=6),
                 st.floats(allow_nan=False, allow_infinity=False)))
def test_option_round_trip(scope, key, value):
    item = (f"{scope}." if scope else "") + f"{key}={json.dumps(value)}"
    assert parse_option(item) == (scope, key, value)


def test_scopes_per_command():
    ns = argparse.Namespace(option=["lag=3", "isam2.converge=none"], config_options={"ekf": {"gate": 0.5}})
    assert options_for(ns, "isam2") == {"lag": 3, "converge": "none"}  # the file's [options.ekf]: not for isam2
    with pytest.raises(ValueError, match="this command runs 'ekf'"):
        options_for(argparse.Namespace(option=["isam2.lag=3"]), "ekf")
    ns = argparse.Namespace(option=["ekf.gate=null", "isam2.lag=4"], config_options={"ekf": {"gate": 0.5}})
    assert options_by_estimator(ns) == {"ekf": {"gate": None}, "isam2": {"lag": 4}}
    with pytest.raises(ValueError, match=r"name one: ESTIMATOR\.lag"):
        options_by_estimator(argparse.Namespace(option=["lag=3"]))
    with pytest.raises(ValueError, match="no estimator to name"):
        parse_options(["isam2.lag=3"])


def test_section_paths_and_flat_names(tmp_path):
    """-O SECTION.KEY (the smoother's sections), ESTIMATOR.SECTION.KEY and TOML [options.SECTION] reach
    the field the flat name does; the later spelling wins; a typo names the closest."""
    from graphnav.estimators.options import check
    from graphnav.graph.smoother_config import SmootherConfig

    assert parse_option("isam2.gnss.gate=3") == ("isam2", "gnss.gate", 3)
    ns = argparse.Namespace(option=["gnss.gate=3", "isam2.keyframe.period=0.5", "scan.icp-gate=null"])
    opts = options_for(ns, "isam2")
    assert opts == {"gnss.gate": 3, "keyframe.period": 0.5, "scan.icp_gate": None}
    check("isam2", opts)
    cfg = SmootherConfig.from_options(opts)
    assert (cfg.gnss.gate, cfg.keyframe.period, cfg.scan.icp_gate) == (3, 0.5, None)
    for items, want in ((["gnss_gate=5", "gnss.gate=3"], 3), (["gnss.gate=3", "gnss_gate=5"], 5)):
        assert SmootherConfig.from_options(options_for(argparse.Namespace(option=items), "isam2")).gnss.gate == want
    with pytest.raises(ValueError, match=r"unknown isam2 option.*did you mean 'gnss.gate'"):
        check("isam2", options_for(argparse.Namespace(option=["gnss.gat=3"]), "isam2"))
    with pytest.raises(KeyError, match="unknown estimator 'isam3'"):  # not a section: an estimator's name
        options_for(argparse.Namespace(option=["isam3.lag=3"]), "isam2")
    toml = tmp_path / "c.toml"
    toml.write_text("[options.gnss]\ngate = 3.5\n[options.isam2.keyframe]\nperiod = 0.25\n")
    from graphnav.commands._common import config_defaults

    run_parser = next(p for p in leaf_parsers(build_parser()) if p.prog == "graphnav run")
    _, file_opts = config_defaults(run_parser, toml, argparse.Namespace(estimator="isam2", estimators=None))
    opts = options_for(argparse.Namespace(option=None, config_options=file_opts), "isam2")
    check("isam2", opts)
    cfg = SmootherConfig.from_options(opts)
    assert cfg.gnss.gate == 3.5 and cfg.keyframe.period == 0.25


def test_list_options_by_section(capsys):
    assert main(["run", "--list-options", "isam2"]) == 0
    text = capsys.readouterr().out
    assert re.search(r"^  \[gnss\] GNSS fixes", text, re.M)
    assert re.search(r"^  gate +4\.0 +float \| None  \(gnss_gate\)$", text, re.M)
    assert main(["run", "--list-options", "isam2", "--json"]) == 0
    opts = {o["name"]: o for o in _json(capsys)["options"]}
    assert opts["gnss_gate"]["path"] == "gnss.gate" and opts["gnss_gate"]["group"] == "gnss"
    assert opts["keyframe_period"]["path"] == "keyframe.period" and opts["unknown_beacons"]["path"] == "beacon.unknown"


def test_montecarlo_defaults_and_seed(parser):
    args = parser.parse_args(["montecarlo", "solent"])
    assert args.scenario == 2 and args.seed == 0 and args.runs == 50
    help_text = _all_parsers(parser)
    solent = next(p for p in help_text if p.prog.endswith("montecarlo solent"))
    assert "default 2" in solent.format_help() and "--seed0" not in solent.format_help()
    with pytest.raises(SystemExit):
        parser.parse_args(["montecarlo", "solent", "--seed0", "3"])


@pytest.fixture(scope="module")
def small_log(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("log") / "l.jsonl"
    save_log(every_record_log(), path)
    return path


def _json(capsys) -> dict:
    out = capsys.readouterr().out
    assert out.count("\n") == 1
    return json.loads(out)


def test_config_file_gives_options_and_the_command_line_wins(small_log, tmp_path, capsys):
    cfg = tmp_path / "run.toml"
    cfg.write_text(textwrap.dedent(f"""
        log = "{small_log}"
        estimator = "ekf"
        json = true
        [options]
        gate = 0.99
        [options.ekf]
        speed = true
        [options.isam2]
        lag = 5
    """))
    assert main(["run", "--config", str(cfg)]) == 0
    obj = _json(capsys)
    assert obj["estimator"] == "ekf" and obj["options"] == {"gate": 0.99, "speed": True}
    assert main(["run", "--config", str(cfg), "-O", "gate=null", "-e", "dead-reckoning", "--json"]) == 2  # no gate
    capsys.readouterr()
    assert main(["run", "--config", str(cfg), "-O", "ekf.gate=0.9"]) == 0
    assert _json(capsys)["options"] == {"gate": 0.9, "speed": True}


@pytest.mark.parametrize(("text", "match"), [
    ('estimatr = "ekf"\n', r"unknown key 'estimatr' for 'graphnav run'; known: .*estimator"),
    ("json = 3\n", r"--json: expected true or false"),
    ("out = [1]\n", r"--out: expected a single value"),
    ("max-speed = \n", r"not valid TOML"),
    (None, r"[Nn]o such file"),
])
def test_config_file_errors_name_the_file_and_key(small_log, tmp_path, capsys, text, match):
    cfg = tmp_path / "bad.toml"
    if text is not None:
        cfg.write_text(text)
    assert main(["run", str(small_log), "-e", "ekf", "--config", str(cfg), "--json"]) == 2
    err = json.loads(capsys.readouterr().out)
    assert err["where"] == str(cfg) and re.search(match, err["error"]), err


def test_config_file_for_a_sub_sub_command(tmp_path, parser):
    cfg = tmp_path / "mc.toml"
    cfg.write_text('runs = 3\nseed = 7\nscenario = 1\nscheduler = "serial"\n[options.fuzzy-ukf]\nwindow = 40\n')
    from graphnav.cli import _relax_required, _with_config

    argv = ["montecarlo", "solent", "--config", str(cfg), "--seed", "9"]
    p = build_parser("montecarlo")
    relaxed = _relax_required(p)
    args = _with_config(p, argv, p.parse_args(argv), relaxed)
    assert (args.runs, args.seed, args.scenario, args.scheduler) == (3, 9, 1, "serial")
    assert options_by_estimator(args) == {"fuzzy-ukf": {"window": 40}}


def test_list_options(capsys):
    assert main(["run", "--list-options", "isam2", "--json"]) == 0
    obj = _json(capsys)
    opts = {o["name"]: o for o in obj["options"]}
    from graphnav.graph.smoother_config import SmootherConfig

    assert opts["lag"]["default"] == SmootherConfig().optimizer.lag and "fixed-lag window" in opts["lag"]["meaning"]
    assert opts["converge"]["meaning"].endswith('"updates" (final_updates only), "none"')  # continuation lines
    assert "motion" in opts and "imu" in opts and "water_speed_sigma" in opts  # the Pose3 graph's options too
    assert main(["run", "--list-options", "ukf"]) == 0
    text = capsys.readouterr().out
    assert "r_gps_x" in text and "Table 2: 6" in text  # null: the records' sigma
    for name in ("ekf", "ekf-slam", "icp-dr", "scan-to-map", "fuzzy-ukf", "dead-reckoning"):
        assert main(["run", "--list-options", name, "--json"]) == 0
        assert _json(capsys)["estimator"] == name
    assert main(["run", "--list-options", "nope"]) == 2
    assert "known: " in capsys.readouterr().err


def test_progress_on_stderr_unless_json_or_quiet(small_log, capsys):
    assert main(["run", str(small_log), "-e", "ekf"]) == 0
    assert "%|" in capsys.readouterr().err
    for flag in ("--json", "--quiet"):
        assert main(["run", str(small_log), "-e", "ekf", flag]) == 0
        assert "%|" not in capsys.readouterr().err


def test_importing_graphnav_leaves_the_matplotlib_backend_alone():
    code = textwrap.dedent("""
        import importlib, pkgutil, sys
        import matplotlib
        matplotlib.use("svg")
        import graphnav
        failed = []
        for m in pkgutil.walk_packages(graphnav.__path__, "graphnav."):
            if m.name == "graphnav.__main__":  # (runs the CLI)
                continue
            try:
                importlib.import_module(m.name)
            except ImportError as exc:  # an optional extra not installed here
                failed.append(f"{m.name}: {exc}")
        import graphnav.evaluation.plots, graphnav.evaluation.report, graphnav.commands.icp  # noqa: E401
        print(matplotlib.get_backend(), matplotlib.rcParams["backend"], len(failed))
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    backend, rc_backend, _ = r.stdout.split()
    assert backend == "svg" and rc_backend == "svg", r.stdout


def test_config_file_gives_required_options(small_log, tmp_path, capsys):
    cfg = tmp_path / "cmp.toml"
    out = tmp_path / "cmp"
    cfg.write_text(f'out = "{out}"\nestimators = "ekf,dead-reckoning"\nno-icp-cache = true\n'
                   '[options.ekf]\ngate = 0.99\n')
    assert main(["compare", str(small_log), "--config", str(cfg), "--json"]) == 0
    obj = _json(capsys)
    assert obj["icp_cache_hits"] is None and (out / "report.md").exists()
    assert set(obj["estimators"]) == {"ekf", "dead-reckoning"} and obj["estimators"]["ekf"]["options"] == {"gate": 0.99}
    (tmp_path / "empty.toml").write_text("")
    with pytest.raises(SystemExit):  # --out is still required
        main(["compare", str(small_log), "--config", str(tmp_path / "empty.toml")])
    assert "required: --out" in capsys.readouterr().err
