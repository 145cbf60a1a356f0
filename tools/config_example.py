"""Write examples/config.toml from the option dataclasses (their defaults and help: the fields' metadata
(graphnav.config.option), else their source comments; group headers from the ``# -- name`` comments).

    PYTHONPATH=. python tools/config_example.py

Run it after adding an option to SmootherConfig (its sections), ImuConfig, IcpConfig, LoopConfig or CloudMatchConfig:
tests/test_examples.py checks that the example lists every field and that every commented value loads.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import numbers
import re
import textwrap
from pathlib import Path
from typing import Any

from graphnav.config import plain_text, sections
from graphnav.estimators.options import describe
from graphnav.graph.imu_chain import ImuConfig
from graphnav.graph.loops import LoopConfig
from graphnav.graph.smoother_config import SmootherConfig
from graphnav.scan.cloud_match import CloudMatchConfig
from graphnav.scan.weighted_icp import IcpConfig

NONE = "...   (default: none; leave it out)"
SUBTABLES = (
    ("scan.icp", IcpConfig, "the weighted ICP between 2D scans (graphnav.scan.weighted_icp.IcpConfig; "
                            "docs/weighted-icp.md)"),
    ("scan.loop", LoopConfig, "loop closures on 2D scans (graphnav.graph.loops.LoopConfig; docs/loops.md)"),
    ("scan.cloud", CloudMatchConfig, "3D clouds: GICP projected to SE(2) (graphnav.scan.cloud_match.CloudMatchConfig; "
                                     "docs/scan-matching-3d.md)"),
    ("imu", ImuConfig, "the IMU's error model where the log states none (graphnav.graph.imu_chain.ImuConfig): "
                       "set it from the datasheet, docs/tuning.md"),
)
SET = {"gnss": {"gate": "4.0"}, "robust": {"noise_estimation": '"defaulted"'}}  # two set, as an example


def toml_value(v: Any) -> str | None:
    """``v`` in TOML, or None when TOML cannot spell it (None, a table, a non-finite number)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v + '"'
    if isinstance(v, numbers.Integral):
        return str(int(v))
    if isinstance(v, numbers.Real) and math.isfinite(float(v)):
        return repr(float(v))
    return None


def comments(cls: type) -> tuple[dict[str, str], dict[str, str], dict[str, str]]:
    """From the class's source: each field's comment (with its ``#  `` continuation lines), the group
    header (``# -- name ---``) before a field, and a free comment line before a field."""
    out: dict[str, str] = {}
    groups: dict[str, str] = {}
    notes: dict[str, str] = {}
    cur: str | None = None
    group: str | None = None
    note: list[str] = []
    for line in inspect.getsource(cls).splitlines():
        m = re.match(r"\s+# -- (.*?) -+\s*$", line)
        if m:
            group = m.group(1)
            continue
        m = re.match(r"\s+([a-z_0-9]+): [^=]+=\s*(.*?)(?:\s+#\s?(.*))?$", line)
        if m:
            cur = m.group(1)
            out[cur] = (m.group(3) or "").strip()
            if note:
                notes[cur] = " ".join(note)
                note = []
            if group:
                groups[cur], group = group, None
            continue
        m = re.match(r"\s+#  +(.*)$", line)
        if m and cur:
            out[cur] += " " + m.group(1).strip()
            continue
        m = re.match(r"\s+# (.*)$", line)
        if m:
            note.append(m.group(1).strip())
            cur = None
    for f in dataclasses.fields(cls):  # a field's help in its metadata wins (graphnav.config.option)
        if f.metadata.get("help"):
            unit = f.metadata.get("unit", "")
            out[f.name] = (f"[{unit}] " if unit else "") + plain_text(f.metadata["help"])
    return out, groups, notes


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None


def block(cls: type, skip: tuple[str, ...] = (), setv: dict[str, str] | None = None) -> str:
    """The fields of ``cls`` as TOML lines: commented defaults (``setv``: set, uncommented), each with
    its meaning on the lines below."""
    setv = setv or {}
    com, groups, notes = comments(cls)
    lines: list[str] = []
    for f in dataclasses.fields(cls):
        if f.name in skip:
            continue
        if f.name in groups:
            lines += ["", f"# -- {groups[f.name]}"]
        if f.name in notes:
            lines += ["# " + w for w in textwrap.wrap(notes[f.name], 96, break_on_hyphens=False)]
        tv = toml_value(_default(f))
        if f.name in setv:
            lines.append(f"{f.name} = {setv[f.name]}")
        else:
            lines.append(f"# {f.name} = {tv if tv is not None else NONE}")
        if com.get(f.name):
            lines += ["#     " + w for w in textwrap.wrap(com[f.name], 94, break_on_hyphens=False)]
    return "\n".join(lines)


