"""Innovation gating shared by the filters (``ekf``, ``ukf``, ``fuzzy-ukf``): a chi-square test on
every GNSS / compass (/ speed) update, and re-initialisation only on sustained evidence.

The rule (docs/ekf.md, *Gating*), per sensor, with the defaults of :data:`GATING_DEFAULTS`:

1. **Test.** The normalised innovation squared ``d2 = nu^T S^-1 nu`` (``S = H P H^T + R``) is
   compared with ``s * chi2.ppf(gate, dof)`` (gate 0.999). ``s`` is the sensor's innovation scale:
   the median of its last ``scale_window`` (50) samples ``d2 / median(chi2(dof))``, never below 1
   (``scale_window=0``: always 1). The samples are the accepted measurements and the *lone*
   rejections, those that agree (2.) with neither neighbour: noise, not a jump. For a consistent
   filter ``s`` = 1 and this is the plain chi-square test; when a sensor is noisier than its
   stated sigma (a receiver's optimistic HDOP; the Solent paper's scenario 2, 20 m GNSS and 5 deg
   compass under a stated 7 m / 0.5 deg) ``s`` grows until its innovations pass, so the gate does
   not starve a filter of honest but under-stated measurements. A jump's measurements agree with
   each other and never enter ``s``: a jump cannot widen the gate that rejects it.
2. **Agreement.** Two measurements agree within their sigmas when the difference of their
   innovations passes the same test with covariance ``R_i + R_j + (H P_i H^T - H P_j H^T)^+``
   (the state's growth in between).
3. **Jumps are rejected for as long as they last.** Consecutive rejections form a *streak*;
   inside it, rejections that agree with the previous one form a *run*. A run that began with a
   *jump on a tracking filter* -- the filter had accepted ``confirm_n`` (3) measurements of this
   sensor, the last within ``confirm_s`` (30 s) before the streak, and the run's first innovation
   does not continue the recently accepted ones (it disagrees, by the unscaled test of 2., with the
   median of the last 5 accepted innovations, covariance ``pi/2 R / 5``) -- is the sensor's fault
   (the vessel cannot teleport: multipath, spoofing, a datum switch): rejected until the streak
   has lasted ``reinit_after_s`` (300 s), or until the run outnumbers the measurements the filter
   accepted since it (re)started (a cold start whose first fixes were the wrong ones; the graph's
   gate has the same rule, graphnav.graph.fix_gate), then believed.
4. **Re-initialise on sustained evidence.** Any other run of ``reinit_n`` (5) measurements that
   agree with each other and not with the estimate re-initialises the measured components (the
   caller sets them to the last measurement, covariance ``s R``, cross-covariances zero): a wrong
   prior, the start, a long outage, an estimate that drifted off (its innovations grew into the
   gate, continuing the accepted ones). Likewise ``reinit_n`` accepted measurements in a row that
   passed only thanks to ``s`` (beyond the unscaled test) and agree with each other: the same
   offset again and again is the estimate's drift (a motion model that misses a current), not noise.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from ..config import option
from ..geometry import se2_between, wrap_angle
from ..graph.chi2 import chi2_ppf


@dataclass
class GateOptions:
    """The innovation gate's options (estimator options of the same names; docs/ekf.md, Gating)."""

    group: ClassVar[str] = "innovation gate"
    gate: float | None = option(0.999, "chi-square probability of the gate (null: every measurement is accepted)")
    reinit_n: int = option(5, "a run of this many measurements that agree with each other and not with the "
                           "estimate re-initialises the filter on them")
    confirm_n: int = option(3, "a jump on a tracking filter (it had accepted this many measurements of the sensor "
                            "within confirm_s before the streak) is rejected until it lasts reinit_after_s")
    confirm_s: float = option(30.0, "the window of confirm_n", unit="s")
    reinit_after_s: float = option(300.0, "a confirmed jump is believed after this long", unit="s")
    scale_window: int = option(50, "the gate's scale: the median of the last this many d2 / median(chi2(dof)), "
                               "never below 1 (0: always 1)")


GATING_DEFAULTS: dict[str, Any] = {f.name: f.default for f in fields(GateOptions)}
"""The gate's options and their defaults (:class:`GateOptions`)."""


@dataclass
class _Sensor:
    window: deque[float]
    accepted: int = 0
    last_accept_t: float = -math.inf
    recent: deque = field(default_factory=lambda: deque(maxlen=5))  # the last accepted (t, nu, R, HPH)
    run: list[tuple[float, NDArray, NDArray, NDArray]] = field(default_factory=list)  # (t, nu, R, HPH)
    streak: int = 0  # consecutive rejections (the runs of agreeing ones lie inside a streak)
    drift: list = field(default_factory=list)  # accepted, but beyond the unscaled test, agreeing in a row
    isolated: float | None = None  # the last rejection's scale sample while it agrees with no neighbour
    tracking: bool = False  # the filter was confirmed when the streak began
    jumped: bool = False  # the current run began with a jump on a tracking filter
    streak_t0: float = 0.0


