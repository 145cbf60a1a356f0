"""The Solent waypoint mission of Liu, Liu & Bucknall (IEEE Access 2019), section V.

A USV starts at (765, 728) m at 1 m/s on nautical heading 210 deg, steers toward the waypoints
(650, 385), (320, 190) and the end point (30, 250) with a waypoint clearance radius ``d`` (eq. 29),
and is set by a tidal current of constant speed whose direction follows the coastline (eq. 30).
Sensors are sampled every T = 1 s:

* ``imu``: body-frame acceleration and yaw rate, eq. 5-6, with Table 3's biases and noise. The
  record at t_k holds the mean over (t_{k-1}, t_k] (a delta-velocity / delta-angle IMU output).
  **Calibration** (the paper: "the constant bias ... can be determined by a calibration process
  prior to operation"): the log holds ``raw - b_hat`` where ``b_hat = b - e`` and the residual
  ``e ~ N(0, (calib_residual * b)^2)`` per channel (default 10 % of Table 3's bias). True bias,
  estimate and residual are in ``meta["imu"]``; ``calib_residual=1`` with ``--no-calibration``
  gives the raw (uncalibrated) IMU.
* ``gnss`` (eq. 7) and ``heading`` (compass, eq. 8): white noise per scenario: (1) Table 3,
  (2) GNSS 20 m, compass 5 deg, (3) scenario 1 for the first ``switch_step`` = 300 steps, then 2.
  The records' ``sigma`` is the a-priori (datasheet) value of Table 2 in every scenario (the
  filters' knowledge); the true noise is in ``meta["noise"]``.
* ``odometry``: speed over ground ``v`` (the log format's meaning: a Doppler log / SOG sensor) and
  the rate of turn ``w`` of a ROT gyro, white noise ``sigma_v`` = 0.05 m/s, ``sigma_w`` = 0.1 deg/s,
  so odometry-driven estimators (EKF, smoothers) can run on the log. The *direction* of the ground
  velocity (course, which differs from the heading by the crab angle the current causes) is not
  in it (``meta["odometry"]`` says so: :data:`graphnav.log.ODOMETRY_FROM_ROT`, no odometer).
  ``odometry="fore_aft"`` writes the fore-aft component of the ground velocity instead.
* ``truth`` at every step, a ``pose_prior`` at t = 0 (the known start berth, 1 m / 1 deg).

The numeric core :func:`simulate_solent` returns a :class:`NavLog`; the CLI is in :mod:`graphnav.commands.simulate`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from ..geometry import heading_deg_to_yaw, wrap_angle
from ..log import ODOMETRY_FROM_ROT, Gnss, Heading, Imu, NavLog, Odometry, PosePrior, Truth

START = (765.0, 728.0)
WAYPOINTS = ((650.0, 385.0), (320.0, 190.0), (30.0, 250.0))
# A schematic coastline along which the tidal stream runs (NE -> SW, the mission's direction); the
# current direction at a point is the inverse-distance-weighted direction of its segments. This is a
# smooth stand-in for the paper's Fig. 5(a) flow field, not chart data.
COASTLINE = np.array([[900.0, 640.0], [760.0, 330.0], [560.0, 170.0], [300.0, 110.0], [-50.0, 180.0]])

TABLE3_ACC_BIAS = (0.03, 0.02)  # m/s^2
TABLE3_ACC_STD = 0.0042  # m/s^2 (Table 3 "variance" column, read as a 1-sigma value in its units)
TABLE3_GYRO_BIAS_DEG = 0.28  # deg/s
TABLE3_GYRO_STD_DEG = 0.036  # deg/s
NOISE = {  # (gnss_x, gnss_y [m], compass [deg]) true white-noise 1-sigma per scenario
    1: (8.0, 7.0, 0.8),
    2: (20.0, 20.0, 5.0),
}
DATASHEET_GNSS = 7.0  # m, Table 2 (6 m / 7 m per axis; the record has one sigma: the larger)
DATASHEET_COMPASS_DEG = 0.5


@dataclass
class SolentConfig:
    """Everything that defines one simulated mission (stored in ``meta["config"]``)."""

    scenario: int = 1
    seed: int = 0
    dt: float = 1.0  # sensor sample time [s]
    substeps: int = 10  # truth integration steps per sample
    speed: float = 1.0  # USV speed through the water [m/s]
    current_speed: float = 0.85  # tidal stream [m/s] (paper: 0.7 flood .. 1.0 ebb)
    clearance: float = 20.0  # waypoint clearance radius d [m] (eq. 29)
    heading_gain: float = 0.1  # yaw-rate command per rad of heading error [1/s]
    max_rate_deg: float = 3.0  # yaw-rate limit [deg/s]
    rate_tau: float = 2.0  # yaw-rate response time constant [s]
    max_steps: int = 2500
    switch_step: int = 300  # scenario 3: noise grows after this many steps
    calibrate: bool = True
    calib_residual: float = 0.1  # residual bias after calibration, as a fraction of Table 3's bias
    odo_sigma_v: float = 0.05
    odo_sigma_w_deg: float = 0.1
    odometry: str = "sog"  # or "fore_aft"
    extra: dict = field(default_factory=dict)


_SEGS = [(float(a[0]), float(a[1]), float(b[0] - a[0]), float(b[1] - a[1]))
         for a, b in zip(COASTLINE[:-1], COASTLINE[1:], strict=True)]


def current_direction(p) -> float:
    """Direction delta [rad, CCW from east] of the tidal stream at position p (eq. 30): the
    inverse-squared-distance weighted mean of the coastline segments' unit directions."""
    px, py = float(p[0]), float(p[1])
    ux = uy = 0.0
    for ax, ay, dx, dy in _SEGS:
        L2 = dx * dx + dy * dy
        s = min(1.0, max(0.0, ((px - ax) * dx + (py - ay) * dy) / L2))
        ex, ey = ax + s * dx - px, ay + s * dy - py
        w = 1.0 / ((ex * ex + ey * ey + 1e2) ** 2 * math.sqrt(L2))
        ux += w * dx
        uy += w * dy
    return math.atan2(uy, ux)


