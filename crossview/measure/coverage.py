"""How many cameras see each cell of a store's walkable floor, at hip and at head height (`crossview coverage`).

The tracker triangulates a joint from two views or more (`tracker.triangulation`), so a person is tracked
only where at least two cameras see them. A cell of the walkable floor (`sim.store.StoreGeometry.free`: the
navigation grid where a pelvis may be, the floor the crowd walks on) counts as seen by a camera when the
point above its centre at hip height (`HIP_HEIGHT_M`) or at head height (`HEAD_HEIGHT_M`) projects into the
camera's image through its own lens (`core.projection.in_image`, the detector's test). Shelves and people in
between are not counted: this is the most a rig can see, before occlusion.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.records import BoxKind
from core.types import Camera

HIP_HEIGHT_M = 0.9
"""Height of an adult's hips above the floor, metres (the middle of the body: its torso and legs)."""
HEAD_HEIGHT_M = 1.6
"""Height of an adult's head above the floor, metres (the top of the body, the first to leave a view)."""
HEIGHTS_M = (("hip", HIP_HEIGHT_M), ("head", HEAD_HEIGHT_M))
WARN_TWO_VIEW_SHARE = 0.9
"""`generate`, `run` and `coverage` warn when less than this share of the walkable floor is seen by two
cameras or more (at either height)."""
SHARES_OF = (1, 2, 3)
"""The shares reported: of the walkable floor seen by at least 1, 2 and 3 cameras."""


@dataclass(frozen=True)
class HeightCoverage:
    """The walkable floor's cells seen at one height.

    Attributes:
        name: "hip" or "head".
        height_m: the height above the floor of the points tested, metres.
        counts: (N,) int, how many cameras see the point above each walkable cell's centre.
    """

    name: str
    height_m: float
    counts: np.ndarray

    def share(self, at_least: int) -> float:
        """The share of the walkable floor seen by `at_least` cameras or more (0 for a floor without cells)."""
        return float((self.counts >= at_least).mean()) if len(self.counts) else 0.0


@dataclass(frozen=True)
class Coverage:
    """A rig's coverage of a store's walkable floor.

    Attributes:
        scenario: the scenario's name.
        cameras: the rig.
        cell_m: the side of a floor cell, metres (`sim.store.GRID_CELL_M`).
        cells_xy: (N, 2) centres of the walkable cells, metres, world frame.
        boxes: the store's boxes (for the map).
        heights: the coverage at hip and at head height (`HEIGHTS_M`).
    """

    scenario: str
    cameras: tuple[Camera, ...]
    cell_m: float
    cells_xy: np.ndarray
    boxes: tuple
    heights: tuple[HeightCoverage, ...]

    @property
    def floor_m2(self) -> float:
        """The walkable floor's area, m²."""
        return len(self.cells_xy) * self.cell_m**2

    def two_view_share(self) -> float:
        """The share of the walkable floor seen by two cameras or more at the worse of the two heights."""
        return min(h.share(2) for h in self.heights)

    def warning(self) -> str | None:
        """One line when less than `WARN_TWO_VIEW_SHARE` of the walkable floor is seen by two cameras or more;
        None otherwise."""
        worst = min(self.heights, key=lambda h: h.share(2))
        if worst.share(2) >= WARN_TWO_VIEW_SHARE:
            return None
        return (f"warning: {self.scenario}: only {100 * worst.share(2):.0f} % of the walkable floor is seen by two "
                f"cameras or more at {worst.name} height ({worst.height_m:g} m), below "
                f"{100 * WARN_TWO_VIEW_SHARE:.0f} %: people elsewhere cannot be triangulated "
                "(`crossview coverage SCENARIO -o MAP.png` shows where)")

    def lines(self) -> list[str]:
        """The answer in words: the rig, the floor, then per height the shares seen by 1, 2, 3 cameras or more."""
        cameras = f"{len(self.cameras)} camera{'' if len(self.cameras) == 1 else 's'}"
        out = [f"{self.scenario}: {cameras}, {self.floor_m2:.1f} m² of walkable floor "
               f"({self.cell_m:g} m cells)"]
        for h in self.heights:
            shares = ", ".join(f">= {n}: {100 * h.share(n):5.1f} %" for n in SHARES_OF)
            out.append(f"  {h.name:<4} height {h.height_m:g} m  seen by {shares}")
        return out


def coverage(scenario, cameras: list[Camera] | None = None) -> Coverage:
    """How many cameras see each cell of a scenario's walkable floor, at hip and at head height.

    Args:
        scenario: a `sim.scenario.Scenario`.
        cameras: the rig; None builds the scenario's own (`sim.cameras.build_rig`, with its seed, as
            `crossview generate` does).

    Raises:
        ScenarioError: the store or the rig cannot be built (named by the scenario's file and key).
    """
    from core.projection import in_image
    from sim.cameras import build_rig
    from sim.rng import child_rng
    from sim.store import GRID_CELL_M, StoreGeometry

    store = StoreGeometry(scenario.store, name=scenario.where)
    if cameras is None:
        cameras = build_rig(scenario, child_rng(scenario.seed, "cameras"))
    cells_xy = store.cell_centers[store.free]
    heights = []
    for name, height_m in HEIGHTS_M:
        points = np.column_stack([cells_xy, np.full(len(cells_xy), height_m)])
        counts = np.zeros(len(cells_xy), np.int64)
        for camera in cameras:
            counts += in_image(camera, points)[1]
        heights.append(HeightCoverage(name, height_m, counts))
    return Coverage(scenario.name, tuple(cameras), GRID_CELL_M, cells_xy, store.boxes, tuple(heights))


def write_map(cov: Coverage, path: Path, px_per_m: float | None = None) -> Path:
    """Writes the coverage map (PNG): the store from above at hip height and at head height side by side,
    each walkable cell coloured by how many cameras see it (`crossview.pictures.layout.draw_layout`)."""
    from crossview.pictures import layout as pictures

    floor = next(b for b in cov.boxes if b.kind == BoxKind.FLOOR)
    scale = px_per_m or pictures.layout_scale(floor.size_m[0])
    images = []
    for h in cov.heights:
        title = (f"{cov.scenario}, {h.name} height {h.height_m:g} m: "
                 + ", ".join(f">= {n} cameras {100 * h.share(n):.0f} %" for n in SHARES_OF))
        images.append(pictures.draw_layout(cov.boxes, list(cov.cameras), title=title, px_per_m=scale,
                                           seen_by=(cov.cells_xy, h.counts, cov.cell_m)))
    gap = np.full((images[0].shape[0], 12, 3), 255, np.uint8)
    return pictures.write_png(np.hstack([images[0], gap, *images[1:]]), path)
