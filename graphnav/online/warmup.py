"""Live mode's motion model chosen from the stream itself, as an offline run chooses it from its log.

Offline, ``motion="auto"`` is decided from the whole log (:func:`graphnav.graph.smoother_config.auto_motion`
in :func:`graphnav.graph.navigator.log_inputs`): an IMU gives the IMU graph, a vessel's instruments
(heading with GNSS velocity or water speed; no IMU, odometer or LiDAR; rate of turn + SOG is no
odometer) the Pose3 vessel graph, anything else the Pose2 graph. A live stream has no log to read
first, so :class:`WarmUp` holds the first records back (the **warm-up**), then decides with the same
function on them, builds the :class:`~graphnav.graph.navigator.Navigator` with the same arguments
``log_inputs`` gives an offline run of those records (the vessel model's position walk estimated from
them by :func:`graphnav.graph.position_walk.position_walk` when they are enough, else the documented
default), hands it every held record in order, and from then on passes each record straight through.

The warm-up ends at the first record for which (stream time ``t``, the records' own stamps):

* an IMU record has come: nothing later can change the choice (``auto_motion`` picks the IMU graph
  whatever else the stream carries); or
* ``--warmup S`` given: ``t >= t_fix + S`` (``t_fix`` the first GNSS fix; ``S = 0``: at the first fix); or
* by default: a fix has come, every kind seen so far has been seen at least twice (so that its rate is
  known), and ``t >= t_fix + WARMUP_PERIODS x`` the longest mean interval of those kinds, at least
  :data:`MIN_PERIOD_S` (1 s, the standards' slowest navigation rate): the slowest instrument has had two
  of its periods to show itself after the first fix (a 1 Hz NMEA 0183 stream or a 10 Hz NMEA 2000 bus:
  2 s; a kind slower than every kind seen and absent for that long is not waited for); or
* a bound: ``MAX_WARMUP_S`` of stream time since the first record (``S`` if longer), or
  ``MAX_WARMUP_RECORDS`` records held (memory).

The vessel graph's position random walk (``imu.vessel_position_walk``: how far the fixes wander from
the integrated velocity) is, offline, estimated from the whole log; live it starts from the warm-up's
records or the documented default (``integration_sigma``) and is estimated again from the stream's fixes
and GNSS velocities as they come (:class:`WalkTracker`; the vessel factors made from then on take it),
unless ``-O imu.vessel_position_walk=W`` gives it. So the live graph converges to the offline run's.

Nothing is lost: every held record goes to the navigator, and the estimates it makes from them are
published at once (in time order, before the one of the record that ended the warm-up; their latency
is not timed: :attr:`WarmUp.coasted_out`). While the warm-up lasts nothing is published or coasted.
A kind first seen after the warm-up that would have changed the choice is warned about once and named
in :meth:`WarmUp.motion_choice` (``motion_changed_by``); the graph is not rebuilt. An explicit
``-O motion=...`` skips the warm-up (:func:`live_estimator`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from ..config import given_option
from ..graph.navigator import Navigator, log_inputs
from ..graph.position_walk import WALK_EVERY_S, WalkTracker
from ..graph.smoother_config import VESSEL_KINDS, SmootherConfig, auto_motion
from ..log import ODOMETRY_FROM_ROT, NavLog, Record, odometry_is_rot
from ..result import Estimate, OnlineEstimator

log_ = logging.getLogger("graphnav.live")

#: the default warm-up: this many of the slowest kind's record intervals after the first fix
WARMUP_PERIODS = 2.0
#: [s] ... the slowest kind's interval taken as at least this: the standards' slowest navigation rate (NMEA 0183
#: instruments send once a second; NMEA 2000 GNSS position data 129029 and speed through water 128259 are 1 Hz),
#: so a bus of fast PGNs still waits for a 1 Hz kind
MIN_PERIOD_S = 1.0
#: [s] of stream time since the first record: the warm-up ends by then whatever has come (a stream without a fix)
MAX_WARMUP_S = 30.0
#: records held at most (a memory bound: 30 s of a 10 Hz bus with ~30 kinds)
MAX_WARMUP_RECORDS = 10_000
def motion_reason(motion: str, kinds: set[str], rot_odometry: bool) -> str:
    """Why :func:`auto_motion` picked ``motion`` from the record ``kinds`` (words for the log and summary)."""
    if motion == "imu":
        return "IMU records: the IMU graph (Pose3 + preintegration)"
    vessel_kinds = sorted(kinds & set(VESSEL_KINDS))
    if motion == "vessel":
        rot = "; its odometry is rate of turn + SOG, no odometer" if rot_odometry and "odometry" in kinds else ""
        return f"a vessel's instruments (heading + {' + '.join(vessel_kinds)}; no IMU, odometer or LiDAR{rot})"
    blocking = sorted(kinds & {"scan", "cloud"} | ({"odometry"} & kinds if not rot_odometry else set()))
    if blocking:
        return f"{' + '.join(blocking)} records: the Pose2 graph (odometry, scan matching, constant velocity)"
    missing = [what for what, ok in (("a heading", "heading" in kinds),
                                     ("GNSS velocity or water speed", bool(vessel_kinds))) if not ok]
    return f"no {' and no '.join(missing)}: the Pose2 graph (odometry, constant velocity)"


class WarmUpRule:
    """When the warm-up ends (the module docstring): ``add(rec)`` returns the reason once it has."""

    def __init__(self, seconds: float | None = None) -> None:
        self.seconds = seconds
        self.t_first: float | None = None
        self.t_now: float | None = None
        self.t_fix: float | None = None
        self.first: dict[str, float] = {}
        self.last: dict[str, float] = {}
        self.count: dict[str, int] = {}
        self.n = 0

    def interval(self, kind: str) -> float | None:
        """The mean interval of ``kind``'s records so far (``None`` before its second)."""
        c = self.count.get(kind, 0)
        return (self.last[kind] - self.first[kind]) / (c - 1) if c >= 2 else None

    def add(self, rec: Record) -> str | None:
        k, t = rec.kind, float(rec.t)
        self.n += 1
        self.t_first = t if self.t_first is None else self.t_first
        self.t_now = t if self.t_now is None else max(self.t_now, t)
        self.first.setdefault(k, t)
        self.last[k] = max(self.last.get(k, t), t)
        self.count[k] = self.count.get(k, 0) + 1
        if k == "gnss" and self.t_fix is None:
            self.t_fix = t
        if k == "imu":
            return "an IMU record (the choice is final)"
        since_first = self.t_now - self.t_first
        if self.t_fix is not None:
            since_fix = self.t_now - self.t_fix
            if self.seconds is not None:
                if since_fix >= self.seconds:
                    return f"{self.seconds:g} s after the first fix (--warmup)"
            else:
                iv = [self.interval(kk) for kk in self.count]
                if all(i is not None for i in iv):
                    slowest = max([MIN_PERIOD_S, *(i for i in iv if i is not None)])
                    if since_fix >= WARMUP_PERIODS * slowest:
                        return (f"every kind seen twice and {WARMUP_PERIODS:g} x the slowest kind's interval "
                                f"({slowest:.3g} s) after the first fix")
        bound = max(MAX_WARMUP_S, self.seconds or 0.0)
        if since_first >= bound:
            return f"bound: {bound:g} s of stream" + ("" if self.t_fix is not None else " without a fix")
        if self.n >= MAX_WARMUP_RECORDS:
            return f"bound: {MAX_WARMUP_RECORDS} records held"
        return None


