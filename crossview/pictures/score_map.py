"""Where and when a tracker failed (`crossview score --map`): floor heat maps of misses, false positives and identity
switches over the store's plan, and every person's time line, drawn with matplotlib from a score JSON's
`floor_grid`, `timeline` and `id_switch_events` (docs/metrics.md, "Over time and place")."""

from __future__ import annotations

import io
import math

import numpy as np

from core.records import Box, BoxKind

_OUTLINED = (BoxKind.SHELF, BoxKind.CHECKOUT, BoxKind.WALL)
"""The boxes drawn over the heat maps (what stands on the floor)."""


def _outline(ax, boxes: tuple[Box, ...] | list[Box]) -> None:
    for b in boxes:
        if b.kind not in _OUTLINED:
            continue
        c, s = math.cos(b.yaw_rad), math.sin(b.yaw_rad)
        hx, hy = b.size_m[0] / 2, b.size_m[1] / 2
        corners = [(b.center_m[0] + c * dx - s * dy, b.center_m[1] + s * dx + c * dy)
                   for dx, dy in ((-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy), (-hx, -hy))]
        ax.plot(*zip(*corners), color="black", linewidth=0.8)


def score_map_png(score: dict, boxes: tuple[Box, ...] | list[Box] = (), title: str = "") -> bytes:
    """The picture as PNG bytes.

    Args:
        score: a score JSON (`ScoreReport.to_json`) with `floor_grid`, `timeline` and `id_switch_events`.
        boxes: the store's boxes, outlined on the maps.
        title: the figure's title.
    """
    buffer = io.BytesIO()
    score_map_figure(score, boxes, title).savefig(buffer, format="png", metadata={"Software": None})
    return buffer.getvalue()


def score_map_figure(score: dict, boxes: tuple[Box, ...] | list[Box] = (), title: str = ""):
    """The matplotlib Figure of `score_map_png`: three floor maps (missed share, false positives, switches) over
    the plan, and the people's time line under them."""
    from matplotlib.figure import Figure

    floor, timeline = score["floor_grid"], score["timeline"]
    rows, cols = floor["shape"]
    x0, y0 = floor["origin_m"]
    cell = floor["cell_m"]
    extent = (x0, x0 + cols * cell, y0, y0 + rows * cell)
    people = timeline["people"]
    figure = Figure(figsize=(13.0, 4.2 + 0.16 * max(len(people), 8)), dpi=100, layout="constrained")
    top, bottom = figure.subfigures(2, 1, height_ratios=(4.2, 0.16 * max(len(people), 8)))
    axes = top.subplots(1, 3)
    truth = np.asarray(floor["truth"], dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        miss_share = np.where(truth > 0, np.asarray(floor["misses"]) / truth, np.nan)
    panels = (
        (miss_share, "missed share of person-instants", "Reds", (0.0, 1.0)),
        (np.asarray(floor["false_positives"], dtype=np.float64), "false positives (target-instants)", "Purples",
         None),
        (np.asarray(floor["id_switches"], dtype=np.float64), "identity switches", "Oranges", None),
    )
    for ax, (grid, name, cmap, limits) in zip(axes, panels):
        vmin, vmax = limits or (0.0, max(1.0, float(np.nanmax(grid)) if grid.size else 1.0))
        image = ax.imshow(grid, origin="lower", extent=extent, cmap=cmap, vmin=vmin, vmax=vmax,
                          interpolation="nearest")
        _outline(ax, boxes)
        ax.set_xlim(extent[0], extent[1])
        ax.set_ylim(extent[2], extent[3])
        ax.set_aspect("equal")
        ax.set_title(f"{name} ({cell:g} m cells)", fontsize="medium")
        ax.set_xlabel("x (m)")
        top.colorbar(image, ax=ax, shrink=0.8)
    axes[0].set_ylabel("y (m)")
    switches = score.get("id_switch_events") or []
    if switches:
        axes[2].scatter([s["x_m"] for s in switches], [s["y_m"] for s in switches], s=14, facecolors="none",
                        edgecolors="red", linewidths=0.8)
    if title:
        top.suptitle(title, fontsize="medium")
    ax = bottom.subplots()
    ids = list(people)
    start, bin_s, num_bins = timeline["start_s"], timeline["bin_s"], timeline["bins"]
    share = np.full((len(ids), num_bins), np.nan)
    for i, pid in enumerate(ids):
        matched, missed = np.asarray(people[pid]["matched"], float), np.asarray(people[pid]["missed"], float)
        present = matched + missed > 0
        share[i, present] = missed[present] / (matched + missed)[present]
    ax.imshow(share if ids else np.full((1, max(num_bins, 1)), np.nan), aspect="auto", cmap="Reds", vmin=0.0,
              vmax=1.0, interpolation="nearest",
              extent=(start, start + max(num_bins, 1) * bin_s, len(ids) - 0.5 if ids else 0.5, -0.5))
    for i, pid in enumerate(ids):
        for s in people[pid]["switches"]:
            ax.plot(s["t_s"], i, marker="x", color="black", markersize=5)
    ax.set_yticks(range(len(ids)), [f"person {pid}" for pid in ids], fontsize="x-small")
    ax.set_xlabel("time (s); grey: not in the store, white to red: share of the bin missed, x: identity switch")
    ax.set_facecolor("0.85")
    ax.set_title(f"per-person time line ({bin_s:g} s bins, scored from {start:g} s)", fontsize="medium")
    return figure