def final() -> str:
    ekf_lines = []
    for o in describe("ekf"):
        tv = toml_value(o["default"])
        ekf_lines.append(f"# {o['name']} = {tv if tv is not None else NONE}")
        ekf_lines += ["#     " + w for w in textwrap.wrap(o["meaning"], 92, break_on_hyphens=False)]
    head = '''# graphnav --config example: every section, commented (tests/test_examples.py loads it).
#
#   graphnav run LOG --config examples/config.toml            # isam2 on LOG, outputs in out/run
#   graphnav run LOG --config examples/config.toml -e batch   # the command line wins over the file
#
# Top-level keys are the command's long options (here `graphnav run`'s; `_` or `-`); [options] holds
# what `-O KEY=VALUE` gives (the factor graph's options: isam2, batch, fixed-lag and live use them;
# `graphnav run --list-options isam2` prints them with their meanings); [options.ESTIMATOR] tables
# hold one estimator's options and are used only when that estimator runs (one file can serve
# several commands and estimators). An unknown key is an error naming this file and the key.
# [options] here are the factor graph's: a filter (-e ekf) refuses them; give it a file of its own
# or move them under [options.isam2] / [options.batch] / [options.fixed-lag].
# Units: SI (m, s, m/s, rad) unless a name says _deg; docs/conventions.md. How to choose the noise
# values from a datasheet, and how to check them (NEES, innovations): docs/tuning.md.
# The commented values are the defaults: uncomment a line to change it.

estimator = "isam2"          # -e: the estimator (graphnav run --list-options NAME for its options)
out = "out/run"              # --out: output directory (trajectory.tum/.csv, summary.json, ...)
overwrite = true             # --overwrite: replace the files a previous graphnav run wrote in out/
# lenient = false            # --lenient: skip (and count) malformed records instead of stopping
# max-speed = 50.0           # --max-speed [m/s]: faster odometry is invalid (a fast craft raises it)
# date = "2024-06-01"        # --date: the UTC day of an NMEA log without a date of its own
# columns = "t=time,lat=Latitude,lon=Longitude,sigma=2.5"   # --columns: a CSV log's mapping (docs/csv.md)
# drop = ["odometry"]        # --drop: record kinds left out before the estimator sees the log
# json = false               # --json: one JSON object on stdout

[options]
# The factor graph (graphnav.graph.smoother_config.SmootherConfig): the state here, then one table per
# section ([options.gnss] gate = 4.0 is -O gnss.gate=4.0). Every option also answers to its flat name
# here in [options] (gnss_gate = 4.0; `graphnav run --list-options isam2` gives both). Options whose
# default is "none" have no TOML spelling: leave them out (or use -O KEY=null).'''
    secs = sections(SmootherConfig)
    body = block(SmootherConfig, skip=("solver", "imu", "mounts", *secs))
    what = {f.name: plain_text(f.metadata.get("help", "")) for f in dataclasses.fields(SmootherConfig)}
    tables = [table(name, cls, what[name], SET.get(name)) for name, cls in secs.items()]
    subs = [table(name, cls, what) for name, cls, what in SUBTABLES if "." not in name]
    mounts = '''
# Sensor mounts: where each sensor sits in the body frame (x forward, y left, z up; m and rad,
# ZYX roll/pitch/yaw). They override the log meta's "mounts" per sensor (docs/mounts.md).
[options.mounts.gnss]        # the GNSS antenna's phase centre: the fixes are applied there
x = 0.0                      # e.g. 3.0: 3 m forward of the body origin
y = 0.0
z = 0.0                      # (its height is not used: the graph observes no heel)

# [options.mounts."gnss@52"]  # one source's antenna (two receivers on one bus; a record's source)
#   x = 1.2

[options.mounts.lidar]       # the LiDAR's optical centre and axes: matches are conjugated to the body
# x = 0.0
# y = 0.0
# yaw = 0.0                  # [rad] the scanner's forward axis from the bow

[options.mounts.imu]         # GTSAM's body_P_sensor: rotated samples, centripetal term removed
# x = 0.0
# y = 0.0
# z = 0.0

[options.mounts.water_speed] # the speed log: its yaw misalignment (|yaw| <= 60 deg)
# yaw = 0.0
'''
    est = '''
# One estimator's options: used only when that estimator runs (here when -e ekf is given).
[options.ekf]
''' + "\n".join(ekf_lines) + '''

[options.isam2]              # isam2 only (the [options] above apply to every graph smoother)
# converge = "lm"
'''
    return head + "\n" + body + "\n" + "\n".join(tables) + "\n" + "\n".join(subs) + "\n" + mounts + est


def table(name: str, cls: type, what: str, setv: dict[str, str] | None = None) -> str:
    """``[options.NAME]``: its meaning, then its fields (:func:`block`), then its sub-tables (SUBTABLES)."""
    subs = [(n, c, w) for n, c, w in SUBTABLES if n.startswith(name + ".")]
    return (f"\n[options.{name}]\n# " + "\n# ".join(textwrap.wrap(what, 96, break_on_hyphens=False)) + "\n"
            + block(cls, skip=tuple(n.rpartition(".")[2] for n, _, _ in subs), setv=setv).lstrip("\n")
            + "".join("\n" + table(n, c, w) for n, c, w in subs))


if __name__ == "__main__":
    out = Path(__file__).resolve().parents[1] / "examples" / "config.toml"
    out.write_text(final())
    print(f"wrote {out}")
