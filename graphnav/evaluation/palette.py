"""One colour per estimator, shared by every figure and the track map: an estimator has the same
colour in every PNG and on map.html (its position in the comparison's order picks it)."""

from __future__ import annotations

from collections.abc import Sequence

#: matplotlib's tab10 first (figures with up to ten estimators keep their colours), then ten more
#: distinct, dark enough for a thin line on white; beyond twenty the colours repeat
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
           "#17becf", "#393b79", "#637939", "#e7ba52", "#843c39", "#7b4173", "#00a087", "#fd8d3c", "#3182bd",
           "#a55194", "#006d2c")
TRUTH = "#000000"
GNSS = "#8a8a8a"


def colors(names: Sequence[str]) -> dict[str, str]:
    """``{name: colour}``, by position in ``names`` (``truth`` is always black and takes no slot)."""
    out: dict[str, str] = {}
    i = 0
    for n in names:
        if n == "truth":
            out[n] = TRUTH
            continue
        out[n] = PALETTE[i % len(PALETTE)]
        i += 1
    return out
