"""The beacon paper's fairway (section 7): a 1000 m x 400 m approach fairway, the vessel on the
centre line y = 200 m from x = 0 heading east (yaw 0), V = 10 m/s, ROT = 0, 200 steps of 0.5 s.
Odometry (V, ROT) carries sigma_V = 0.5 m/s, sigma_ROT = 0.1 deg/s errors (eq. 4-5); every step
the vessel measures range and bearing to every beacon (sigma_r = 0.5 m, sigma_beta = 0.5 deg,
eq. 7-8). Truth is the exact track; the start pose is error-free (eq. 1-2).

The noise comes from :func:`graphnav.beacons.layout.draw_noise`, the stream the batched layout
search uses, so a simulated log and the search see the same draw for a (layout, seed).
Convention: the odometry record at t_k is the control over (t_k, t_k+1] (as dead reckoning).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..beacons.layout import Fairway, draw_noise
from ..geometry import wrap_angle
from ..log import BeaconObs, NavLog, Odometry, Truth


def simulate_fairway(beacons: ArrayLike, seed: int = 0, fw: Fairway | None = None) -> NavLog:
    """One passage past ``beacons`` ((B, 2) positions [m]) with noise stream ``seed``."""
    fw = fw or Fairway()
    lay = np.asarray(beacons, dtype=float).reshape(-1, 2)
    nz = draw_noise(fw, lay, seed)
    track = fw.track()
    recs: list = []
    for k in range(fw.steps + 1):
        t = k * fw.dt
        x, y, yaw = track[k]
        recs.append(Truth(t, float(x), float(y), float(yaw)))
        if k >= 1:
            for j, (bx, by) in enumerate(lay):
                dx, dy = bx - x, by - y
                recs.append(BeaconObs(t, f"B{j + 1}", float(np.hypot(dx, dy) + nz["dr"][k - 1, j]),
                                      float(wrap_angle(np.arctan2(dy, dx) - yaw + nz["db"][k - 1, j])),
                                      fw.sigma_range, fw.sigma_bearing))
        i = min(k, fw.steps - 1)  # the last record repeats the last control (no step follows it)
        recs.append(Odometry(t, float(fw.v + nz["dv"][i]), float(nz["drot"][i]), fw.sigma_v, fw.sigma_rot))
    meta = {"name": "fairway", "scenario": "fairway", "seed": int(seed), "beacons": lay.tolist(),
            "dt": fw.dt, "events": []}
    return NavLog.from_unsorted(recs, meta=meta)


def parse_beacons(text: str) -> np.ndarray:
    """``"x1,y1;x2,y2"`` -> (B, 2) array."""
    try:
        pts = [[float(v) for v in item.split(",")] for item in text.split(";") if item.strip()]
    except ValueError as err:
        raise ValueError(f"--beacons: expected 'x1,y1;x2,y2;...', got {text!r}") from err
    if not pts or any(len(p) != 2 for p in pts):
        raise ValueError(f"--beacons: expected 'x1,y1;x2,y2;...', got {text!r}")
    return np.array(pts)