def _truth(cfg: SolentConfig) -> dict[str, np.ndarray]:
    """Integrate the mission; returns per-sample truth and per-interval mean body accel / yaw rate."""
    h = cfg.dt / cfg.substeps
    px, py = START
    psi = float(heading_deg_to_yaw(210.0))
    r = 0.0
    wp = 0
    vc, u = cfg.current_speed, cfg.speed
    rmax = math.radians(cfg.max_rate_deg)

    def ground_vel(px: float, py: float, psi: float) -> tuple[float, float]:
        d = current_direction((px, py))
        return u * math.cos(psi) + vc * math.cos(d), u * math.sin(psi) + vc * math.sin(d)  # eq. 30

    vx, vy = ground_vel(px, py, psi)
    T = [0.0]
    P, PSI, V = [(px, py)], [psi], [(vx, vy)]
    ACC, RATE, WPT = [], [], []
    for k in range(1, cfg.max_steps + 1):
        abx = aby = dpsi = 0.0
        for _ in range(cfg.substeps):
            tx, ty = WAYPOINTS[wp]
            err = wrap_angle(math.atan2(ty - py, tx - px) - psi)
            r_cmd = min(rmax, max(-rmax, cfg.heading_gain * err))
            r += (r_cmd - r) * h / cfg.rate_tau
            psi_new = psi + r * h
            px, py = px + vx * h, py + vy * h
            vx_new, vy_new = ground_vel(px, py, psi_new)
            anx, any_ = (vx_new - vx) / h, (vy_new - vy) / h
            psi_mid = 0.5 * (psi + psi_new)
            c, s = math.cos(psi_mid), math.sin(psi_mid)
            abx += (c * anx + s * any_) * h  # nav -> body frame
            aby += (-s * anx + c * any_) * h
            dpsi += r * h
            psi, vx, vy = psi_new, vx_new, vy_new
            if math.hypot(WAYPOINTS[wp][0] - px, WAYPOINTS[wp][1] - py) < cfg.clearance:  # eq. 29
                wp += 1
                if wp == len(WAYPOINTS):
                    break
        T.append(k * cfg.dt)
        P.append((px, py))
        PSI.append(psi)
        V.append((vx, vy))
        ACC.append((abx / cfg.dt, aby / cfg.dt))
        RATE.append(dpsi / cfg.dt)
        WPT.append(wp)
        if wp == len(WAYPOINTS):
            break
    return {"t": np.array(T), "p": np.array(P), "psi": np.array(PSI), "v": np.array(V),
            "acc_b": np.array(ACC), "rate": np.array(RATE), "wp": np.array(WPT)}


def noise_sigmas(scenario: int, n: int, switch_step: int) -> np.ndarray:
    """(n, 3) true 1-sigma of (gnss x [m], gnss y [m], compass [rad]) per sample for a scenario."""
    if scenario not in (1, 2, 3):
        raise ValueError(f"scenario must be 1, 2 or 3, not {scenario!r}")
    s1 = np.array(NOISE[1]) * [1, 1, math.pi / 180]
    s2 = np.array(NOISE[2]) * [1, 1, math.pi / 180]
    out = np.tile(s1 if scenario == 1 else s2, (n, 1))
    if scenario == 3:
        out[:switch_step] = s1
    return out


