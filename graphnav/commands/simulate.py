"""``graphnav simulate SCENARIO ... --out LOG``: write a simulated log.

The scenarios are the simulators of :mod:`graphnav.sim` (numeric cores: a seed in, a
:class:`~graphnav.log.NavLog` out); their command-line glue (arguments, writing, the JSON summary)
is here. ``degrade`` adds simulated sensors to an existing log (:mod:`graphnav.sim.degrade`).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from pathlib import Path

from ..io import save_log
from ..sim import degrade, fairway, harbour, marina_degraded, solent
from ._common import add_json_flag, emit, seed_arg

OVERWRITE_HELP = "replace --out when it is an existing regular file (it is replaced atomically)"


def _prepare_out(args: argparse.Namespace) -> Path:
    """``--out``: its directory created, and refused before any work when it exists without
    ``--overwrite`` or is no regular file."""
    from ..io.outputs import check_replaceable, ensure_dir

    out = Path(args.out)
    ensure_dir(out.parent, "--out (its directory)")
    check_replaceable(out, overwrite=args.overwrite)
    return out


def _save(log, args: argparse.Namespace) -> None:  # noqa: ANN001
    save_log(log, args.out, overwrite=args.overwrite)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="simulate a scenario into a log", description=__doc__)
    scen = p.add_subparsers(dest="scenario", metavar="SCENARIO", required=True)
    for add in (_register_fairway, _register_harbour, _register_marina_degraded, _register_solent, _register_degrade):
        add(scen)


def _register_fairway(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fairway", help="the beacon paper's fairway passage: odometry + beacon range/bearing",
                       description=fairway.__doc__)
    p.add_argument("--beacons", required=True, help='beacon positions "x1,y1;x2,y2;..." [m]')
    p.add_argument("--seed", type=seed_arg, default=0, help="random seed of the simulated noise (default 0)")
    p.add_argument("--out", required=True, help="output log (.jsonl, .jsonl.gz or .npz)")
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    p.set_defaults(func=_fairway)


def _fairway(args: argparse.Namespace) -> int:
    _prepare_out(args)
    log = fairway.simulate_fairway(fairway.parse_beacons(args.beacons), args.seed)
    _save(log, args)
    return 0


MAX_DURATION = 7 * 86400.0  # [s]: --duration's bound (a week)
MAX_LAPS = 1000  # --laps' bound (a lap is ~11 min: about a week)
#: the simulated log is held in memory: its estimated size is bounded (2 GiB). Peak RSS measured on
#: `simulate harbour` (2-core VM): 0.084 MB per simulated second without LiDAR, 9.3 kB per 2D scan,
#: 160 kB per 16-beam 3D cloud (120 s vs 480 s, --lidar-hz 0/10/20; 3D 20 s vs 60 s)
MAX_SIM_BYTES = 2 << 30
SIM_BYTES_PER_S = 84e3
SCAN_BYTES = {"2d": 9.3e3, "3d": 160e3}
LAP_S = 11 * 60.0  # [s] a lap of the harbour route, about


def memory_bound(seconds: float, lidar_hz: float, lidar: str) -> None:
    """A ``ValueError`` naming --duration/--laps when the simulated log would hold more than
    :data:`MAX_SIM_BYTES` in memory."""
    need = seconds * (SIM_BYTES_PER_S + lidar_hz * SCAN_BYTES[lidar])
    if need > MAX_SIM_BYTES:
        most = MAX_SIM_BYTES / (SIM_BYTES_PER_S + lidar_hz * SCAN_BYTES[lidar])
        raise ValueError(f"--duration/--laps: {seconds:g} s of simulation at --lidar-hz {lidar_hz:g} ({lidar}) would "
                         f"hold ~{need / 2**30:.1f} GiB in memory; at most {most:.0f} s there (the bound is "
                         f"{MAX_SIM_BYTES / 2**30:g} GiB): simulate longer runs in pieces with --t0")


def _register_harbour(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "harbour",
        help="a vessel crossing a small harbour: IMU, GNSS (+ Doppler), compass, speed log, LiDAR, beacons",
        description=harbour.__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--seed", type=seed_arg, default=0, help="random seed of the simulated noise (default 0)")
    p.add_argument("--profile", choices=harbour.PROFILES, default="usv",
                   help="usv: a real USV's sensors (100 Hz IMU with bias drift, GNSS + Doppler velocity, compass "
                        "with deviation, speed log in a tidal current, 10 Hz LiDAR; default); legacy: the "
                        "robot-style log data/harbour.npz was first made with (10 Hz odometry, 1 Hz IMU, 5 Hz "
                        "LiDAR, still water), draw for draw")
    p.add_argument("--odometer", action="store_true",
                   help="add 10 Hz odometry records (SOG, ROT) for robot-style logs (legacy has them)")
    p.add_argument("--current-speed", type=float, default=None, metavar="M/S",
                   help="mean speed of the tidal current (usv default 0.4, +-0.1 over 20 min; 0: still water)")
    p.add_argument("--duration", type=float, default=None,
                   help="length of the run [s] (shorter: truncated; longer: the route repeats)")
    p.add_argument("--laps", type=int, default=None, help="times round the route (default 1, or what --duration needs)")
    p.add_argument("--fix-hz", type=float, default=1.0, help="GNSS and compass rate [Hz] (default 1)")
    p.add_argument("--lidar-hz", type=float, default=None,
                   help="LiDAR rate [Hz] (default 10; 5 with --profile legacy; 0: no scans)")
    p.add_argument("--lidar-sweep", type=float, default=0.0, metavar="S",
                   help="2D LiDAR sweep duration [s]: beam i of N is taken at stamp + i*S/N along the true track "
                        "and meta lidar states sweep_s (default 0: every beam at the stamp; 1/lidar-hz for a "
                        "spinning LiDAR, e.g. 0.1 at 10 Hz)")
    p.add_argument("--lidar", choices=("2d", "3d"), default="2d",
                   help="2d: 360-beam scans (default); 3d: a 16-beam VLP-16-like cloud ray-cast against the "
                        "extruded harbour, with wave roll/pitch, water returns and spray (graphnav.sim.harbour3d)")
    p.add_argument("--t0", type=float, default=0.0, help="time of the first record [s] (e.g. a POSIX time)")
    p.add_argument("--out", type=Path, required=True, help="output log (.jsonl[.gz] or .npz)")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    p.set_defaults(func=_harbour)


def harbour_config(args: argparse.Namespace) -> harbour.HarbourConfig:
    """The :class:`graphnav.sim.harbour.HarbourConfig` the ``simulate harbour`` options describe
    (``ValueError`` naming the option when one is out of range)."""
    from ..log import default_limits

    if args.duration is not None and not 0.0 < args.duration <= MAX_DURATION:
        raise ValueError(f"--duration must be > 0 and <= {MAX_DURATION:g} s (a week), got {args.duration}")
    if args.laps is not None and not 0 < args.laps <= MAX_LAPS:
        raise ValueError(f"--laps must be between 1 and {MAX_LAPS}, got {args.laps}")
    if not (math.isfinite(args.fix_hz) and 0.0 < args.fix_hz <= 50.0):
        raise ValueError(f"--fix-hz must be > 0 and <= 50, got {args.fix_hz}")
    if args.lidar_hz is not None and not (math.isfinite(args.lidar_hz) and 0.0 <= args.lidar_hz <= 50.0):
        raise ValueError(f"--lidar-hz must be >= 0 and <= 50, got {args.lidar_hz}")
    top = default_limits().max_time - (args.duration or MAX_DURATION)
    if not (math.isfinite(args.t0) and abs(args.t0) <= top):  # every record's time must stay a valid time
        raise ValueError(f"--t0 must be finite and within +-{top:g} s, got {args.t0}")
    kw: dict = {"fix_hz": args.fix_hz, "t0": args.t0}
    sweep = getattr(args, "lidar_sweep", 0.0)
    if sweep:
        hz = args.lidar_hz if args.lidar_hz is not None else harbour.HarbourConfig.for_profile(args.profile).lidar_hz
        if not (math.isfinite(sweep) and 0.0 < sweep <= (1.0 / hz if hz > 0 else 1.0)):
            raise ValueError(f"--lidar-sweep must be >= 0 and at most a scan period (1/lidar-hz), got {sweep}")
        if args.lidar != "2d":
            raise ValueError("--lidar-sweep is for the 2D LiDAR (--lidar 2d)")
        kw["lidar_sweep"] = sweep
    if args.lidar_hz is not None:
        kw["lidar_hz"] = args.lidar_hz
    elif args.lidar == "3d":
        kw["lidar_hz"] = 10.0
    seconds = args.duration if args.duration is not None else LAP_S * (args.laps or 1)
    memory_bound(seconds, kw.get("lidar_hz", harbour.HarbourConfig.for_profile(args.profile).lidar_hz), args.lidar)
    if args.odometer:
        kw["odometer"] = True
    if args.current_speed is not None:
        if not (math.isfinite(args.current_speed) and 0.0 <= args.current_speed <= 5.0):
            raise ValueError(f"--current-speed must be >= 0 and <= 5 m/s, got {args.current_speed}")
        base = harbour.HarbourConfig.for_profile(args.profile).current
        amp = min(base.speed_amp, args.current_speed) if base.speed_amp else 0.0
        kw["current"] = replace(base, speed=args.current_speed, speed_amp=amp)
    return harbour.HarbourConfig.for_profile(args.profile, **kw)


def _harbour(args: argparse.Namespace) -> int:
    _prepare_out(args)
    cfg = harbour_config(args)
    hz = cfg.lidar_hz
    if args.lidar == "3d":
        from ..sim.harbour3d import Lidar3dConfig, simulate_harbour3d

        if not 0.0 < hz <= 10.0:
            raise ValueError("--lidar 3d needs 0 < --lidar-hz <= 10 (the truth poses are at 10 Hz)")
        log = simulate_harbour3d(args.seed, cfg, Lidar3dConfig(hz=hz), duration=args.duration, laps=args.laps)
    else:
        log = harbour.simulate_harbour(args.seed, cfg, duration=args.duration, laps=args.laps)
    _save(log, args)
    emit(
        args,
        {
            "scenario": "harbour" if args.lidar == "2d" else "harbour3d",
            "profile": cfg.profile,
            "seed": args.seed,
            "out": str(args.out),
            "records": log.counts(),
            "t0": log.t0,
            "t1": log.t1,
        },
    )
    return 0


def _register_marina_degraded(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "marina-degraded",
        help="real marina scans + simulated GNSS (outage, jump) and biased compass",
        description=marina_degraded.__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--marina", type=Path, required=True, help="the icp_data_marina directory")
    p.add_argument("--seed", type=seed_arg, default=1, help="random seed of the simulated noise (default 1)")
    p.add_argument("--jump-m", type=float, default=20.0, help="GNSS jump size [m] (0: none, same noise)")
    p.add_argument("--out", type=Path, required=True, help="output log (.jsonl[.gz] or .npz)")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    p.set_defaults(func=_marina_degraded)


MAX_JUMP_M = 1e4  # [m] --jump-m's bound: a GNSS jump farther than 10 km is no multipath


def _marina_degraded(args: argparse.Namespace) -> int:
    if not (math.isfinite(args.jump_m) and 0.0 <= args.jump_m <= MAX_JUMP_M):
        raise ValueError(f"--jump-m must be >= 0 and <= {MAX_JUMP_M:g} m, got {args.jump_m}")
    _prepare_out(args)
    log = marina_degraded.simulate_marina_degraded(args.marina, args.seed, jump_m=args.jump_m)
    _save(log, args)
    emit(
        args,
        {
            "scenario": "marina-degraded",
            "seed": args.seed,
            "out": str(args.out),
            "records": log.counts(),
            "events": log.meta["events"],
        },
    )
    return 0


def _register_solent(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("solent", help="the fuzzy-adaptive-UKF paper's Solent waypoint mission (3 scenarios)",
                       description=solent.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", type=int, choices=(1, 2, 3), default=1,
                   help="the paper's scenario: 1 datasheet noise (Table 3), 2 GNSS 20 m and compass 5 deg, "
                        "3 the first then the second from step 300 (default 1)")
    p.add_argument("--seed", type=seed_arg, default=0, help="random seed of the simulated noise (default 0)")
    p.add_argument("--current-speed", type=float, default=solent.SolentConfig.current_speed,
                   help=f"sea current [m/s] (default {solent.SolentConfig.current_speed:g})")
    p.add_argument("--calib-residual", type=float, default=solent.SolentConfig.calib_residual,
                   help="residual IMU bias after calibration, fraction of Table 3's bias (default 0.1)")
    p.add_argument("--no-calibration", action="store_true", help="leave Table 3's IMU biases in the log")
    p.add_argument("--out", type=Path, required=True, help="log file (.jsonl, .jsonl.gz or .npz)")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    p.set_defaults(func=_solent)


def _solent(args: argparse.Namespace) -> int:
    from ..config import Range, number

    number("--current-speed", args.current_speed, Range(lo=0.0, hi=10.0))
    number("--calib-residual", args.calib_residual, Range(lo=0.0, hi=10.0))
    _prepare_out(args)
    cfg = solent.SolentConfig(scenario=args.scenario, seed=args.seed, current_speed=args.current_speed,
                              calib_residual=args.calib_residual, calibrate=not args.no_calibration)
    log = solent.simulate_solent(cfg)
    _save(log, args)
    summary = {"out": str(args.out), "scenario": cfg.scenario, "seed": cfg.seed, "records": log.counts(),
               "duration_s": log.t1 - log.t0, "waypoints_reached": log.meta["waypoints_reached"]}
    emit(args, summary)
    return 0


DEGRADE_DOC = """``graphnav simulate degrade LOG --odometry-noise V,W,W0DEG --seed S --out OUT``: simulated sensors
from a log's truth, added to the log (the model: :mod:`graphnav.sim.degrade`, docs/datasets.md).

