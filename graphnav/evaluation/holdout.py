"""Scoring a log without truth: GNSS hold-out.

Every ``every_s`` seconds the last ``length_s`` seconds of GNSS (position fixes and GNSS velocity)
are withheld from the estimators; each estimate is then scored against the withheld position fixes:
the error at the end of each window (the last withheld fix, where an estimator that coasted through
the window is farthest from its last fix), their RMSE over the windows, and beside it the fixes' own
sigma (a hold-out error near it is as good as the fixes can tell). Pure: no files, no printing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..log import NavLog
from ..trajectory import Trajectory
from .metrics import gnss_residuals

WITHHELD_KINDS = ("gnss", "gnss_velocity")


@dataclass(frozen=True)
class HoldoutSpec:
    """``--holdout-gnss EVERY,LENGTH``: every ``every_s`` seconds of log time, withhold ``length_s`` seconds of GNSS."""

    every_s: float
    length_s: float

    @classmethod
    def parse(cls, text: str) -> HoldoutSpec:
        """``"300,60"`` -> ``HoldoutSpec(300.0, 60.0)``; a ``ValueError`` naming the option otherwise."""
        parts = [p.strip() for p in str(text).split(",")]
        try:
            every, length = (float(p) for p in parts)
        except ValueError:
            raise ValueError(f"--holdout-gnss {text!r}: expected EVERY,LENGTH in seconds, e.g. 300,60") from None
        if not (math.isfinite(every) and math.isfinite(length) and 0 < length < every <= 1e7):
            raise ValueError(f"--holdout-gnss {text!r}: need 0 < LENGTH < EVERY <= 1e7 s")
        return cls(every, length)

    def windows(self, t0: float, t1: float) -> list[tuple[float, float]]:
        """The withheld windows ``[k·every - length, k·every)`` after ``t0`` (k = 1, 2, ...) that end
        inside the log: the estimators have ``every - length`` seconds of GNSS before the first one."""
        out = []
        k = 1
        while t0 + k * self.every_s <= t1 and k <= 100_000:
            end = t0 + k * self.every_s
            out.append((end - self.length_s, end))
            k += 1
        return out


def _inside(t: NDArray, windows: list[tuple[float, float]]) -> NDArray:
    m = np.zeros(len(t), bool)
    for a, b in windows:
        m |= (t >= a) & (t < b)
    return m


@dataclass
class Holdout:
    """A hold-out plan applied to a log: ``log`` is what the estimators see (GNSS withheld in
    ``windows``); ``fixes`` the withheld position fixes (``t``, ``x``, ``y``, ``sigma``) and ``ends``
    the index of each window's last withheld fix (windows without a fix, e.g. in a logger gap, are
    not scored). ``silent``: per scored window, whether the log holds no other record inside it (only
    GNSS was logged then): an estimator has only its motion model there -- a coasting navigator's
    predictions, a smoother's track between the poses around the window (:meth:`score`
    ``smoothed``), else its last estimate before (a causal estimator silent there: the distance
    sailed) --, so the window tells little of the sensors; ``rmse_informative_m`` leaves them out."""

    spec: HoldoutSpec
    windows: list[tuple[float, float]]
    log: NavLog
    fixes: dict[str, NDArray]
    ends: list[int]
    withheld: dict[str, int]
    silent: list[bool] = field(default_factory=list)

    @property
    def scored_windows(self) -> int:
        return len(self.ends)

    def score(self, traj: Trajectory | None, smoothed: bool = False) -> dict[str, Any]:
        """``end_errors_m`` (one per scored window: the estimate against the window's last fix),
        ``rmse_m`` and ``max_m`` over them, ``mean_m`` over every withheld fix, ``nis_mean`` (the
        withheld fixes' normalised residual against the estimate's covariance plus the fix's, 2 dof).
        ``smoothed``: ``traj`` is a smoother's final track: across a hole in it (a silent window) it
        is read between its poses on either side, which its motion factor ties (its own answer
        there; :func:`~graphnav.evaluation.metrics.gnss_residuals` ``bridge``); an online or causal
        track is read as it was then: its last estimate before the hole (a coasting navigator has
        its own predictions inside)."""
        nan = float("nan")
        if traj is None or not len(traj) or not self.ends:
            return {"end_errors_m": [], "rmse_m": nan, "max_m": nan, "mean_m": nan, "nis_mean": None, "scored": 0}
        f = self.fixes
        r = gnss_residuals(traj, f["t"], np.column_stack([f["x"], f["y"]]), f["sigma"], bridge=smoothed)
        err = np.full(len(f["t"]), np.nan)
        err[r["i_fix"]] = r["residual_m"]
        all_ends = err[self.ends]
        ends = all_ends[np.isfinite(all_ends)]
        loud = all_ends[np.isfinite(all_ends) & ~np.asarray(self.silent or [False] * len(self.ends), bool)]
        nis = r["nis"]
        return {"end_errors_m": [float(v) for v in err[self.ends]],
                "rmse_m": float(np.sqrt(np.mean(ends ** 2))) if ends.size else nan,
                "rmse_informative_m": float(np.sqrt(np.mean(loud ** 2))) if loud.size else nan,
                "max_m": float(np.max(ends)) if ends.size else nan,
                "mean_m": float(np.nanmean(err)) if np.isfinite(err).any() else nan,
                "nis_mean": float(np.mean(nis)) if nis is not None and nis.size else None,
                "scored": int(ends.size)}

    def score_online(self, traj: Trajectory) -> dict[str, Any]:
        """A smoother's online track scored as it was then (:meth:`score`): ``online_rmse_m`` and, without the
        silent windows, ``online_rmse_informative_m``."""
        on = self.score(traj)
        return {"online_rmse_m": on["rmse_m"], "online_rmse_informative_m": on["rmse_informative_m"]}

    def describe(self) -> dict[str, Any]:
        """The plan as JSON: windows, how many fixes were withheld, and the sigma of the scored fixes."""
        s = self.fixes["sigma"][self.ends] if self.ends else np.zeros(0)
        return {"every_s": self.spec.every_s, "length_s": self.spec.length_s,
                "windows": [[a, b] for a, b in self.windows], "scored_windows": self.scored_windows,
                "withheld": dict(self.withheld),
                "silent_windows": int(sum(self.silent)),
                "fix_sigma_m": float(np.median(s)) if s.size else None}


def withhold(log: NavLog, spec: HoldoutSpec) -> Holdout:
    """Apply ``spec`` to ``log``: the log without GNSS in the windows, and the withheld fixes."""
    if not log.records:
        raise ValueError("--holdout-gnss: the log is empty")
    wins = spec.windows(float(log.t0), float(log.t1))
    if not wins:
        raise ValueError(f"--holdout-gnss {spec.every_s:g},{spec.length_s:g}: the log lasts "
                         f"{log.t1 - log.t0:.0f} s, shorter than one period ({spec.every_s:g} s)")
    if not log.of("gnss"):
        raise ValueError("--holdout-gnss: the log has no GNSS fixes to withhold")
    c = log.columns("gnss")
    t = np.asarray(c["t"], float)
    sel = _inside(t, wins)
    fixes = {"t": t[sel], "x": np.asarray(c["x"], float)[sel], "y": np.asarray(c["y"], float)[sel],
             "sigma": np.asarray(c["sigma"], float)[sel]}
    others = np.sort(np.array([r.t for r in log.records if r.kind not in (*WITHHELD_KINDS, "truth")], dtype=float))
    ends, silent = [], []
    for a, b in wins:
        idx = np.flatnonzero((fixes["t"] >= a) & (fixes["t"] < b))
        if idx.size:
            ends.append(int(idx[-1]))
            silent.append(bool(np.searchsorted(others, b) == np.searchsorted(others, a)))
    withheld = {k: 0 for k in WITHHELD_KINDS}

    def held(r: Any) -> bool:
        if r.kind in WITHHELD_KINDS and any(a <= r.t < b for a, b in wins):
            withheld[r.kind] += 1
            return True
        return False

    return Holdout(spec, wins, log.without(held), fixes, ends, withheld, silent)


def ranking(scores: dict[str, dict[str, Any]]) -> list[str]:
    """Estimator names by hold-out RMSE, smallest first (those without a figure left out)."""
    ok = [(s["rmse_m"], n) for n, s in scores.items() if isinstance(s.get("rmse_m"), float)
          and math.isfinite(s["rmse_m"])]
    return [n for _, n in sorted(ok)]
