"""A static, self-contained HTML map of tracks: inline SVG in local metres (equal scale, north up),
a latitude/longitude graticule when the log has a geodetic origin, a scale bar and a legend. No
network resource unless map tiles are asked for (``tiles``: a ``{z}/{x}/{y}`` URL template, e.g. an
OpenStreetMap tile server's -- then the page loads them, and their terms of use apply).

Tiles are Web Mercator squares; each is drawn as the axis-aligned rectangle between its corners'
local coordinates (:class:`graphnav.geodesy.LocalFrame`), which over a harbour-sized area (a few km)
differs from the tangent plane by well under a pixel.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from html import escape
from pathlib import Path

import numpy as np

from ..geodesy import LocalFrame, origin_frame
from ..io.outputs import write_text_atomic
from ..trajectory import Trajectory
from .palette import GNSS, colors

MAX_POINTS = 4000  # per track, drawn (a stride keeps the file small; the GeoJSON has every pose)
#: Graticule spacings to choose from, in arc-minutes.
STEPS_MIN = (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 60.0, 120.0, 300.0, 600.0)
EARTH_CIRCUMFERENCE_M = 40075016.686
MAX_TILES = 64


def _dm(value: float, lat: bool) -> str:
    hemi = ("N" if value >= 0 else "S") if lat else ("E" if value >= 0 else "W")
    a = abs(value)
    d = int(a)
    m = (a - d) * 60.0
    if round(m, 3) >= 60.0:
        d, m = d + 1, 0.0
    return f"{d}°{m:06.3f}′{hemi}"


def _nice(v: float) -> float:
    """The largest 1, 2 or 5 x 10^k not above ``v``."""
    k = 10.0 ** math.floor(math.log10(v))
    return max(m * k for m in (1.0, 2.0, 5.0) if m * k <= v)


def _step(span_deg: float, max_lines: int = 8) -> float:
    for s in STEPS_MIN:
        if span_deg / (s / 60.0) <= max_lines:
            return s / 60.0
    return STEPS_MIN[-1] / 60.0


class _Canvas:
    """Local metres -> SVG pixels (north up, equal scale)."""

    def __init__(self, xs: np.ndarray, ys: np.ndarray, width: int, max_height: int) -> None:
        x0, x1, y0, y1 = float(xs.min()), float(xs.max()), float(ys.min()), float(ys.max())
        span = max(x1 - x0, y1 - y0, 10.0)
        pad = 0.06 * span
        cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        half_x, half_y = max(0.5 * (x1 - x0), 5.0) + pad, max(0.5 * (y1 - y0), 5.0) + pad
        self.x0, self.x1, self.y0, self.y1 = cx - half_x, cx + half_x, cy - half_y, cy + half_y
        self.s = min(width / (self.x1 - self.x0), max_height / (self.y1 - self.y0))
        self.w = (self.x1 - self.x0) * self.s
        self.h = (self.y1 - self.y0) * self.s

    def px(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x) - self.x0) * self.s

    def py(self, y: np.ndarray) -> np.ndarray:
        return (self.y1 - np.asarray(y)) * self.s

    def points(self, x: np.ndarray, y: np.ndarray) -> str:
        return " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(self.px(x), self.py(y), strict=True))


def _graticule(c: _Canvas, frame: LocalFrame) -> list[str]:
    """Lines of constant latitude and longitude across the canvas, labelled at the left and bottom."""
    ex = np.array([c.x0, c.x1, c.x0, c.x1, 0.5 * (c.x0 + c.x1), 0.5 * (c.x0 + c.x1)])
    ey = np.array([c.y0, c.y0, c.y1, c.y1, c.y0, c.y1])
    lat, lon = frame.to_geodetic(ex, ey)
    out = ['<g class="graticule">']
    lat_step, lon_step = _step(float(lat.max() - lat.min())), _step(float(lon.max() - lon.min()))
    u = np.linspace(0.0, 1.0, 41)
    for v in np.arange(math.ceil(lat.min() / lat_step) * lat_step, lat.max(), lat_step)[:50]:
        gx, gy = frame.to_local(np.full(u.size, v), lon.min() + u * (lon.max() - lon.min()))
        out.append(f'<polyline points="{c.points(gx, gy)}"/>')
        ly = float(np.interp(c.x0, gx, gy))
        if c.y0 < ly < c.y1 and float(c.py(ly)) > 14.0:  # (a label at the very top would be cut)
            out.append(f'<text x="3" y="{float(c.py(ly)) - 3:.1f}">{_dm(float(v), True)}</text>')
    for v in np.arange(math.ceil(lon.min() / lon_step) * lon_step, lon.max(), lon_step)[:50]:
        gx, gy = frame.to_local(lat.min() + u * (lat.max() - lat.min()), np.full(u.size, v))
        out.append(f'<polyline points="{c.points(gx, gy)}"/>')
        lx = float(np.interp(c.y0, gy, gx))
        if c.x0 < lx < c.x1 and float(c.px(lx)) < c.w - 75.0:  # (room for the label)
            out.append(f'<text x="{float(c.px(lx)) + 3:.1f}" y="{c.h - 4:.1f}">{_dm(float(v), False)}</text>')
    out.append("</g>")
    return out


def _tile_xy(lat: float, lon: float, z: int) -> tuple[float, float]:
    """Web Mercator tile coordinates (fractional) of a point at zoom ``z``."""
    n = 2.0**z
    la = math.radians(max(min(lat, 85.0511), -85.0511))
    return (lon + 180.0) / 360.0 * n, (1.0 - math.asinh(math.tan(la)) / math.pi) / 2.0 * n


def _tile_lonlat(x: float, y: float, z: int) -> tuple[float, float]:
    n = 2.0**z
    return x / n * 360.0 - 180.0, math.degrees(math.atan(math.sinh(math.pi * (1.0 - 2.0 * y / n))))


def _tiles(c: _Canvas, frame: LocalFrame, template: str) -> list[str]:
    """``<image>`` elements of the tiles covering the canvas (at most :data:`MAX_TILES`)."""
    lat, lon = frame.to_geodetic(np.array([c.x0, c.x1]), np.array([c.y0, c.y1]))
    span = max(c.x1 - c.x0, c.y1 - c.y0)
    tile_m = EARTH_CIRCUMFERENCE_M * math.cos(math.radians(frame.lat0))
    z = int(min(19, max(0, math.floor(math.log2(tile_m / (span / 3.0))))))
    while True:
        (tx0, ty0), (tx1, ty1) = _tile_xy(lat[1], lon[0], z), _tile_xy(lat[0], lon[1], z)
        xs, ys = range(int(tx0), int(tx1) + 1), range(int(ty0), int(ty1) + 1)
        if len(xs) * len(ys) <= MAX_TILES or z == 0:
            break
        z -= 1
    out = ['<g class="tiles">']
    for ty in ys:
        for tx in xs:
            w, n = _tile_lonlat(tx, ty, z)
            e, s = _tile_lonlat(tx + 1, ty + 1, z)
            ax, bx = frame.to_local(np.array([frame.lat0, frame.lat0]), np.array([w, e]))[0]  # west, east x
            ay, by = frame.to_local(np.array([n, s]), np.array([frame.lon0, frame.lon0]))[1]  # north, south y
            url = template.replace("{z}", str(z)).replace("{x}", str(tx)).replace("{y}", str(ty))
            out.append(f'<image href="{escape(url)}" x="{float(c.px(ax)):.1f}" y="{float(c.py(ay)):.1f}" '
                       f'width="{float((bx - ax) * c.s):.1f}" height="{float((ay - by) * c.s):.1f}" '
                       'preserveAspectRatio="none"/>')
    out.append("</g>")
    return out


def _track_svg(c: _Canvas, i: int, name: str, tr: Trajectory, col: str) -> str:
    ok = np.isfinite(tr.x) & np.isfinite(tr.y)
    x, y = tr.x[ok], tr.y[ok]
    stride = max(1, math.ceil(len(x) / MAX_POINTS))
    x, y = np.append(x[::stride], x[-1:]), np.append(y[::stride], y[-1:])
    dash = ' stroke-dasharray="6 4"' if name == "truth" else ""
    return (f'<g class="tk{i}"><polyline class="track" stroke="{col}"{dash} points="{c.points(x, y)}">'
            f"<title>{escape(name)}</title></polyline>"
            f'<circle cx="{float(c.px(x[0])):.1f}" cy="{float(c.py(y[0])):.1f}" r="3.5" fill="{col}"/></g>')


def _gnss_svg(c: _Canvas, xy: np.ndarray) -> str:
    """The fixes as dots (a zero-length segment per fix, round caps: one small path)."""
    xy = xy[np.isfinite(xy).all(axis=1)]
    xy = xy[:: max(1, math.ceil(len(xy) / MAX_POINTS))]
    d = " ".join(f"M{a:.1f} {b:.1f}h0" for a, b in zip(c.px(xy[:, 0]), c.py(xy[:, 1]), strict=True))
    return f'<g class="tkg"><path class="gnss" d="{d}"><title>GNSS fixes</title></path></g>'


def track_map_html(trajectories: Mapping[str, Trajectory], meta: dict, *, title: str = "Tracks",
                   tiles: str | None = None, width: int = 900, max_height: int = 800,
                   gnss: np.ndarray | None = None) -> str:
    """The page (see the module docstring). ``trajectories``: name -> local-frame trajectory, each in
    its estimator's colour (:mod:`.palette`, as in the figures); a track named ``truth`` is drawn
    black and dashed, on top of the others; ``gnss``: the fixes (N, 2), grey dots under the tracks;
    ``meta``: the log's, for its geodetic origin. Each track can be hidden and shown again from the
    legend (checkboxes and CSS: the page has no script)."""
    frame, reason = origin_frame(meta)
    tracks = {n: tr for n, tr in trajectories.items() if len(tr)}
    notes = []
    fixes = np.asarray(gnss, float).reshape(-1, 2) if gnss is not None and len(gnss) else None
    if tracks:
        xs = np.concatenate([tr.x for tr in tracks.values()])
        ys = np.concatenate([tr.y for tr in tracks.values()])
        ok = np.isfinite(xs) & np.isfinite(ys)
        xs, ys = (xs[ok], ys[ok]) if ok.any() else (np.zeros(1), np.zeros(1))
    else:
        xs = ys = np.zeros(1)
        notes.append("no track to draw")
    c = _Canvas(xs, ys, width, max_height)
    svg = [f'<svg width="{c.w:.0f}" height="{c.h:.0f}" viewBox="0 0 {c.w:.1f} {c.h:.1f}" role="img">',
           f'<rect class="sea" width="{c.w:.1f}" height="{c.h:.1f}"/>']
    if frame is not None:
        o = f"origin {_dm(frame.lat0, True)} {_dm(frame.lon0, False)} (WGS84), x east, y north"
        if tiles:
            svg += _tiles(c, frame, tiles)
            notes.append(f"map tiles from {escape(tiles)} (loaded over the network; their terms of use apply)")
        svg += _graticule(c, frame)
    else:
        o = f"local metres only: {reason}"
        if tiles:
            notes.append("map tiles not drawn: the log has no geodetic origin to place them")
    col = colors(list(trajectories))  # (by the comparison's order, as in the figures)
    order = [n for n in tracks if n != "truth"] + (["truth"] if "truth" in tracks else [])  # the truth on top
    index = {n: i for i, n in enumerate(tracks)}
    toggles, legend = [], []
    if fixes is not None:
        svg.append(_gnss_svg(c, fixes))
        toggles.append('<input type="checkbox" id="tkg" checked>')
        legend.append(f'<li><label for="tkg"><span class="dot" style="background:{GNSS}"></span>GNSS fixes '
                      f"({len(fixes)})</label></li>")
    for name in order:
        i = index[name]
        svg.append(_track_svg(c, i, name, tracks[name], col[name]))
    for name, tr in tracks.items():
        i = index[name]
        toggles.append(f'<input type="checkbox" id="tk{i}" checked>')
        legend.append(f'<li><label for="tk{i}"><span class="sw" style="background:{col[name]}"></span>'
                      f"{escape(name)} ({len(tr)} poses)</label></li>")
    bar = _nice((c.x1 - c.x0) / 5.0)
    bx, by = c.w - bar * c.s - 12.0, c.h - 26.0  # above the longitude labels
    svg.append(f'<g class="scale"><line x1="{bx:.1f}" y1="{by:.1f}" x2="{bx + bar * c.s:.1f}" y2="{by:.1f}"/>'
               f'<text x="{bx:.1f}" y="{by - 5:.1f}">{bar:g} m</text></g>')
    svg.append(f'<g class="north"><text x="{c.w - 22:.1f}" y="22">N</text>'
               f'<line x1="{c.w - 18:.1f}" y1="44" x2="{c.w - 18:.1f}" y2="26"/></g>')
    svg.append("</svg>")
    ids = [f"tk{index[n]}" for n in tracks] + (["tkg"] if fixes is not None else [])
    hide = "".join(f"#{k}:not(:checked)~svg .{k}{{display:none}}#{k}:not(:checked)~ul label[for={k}]{{opacity:.35;"
                   "text-decoration:line-through}" for k in ids)
    style = ("body{font-family:sans-serif;margin:1.5em;color:#222}svg{border:1px solid #999}"
             ".sea{fill:#f4f8fb}.graticule polyline{fill:none;stroke:#9ab;stroke-width:0.6}"
             ".graticule text{font-size:10px;fill:#567}.track{fill:none;stroke-width:1.6}"
             f".gnss{{fill:none;stroke:{GNSS};stroke-width:3;stroke-linecap:round;opacity:.55}}"
             ".scale line,.north line{stroke:#222;stroke-width:2}.scale text,.north text{font-size:11px}"
             "input{display:none}ul{list-style:none;padding:0}label{cursor:pointer}"
             ".sw{display:inline-block;width:1.4em;height:0.3em;margin-right:0.5em;vertical-align:middle}"
             ".dot{display:inline-block;width:.5em;height:.5em;border-radius:50%;margin:0 .9em 0 .4em;"
             "vertical-align:middle}" + hide)
    body = "".join(f"<p>{n}</p>" for n in notes)
    return (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>{escape(title)}</title>'
            f"<style>{style}</style></head><body><h1>{escape(title)}</h1><p>{escape(o)}</p>{body}"
            "<p>Click a name to hide or show its track.</p>" + "".join(toggles)
            + "\n".join(svg) + f"<ul>{''.join(legend)}</ul></body></html>\n")


def write_track_map(path: str | Path, trajectories: Mapping[str, Trajectory], meta: dict, *,
                    title: str = "Tracks", tiles: str | None = None, gnss: np.ndarray | None = None) -> Path:
    """Write :func:`track_map_html` to ``path`` atomically."""
    return write_text_atomic(path, track_map_html(trajectories, meta, title=title, tiles=tiles, gnss=gnss))
