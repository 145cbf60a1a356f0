"""Leave record kinds out of a log before any estimator sees it (``graphnav run|compare --drop``).

The kinds are the record types of :data:`graphnav.log.RECORD_TYPES` plus ``beacon_known`` (the
charted beacons, which are not time-stamped records). Dropping a kind is what a user does to ask
what a sensor is worth: ``--drop odometry,beacon`` runs the estimators on the log without them.
"""

from __future__ import annotations

from collections.abc import Iterable

from ..log import RECORD_TYPES, NavLog

__all__ = ["KINDS", "drop_kinds", "parse_kinds"]

#: Every kind ``--drop`` accepts, in the log's order.
KINDS: tuple[str, ...] = (*RECORD_TYPES, "beacon_known")


def parse_kinds(items: str | Iterable[str] | None) -> list[str]:
    """``"odometry,beacon"`` (or several such items) -> ``["odometry", "beacon"]`` in :data:`KINDS`
    order, each once. An unknown kind is a ``ValueError`` naming the known ones."""
    if items is None:
        return []
    parts = [items] if isinstance(items, str) else list(items)
    given = [k.strip() for p in parts for k in str(p).split(",") if k.strip()]
    unknown = [k for k in given if k not in KINDS]
    if unknown:
        raise ValueError(f"--drop: unknown record kind {unknown[0]!r}; known: {', '.join(KINDS)}")
    return [k for k in KINDS if k in given]


def drop_kinds(log: NavLog, kinds: Iterable[str]) -> NavLog:
    """A copy of ``log`` without the records of ``kinds`` (``beacon_known``: without the charted
    beacons); ``meta`` is kept. ``log`` itself is not changed."""
    drop = set(parse_kinds(list(kinds)))
    if not drop:
        return log
    known = [] if "beacon_known" in drop else list(log.beacons_known)
    return NavLog([r for r in log.records if r.kind not in drop], known, dict(log.meta))
