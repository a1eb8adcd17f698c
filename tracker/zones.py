"""The store's floor cut into zones, each tracked by its own tracker (issue 47): a grid of cells, each widened
into its neighbours by half the overlap, so that two neighbouring zones share a band `overlap_m` wide where a
person is tracked by both and handed over (`tracker.handover`).

A camera belongs to every zone whose widened cell its view touches at hip height (`tracker.visibility.floor_sight`
on a grid of floor points `SAMPLE_M` apart): a zone's tracker gets the frames of every camera that can see a
person inside it. A person is reported by the zone whose cell (not widened) holds their body root: the cells
tile the floor, so each place has one owner.

Pure: cameras and a floor rectangle in, zones out.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from core.errors import ConfigError
from core.types import Camera
from tracker.visibility import HIP_HEIGHT_M, floor_sight

MIN_OVERLAP_M = 2.0
"""The least overlap of two neighbouring zones, metres: a person crossing is seen whole by both (a body is
about 0.6 m wide, and the tracker needs a few frames of both zones' cameras to match them)."""

SAMPLE_M = 0.5
"""Spacing of the floor points on which a camera's view is measured, metres."""

CAMERAS_PER_ZONE = 60
"""`--zones auto`: about this many cameras per zone (one core tracks the hypermarket's 240 at 1.4x live, so 60
leave each zone's tracker several times live on one core)."""


@dataclass(frozen=True)
class Zone:
    """One zone: its cell (x0, y0, x1, y1) that it owns, the cell widened by half the overlap into its
    neighbours (`region`), and the indices of the cameras that see into the region."""

    index: int
    cell: tuple[float, float, float, float]
    region: tuple[float, float, float, float]
    cameras: tuple[int, ...]
    closed: tuple[bool, bool] = (False, False)  # (the cell's far x and y edges are the floor's: included)

    def owns(self, xy: np.ndarray) -> np.ndarray:
        """(N,) whether floor points xy (N, 2) lie in this zone's cell (half-open: [x0, x1) x [y0, y1), the last
        cell of a row or column closed, so that every floor point has one owner)."""
        return _inside(self.cell, np.asarray(xy, dtype=np.float64).reshape(-1, 2), self.closed)


def _inside(box, xy, closed=(False, False)) -> np.ndarray:
    x0, y0, x1, y1 = box
    x, y = xy[:, 0], xy[:, 1]
    in_x = (x >= x0) & ((x <= x1) if closed[0] else (x < x1))
    in_y = (y >= y0) & ((y <= y1) if closed[1] else (y < y1))
    return in_x & in_y


def grid_shape(count: int, width_m: float, depth_m: float) -> tuple[int, int]:
    """(columns along x, rows along y) of `count` cells whose shape is nearest a square (ties: more columns)."""
    best = None
    for cols in range(1, count + 1):
        if count % cols:
            continue
        rows = count // cols
        badness = abs(math.log((width_m / cols) / (depth_m / rows)))
        if best is None or badness < best[0] - 1e-12:
            best = (badness, cols, rows)
    return best[1], best[2]


AUTO_SPREAD = 0.25
"""`--zones auto` tries every count within this fraction of `auto_count` and keeps the cut with the fewest zone
cameras: a camera near a border belongs to both zones, and a prime count is a row of strips whose long borders
cost the most (megastore, 1,000 cameras on 80 m x 60 m: 17 zones are 17 x 1 strips, 3.33 zone cameras per
camera; 16 are 4 x 4, 1.97)."""


def auto_count(num_cameras: int) -> int:
    """About how many zones `--zones auto` asks for: one per `CAMERAS_PER_ZONE` cameras, at least one (`cut`
    with no count tries those within `AUTO_SPREAD` of it)."""
    return max(1, round(num_cameras / CAMERAS_PER_ZONE))


def cut(cameras: Sequence[Camera], floor: tuple[float, float, float, float], count: int | None,
        overlap_m: float = MIN_OVERLAP_M) -> list[Zone]:
    """The floor (x0, y0, x1, y1) cut into `count` zones (`grid_shape`), each with the cameras that see into it;
    `count` None (`--zones auto`): of the counts within `AUTO_SPREAD` of `auto_count`, the cut with the fewest
    zone cameras (ties: the count nearest `auto_count`, then the fewer).

    Raises:
        ConfigError: count < 1; an overlap below `MIN_OVERLAP_M` or as wide as a cell; a zone that no camera
            sees (more zones than the cameras allow).
    """
    if count is not None and count < 1:
        raise ConfigError(f"--zones {count}: must be at least 1 (or auto)")
    if not overlap_m >= MIN_OVERLAP_M:
        raise ConfigError(f"zone overlap {overlap_m} m: must be at least {MIN_OVERLAP_M} m")
    x0, y0, x1, y1 = floor
    xs = np.arange(x0 + SAMPLE_M / 2, x1, SAMPLE_M)
    ys = np.arange(y0 + SAMPLE_M / 2, y1, SAMPLE_M)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    sight = floor_sight(cameras, grid, HIP_HEIGHT_M)  # (C, N)
    if count is not None:
        return _cut(floor, count, overlap_m, grid, sight)
    target = len(cameras) / CAMERAS_PER_ZONE
    nearest = auto_count(len(cameras))
    counts = sorted({nearest, *range(max(1, math.ceil(target * (1 - AUTO_SPREAD))),
                                     math.floor(target * (1 + AUTO_SPREAD)) + 1)}, key=lambda n: (abs(n - target), n))
    best = None
    for n in counts:
        try:
            zones = _cut(floor, n, overlap_m, grid, sight)
        except ConfigError:
            continue
        cost = sum(len(zone.cameras) for zone in zones)
        if best is None or cost < best[0]:
            best = (cost, zones)
    return best[1] if best is not None else _cut(floor, nearest, overlap_m, grid, sight)


def _cut(floor, count: int, overlap_m: float, grid: np.ndarray, sight: np.ndarray) -> list[Zone]:
    """`cut` into `count` zones, given the floor points `grid` (N, 2) and which cameras see them (C, N)."""
    x0, y0, x1, y1 = floor
    cols, rows = grid_shape(count, x1 - x0, y1 - y0)
    cell_w, cell_d = (x1 - x0) / cols, (y1 - y0) / rows
    if count > 1 and overlap_m >= min(cell_w if cols > 1 else math.inf, cell_d if rows > 1 else math.inf):
        raise ConfigError(f"--zones {count}: cells of {cell_w:.1f} x {cell_d:.1f} m ({cols} x {rows}) are not wider "
                          f"than the overlap {overlap_m} m; ask for fewer zones or a smaller overlap")
    zones = []
    half = overlap_m / 2 if count > 1 else 0.0
    for r in range(rows):
        for c in range(cols):
            cell = (x0 + c * cell_w, y0 + r * cell_d, x0 + (c + 1) * cell_w, y0 + (r + 1) * cell_d)
            if c == cols - 1:
                cell = (cell[0], cell[1], x1, cell[3])
            if r == rows - 1:
                cell = (cell[0], cell[1], cell[2], y1)
            region = (max(x0, cell[0] - half), max(y0, cell[1] - half), min(x1, cell[2] + half),
                      min(y1, cell[3] + half))
            inside = _inside(region, grid, (True, True))
            seeing = tuple(int(i) for i in np.flatnonzero(sight[:, inside].any(axis=1)))
            if not seeing:
                raise ConfigError(f"--zones {count}: zone {len(zones)} (x {cell[0]:.1f}..{cell[2]:.1f} m, "
                                  f"y {cell[1]:.1f}..{cell[3]:.1f} m) is seen by no camera; ask for fewer zones")
            zones.append(Zone(len(zones), cell, region, seeing, (c == cols - 1, r == rows - 1)))
    return zones


def owner(zones: Sequence[Zone], xy: np.ndarray) -> np.ndarray:
    """(N,) the index of the zone whose cell holds each floor point (N, 2); -1 off the floor."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    out = np.full(len(xy), -1, dtype=np.int64)
    for zone in zones:
        out[(out < 0) & zone.owns(xy)] = zone.index
    return out
