"""Leave record kinds out of a log before any estimator sees it (``graphnav run|compare --drop``).

The kinds are the record types of :data:`graphnav.log.RECORD_TYPES` plus ``beacon_known`` (the
charted beacons, which are not time-stamped records). Dropping a kind is what a user does to ask
what a sensor is worth: ``--drop odometry,beacon`` runs the estimators on the log without them.
``KIND@SOURCE`` drops only the records of that kind from one source (an NMEA 2000 source address, a
Signal K ``$source``: docs/log-format.md, "Sources"), so that of two GNSS receivers one is chosen:
``--drop gnss@52`` keeps the fixes of every other source.
"""

from __future__ import annotations

from collections.abc import Iterable

from ..log import RECORD_TYPES, SOURCED_KINDS, NavLog

__all__ = ["KINDS", "drop_kinds", "parse_kinds"]

#: Every kind ``--drop`` accepts, in the log's order.
KINDS: tuple[str, ...] = (*RECORD_TYPES, "beacon_known")


def parse_kinds(items: str | Iterable[str] | None) -> list[str]:
    """``"odometry,beacon,gnss@52"`` (or several such items) -> ``["odometry", "beacon", "gnss@52"]``:
    kinds in :data:`KINDS` order, each once, then ``KIND@SOURCE`` items in the order given. An unknown
    kind (or a source on a kind that carries none) is a ``ValueError`` naming the known ones."""
    if items is None:
        return []
    parts = [items] if isinstance(items, str) else list(items)
    given = [k.strip() for p in parts for k in str(p).split(",") if k.strip()]
    sourced: list[str] = []
    for item in given:
        kind, at, src = item.partition("@")
        if kind not in KINDS:
            raise ValueError(f"--drop: unknown record kind {kind!r}; known: {', '.join(KINDS)}")
        if at:
            if kind not in SOURCED_KINDS or not src.strip():
                raise ValueError(f"--drop {item!r}: KIND@SOURCE needs a source and one of the kinds that carry "
                                 f"one: {', '.join(SOURCED_KINDS)}")
            norm = f"{kind}@{src.strip()}"
            if norm not in sourced:
                sourced.append(norm)
    return [k for k in KINDS if k in given] + sourced


def drop_kinds(log: NavLog, kinds: Iterable[str]) -> NavLog:
    """A copy of ``log`` without the records of ``kinds`` (``beacon_known``: without the charted
    beacons; ``KIND@SOURCE``: that kind's records whose ``source`` is SOURCE); ``meta`` is kept.
    ``log`` itself is not changed."""
    items = parse_kinds(list(kinds))
    if not items:
        return log
    drop = {k for k in items if "@" not in k}
    pairs = {tuple(k.split("@", 1)) for k in items if "@" in k}
    known = [] if "beacon_known" in drop else list(log.beacons_known)
    return NavLog([r for r in log.records if r.kind not in drop
                   and (r.kind, getattr(r, "source", "")) not in pairs], known, dict(log.meta)).checks_from(log)