class WarmUp:
    """An :class:`~graphnav.result.OnlineEstimator` for live mode: the warm-up, then the navigator
    ``motion="auto"`` picks from its records (the module docstring). ``solver``: ``"fixed-lag"`` or
    ``"isam2"``; ``options``: the estimator's ``-O`` options; ``seconds``: ``--warmup`` (``None``: the
    default rule); ``rot_odometry``: odometry records are a rate of turn with the SOG (every live decoder's:
    NMEA 0183 ROT, NMEA 2000 127251, Signal K rateOfTurn), not an odometer."""

    def __init__(self, solver: str, options: dict[str, Any], seconds: float | None = None, *,
                 rot_odometry: bool = True) -> None:
        self.solver, self.options = solver, dict(options)
        self.rule = WarmUpRule(seconds)
        self.meta = {"odometry": ODOMETRY_FROM_ROT} if rot_odometry else {}
        self.held: list[Record] = []
        self.nav: Navigator | None = None
        self.motion: str | None = None
        self.reason = ""
        self.ended_by = ""
        self.warmup_s: float | None = None
        self.walk: dict[str, Any] | None = None
        self._out: list[Estimate] = []  # estimates of the held records, out before the current one's
        self.replayed_out: list[Estimate] = []  # the same when the end of input ended the warm-up (flush)
        self._kinds: set[str] = set()
        self._changed: list[str] = []
        self.walker: WalkTracker | None = None  # the vessel graph's position walk, re-estimated as the stream goes

    # -- OnlineEstimator
    def add(self, rec: Record) -> Estimate | None:
        if self.nav is not None:
            self._out = []
            self._watch(rec)
            self._walk(rec)
            return self.nav.add(rec)
        self.held.append(rec)
        why = self.rule.add(rec)
        if why is None:
            return None
        return self._start(why)

    @property
    def coasted_out(self) -> list[Estimate]:
        """What the last ``add()`` put out before its own estimate: the estimates of the held records
        (the record that ended the warm-up), else the navigator's coasted predictions."""
        if self._out:
            return self._out
        return self.nav.coasted_out if self.nav is not None else []

    def coast(self, t: float) -> list[Estimate]:
        return self.nav.coast(t) if self.nav is not None else []

    def no_fix(self, t: float) -> list[float]:
        return self.nav.no_fix(t) if self.nav is not None else []

    def flush(self) -> Estimate | None:
        """End of input: a warm-up still going ends here (its estimates in :attr:`replayed_out`)."""
        if self.nav is None:
            if not self.held:
                return None
            last = self._start("the end of the input")
            self.replayed_out = [*self._out, *([last] if last is not None else [])]
            self._out = []
        assert self.nav is not None
        return self.nav.flush()

    def info(self) -> dict[str, Any]:
        return {**(self.nav.info() if self.nav is not None else {"estimator": f"navigator ({self.solver})"}),
                **self.motion_choice()}

    def motion_choice(self) -> dict[str, Any]:
        """``motion``, ``motion_reason`` and the warm-up (``warmup``: held records, stream seconds, what ended it)."""
        if self.nav is None:
            return {"motion": None, "motion_reason": f"warm-up: {len(self.held)} records held so far"}
        out: dict[str, Any] = {"motion": self.motion, "motion_reason": self.reason,
                               "warmup": {"records": len(self.held), "stream_s": self.warmup_s,
                                          "ended_by": self.ended_by}}
        if self.walk is not None:
            out["warmup"]["position_walk"] = self.walk
        if self.walker is not None:
            out["position_walk_live"] = self.walker.last
        if self._changed:
            out["motion_changed_by"] = self._changed
        return out

    # -- inside
    def _start(self, why: str) -> Estimate | None:
        """Decide, build the navigator, replay the held records; the last one's estimate is returned,
        the others' in :attr:`_out`."""
        log = NavLog.from_unsorted(self.held, meta=self.meta)  # (a live stream may step back a little)
        kinds = set(log.counts())
        rot = odometry_is_rot(log.meta)
        self.motion = auto_motion(kinds, log.meta)
        cfg = SmootherConfig.from_options({**self.options, "solver": self.solver})  # as the offline estimator's
        args = log_inputs(log, cfg, {})
        for k in ("scans", "imu", "odometry"):  # not seen yet: unknown (may come later), as without a warm-up
            if not args[k]:
                args[k] = None
        self.nav = Navigator(cfg, history=False, **args)
        imu_model = args.get("imu_model") or {}
        self.walk = imu_model.get("position_walk")
        self.reason = motion_reason(self.motion, kinds, rot)
        if self.motion == "vessel":
            self.reason += (f"; position walk {self.walk['walk']:.3g} m/sqrt(s) from the warm-up's fixes"
                            if self.walk is not None else "; position walk: the default (too few fixes to estimate)")
        self.ended_by = why
        t0, t1 = self.rule.t_first, self.rule.t_now
        self.warmup_s = (t1 - t0) if t0 is not None and t1 is not None else None
        self._kinds = kinds
        if self.motion == "vessel" and cfg.imu.get("vessel_position_walk") is None:
            self.walker = WalkTracker()
            for r in self.held:
                self.walker.add(r)
            self.reason += f" (estimated again every {WALK_EVERY_S:g} s)"
        log_.info("motion %s after a %.3g s warm-up of %d records (%s): %s", self.motion, self.warmup_s or 0.0,
                  len(self.held), why, self.reason)
        out: list[Estimate] = []
        last = None
        n = len(self.held)
        for i, r in enumerate(self.held):
            e = self.nav.add(r)
            out.extend(self.nav.coasted_out)
            if e is not None:
                if i == n - 1:
                    last = e
                else:
                    out.append(e)
        self._out = out
        return last

    def _walk(self, rec: Record) -> None:
        """The vessel graph's position walk from the stream so far: the factors to come take it."""
        if self.walker is None or self.nav is None or self.nav.builder.motion.imu is None:
            return
        walk = self.walker.add(rec)
        if walk is not None:
            self.nav.builder.motion.imu.set_vessel_walk(walk["walk"], walk)
            if self.walker.updates == 1:
                log_.info("vessel position walk %.3g m/sqrt(s) from %.0f s of the stream's fixes and velocities "
                          "(then every %g s)", walk["walk"], self.walker.last["window_s"], WALK_EVERY_S)

    def _watch(self, rec: Record) -> None:
        """A kind first seen after the warm-up that would have changed the choice: warned about once."""
        if rec.kind in self._kinds:
            return
        self._kinds.add(rec.kind)
        if auto_motion(self._kinds, self.meta) != self.motion:
            self._changed.append(rec.kind)
            log_.warning("a %s record after the warm-up: from the start the stream would have had motion %s, "
                         "not %s (the graph is kept; -O motion=... chooses, --warmup S waits longer)",
                         rec.kind, auto_motion(self._kinds, self.meta), self.motion)


