"""Issue #27 (1, 2, 6, 7, 9): option values outside their declared type or range are exit 2 naming the
option and the range, before any work and before any C++ library sees them; ``--config`` files that
are not UTF-8 TOML or nest without bound are exit 2 naming the file; registrations that found nothing
say so (``converged`` false with a reason) the same for every method."""

from __future__ import annotations

import io
import json
import subprocess
import sys
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np
import pytest

from graphnav.cli import main
from graphnav.config import OptionError, Range, number
from graphnav.errors import LogError
from graphnav.estimators.options import check
from graphnav.scan.cloud_match import CloudMatchConfig
from graphnav.scan.register3d import METHODS, Reg3Params, register

REPO = Path(__file__).resolve().parents[1]


def cli(*argv: str) -> tuple[int, dict | None, str]:
    """``graphnav ARGV --json`` in this process: exit code, the one JSON object, stderr."""
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = main([*argv, "--json"])
    text = out.getvalue().strip()
    return code, (json.loads(text) if text else None), err.getvalue()


def cloud_file(path: Path, pts: np.ndarray) -> Path:
    p = np.zeros((len(pts), 4), np.float32)
    p[:, :3] = pts
    p.tofile(path)
    return path


@pytest.fixture(scope="module")
def clouds(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("clouds")
    rng = np.random.default_rng(0)
    a = rng.uniform(-10, 10, (800, 3))
    cloud_file(d / "a.bin", a)
    cloud_file(d / "b.bin", a + [0.1, 0.0, 0.0])
    return d


# -- (1) signals: no value reaches small_gicp/open3d unchecked --------------------------------------------

@pytest.mark.parametrize("option", ["threads=0", "knn=0"])
def test_register_bad_native_option_is_exit_2_not_a_signal(clouds, option):
    """Before: ``threads=0`` segfaulted (139), ``knn=0`` aborted (134), with no JSON."""
    r = subprocess.run([sys.executable, "-m", "graphnav", "register", str(clouds / "a.bin"), str(clouds / "b.bin"),
                        "-O", option, "--json"], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert r.returncode == 2, r.stderr
    obj = json.loads(r.stdout)
    assert obj["where"] == f"option {option.split('=')[0]}" and "must be an integer >= 1" in obj["error"]


@pytest.mark.parametrize(("option", "words"), [
    ("threads=100000", "<= 256"), ("knn=1.5", "an integer"), ("knn=true", "an integer"), ("eps_trans=NaN", "> 0"),
    ("eps_rot=-1", "> 0"), ("max_corr=0", "> 0"), ("voxel=-1", ">= 0"), ("max_iter=0", ">= 1"),
    ("neighbors=5", "1, 7 or 27"), ("resolution=Infinity", "finite"), ("voxel=[1,2]", "finite number"),
])
def test_register_options_checked_against_their_range(clouds, option, words):
    code, obj, err = cli("register", str(clouds / "a.bin"), str(clouds / "b.bin"), "-O", option)
    assert code == 2 and obj["where"] == f"option {option.split('=')[0]}" and words in obj["error"], (obj, err)


@pytest.mark.parametrize("method", ["gicp", "o3d-p2plane"])
def test_register_knn_zero_any_method(clouds, method):
    code, obj, _ = cli("register", str(clouds / "a.bin"), str(clouds / "b.bin"), "--method", method, "-O", "knn=0")
    assert code == 2 and obj["where"] == "option knn"


def test_reg3params_and_cloud_config_check_on_construction():
    with pytest.raises(OptionError, match="threads"):
        Reg3Params(threads=0)
    assert Reg3Params(knn=12.0).knn == 12 and isinstance(Reg3Params(knn=12.0).knn, int)
    with pytest.raises(OptionError, match="cloud option knn"):
        CloudMatchConfig.from_options({"knn": 0})
    with pytest.raises(OptionError, match="cloud option threads"):
        CloudMatchConfig(threads=-1)
    with pytest.raises(OptionError, match="max_range"):
        CloudMatchConfig(min_range=10.0, max_range=5.0)
    with pytest.raises(OptionError, match="option cloud"):
        CloudMatchConfig.from_options([1, 2])


def test_number_names_the_option_and_range():
    with pytest.raises(OptionError) as ei:
        number("--laps", -3, Range(lo=1, hi=12, integer=True))
    assert ei.value.where == "--laps" and "an integer >= 1 and <= 12" in ei.value.message and "-3" in ei.value.message
    assert number("x", None, Range(optional=True)) is None
    for bad in (float("nan"), float("inf"), True, "1", [1], {"a": 1}):
        with pytest.raises(OptionError):
            number("x", bad, Range())


# -- (6, 7) estimator option values: NaN, Infinity, true, lists, tables, null, negative ------------------

@pytest.mark.parametrize("value", [float("nan"), float("inf"), True, [1, 2], {"a": 1}, None, -5, "ten"])
def test_estimator_numeric_option_of_the_wrong_kind(value):
    with pytest.raises(OptionError) as ei:
        check("isam2", {"lag": value})
    assert ei.value.where == "option lag" and ">= 0" in ei.value.message


def test_estimator_option_kinds():
    check("isam2", {"lag": 5, "use_icp": False, "gnss_robust": "cauchy", "gnss_k": 2.0, "cloud": {"knn": 12}})
    check("ukf", {"kappa": -1.0})  # a signed option
    with pytest.raises(OptionError, match="true or false"):
        check("isam2", {"use_icp": 1})
    with pytest.raises(OptionError, match="relinearize_skip.*int"):
        check("isam2", {"relinearize_skip": 1.5})
    with pytest.raises(OptionError, match="cloud option knn"):
        check("isam2", {"cloud": {"knn": 0}})
    with pytest.raises(OptionError, match="table"):
        check("isam2", {"cloud": 3})


@pytest.mark.parametrize("value", ["NaN", "Infinity", "true", "[1,2]", '{"a":1}', "null", "-5", "ten",
                                   "[" * 3000 + "]" * 3000])
def test_run_option_values_are_exit_2_before_the_run(tmp_path, value):
    log = tmp_path / "l.jsonl"
    log.write_text('{"type": "gnss", "t": 0.0, "x": 0.0, "y": 0.0, "sigma": 1.0}\n')
    code, obj, err = cli("run", str(log), "-e", "isam2", "-O", f"lag={value}", "--out", str(tmp_path / "o"))
    assert code == 2 and "Traceback" not in err, err
    assert obj["where"] == "option lag" or "nested deeper" in obj["error"]
    assert not (tmp_path / "o").exists()  # checked before --out is touched


def test_run_cloud_option_checked(tmp_path):
    log = tmp_path / "l.jsonl"
    log.write_text('{"type": "gnss", "t": 0.0, "x": 0.0, "y": 0.0, "sigma": 1.0}\n')
    code, obj, _ = cli("run", str(log), "-e", "isam2", "-O", 'cloud={"knn":0}')
    assert code == 2 and obj["where"] == "cloud option knn"


# -- (2) --config: UTF-8 TOML, bounded size and depth --------------------------------------------------

@pytest.mark.parametrize(("content", "words"), [
    ('out = "x"\n'.encode("utf-16"), "not UTF-8"),
    (bytes(range(256)) * 4, "not UTF-8"),
    (("a = " + "[" * 5000 + "]" * 5000 + "\n").encode(), "nested deeper"),
    (("[options]\nlag = " + "[" * 40 + "]" * 40 + "\n").encode(), "nested deeper"),
    (b"# " + b"x" * (1 << 20) + b"\n", "larger than"),
])
def test_config_files_that_are_not_bounded_utf8_toml(tmp_path, content, words):
    cfg = tmp_path / "c.toml"
    cfg.write_bytes(content)
    code, obj, err = cli("info", str(tmp_path / "none.jsonl"), "--config", str(cfg))
    assert code == 2 and "Traceback" not in err
    assert obj["where"] == str(cfg) and words in obj["error"], obj


def test_config_datetime_for_a_numeric_option(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text("[options]\nlag = 1979-05-27T07:32:00Z\n")
    log = tmp_path / "l.jsonl"
    log.write_text('{"type": "gnss", "t": 0.0, "x": 0.0, "y": 0.0, "sigma": 1.0}\n')
    code, obj, _ = cli("run", str(log), "-e", "isam2", "--config", str(cfg))
    assert code == 2 and obj["where"] == "option lag"


# -- (6) registration that found nothing says so, for every method -------------------------------------

def _degenerate() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(1)
    line = np.zeros((300, 3))
    line[:, 0] = np.arange(300) * 0.1
    plane = rng.uniform(-10, 10, (800, 3))
    plane[:, 2] = 0.0
    return {"identical": np.ones((5000, 3)), "line": line, "plane": plane}


@pytest.mark.parametrize("method", [m for m in METHODS if not m.startswith("o3d")] + ["o3d-icp"])
def test_degenerate_clouds_do_not_converge(method):
    if method.startswith("o3d"):
        pytest.importorskip("open3d")
    target = np.random.default_rng(2).uniform(-10, 10, (800, 3))
    for name, pts in _degenerate().items():
        r = register(pts, target, method)
        assert r.converged is False and "degenerate" in r.extra["reason"], (name, r.extra)
        assert r.fitness == 0.0 and np.all(np.isinf(np.diag(r.cov)))


@pytest.mark.parametrize("offset", [1e6, 1e9, 1e30])
def test_clouds_beyond_the_bound_are_errors_naming_the_cloud(offset):
    rng = np.random.default_rng(3)
    a = rng.uniform(-10, 10, (500, 3))
    far = a.copy()
    far[0, 0] = offset
    with pytest.raises(LogError, match="beyond the registration bound") as ei:
        register(far, a, "gicp")
    assert ei.value.where == "source"


def test_register_cli_names_the_file_and_says_converged_false(clouds, tmp_path):
    far = cloud_file(tmp_path / "far.bin", np.random.default_rng(4).uniform(-10, 10, (500, 3)) + [2e6, 0, 0])
    code, obj, _ = cli("register", str(far), str(clouds / "a.bin"), "--method", "o3d-icp")
    assert code == 2 and obj["where"] == str(far) and "source cloud" in obj["error"]
    same = cloud_file(tmp_path / "same.bin", np.ones((5000, 3)))
    code, obj, err = cli("register", str(same), str(clouds / "a.bin"))
    assert code == 0 and obj["converged"] is False and "all points at one spot" in obj["reason"]
    assert "voxel coord" not in err


def test_no_overlap_is_not_converged(clouds):
    rng = np.random.default_rng(5)
    a = rng.uniform(-10, 10, (800, 3))
    r = register(a + [500.0, 0.0, 0.0], a, "gicp", max_corr=1.0)
    assert r.converged is False and "no source point within max_corr" in r.extra["reason"]
