"""Every estimator's options (``-O KEY=VALUE``) with their defaults and meanings, read from the code
that defines them: the config dataclasses' field comments (``SmootherConfig``,
``IcpConfig``, ``ScanToMapConfig``), the run functions' keyword arguments (meaning: the sentence of
their docstring that names them) and the UKF's option table. ``graphnav run --list-options NAME``
prints them."""

from __future__ import annotations

import dataclasses
import inspect
import re
from collections.abc import Callable, Iterable
from typing import Any

from ..config import plain_text

__all__ = ["Option", "check", "dataclass_options", "describe", "function_options"]

Option = dict[str, Any]  # {"name", "default", "meaning", "group"}


def _comment(line: str) -> str:
    """The comment of a source line (``#`` outside a string literal; '' if none)."""
    quote = None
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch == "#":
            return line[i + 1:].strip()
    return ""


def _field_comments(cls: type) -> dict[str, str]:
    """Field name -> its comments: the comment block just above it (not a ``# --`` section header),
    the comment on its line and the continuation lines below it (``#`` followed by two spaces or more)."""
    try:
        lines = inspect.getsource(cls).splitlines()
    except (OSError, TypeError):
        return {}
    names = {f.name for f in dataclasses.fields(cls)}
    out: dict[str, str] = {}
    for i, line in enumerate(lines):
        m = re.match(r"\s+(\w+)\s*:", line)
        if not m or m.group(1) not in names:
            continue
        above: list[str] = []
        j = i - 1
        while j >= 0 and lines[j].strip().startswith("#") and not lines[j].strip().startswith("# --") \
                and not lines[j].strip().startswith("#  "):
            above.insert(0, lines[j].strip()[1:].strip())
            j -= 1
        parts = above + [_comment(line)]
        j = i + 1
        while j < len(lines) and lines[j].strip().startswith("#  "):
            parts.append(lines[j].strip()[1:].strip())
            j += 1
        out[m.group(1)] = " ".join(p for p in parts if p)
    return out


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None


def dataclass_options(cls: type, group: str, skip: Iterable[str] = ()) -> list[Option]:
    """The fields of a config dataclass: default, and meaning (``metadata["help"]`` or its comments)."""
    comments = _field_comments(cls)
    return [{"name": f.name, "default": _default(f), "group": group,
             "meaning": plain_text(f.metadata.get("help") or comments.get(f.name, ""))}
            for f in dataclasses.fields(cls) if f.name not in skip]


def _doc_sentence(doc: str, name: str) -> str:
    """The sentence (or ``;``-clause) of ``doc`` that names ``name`` in double backticks, narrowed to
    its comma-separated part naming it when it lists several options ('' if none); plain text."""
    text = " ".join(doc.split())
    k = text.find(f"``{name}``")
    if k < 0:
        return ""
    start = max([text.rfind(sep, 0, k) + 2 for sep in (". ", "; ", ": ") if text.rfind(sep, 0, k) >= 0]
                + [0])
    ends = [e for e in (text.find(". ", k), text.find("; ", k)) if e >= 0]
    sentence = text[start:min(ends) if ends else len(text)].strip()
    if len(re.findall(r"``\w+``", sentence)) > 2:  # a list of options: the part about this one
        parts, depth, cur = [], 0, ""
        for ch in sentence:
            depth += (ch == "(") - (ch == ")")
            if ch == "," and depth == 0:
                parts.append(cur)
                cur = ""
            else:
                cur += ch
        parts.append(cur)
        sentence = next((p.strip() for p in parts if f"``{name}``" in p), sentence)
    return plain_text(sentence)


def function_options(fn: Callable, group: str, skip: Iterable[str] = ("on_estimate",)) -> list[Option]:
    """The keyword arguments with defaults of ``fn`` (meaning from its docstring, else its module's)."""
    docs = [inspect.getdoc(fn) or "", inspect.getdoc(inspect.getmodule(fn)) or ""]
    out = []
    for p in inspect.signature(fn).parameters.values():
        if p.default is inspect.Parameter.empty or p.name in skip or p.kind is p.VAR_KEYWORD:
            continue
        meaning = next((m for m in (_doc_sentence(d, p.name) for d in docs) if m), "")
        out.append({"name": p.name, "default": p.default, "meaning": meaning, "group": group})
    return out