class InnovationGate:
    """``test(sensor, t, nu, HPH, R, angle=...) -> "accept" | "reject" | "reinit"`` (module docstring).

    ``gate``: chi-square probability (``None``: every measurement is accepted, nothing is tracked).
    ``angle``: the innovation is an angle (differences are wrapped). ``counts`` holds
    ``accepted``, ``rejected`` and ``reinit`` over all sensors.
    """

    def __init__(self, gate: float | None = 0.999, *, reinit_n: int = 5, confirm_n: int = 3,
                 confirm_s: float = 30.0, reinit_after_s: float = 300.0, scale_window: int = 50) -> None:
        if gate is not None and not 0.0 < gate < 1.0:
            raise ValueError(f"gate must be a probability in (0, 1) or null, not {gate!r}")
        if reinit_n < 1 or confirm_n < 0 or scale_window < 0:
            raise ValueError("reinit_n must be >= 1, confirm_n and scale_window >= 0")
        self.gate = gate
        self.reinit_n, self.confirm_n = int(reinit_n), int(confirm_n)
        self.confirm_s, self.reinit_after_s = float(confirm_s), float(reinit_after_s)
        self.scale_window = int(scale_window)
        self.sensors: dict[str, _Sensor] = {}
        self.counts = {"accepted": 0, "rejected": 0, "reinit": 0}
        self._limit: dict[int, float] = {}
        self._median: dict[int, float] = {}

    def limit(self, dof: int) -> float:
        """``chi2.ppf(gate, dof)``, computed once per dof."""
        if dof not in self._limit:
            self._limit[dof] = chi2_ppf(self.gate if self.gate is not None else 0.999, dof)
        return self._limit[dof]

    def _chi2_median(self, dof: int) -> float:
        if dof not in self._median:
            self._median[dof] = chi2_ppf(0.5, dof)
        return self._median[dof]

    def _state(self, sensor: str) -> _Sensor:
        st = self.sensors.get(sensor)
        if st is None:
            st = self.sensors[sensor] = _Sensor(deque(maxlen=max(1, self.scale_window)))
        return st

    def scale(self, sensor: str) -> float:
        """The sensor's innovation scale ``s`` >= 1 (1 until it has accepted measurements)."""
        st = self.sensors.get(sensor)
        if st is None or not st.window or self.scale_window <= 1:
            return 1.0
        return max(1.0, float(np.median(st.window)))

    def confirmed(self, sensor: str, t: float) -> bool:
        """Whether the filter is tracking this sensor: ``confirm_n`` accepted so far, the last within ``confirm_s``."""
        st = self._state(sensor)
        return st.accepted >= self.confirm_n and t - st.last_accept_t <= self.confirm_s

    def test(self, sensor: str, t: float, nu: NDArray, HPH: NDArray, R: NDArray, *, angle: bool = False) -> str:
        """The verdict on one measurement of ``sensor`` at time ``t`` [s]: innovation ``nu``, ``H P H^T``
        and ``R`` (the module docstring's rule); on ``"reinit"`` the caller re-initialises."""
        if self.gate is None:
            self.counts["accepted"] += 1
            return "accept"
        nu = np.atleast_1d(np.asarray(nu, dtype=float))
        HPH, R = np.atleast_2d(HPH), np.atleast_2d(R)
        dof = nu.shape[0]
        st = self._state(sensor)
        s = self.scale(sensor)
        d2 = float(nu @ np.linalg.solve(HPH + R, nu))
        entry = (t, nu, R, HPH)
        isolated, st.isolated = st.isolated, None
        if d2 <= s * self.limit(dof):
            if len(st.run) == 1 and isolated is not None:  # a lone rejection between accepted ones: noise
                st.window.append(isolated)
            if s > 1.0 and d2 > self.limit(dof):  # passes only thanks to the scale: drift or noise?
                if st.drift and self._agree(entry, st.drift[-1], 1.0, angle):
                    st.drift.append(entry)
                else:
                    st.drift = [entry]
                if len(st.drift) >= self.reinit_n:  # the same offset again and again: the estimate drifted
                    return self._reinit(st, t)
            else:
                st.drift.clear()
            st.window.append(d2 / self._chi2_median(dof))
            st.accepted += 1
            st.last_accept_t = t
            st.recent.append(entry)
            st.run.clear()
            st.streak = 0
            self.counts["accepted"] += 1
            return "accept"
        if st.streak == 0:
            st.tracking = self.confirmed(sensor, t)  # was the filter tracking this sensor when rejections began?
            st.streak_t0 = t
        st.streak += 1
        if st.run and self._agree(entry, st.run[-1], s, angle):
            st.run.append(entry)
        else:
            if len(st.run) == 1 and st.isolated is not None:
                # the previous rejection agreed with neither neighbour: noise, not a jump; it tells
                # how noisy the sensor is (so a sensor noisier than its sigma is learnt, not starved)
                st.window.append(st.isolated)
            st.run = [entry]
            # a jump: the filter was tracking this sensor and the innovation broke away from the recently
            # accepted ones at once. Innovations that grew into the gate instead (they continue the
            # accepted ones) mean the estimate drifted off: the filter, not the sensor, is wrong.
            st.jumped = st.tracking and not self._continues(entry, st.recent, angle)
        if len(st.run) == 1:
            st.isolated = d2 / self._chi2_median(dof)  # its scale sample, if no neighbour agrees with it
        if len(st.run) >= self.reinit_n and (not st.jumped or t - st.streak_t0 >= self.reinit_after_s
                                             or len(st.run) > st.accepted):
            return self._reinit(st, t)
        self.counts["rejected"] += 1
        return "reject"

    def _reinit(self, st: _Sensor, t: float) -> str:
        st.run.clear()
        st.drift.clear()
        st.recent.clear()  # innovations of the old state
        st.streak = 0
        st.accepted = 1  # the new state rests on this measurement alone: confirmed again only by more
        st.last_accept_t = t
        self.counts["reinit"] += 1
        return "reinit"

    def _continues(self, entry: tuple, recent: deque, angle: bool) -> bool:
        """Whether a rejected innovation continues the recently accepted ones: it agrees (as in
        :meth:`_agree`) with their component-wise median, whose covariance is taken as
        ``pi/2 R / n`` (the median's efficiency; one accepted outlier does not move it)."""
        if not recent:
            return False
        nus = np.array([r[1] for r in recent])
        ref = recent[-1]
        if angle:  # median of the wrapped differences to the last one
            d = wrap_angle(nus - ref[1])
            med = ref[1] + np.median(d, axis=0)
        else:
            med = np.median(nus, axis=0)
        return self._agree(entry, (ref[0], med, ref[2] * (0.5 * math.pi / len(recent)), ref[3]), 1.0, angle)

    def _agree(self, a: tuple, b: tuple, s: float, angle: bool) -> bool:
        """Whether two rejected measurements agree with each other within their sigmas."""
        d = a[1] - b[1]
        if angle:
            d = wrap_angle(d)
        grow = a[3] - b[3]
        w, v = np.linalg.eigh(0.5 * (grow + grow.T))
        C = a[2] + b[2] + (v * np.maximum(w, 0.0)) @ v.T
        return float(d @ np.linalg.solve(C, d)) <= s * self.limit(d.shape[0])

    def info(self) -> dict[str, Any]:
        """Counts and the innovation scale per sensor (for ``RunResult.info``)."""
        return {**self.counts, "gate": self.gate,
                "innovation_scale": {k: round(self.scale(k), 3) for k in sorted(self.sensors)}}