def motion_of(estimator: Any) -> dict[str, Any]:
    """Live mode's summary: the motion model in use and why (``{}`` for an estimator without one)."""
    if isinstance(estimator, WarmUp):
        return estimator.motion_choice()
    if not isinstance(estimator, Navigator):
        return {}
    m = estimator.cfg.motion
    if m != "auto":
        return {"motion": m, "motion_reason": f"given (motion={m})"}
    return {"motion": "imu" if estimator.builder.nav else "odometry",
            "motion_reason": "motion auto, decided when the navigator was made (no warm-up): "
            + ("told of an IMU" if estimator.builder.nav else "no IMU known, the Pose2 graph")}


def live_estimator(name: str, options: dict[str, Any], warmup: float | None = None) -> Callable[[], OnlineEstimator]:
    """The factory of live mode's estimator ``name``: the navigation graph (``fixed-lag``, ``isam2``) with
    ``motion`` auto (not given) goes through a :class:`WarmUp`; otherwise :func:`graphnav.estimators.make_online`."""
    from ..estimators import get, make_online

    make = lambda: make_online(name, **options)  # noqa: E731
    est = make()  # options checked (a ValueError naming a bad one) before any stream
    if isinstance(est, Navigator) and given_option(SmootherConfig, options, "motion", "auto") == "auto":
        solver = get(name).solver
        return lambda: WarmUp(solver, options, warmup)
    return make