# Options whose meaning neither a field comment nor a docstring sentence gives (docs/ekf.md,
# docs/fuzzy-ukf.md say more).
_MEANINGS: dict[str, dict[str, str]] = {
    "ekf": {"speed": "true: the state is [x, y, yaw, v] (v a random walk, the odometry speed a measurement of it)",
            "use_gnss": "false: GNSS fixes are not used", "use_heading": "false: compass headings are not used",
            "icp_inflate": "a failed ICP match re-uses the last increment with its covariance x this"},
    "ekf-slam": {"paper": "true: the beacon paper's filter exactly (no gate, its init and sigmas, a slot per beacon)",
                 "sigma_v": "[m/s] speed sigma when the record gives none (null: the mode's default)",
                 "sigma_rot": "[rad/s] rate-of-turn sigma when the record gives none (null: the mode's default)",
                 "sigma_range": "[m] range sigma when the record gives none (null: the mode's default)",
                 "sigma_bearing": "[rad] bearing sigma when the record gives none (null: the mode's default)",
                 "init": 'a beacon\'s first sighting: "inverse" (inverse observation, the default) or "paper"',
                 "window": "innovations in the adaptive motion-noise scale's window",
                 "fej": "first-estimates Jacobians (Huang et al. 2008; null: on unless paper=true)",
                 "p0_cross": 'initial cross covariances: "zero" (a valid P0) or "paper" (eq. 14 as printed)',
                 "w_second": 'second column of W (eq. 22): "rot" = dg/dROT or "theta" as printed',
                 "use_known": "false: ignore the log's charted beacons (map every beacon)"},
    "ukf": {"alpha": "sigma-point spread (Merwe weights)", "beta": "sigma-point weight of the prior (2: Gaussian)",
            "kappa": "secondary sigma-point spread", "sigma_v0": "[m/s] prior 1-sigma of the initial velocity",
            "q_bias_gyro_deg": "[deg/s/sqrt(s)] bias states: gyro bias random walk (null: the log's meta['imu'])",
            "q_bias_acc": "[m/s^2/sqrt(s)] bias states: accelerometer bias random walk (null: the log's meta['imu'])",
            "sigma_bias_acc": "[m/s^2] bias states: prior on the residual accelerometer bias",
            "sigma_bias_gyro_deg": "[deg/s] bias states: prior on the residual gyro bias",
            "r_gps_x": "[m] GNSS x sigma (null: the records'; Table 2: 6)",
            "r_gps_y": "[m] GNSS y sigma (null: the records'; Table 2: 7)",
            "r_com_deg": "[deg] compass sigma (null: the records'; Table 2: 0.5)",
            "q_acc": "[m/s^2] IMU acceleration noise per sample (null: meta['imu'] acc_std, else Table 2's 0.0039)",
            "q_gyro_deg": "[deg/s] IMU yaw-rate noise per sample (null: meta['imu'] gyro_std, else Table 2's 0.033)",
            "current": "water-current states: auto (when the log has water_speed), true, false",
            "sigma_current0": "[m/s] prior 1-sigma of the water current",
            "sigma_water_speed": "[m/s] water-speed sigma when the record gives none",
            "q_current": "[m/s/sqrt(s)] water-current random walk",
            "bias": "IMU bias states: auto (unless meta['imu'] says bias_free), true, false (the paper's 5-state UKF)"},
}
_MEANINGS["ekf"].update({
    "motion": "odometry, imu, icp or auto (odometry if the log has it, else the IMU, else ICP on the scans)",
    "acc_density": "[m/s^2/sqrt(Hz)] IMU motion: accelerometer noise density (null: the log's meta['imu'])",
    "gyro_density": "[rad/s/sqrt(Hz)] IMU motion: gyro noise density (null: the log's meta['imu'])",
    "acc_bias_rw": "[m/s^2/sqrt(s)] IMU motion: accelerometer bias random walk (null: the log's meta['imu'])",
    "gyro_bias_rw": "[rad/s/sqrt(s)] IMU motion: gyro bias random walk (null: the log's meta['imu'])",
    "bias": "IMU motion: bias states, auto (unless meta['imu'] says bias_free), true, false",
    "current": "IMU motion: water-current states, auto (when the log has water_speed), true, false",
    "sigma_bias_acc": "[m/s^2] IMU motion: prior on the residual accelerometer bias",
    "sigma_bias_gyro_deg": "[deg/s] IMU motion: prior on the residual gyro bias",
    "sigma_current0": "[m/s] IMU motion: prior 1-sigma of the water current",
    "q_current": "[m/s/sqrt(s)] IMU motion: water-current random walk",
    "v0": "IMU motion: initial velocity [vx, vy, sigma] (null: meta initial_velocity, else the first GNSS velocity)",
    "sigma_gnss_velocity": "[m/s] GNSS velocity sigma when the record gives none",
    "sigma_water_speed": "[m/s] water-speed sigma when the record gives none",
    "use_velocity": "false: GNSS velocities are not used (IMU motion)",
    "use_odometry": "false: odometry speeds are not used as SOG updates (IMU motion)",
})