Wheel odometry: the unicycle arc between consecutive truth poses, then per sample (white noise)
v x (1 + N(0, V)) and w x (1 + N(0, W)) + N(0, W0DEG deg/s), plus an optional constant yaw-rate
bias (--yaw-rate-bias). The records carry the sigmas the simulator used (V|v|, sqrt((W w)^2 + W0^2)).
GNSS and compass come from the truth poses with the given sigmas; outages and jumps are windows
whose start is seconds after the first truth pose, or 'A%..B%' (centred at a time drawn in that
part of the run). --preset marina-degraded reproduces 'graphnav simulate marina-degraded' draw for
draw (GNSS 3 m, a 40 s outage in 15%..45%, a 20 m 10 s jump in 60%..85%, compass 2 deg + 3 deg bias).
"""


def _floats(text: str, opt: str, n_min: int, n_max: int) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        raise ValueError(f"{opt} {text!r}: expected {n_min}-{n_max} comma-separated numbers") from None
    if not n_min <= len(vals) <= n_max or not all(math.isfinite(v) for v in vals):
        raise ValueError(f"{opt} {text!r}: expected {n_min}-{n_max} comma-separated finite numbers")
    return vals


def parse_start(text: str, opt: str) -> float | tuple[float, float]:
    """``"120"`` -> 120.0 s; ``"15%..45%"`` -> (0.15, 0.45)."""
    if "%" in text:
        a, sep, b = text.partition("..")
        try:
            lo, hi = float(a.strip().rstrip("%")) / 100, float(b.strip().rstrip("%")) / 100
        except ValueError:
            raise ValueError(f"{opt}: start {text!r} is not SECONDS or A%..B%") from None
        if not sep or not 0.0 <= lo <= hi <= 1.0:
            raise ValueError(f"{opt}: start {text!r} is not A%..B% with 0 <= A <= B <= 100")
        return lo, hi
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"{opt}: start {text!r} is not SECONDS or A%..B%") from None


def parse_window(text: str, opt: str, *, jump: bool) -> degrade.Window:
    parts = text.split(",")
    if len(parts) != (3 if jump else 2):
        raise ValueError(f"{opt} {text!r}: expected START,DURATION" + (",METRES" if jump else ""))
    rest = _floats(",".join(parts[1:]), opt, len(parts) - 1, len(parts) - 1)
    if rest[0] <= 0:
        raise ValueError(f"{opt} {text!r}: the duration must be > 0")
    return degrade.Window(parse_start(parts[0], opt), rest[0], rest[1] if jump else 0.0)


def _register_degrade(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("degrade", help="add simulated odometry, GNSS and compass (from the log's truth) to a log",
                       description=DEGRADE_DOC, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("log", help="input log with truth (any format graphnav reads: .jsonl[.gz], a CARMEN log, ...)")
    p.add_argument("--preset", choices=tuple(degrade.PRESETS), help="start from a preset (options below override it)")
    p.add_argument("--odometry-noise", metavar="V,W,W0DEG",
                   help="wheel odometry with per-sample noise: relative 1-sigma V on v, W on w, plus an additive "
                        "1-sigma W0DEG deg/s on w (e.g. 0.05,0.05,0.5)")
    p.add_argument("--yaw-rate-bias", type=float, default=0.0, metavar="DEG_S",
                   help="a constant yaw-rate bias added to the odometry w (deg/s; default 0; not in the sigmas)")
    p.add_argument("--gnss", metavar="SIGMA[,HZ]", help="GNSS fixes, SIGMA m per axis, at most HZ (default: every "
                                                         "truth time)")
    p.add_argument("--compass", metavar="SIGMA_DEG[,BIAS_DEG[,HZ]]", help="compass with a constant bias")
    p.add_argument("--gnss-outage", action="append", metavar="START,DURATION",
                   help="no GNSS for DURATION s from START (s after the first truth, or A%%..B%%); repeatable")
    p.add_argument("--gnss-jump", action="append", metavar="START,DURATION,METRES",
                   help="GNSS off by METRES (direction from the seed) for DURATION s from START; repeatable")
    p.add_argument("--seed", type=seed_arg, default=0, help="random seed of the simulated noise (default 0)")
    p.add_argument("--out", type=Path, required=True, help="output log (.jsonl[.gz] or .npz)")
    p.add_argument("--lenient", action="store_true", help="skip malformed input records (and count them)")
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    add_json_flag(p)
    p.set_defaults(func=_degrade)


def degrade_config(args: argparse.Namespace) -> degrade.DegradeConfig:
    """The :class:`graphnav.sim.degrade.DegradeConfig` the ``degrade`` options describe."""
    from ..config import Range, number

    number("--yaw-rate-bias", args.yaw_rate_bias, Range(lo=-2000.0, hi=2000.0))
    cfg = degrade.PRESETS[args.preset] if args.preset else degrade.DegradeConfig()
    if args.odometry_noise:
        v, w, w0 = _floats(args.odometry_noise, "--odometry-noise", 3, 3)
        for what, val, top in (("V", v, 10.0), ("W", w, 10.0), ("W0DEG", w0, 360.0)):
            number(f"--odometry-noise {what}", val, Range(lo=0.0, hi=top))
        if min(v, w, w0) < 0:
            raise ValueError("--odometry-noise: the sigmas must be >= 0")
        cfg = replace(cfg, odometry=degrade.OdometryNoise(v, w, math.radians(w0), math.radians(args.yaw_rate_bias)))
    elif args.yaw_rate_bias:
        raise ValueError("--yaw-rate-bias needs --odometry-noise")
    if args.gnss:
        g = _floats(args.gnss, "--gnss", 1, 2)
        number("--gnss SIGMA", g[0], Range(lo=0.0, hi=1e6, lo_open=True))
        if len(g) > 1:
            number("--gnss HZ", g[1], Range(lo=0.0, hi=1000.0, lo_open=True))
        cfg = replace(cfg, gnss_sigma=g[0], gnss_hz=g[1] if len(g) > 1 else None)
    if args.compass:
        c = _floats(args.compass, "--compass", 1, 3)
        for what, v, rng in zip(("SIGMA_DEG", "BIAS_DEG", "HZ"), c,
                                (Range(lo=0.0, hi=360.0, lo_open=True), Range(lo=-360.0, hi=360.0),
                                 Range(lo=0.0, hi=1000.0, lo_open=True)), strict=False):
            number(f"--compass {what}", v, rng)
        cfg = replace(cfg, compass_sigma=math.radians(c[0]), compass_bias=math.radians(c[1]) if len(c) > 1 else 0.0,
                      compass_hz=c[2] if len(c) > 2 else None)
    if args.gnss_outage:
        cfg = replace(cfg, outages=tuple(parse_window(w, "--gnss-outage", jump=False) for w in args.gnss_outage))
    if args.gnss_jump:
        cfg = replace(cfg, jumps=tuple(parse_window(w, "--gnss-jump", jump=True) for w in args.gnss_jump))
    if (cfg.outages or cfg.jumps) and cfg.gnss_sigma is None:
        raise ValueError("--gnss-outage / --gnss-jump need --gnss")
    if cfg.odometry is None and cfg.gnss_sigma is None and cfg.compass_sigma is None:
        raise ValueError("nothing to simulate: give --odometry-noise, --gnss, --compass or --preset")
    return cfg


def _degrade(args: argparse.Namespace) -> int:
    _prepare_out(args)
    from ..io import load_log

    cfg = degrade_config(args)
    base = load_log(args.log, lenient=args.lenient)
    log = degrade.degrade(base, cfg, args.seed)
    _save(log, args)
    out = {"scenario": "degrade", "input": str(args.log), "seed": args.seed, "out": str(args.out),
           "records": log.counts(), "t0": log.t0, "t1": log.t1, "simulated": log.meta["simulated"],
           "events": log.meta["events"]}
    for key in ("odometry_arc_residual_m", "odometry_skipped_steps", "replaced", "skipped"):
        if key in log.meta:
            out[key] = log.meta[key]
    emit(args, out)
    return 0