def imu_measurements(rng: np.random.Generator, acc_b: np.ndarray, rate: np.ndarray, *, calibrate: bool = True,
                     calib_residual: float = 0.1) -> tuple[np.ndarray, np.ndarray, dict]:
    """IMU records from the true body acceleration ``acc_b`` (m, 2) and yaw rate ``rate`` (m,): eq. 5-6
    with Table 3's biases and white noise, then the calibration (the module docstring). Returns the
    logged ``(acc (m, 2), gyro (m,), meta["imu"])``. Draws, in this order: the calibration residual
    (3, only when ``calibrate``), the accelerometer noise (m, 2), the gyro noise (m). Shared by every
    simulator with an IMU (``solent``, ``harbour``), so they have one noise model."""
    m = len(rate)
    b_acc = np.array(TABLE3_ACC_BIAS)
    b_gyr = math.radians(TABLE3_GYRO_BIAS_DEG)
    bias = np.array([*b_acc, b_gyr])
    frac = calib_residual if calibrate else 1.0
    resid = rng.normal(0.0, 1.0, 3) * frac * np.abs(bias) if calibrate else bias.copy()
    b_hat = bias - resid if calibrate else np.zeros(3)
    acc = acc_b + b_acc + rng.normal(0.0, TABLE3_ACC_STD, (m, 2)) - b_hat[:2]
    gyr = rate + b_gyr + rng.normal(0.0, math.radians(TABLE3_GYRO_STD_DEG), m) - b_hat[2]
    meta = {
        "record_semantics": "mean over (t_{k-1}, t_k], stamped t_k; calibrated (bias estimate removed)",
        "bias_true": bias.tolist(), "bias_estimate": b_hat.tolist(),
        "bias_residual": resid.tolist(), "calib_residual_frac": frac,
        "acc_std": TABLE3_ACC_STD, "gyro_std": math.radians(TABLE3_GYRO_STD_DEG),
    }
    return acc, gyr, meta


def simulate_solent(cfg: SolentConfig | None = None, **kw) -> NavLog:
    """Simulate one Solent mission (section V) and return its log (see the module docstring)."""
    cfg = cfg or SolentConfig(**kw)
    rng = np.random.default_rng(cfg.seed)
    tr = _truth(cfg)
    t, n = tr["t"], len(tr["t"])
    acc, gyr, imu_meta = imu_measurements(rng, tr["acc_b"], tr["rate"], calibrate=cfg.calibrate,
                                          calib_residual=cfg.calib_residual)
    # GNSS / compass, eq. 7-8
    sig = noise_sigmas(cfg.scenario, n, cfg.switch_step)
    gx = tr["p"][:, 0] + rng.normal(0.0, 1.0, n) * sig[:, 0]
    gy = tr["p"][:, 1] + rng.normal(0.0, 1.0, n) * sig[:, 1]
    hd = wrap_angle(tr["psi"] + rng.normal(0.0, 1.0, n) * sig[:, 2])
    # odometry: speed over ground (or its fore-aft component) + rate of turn
    if cfg.odometry == "sog":
        v_odo = np.hypot(tr["v"][:, 0], tr["v"][:, 1])
    elif cfg.odometry == "fore_aft":
        v_odo = np.cos(tr["psi"]) * tr["v"][:, 0] + np.sin(tr["psi"]) * tr["v"][:, 1]
    else:
        raise ValueError(f"odometry must be 'sog' or 'fore_aft', not {cfg.odometry!r}")
    sw = math.radians(cfg.odo_sigma_w_deg)
    odo_v = v_odo + rng.normal(0.0, cfg.odo_sigma_v, n)
    rate = np.concatenate([tr["rate"][:1], tr["rate"]])  # yaw rate over the interval ending at t_k
    odo_w = rate + rng.normal(0.0, sw, n)

    recs: list = [PosePrior(0.0, float(START[0]), float(START[1]), float(tr["psi"][0]), 1.0,
                            math.radians(1.0))]
    sd_c = math.radians(DATASHEET_COMPASS_DEG)
    for k in range(n):
        tk = float(t[k])
        recs.append(Truth(tk, float(tr["p"][k, 0]), float(tr["p"][k, 1]), float(wrap_angle(tr["psi"][k]))))
        recs.append(Gnss(tk, float(gx[k]), float(gy[k]), DATASHEET_GNSS))
        recs.append(Heading(tk, float(hd[k]), sd_c))
        recs.append(Odometry(tk, float(odo_v[k]), float(odo_w[k]), cfg.odo_sigma_v, sw))
        if k >= 1:
            recs.append(Imu(tk, float(acc[k - 1, 0]), float(acc[k - 1, 1]), float(gyr[k - 1])))
    meta = {
        "name": f"solent-s{cfg.scenario}-seed{cfg.seed}",
        "source": "graphnav.sim.solent",
        "paper": "Liu, Liu, Bucknall, IEEE Access 7 (2019) 46071-46083, section V",
        "scenario": cfg.scenario,
        "config": asdict(cfg),
        "imu": imu_meta,
        "noise": {"gnss_x": sig[:, 0].tolist(), "gnss_y": sig[:, 1].tolist(), "compass": sig[:, 2].tolist()},
        "initial_velocity": tr["v"][0].tolist(),
        "waypoints_reached": int(tr["wp"][-1]),
        **({"odometry": ODOMETRY_FROM_ROT} if cfg.odometry == "sog" else {}),  # a SOG sensor and a ROT gyro
        "events": ([{"kind": "noise_increase", "t0": float(t[min(cfg.switch_step, n - 1)]),
                     "t1": float(t[-1])}] if cfg.scenario == 3 else []),
    }
    return NavLog.from_unsorted(recs, meta=meta)