def reinit_block(x: NDArray, P: NDArray, idx: NDArray | list[int], z: NDArray, R: NDArray) -> None:
    """Re-initialise the state components ``idx`` in place: ``x[idx] = z``, ``P[idx, idx] = R``,
    their cross-covariances with the rest 0 (the rest keeps its marginal; P stays PSD)."""
    idx = np.asarray(idx)
    x[idx] = z
    P[idx, :] = 0.0
    P[:, idx] = 0.0
    P[np.ix_(idx, idx)] = np.atleast_2d(R)


def consistent(prior: NDArray[np.float64], p_cov: NDArray[np.float64], meas: NDArray[np.float64],
               m_cov: NDArray[np.float64], weak: NDArray[np.float64] | None = None, p: float = 0.999) -> bool:
    """Whether ``meas`` can be the same pose (or increment) as ``prior`` (the inputs of
    :func:`~graphnav.scan.imu_guess.fuse_se2`; icp-dr's and scan-to-map's gate on a match): their
    difference's Mahalanobis distance under both covariances within the chi-square bound ``p`` of the
    directions the measurement sees (3 less the rank of ``weak``); False for a non-finite input."""
    r = np.asarray(m_cov, dtype=float)
    dof = 3
    if weak is not None:
        w = np.asarray(weak, dtype=float)
        r = r + 1e8 * (w @ w.T)
        dof -= int(np.linalg.matrix_rank(w, tol=1e-6))
    if dof <= 0:
        return True
    xi = se2_between(np.asarray(prior, dtype=float), np.asarray(meas, dtype=float))
    both = np.asarray(p_cov, dtype=float) + r
    if not (np.all(np.isfinite(xi)) and np.all(np.isfinite(both))):
        return False
    try:
        d2 = float(xi @ np.linalg.solve(both, xi))
    except np.linalg.LinAlgError:
        return False
    return d2 <= chi2_ppf(float(p), dof)