def _fill(options: list[Option], table: str) -> list[Option]:
    for o in options:
        if not o["meaning"]:
            o["meaning"] = _MEANINGS[table].get(o["name"], "")
    return options


def _ukf_options(group: str) -> list[Option]:
    from . import gating, ukf

    comments: dict[str, str] = {}  # the comments on the option tables' lines in ukf.py
    for line in inspect.getsource(ukf).splitlines():
        m = re.match(r'\s*"(\w+)":', line)
        if m and _comment(line):
            comments[m.group(1)] = _comment(line)
    gate_doc = {o["name"]: o["meaning"] for o in function_options(gating.InnovationGate, "gate")}
    gate_word = "innovation gate (docs/ekf.md, Gating)"
    return _fill([{"name": k, "default": v, "group": group,
                   "meaning": _MEANINGS["ukf"].get(k) or comments.get(k) or gate_doc.get(k)
                   or (gate_word if k in gating.GATING_DEFAULTS else "")}
                  for k, v in ukf.DEFAULTS.items()], "ukf")


def describe(name: str) -> list[Option]:
    """The options estimator ``name`` accepts, each ``{"name", "default", "meaning", "group"}``."""
    from . import get

    spec = get(name)  # KeyError naming the known ones
    if name in ("isam2", "batch", "fixed-lag"):
        from ..graph.smoother_config import SmootherConfig

        return dataclass_options(SmootherConfig, "navigation graph (SmootherConfig)", skip=("solver",))
    if name == "ekf":
        from .ekf import IMU_DEFAULTS, run_ekf
        from .gating import InnovationGate

        imu: list[Option] = [{"name": k, "group": "IMU motion (motion=imu)", "meaning": "",
                              "default": "auto" if k in ("bias", "current") else
                              None if k in ("acc_density", "gyro_density", "acc_bias_rw", "gyro_bias_rw", "v0")
                              else v} for k, v in IMU_DEFAULTS.items()]
        return (_fill(function_options(run_ekf, "ekf"), "ekf") + function_options(InnovationGate, "innovation gate",
                                                                                  skip=("gate",))
                + _fill(imu, "ekf"))
    if name == "icp-dr":
        from ..scan.weighted_icp import IcpConfig
        from .icp_odometry import run_icp_dr

        return function_options(run_icp_dr, "icp-dr") + dataclass_options(IcpConfig, "ICP (IcpConfig)",
                                                                          skip=("variant",))
    if name == "scan-to-map":
        from .scan_to_map import ScanToMapConfig

        return dataclass_options(ScanToMapConfig, "scan-to-map (ScanToMapConfig)")
    if name in ("ukf", "ukf-bias"):
        bias = [{"name": "bias", "default": "auto", "group": name, "meaning": _MEANINGS["ukf"]["bias"]}]
        return (bias if name == "ukf" else []) + _ukf_options(name)
    if name == "ekf-slam":
        from .ekf_slam import run_ekf_slam

        return _fill(function_options(run_ekf_slam, "ekf-slam"), "ekf-slam")
    if name in ("fuzzy-ukf", "fuzzy-ukf-bias"):
        from . import fuzzy_ukf

        doc = inspect.getdoc(fuzzy_ukf) or ""
        own = [{"name": "window", "default": 30, "group": "fuzzy", "meaning": _doc_sentence(doc, "window")},
               {"name": "r_update", "default": "compound", "group": "fuzzy",
                "meaning": "compound (R(k) adapts recursively) or scale_prior (alpha scales R_0)"},
               {"name": "c_a", "default": "centered", "group": "fuzzy",
                "meaning": "centered (C_A = the window's innovation covariance about its mean) or raw "
                           "(eq. 17's second moment, which also books model error as sensor noise)"},
               {"name": "mean_test", "default": 0.95 if name == "fuzzy-ukf" else None, "group": "fuzzy",
                "meaning": "confidence level of the test of the innovations' window mean; when significant "
                           "the predicted covariance is inflated to cover it (null: off)"}]
        if name == "fuzzy-ukf":
            own.append({"name": "bias", "default": "auto", "group": "fuzzy",
                        "meaning": "IMU bias states: auto (unless meta['imu'] says bias_free; then as "
                                   "fuzzy-ukf-bias), true, false (the paper's 5-state filter)"})
        return own + _ukf_options("ukf")
    return function_options(spec.run, name)  # any other estimator: its run function's keyword arguments


