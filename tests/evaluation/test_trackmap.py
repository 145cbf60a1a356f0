"""The static track map (graphnav.evaluation.trackmap): self-contained unless tiles are asked for,
every track drawn, the graticule where the origin puts it."""

from __future__ import annotations

import re
from html.parser import HTMLParser

import numpy as np

from graphnav.evaluation.trackmap import track_map_html
from graphnav.trajectory import Trajectory

ORIGIN = {"lat": 43.5, "lon": 16.4, "h": 0.0}


class _Collect(HTMLParser):
    """Every tag with its attributes, and every attribute that could load something."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict]] = []
        self.loads: list[str] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append((tag, a))
        for k in ("src", "href", "xlink:href", "srcset", "data", "action", "poster"):
            if a.get(k):
                self.loads.append(f"{tag} {k}={a[k]}")
        if tag == "link" or (tag == "script" and "src" in a):
            self.loads.append(tag)


def external_resources(html: str) -> list[str]:
    p = _Collect()
    p.feed(html)
    found = list(p.loads)
    found += re.findall(r"url\(|@import|https?://", html)
    return found


def tracks() -> dict[str, Trajectory]:
    t = np.linspace(0.0, 100.0, 51)
    truth = Trajectory(t, np.column_stack([10 * t, 5 * t, np.full_like(t, 0.46)]), name="truth")
    est = Trajectory(t, np.column_stack([10 * t + 3, 5 * t - 2, np.full_like(t, 0.46)]), name="isam2")
    return {"truth": truth, "isam2": est}


def test_map_is_self_contained_and_draws_every_track():
    html = track_map_html(tracks(), {"origin": ORIGIN})
    assert external_resources(html) == []
    p = _Collect()
    p.feed(html)
    lines = [a for tag, a in p.tags if tag == "polyline" and a.get("class") == "track"]
    assert len(lines) == 2 and any(a.get("stroke-dasharray") for a in lines)  # the truth dashed
    assert len(lines[0]["points"].split()) >= 51
    assert "isam2" in html and "43°30.000′N" in html  # the origin, in degrees and minutes


def test_truth_on_top_gnss_under_colours_of_the_figures_and_toggles():
    """The truth is drawn last (on top), the GNSS fixes first; each estimator has its figures' colour
    (by its place in the comparison, the truth taking none); every track has a checkbox and a CSS rule
    that hides it, and there is no script."""
    from graphnav.evaluation.palette import PALETTE

    trs = {**tracks(), "ekf": tracks()["isam2"]}
    html = track_map_html(trs, {"origin": ORIGIN}, gnss=np.array([[0.0, 0.0], [10.0, 5.0], [np.nan, 1.0]]))
    p = _Collect()
    p.feed(html)
    lines = [a for tag, a in p.tags if tag == "polyline" and a.get("class") == "track"]
    assert [a["stroke"] for a in lines] == [PALETTE[0], PALETTE[1], "#000000"]  # isam2, ekf, then the truth
    assert html.index('class="gnss"') < html.index('class="track"') and html.count("h0") == 2
    boxes = [a["id"] for tag, a in p.tags if tag == "input" and a.get("type") == "checkbox"]
    assert sorted(boxes) == ["tk0", "tk1", "tk2", "tkg"]
    assert all(f"#{b}:not(:checked)~svg .{b}{{display:none}}" in html for b in boxes)
    assert "<script" not in html and external_resources(html) == []


def test_graticule_lines_sit_where_the_origin_puts_them():
    """A line of latitude drawn on the map passes through the pixel row of that latitude."""
    from graphnav.geodesy import LocalFrame

    html = track_map_html(tracks(), {"origin": ORIGIN})
    p = _Collect()
    p.feed(html)
    grat = [a["points"] for tag, a in p.tags if tag == "polyline" and "class" not in a]
    assert len(grat) >= 4  # lines of latitude and of longitude
    # rows: the track's start (origin, y = 0) and end (y = 500 m) pixel rows bound the lines of latitude
    track = [a["points"] for tag, a in p.tags if tag == "polyline" and a.get("class") == "track"
             and a.get("stroke-dasharray")][0].split()  # the truth's
    y_start, y_end = float(track[0].split(",")[1]), float(track[-1].split(",")[1])
    scale = (y_start - y_end) / 500.0  # px per metre
    f = LocalFrame(ORIGIN["lat"], ORIGIN["lon"])
    labels = re.findall(r"(\d+)°(\d+\.\d+)′N", html)
    lat = int(labels[1][0]) + float(labels[1][1]) / 60.0
    _, y_m = f.to_local(lat, ORIGIN["lon"])
    expected_row = y_start - float(y_m) * scale
    rows = [np.mean([float(q.split(",")[1]) for q in g.split()]) for g in grat]
    assert min(abs(r - expected_row) for r in rows) < 1.0


def test_tiles_only_when_asked_and_never_without_an_origin():
    url = "https://tile.example.org/{z}/{x}/{y}.png"
    html = track_map_html(tracks(), {"origin": ORIGIN}, tiles=url)
    res = external_resources(html)
    assert res and all("tile.example.org" in r for r in res if r.startswith("image"))
    assert re.search(r'href="https://tile\.example\.org/\d+/\d+/\d+\.png"', html)
    html = track_map_html(tracks(), {}, tiles=url)
    assert external_resources(html) == [] and "no geodetic origin" in html and "not drawn" in html
