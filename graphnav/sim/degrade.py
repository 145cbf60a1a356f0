"""``degrade``: simulated sensors derived from a log's ``truth``, added to the log (its scans kept).

The model (docs/datasets.md, "degrade"); every draw comes from one ``numpy`` generator seeded
with ``seed``, so the output is deterministic per seed.

**Wheel odometry** (``OdometryNoise``). Between consecutive truth poses ``p_k -> p_k+1``
(``dt = t_k+1 - t_k > 0``) the unicycle arc of constant ``(v, w)`` (the beacon paper's eq. 3,
what dead reckoning and the smoother integrate) is fitted in closed form. With the step
``d`` expressed in the frame of ``p_k`` and ``dth = wrap(th_k+1 - th_k)``:

    w = dth / dt,     v = (d . u) / (dt * sinc(dth / 2)),   u = (cos(dth/2), sin(dth/2)),

where ``sinc(x) = sin(x) / x``: an arc of turn ``dth`` ends at ``v dt sinc(dth/2) u`` (the chord,
of length ``2 (v/w) sin(w dt / 2)``, at half the turn), so ``v`` is the least-squares fit of the
chord length along ``u`` (signed: reversing gives ``v < 0``). For a true unicycle arc the fit is
exact; the part of ``d`` across ``u`` (sideways slip a unicycle cannot make) is reported in
``meta["odometry_arc_residual_m"]``. The measured values are, per sample (white noise),

    v_m = v (1 + V e1),   w_m = w (1 + W e2) + W0 e3 + b,   e1, e2, e3 ~ N(0, 1),

with ``b`` a constant yaw-rate bias (``bias``, default 0). The records carry the sigmas the
simulator used, ``sigma_v = V |v|`` and ``sigma_w = sqrt((W w)^2 + W0^2)`` (floored at
:data:`SIGMA_V_FLOOR` / :data:`SIGMA_W_FLOOR`, since a sigma must be > 0; the noise drawn is
exactly zero there); the bias ``b`` is not in them (it is the systematic error an estimator
must survive). The record at ``t_k`` holds the control over ``[t_k, t_k+1)`` (zero-order hold,
as dead reckoning reads it); the last truth time repeats the last control (no step follows it).
Steps with ``dt <= 0`` are skipped and counted.

**GNSS** (``gnss_sigma`` [m] per axis): the truth position plus N(0, sigma) per axis, at the truth
times (thinned to at most ``gnss_hz``), none inside an outage window, shifted by ``offset_m`` (in
a direction drawn from the seed) inside a jump window. **Compass** (``compass_sigma``,
``compass_bias`` [rad]): truth yaw + bias + N(0, sigma), at the truth times (thinned to
``compass_hz``).

A window's ``start`` is seconds after the first truth time, or a pair ``(a, b)`` of fractions of
the run: the window is then centred at a time drawn uniformly in ``[a, b]`` of the span. Draw order
(fixed, so presets can reproduce older simulators): random window starts (outages, then jumps),
jump directions, GNSS noise (one (x, y) pair per GNSS time, outages included), compass noise,
odometry noise. :data:`PRESETS` holds ``marina-degraded``, which reproduces
:mod:`graphnav.sim.marina_degraded` draw for draw.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geometry import wrap_angle
from ..log import Gnss, Heading, NavLog, Odometry

SIGMA_V_FLOOR = 1e-3  # m/s
SIGMA_W_FLOOR = 1e-4  # rad/s


@dataclass(frozen=True)
class OdometryNoise:
    """Per-sample white noise: ``v`` and ``w`` are the relative (multiplicative) 1-sigma on v and w,
    ``w0`` the additive 1-sigma on w [rad/s]; ``bias`` a constant additive yaw-rate bias [rad/s]."""

    v: float
    w: float
    w0: float
    bias: float = 0.0


@dataclass(frozen=True)
class Window:
    """``start`` [s after the first truth] or ``(a, b)`` (centre drawn in that fraction of the run),
    ``duration`` [s]; a jump also has ``offset_m`` [m] (direction drawn from the seed)."""

    start: float | tuple[float, float]
    duration: float
    offset_m: float = 0.0


@dataclass(frozen=True)
class DegradeConfig:
    odometry: OdometryNoise | None = None
    gnss_sigma: float | None = None
    gnss_hz: float | None = None
    compass_sigma: float | None = None
    compass_bias: float = 0.0
    compass_hz: float | None = None
    outages: tuple[Window, ...] = ()
    jumps: tuple[Window, ...] = ()
    name: str | None = None
    meta: dict[str, Any] = field(default_factory=dict)


PRESETS: dict[str, DegradeConfig] = {
    # graphnav.sim.marina_degraded: GNSS 3 m at every truth time, a 40 s outage centred in 15-45 % of
    # the run, a 10 s 20 m jump centred in 60-85 %, compass 2 deg with a constant +3 deg bias.
    "marina-degraded": DegradeConfig(
        gnss_sigma=3.0, compass_sigma=math.radians(2.0), compass_bias=math.radians(3.0),
        outages=(Window((0.15, 0.45), 40.0),), jumps=(Window((0.6, 0.85), 10.0, 20.0),),
        name="marina-degraded"),
}


def unicycle_fit(p0: NDArray[np.float64], p1: NDArray[np.float64], dt: float) -> tuple[float, float, float]:
    """The constant ``(v, w)`` arc from pose ``p0`` to ``p1`` over ``dt > 0`` (module docstring) and
    the sideways residual [m] a unicycle cannot reproduce (0 for a true arc)."""
    c, s = math.cos(p0[2]), math.sin(p0[2])
    dx, dy = p1[0] - p0[0], p1[1] - p0[1]
    lx, ly = c * dx + s * dy, -s * dx + c * dy
    dth = float(wrap_angle(p1[2] - p0[2]))
    h = dth / 2.0
    ux, uy = math.cos(h), math.sin(h)
    sinc = math.sin(h) / h if h != 0.0 else 1.0
    v = (lx * ux + ly * uy) / (dt * sinc)
    return v, dth / dt, -lx * uy + ly * ux


def _thin(t: NDArray[np.float64], hz: float | None) -> NDArray[np.intp]:
    """Indices of ``t`` at most ``hz`` apart in rate (greedy from the first; all when None)."""
    if hz is None:
        return np.arange(len(t))
    keep, last = [], -math.inf
    for i, ti in enumerate(t):
        if ti - last >= 1.0 / hz - 1e-9:
            keep.append(i)
            last = ti
    return np.array(keep, dtype=np.intp)


def _windows(ws: tuple[Window, ...], rng: np.random.Generator, t0: float, span: float) -> list[float]:
    starts = []
    for w in ws:
        if isinstance(w.start, tuple):
            starts.append(t0 + rng.uniform(w.start[0], w.start[1]) * span - w.duration / 2)
        else:
            starts.append(t0 + float(w.start))
    return starts


def describe(cfg: DegradeConfig) -> str:
    """One line saying what was simulated."""
    parts = []
    if cfg.gnss_sigma is not None:
        parts.append(f"gnss (sigma {cfg.gnss_sigma:.1f} m" + (", outage" if cfg.outages else "")
                     + (", jump" if cfg.jumps else "") + ")")
    if cfg.compass_sigma is not None:
        parts.append(f"compass (sigma {math.degrees(cfg.compass_sigma):.1f} deg, bias "
                     f"{math.degrees(cfg.compass_bias):.1f} deg)")
    if cfg.odometry is not None:
        o = cfg.odometry
        parts.append(f"odometry (v x (1 + N(0, {o.v:g})), w x (1 + N(0, {o.w:g})) + N(0, "
                     f"{math.degrees(o.w0):g} deg/s)" + (f" + {math.degrees(o.bias):g} deg/s" if o.bias else "")
                     + ")")
    return ", ".join(parts)


def degrade(base: NavLog, cfg: DegradeConfig, seed: int = 0) -> NavLog:
    """``base`` plus the sensors of ``cfg`` simulated from its ``truth`` (module docstring). A kind of
    record ``cfg`` simulates replaces the base log's own records of that kind (counted in
    ``meta["replaced"]``)."""
    tr = base.truth()
    if len(tr) < 2:
        raise ValueError("degrade needs a log with at least two truth records")
    for name, v in (("gnss_sigma", cfg.gnss_sigma), ("compass_sigma", cfg.compass_sigma)):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be finite and > 0, got {v!r}")
    for name, v in (("gnss_hz", cfg.gnss_hz), ("compass_hz", cfg.compass_hz)):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be finite and > 0, got {v!r}")
    o = cfg.odometry
    if o is not None and not all(math.isfinite(x) and x >= 0 for x in (o.v, o.w, o.w0)):
        raise ValueError("odometry noise sigmas must be finite and >= 0")
    if o is not None and not math.isfinite(o.bias):
        raise ValueError("odometry bias must be finite")
    rng = np.random.default_rng(seed)
    t0, t1 = float(tr.t[0]), float(tr.t[-1])
    span = t1 - t0
    o_starts = _windows(cfg.outages, rng, t0, span)
    j_starts = _windows(cfg.jumps, rng, t0, span)
    offsets = []
    for w in cfg.jumps:
        ang = rng.uniform(-math.pi, math.pi)
        offsets.append(w.offset_m * np.array([math.cos(ang), math.sin(ang)]))
    gi = _thin(tr.t, cfg.gnss_hz) if cfg.gnss_sigma is not None else np.zeros(0, dtype=np.intp)
    ci = _thin(tr.t, cfg.compass_hz) if cfg.compass_sigma is not None else np.zeros(0, dtype=np.intp)
    noise_g = rng.normal(0.0, cfg.gnss_sigma, (len(gi), 2)) if cfg.gnss_sigma is not None else None
    noise_c = rng.normal(0.0, cfg.compass_sigma, len(ci)) if cfg.compass_sigma is not None else None
    replaced = {k: len(base.of(k)) for k, on in (("gnss", cfg.gnss_sigma is not None),
                                                   ("heading", cfg.compass_sigma is not None),
                                                   ("odometry", o is not None)) if on and base.of(k)}
    recs = [r for r in base.records if r.kind not in replaced]
    g_pos = {int(i): k for k, i in enumerate(gi)}
    c_pos = {int(i): k for k, i in enumerate(ci)}
    for i in range(len(tr)):
        t = float(tr.t[i])
        x, y, yaw = tr.poses[i]
        if i in g_pos and not any(s <= t < s + w.duration for s, w in zip(o_starts, cfg.outages, strict=True)):
            off: Any = 0.0
            for s, w, d in zip(j_starts, cfg.jumps, offsets, strict=True):
                if s <= t < s + w.duration:
                    off = off + d
            gx, gy = np.array([x, y]) + off + noise_g[g_pos[i]]
            recs.append(Gnss(t, float(gx), float(gy), cfg.gnss_sigma))
        if i in c_pos:
            h = yaw + cfg.compass_bias + noise_c[c_pos[i]]
            recs.append(Heading(t, float(wrap_angle(h)), cfg.compass_sigma))
    meta = dict(base.meta)
    if o is not None:
        odo, info = simulate_odometry(tr.t, tr.poses, o, rng)
        recs += odo
        meta.update(info)
    events: list[dict[str, Any]] = [{"kind": "gnss_outage", "t0": s, "t1": s + w.duration}
                                    for s, w in zip(o_starts, cfg.outages, strict=True)]
    events += [{"kind": "gnss_jump", "t0": s, "t1": s + w.duration, "offset_m": d.tolist()}
               for s, w, d in zip(j_starts, cfg.jumps, offsets, strict=True) if w.offset_m]
    if cfg.compass_sigma is not None and cfg.compass_bias:
        events.append({"kind": "compass_bias", "t0": t0, "t1": t1, "bias_deg": math.degrees(cfg.compass_bias)})
    if o is not None and o.bias:
        events.append({"kind": "yaw_rate_bias", "t0": t0, "t1": t1, "bias_degps": math.degrees(o.bias)})
    meta.update({"name": cfg.name or f"{base.meta.get('name', 'log')}-degraded", "seed": seed,
                 "events": list(base.meta.get("events", [])) + events, "simulated": describe(cfg), **cfg.meta})
    if replaced:
        meta["replaced"] = replaced
    return NavLog.from_unsorted(recs, base.beacons_known, meta)


def simulate_odometry(t: NDArray[np.float64], poses: NDArray[np.float64], noise: OdometryNoise,
                      rng: np.random.Generator) -> tuple[list[Odometry], dict[str, Any]]:
    """Odometry records from truth poses (module docstring) and what to put in ``meta``."""
    fits, times = [], []
    residual, zero_dt = [], 0
    for k in range(len(t) - 1):
        dt = float(t[k + 1] - t[k])
        if not dt > 0.0:
            zero_dt += 1
            continue
        v, w, lat = unicycle_fit(poses[k], poses[k + 1], dt)
        fits.append((v, w))
        times.append(float(t[k]))
        residual.append(lat)
    e = rng.normal(0.0, 1.0, (len(fits), 3))
    out: list[Odometry] = []
    for (v, w), tk, (e1, e2, e3) in zip(fits, times, e, strict=True):
        vm = v * (1.0 + noise.v * e1)
        wm = w * (1.0 + noise.w * e2) + noise.w0 * e3 + noise.bias
        sv = max(noise.v * abs(v), SIGMA_V_FLOOR)
        sw = max(math.hypot(noise.w * w, noise.w0), SIGMA_W_FLOOR)
        out.append(Odometry(tk, vm, wm, sv, sw))
    if out:
        out.append(replace(out[-1], t=float(t[-1])))  # the last time repeats the last control
    r = np.abs(np.array(residual)) if residual else np.zeros(1)
    info = {"odometry_arc_residual_m": {"rms": float(np.sqrt(np.mean(r ** 2))), "max": float(r.max())},
            "odometry_skipped_steps": zero_dt}
    return out, info
