"""The estimators' names read from their modules' source (``estimators.declared``) are the registry's, and
``graphnav run -e NAME`` imports only the module that declares NAME (not the filters' numba kernels)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from graphnav import estimators

ROOT = Path(__file__).resolve().parents[2]


def test_the_names_read_from_source_are_the_imported_registry():
    decl = estimators.declared()
    reg = estimators.registry()
    assert sorted(decl) == sorted(reg) == estimators.names()
    for name, module in decl.items():  # each name at the module that declares it
        assert sys.modules[f"graphnav.estimators.{module}"].ESTIMATORS[name] is reg[name]


def test_a_declaration_not_a_literal_is_read_by_importing(monkeypatch):
    monkeypatch.setattr(estimators, "_DECLARATION", __import__("re").compile(r"^NO_SUCH_NAME\s*="))
    got = {n: estimators._declared_names(m, False) for n, m in (("isam2", "smoother"), ("ukf", "ukf"))}
    assert "isam2" in got["isam2"] and "batch" in got["isam2"] and "ukf" in got["ukf"]
    assert estimators._declared_names("base", False) == []  # no ESTIMATORS in its source


def test_run_imports_only_the_estimator_it_runs():
    code = ("import sys; from graphnav import cli, estimators; cli.build_parser('run'); estimators.get('isam2'); "
            "print(sorted(m for m in sys.modules if m.startswith('graphnav.estimators.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}).stdout
    mods = eval(out)  # noqa: S307 - our own printed list
    assert "graphnav.estimators.smoother" in mods
    assert not {"graphnav.estimators.ukf", "graphnav.estimators.ekf", "graphnav.estimators.icp_odometry"} & set(mods)


def test_get_without_the_registry(monkeypatch):
    monkeypatch.setattr(estimators, "_REGISTRY", None)  # (as in a fresh process)
    cls = estimators.get("fixed-lag")
    assert cls.name == "fixed-lag" and cls is sys.modules["graphnav.estimators.smoother"].ESTIMATORS["fixed-lag"]
    with pytest.raises(KeyError, match="unknown estimator 'isam3'; did you mean 'isam2'.*known: batch"):
        estimators.get("isam3")


def test_a_declaration_changed_later_or_in_a_string_is_read_by_importing(monkeypatch, tmp_path):
    """Only a module's one top-level ``ESTIMATORS = {literal}`` is read from source: a later update, or a
    docstring line that looks like one, sends the reader to the module itself."""
    monkeypatch.setattr(estimators, "__path__", [str(tmp_path)])
    monkeypatch.setattr(estimators, "_module_estimators", lambda module: {"imported": object})
    cases = {'ESTIMATORS = {"a": A, "b": B}\n': ["a", "b"],
             'ESTIMATORS = {"a": A}\nESTIMATORS["c"] = C\n': ["imported"],
             '"""\nESTIMATORS = {"a": A}\n"""\n': ["imported"],
             'ESTIMATORS = {**OTHERS}\n': ["imported"],
             'NAMES = 1\n': []}
    for text, want in cases.items():
        (tmp_path / "mod.py").write_text(text, encoding="utf-8")
        assert estimators._declared_names("mod", False) == want, text