_DESCRIBED = ("isam2", "batch", "fixed-lag", "ekf", "ekf-slam", "icp-dr", "scan-to-map", "ukf", "ukf-bias",
              "fuzzy-ukf", "fuzzy-ukf-bias", "dead-reckoning")


MAX_INT_OPTION = 2**31 - 1  # an integer option reaches C++ (GTSAM) as a C int
MAX_FLOAT_OPTION = 1e15  # a numeric option's magnitude: its square stays far from overflow
_SIGNED = {"kappa", "water_margin"}
"""Numeric options that may be negative (every other numeric option is >= 0)."""


def check_value(option: str, value: Any, default: Any) -> None:
    """An :class:`~graphnav.config.OptionError` naming ``option`` when ``value`` is not of the kind of
    its ``default``: a number (finite; an integer when the default is one; >= 0 unless the option is
    signed) for a numeric default, ``true``/``false`` for a flag, a table for a table; a choice (text
    default) or an option without a default (None) takes null, a flag, text or a finite number
    (never a list or a table); the estimator checks the choice itself."""
    from ..config import OptionError, Range, number

    name = f"option {option}"
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise OptionError(name, f"must be true or false, got {value!r:.60}")
    elif isinstance(default, int | float):
        integer = isinstance(default, int)
        hi = MAX_INT_OPTION if integer else MAX_FLOAT_OPTION
        number(name, value, Range(lo=-hi if option.rpartition(".")[2] in _SIGNED else 0.0, hi=hi, integer=integer))
    elif isinstance(default, dict):
        if not isinstance(value, dict):
            raise OptionError(name, f"must be a table of options, got {value!r:.60}")
    elif (default is None or isinstance(default, str)) and not (value is None or isinstance(value, bool | str)):
        # a choice (text) or an option without a default: some also take a number (ekf-slam's gate)
        if isinstance(value, list | dict):
            raise OptionError(name, f"must be a single value (default {default!r}), got {value!r:.60}")
        number(name, value, Range(lo=-MAX_FLOAT_OPTION, hi=MAX_FLOAT_OPTION))


