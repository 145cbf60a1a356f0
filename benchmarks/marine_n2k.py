"""NMEA 2000 / Signal K logs of real boats: the isam2 track against the log's own fixes, and the two
GNSS receivers of the Furuno logs alone and fused.

    python benchmarks/marine_n2k.py [--json] [--data ../shared/data/marine]

For every NMEA 2000 log of ``../shared/data/marine`` (``canboat/*.raw.gz``, ``signalk/aava-n2k.data.gz``):
the record kinds read, and ``graphnav run LOG -e isam2`` (``graphnav.estimators.run``) scored by
the median distance of the smoothed track (``-e E``: another estimator's) to the log's own GNSS fixes
(interpolated at each fix time; every source's fixes). For a log with two GNSS sources, also:

* the receivers' disagreement: median distance of one's fixes to the other's (interpolated);
* each receiver alone (``--drop gnss@OTHER``): the track's median distance to its own fixes;
* RPE over 1 s (median of ``|Δp_track - Δp_fixes|`` over fix pairs 1 s apart, translation only)
  of the fused track and of each single-source track, against each receiver's fixes: an offset
  between receivers cancels in it, so it measures how well the track follows the motion.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from graphnav import estimators  # noqa: E402
from graphnav.io import load_log  # noqa: E402
from graphnav.io.drop import drop_kinds  # noqa: E402


def _fixes(log, source: str | None = None) -> np.ndarray:
    return np.array([[r.t, r.x, r.y] for r in log.of("gnss") if source is None or r.source == source]).reshape(-1, 3)


def _at(track: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.c_[np.interp(t, track[:, 0], track[:, 1]), np.interp(t, track[:, 0], track[:, 2])]


def _inside(track: np.ndarray, f: np.ndarray) -> np.ndarray:
    return f[(f[:, 0] >= track[0, 0]) & (f[:, 0] <= track[-1, 0])]


def median_distance(track: np.ndarray, fixes: np.ndarray) -> float:
    f = _inside(track, fixes)
    return float(np.median(np.hypot(*(_at(track, f[:, 0]) - f[:, 1:]).T)))


def rpe_1s(track: np.ndarray, fixes: np.ndarray, delta: float = 1.0) -> float:
    f = _inside(track, fixes)
    j = np.searchsorted(f[:, 0], f[:, 0] + delta)
    ok = j < len(f)
    i, j = np.flatnonzero(ok), j[ok]
    keep = np.abs(f[j, 0] - f[i, 0] - delta) < 0.25
    i, j = i[keep], j[keep]
    dp_fix = f[j, 1:] - f[i, 1:]
    p = _at(track, f[:, 0])
    dp_trk = p[j] - p[i]
    return float(np.median(np.hypot(*(dp_trk - dp_fix).T)))


ESTIMATOR = "isam2"  # -e


def _track(log) -> np.ndarray:
    tr = estimators.run(ESTIMATOR, log).trajectory
    return np.c_[tr.t, tr.poses[:, :2]]


def study(path: Path) -> dict:
    log = load_log(path)
    out: dict = {"records": log.counts()}
    if not log.of("gnss"):
        out["note"] = "no position PGN in this log: nothing to score against"
        return out
    fused = _track(log)
    out[f"{ESTIMATOR}_median_to_fixes_m"] = median_distance(fused, _fixes(log))
    srcs = sorted({r.source for r in log.of("gnss")})
    if len(srcs) == 2:
        a, b = srcs
        fa, fb = _fixes(log, a), _fixes(log, b)
        out["receivers"] = srcs
        out["disagreement_median_m"] = float(np.median(np.hypot(*(_at(fa, fb[:, 0]) - fb[:, 1:]).T)))
        alone = {s: _track(drop_kinds(log, [f"gnss@{o}"])) for s, o in ((a, b), (b, a))}
        out["alone_median_to_own_fixes_m"] = {s: median_distance(alone[s], _fixes(log, s)) for s in srcs}
        out["fused_median_to_fixes_m"] = {s: median_distance(fused, _fixes(log, s)) for s in srcs}
        out["rpe_1s_m"] = {f"vs {ref} fixes": {"fused": rpe_1s(fused, _fixes(log, ref)),
                                                **{f"{s} alone": rpe_1s(alone[s], _fixes(log, ref)) for s in srcs}}
                           for ref in srcs}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default = next((p for p in (ROOT.parent / "shared" / "data" / "marine", ROOT.parent.parent / "shared" / "data"
                                / "marine") if p.is_dir()), ROOT.parent / "shared" / "data" / "marine")
    ap.add_argument("--data", default=str(default))
    ap.add_argument("--json", action="store_true")
    ap.add_argument("-e", dest="estimator", default="isam2", help="the estimator (default isam2)")
    args = ap.parse_args()
    global ESTIMATOR
    ESTIMATOR = args.estimator
    data = Path(args.data)
    logs = sorted(data.glob("canboat/*.raw.gz")) + sorted(data.glob("signalk/*.data.gz"))
    if not logs:
        sys.exit(f"no NMEA 2000 logs under {data}")
    res = {str(p.relative_to(data)): study(p) for p in logs}
    print(json.dumps(res, indent=None if args.json else 2))


if __name__ == "__main__":
    main()
