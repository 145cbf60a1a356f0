"""The estimator protocol (issue #26): every estimator a class with a ``Config`` dataclass whose fields
carry their help, ``add(record) -> Estimate | None`` / ``finish() -> RunResult``, one registry for batch
runs and live mode, and ``--list-options`` text generated from the field metadata."""

from __future__ import annotations

import json
from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np
import pytest

from graphnav import estimators
from graphnav.cli import main
from graphnav.config import OptionError, describe_config, option
from graphnav.estimators.base import BatchEstimator, Estimator
from graphnav.estimators.ekf import run_ekf
from graphnav.estimators.gating import GATING_DEFAULTS, GateOptions, InnovationGate
from graphnav.estimators.options import check, describe
from graphnav.graph.navigator import Navigator
from graphnav.sim.square import square_loop


@pytest.mark.parametrize("name", estimators.names())
def test_every_estimator_is_a_class_with_a_documented_config(name):
    cls = estimators.get(name)
    assert issubclass(cls, Estimator) and cls.name == name and cls.description and cls.Config is not None
    for f in fields(cls.Config):
        assert f.metadata.get("help"), f"{name}: option {f.name} has no help"


@pytest.mark.parametrize("name", estimators.names())
def test_list_options_text_is_the_field_metadata(name, capsys):
    assert main(["run", "--list-options", name]) == 0
    text = capsys.readouterr().out
    lines = text.splitlines()
    assert lines[0].startswith(f"-O options of {name} ")
    opts = describe(name)
    if not opts:
        assert lines[1:] == ["  (none)"]
    for o in opts:  # each option under its group: its name (in a section: its key, the flat name at the end),
        # default (JSON), type, then its unit and meaning on the next line
        key = o.get("path", o["name"]).rpartition(".")[2]
        start = next(k for k, line in enumerate(lines) if line.startswith(f"  [{o['group']}]"))
        i = next(k for k, line in enumerate(lines) if k > start and line.split()[:1] == [key])
        rest = lines[i].strip().removeprefix(key).strip()
        assert rest.startswith(json.dumps(list(o["default"]) if isinstance(o["default"], tuple) else o["default"]))
        assert rest.endswith(" " + o["type"] + (f"  ({o['name']})" if key != o["name"] else ""))
        assert lines[i + 1].strip() == (f"[{o['unit']}] " if o["unit"] else "") + o["meaning"].removeprefix(
            f"[{o['unit']}] " if o["unit"] else "")
        assert "``" not in lines[i + 1] and ":class:" not in lines[i + 1]  # plain text, no reST
    assert main(["run", "--list-options", name, "--json"]) == 0
    assert [o["name"] for o in json.loads(capsys.readouterr().out)["options"]] == [o["name"] for o in opts]


def test_describe_config_reads_help_unit_type_and_groups():
    @dataclass
    class Base:
        group: ClassVar[str] = "base things"
        a: float = option(1.5, "the ``a`` of :class:`~x.Thing`", unit="m")

    @dataclass
    class Cfg(Base):
        b: int | None = option(None, "b, or null")
        c: list = option(help="a list", factory=lambda: [1])

    got = describe_config(Cfg)
    assert [o["name"] for o in got] == ["b", "c", "a"]  # own fields first
    assert got[2] == {"name": "a", "type": "float", "default": 1.5, "unit": "m", "meaning": "[m] the a of Thing",
                      "group": "base things"}
    assert got[0]["group"] == "Cfg" and got[0]["type"] == "int | None" and got[1]["default"] == [1]


def test_gate_defaults_are_the_gates_own():
    import inspect

    sig = inspect.signature(InnovationGate)
    assert {k: sig.parameters[k].default for k in GATING_DEFAULTS} == GATING_DEFAULTS
    assert [f.name for f in fields(GateOptions)] == list(GATING_DEFAULTS)


def test_check_reads_the_config():
    check("ekf", {"gate": 0.99, "motion": "imu", "v0": [1.0, 0.0, 0.5]})
    with pytest.raises(ValueError, match=r"unknown ekf option\(s\) \['gaet'\]"):
        check("ekf", {"gaet": 0.9})
    with pytest.raises(OptionError, match="option reinit_n"):
        check("ukf", {"reinit_n": 2.5})
    with pytest.raises(OptionError, match="option use_gnss"):
        check("ekf", {"use_gnss": "yes"})
    with pytest.raises(OptionError, match="option lag"):
        check("fixed-lag", {"lag": -1})
    check("fixed-lag", {"keyframe_period": None})


def _square():
    return square_loop(seed=3, laps=1)


def test_one_loop_is_the_batch_run():
    log = _square()
    est = estimators.get("ekf")(log, gate=0.99)
    assert isinstance(est, BatchEstimator) and est.config.gate == 0.99
    for rec in log.records:
        assert est.add(rec) is None
    a, b = est.finish(), run_ekf(log, gate=0.99)
    np.testing.assert_array_equal(a.trajectory.poses, b.trajectory.poses)
    c = estimators.run("ekf", log, gate=0.99)
    np.testing.assert_array_equal(a.trajectory.poses, c.trajectory.poses)


def test_a_smoother_publishes_estimates_as_records_arrive():
    log = _square()
    est = estimators.get("isam2")(log)
    out = [e for e in (est.add(r) for r in log.records) if e is not None]
    res = est.finish()
    assert len(out) > 10 and len(res.trajectory) >= len(out)
    assert res.online is not None
    k = int(np.searchsorted(res.online.t, out[-1].t))
    assert res.online.t[k] == out[-1].t and np.allclose(res.online.poses[k], out[-1].vec)


def test_one_registry_for_batch_and_live():
    assert estimators.online_names() == ["ekf", "fixed-lag", "isam2"]
    nav = estimators.make_online("fixed-lag", lag=3.0)
    assert isinstance(nav, Navigator) and nav.cfg.solver == "fixed-lag" and nav.cfg.optimizer.lag == 3.0
    with pytest.raises(ValueError, match="no online form of estimator 'ukf'.*have: ekf, fixed-lag, isam2"):
        estimators.make_online("ukf")
    with pytest.raises(ValueError, match="contradicts"):
        estimators.make_online("isam2", solver="batch")