def _annotations(name: str) -> dict[str, str]:
    """Option -> its type annotation (text) in the config dataclasses and run functions estimator
    ``name``'s options come from (``float | None``: ``null`` is a value of it, text is not)."""
    from ..graph.smoother_config import SmootherConfig
    from ..scan.weighted_icp import IcpConfig
    from . import ekf, ekf_slam, fuzzy_ukf, gating, get, icp_odometry
    from .scan_to_map import ScanToMapConfig

    sources: dict[str, tuple] = {
        "isam2": (SmootherConfig,), "batch": (SmootherConfig,), "fixed-lag": (SmootherConfig,),
        "ekf": (ekf.run_ekf, gating.InnovationGate),
        "ekf-slam": (ekf_slam.run_ekf_slam,), "icp-dr": (icp_odometry.run_icp_dr, IcpConfig),
        "scan-to-map": (ScanToMapConfig,)}
    ukf = (gating.InnovationGate, fuzzy_ukf.FuzzyCovarianceMatcher)
    out: dict[str, str] = {}
    for src in sources.get(name, ukf if "ukf" in name else (get(name).run,)):
        if dataclasses.is_dataclass(src):
            out.update({f.name: str(f.type) for f in dataclasses.fields(src)})
        else:
            out.update({p.name: str(p.annotation) for p in inspect.signature(src).parameters.values()
                        if p.annotation is not inspect.Parameter.empty})
    return out


def _by_annotation(option: str, value: Any, ann: str) -> bool:
    """True when ``value`` is of a kind the annotation ``ann`` admits (None, a flag, text, a number);
    an annotation that names none of them (or none given) admits anything."""
    kinds = {"None": value is None, "bool": isinstance(value, bool),
             "str": isinstance(value, str), "Literal": isinstance(value, str),
             "float": isinstance(value, int | float) and not isinstance(value, bool),
             "int": isinstance(value, int) and not isinstance(value, bool)}
    tokens = set(re.findall(r"[A-Za-z_]+", ann))
    if tokens & {"dict", "list", "tuple", "Mapping", "Sequence", "Any", "object"}:
        return True
    named = [k for k in kinds if k in tokens]
    return not named or any(kinds[k] for k in named)


def check(name: str, options: dict[str, Any]) -> None:
    """A ``ValueError`` naming the unknown option(s) of estimator ``name`` and the known ones (when
    its options are all known: the estimators described here, or a run function without ``**``); an
    :class:`~graphnav.config.OptionError` naming an option whose value is not of its kind
    (:func:`check_value`), and a ``cloud`` table checked as the cloud matcher's options."""
    from . import get

    if not options:
        return
    if name not in _DESCRIBED and any(p.kind is p.VAR_KEYWORD
                                      for p in inspect.signature(get(name).run).parameters.values()):
        return
    described = describe(name)
    known = {o["name"] for o in described}
    bad = sorted(set(options) - known)
    if bad:
        raise ValueError(f"unknown {name} option(s) {bad}; known: {', '.join(sorted(known)) or 'none'} "
                         f"(graphnav run --list-options {name})")
    defaults: dict[str, list[Any]] = {}
    for o in described:
        defaults.setdefault(o["name"], []).append(o["default"])
    from ..config import OptionError

    annotations = _annotations(name)
    for key, value in options.items():
        ann = annotations.get(key, "")
        if value is None and "None" in ann:
            continue
        errors = []
        for default in defaults[key]:  # an option of two graphs (lag): valid for either
            try:
                check_value(key, value, default)
                break
            except ValueError as exc:
                errors.append(exc)
        else:
            raise errors[0]
        if ann and not _by_annotation(key, value, ann):
            raise OptionError(f"option {key}", f"must be of type {ann}, got {value!r:.60}")
    if isinstance(options.get("cloud"), dict) and name in ("isam2", "batch", "fixed-lag"):
        from ..scan.cloud_match import CloudMatchConfig

        CloudMatchConfig.from_options(dict(options["cloud"]))
