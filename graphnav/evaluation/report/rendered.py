"""A rendered report: what :func:`graphnav.evaluation.report.render` gives and
:func:`graphnav.evaluation.report.writer.write` persists."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ...log import NavLog
from ...trajectory import Trajectory


@dataclass
class Report:
    """A rendered report: file name -> content, nothing written yet. ``tum``: the trajectories to write
    as TUM (file name -> trajectory); ``images``: file name -> (caption, PNG); ``map_html`` ``None``
    when no map was asked; ``geo_tracks`` the tracks for the WGS84 files (truth included)."""

    log: NavLog
    markdown: str
    html: str
    images: dict[str, tuple[str, bytes]]
    tum: dict[str, Trajectory]
    map_html: str | None = None
    geo_tracks: dict[str, Trajectory] = field(default_factory=dict)
    wgs84: dict[str, Any] | None = None
