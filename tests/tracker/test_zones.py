"""Zones (`tracker.zones`): cells that tile the floor, neighbours overlapping by the overlap asked for, each
camera in every zone whose widened cell it sees at hip height (checked with the reference projection), and the
bad inputs refused with their one line."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import ConfigError
from tests.reference.cameras import in_image as reference_in_image
from tests.tracker.synthetic import ceiling_rig, look_at_camera
from tracker import zones
from tracker.visibility import HIP_HEIGHT_M, floor_sight

FLOOR = (0.0, 0.0, 24.0, 12.0)


@pytest.fixture(scope="module")
def rig():
    """18 cameras looking down from 3 m on a 4 m grid (each sees about 4 x 2 m at hip height), and one
    ring of the synthetic tests' (looking across the store) for a lens with distortion."""
    down = [look_at_camera(f"down{i}", (2.0 + 4 * (i % 6), 2.0 + 4 * (i // 6), 3.0), (2.0 + 4 * (i % 6),
                                                                                   2.01 + 4 * (i // 6), 0.0))
            for i in range(18)]
    return down + ceiling_rig(2, 24.0, 12.0, dist=np.array([-0.2, 0.05, 0.0, 0.0, 0.0]))


def test_floor_sight_is_the_reference_projection_at_hip_height(rig):
    xy = np.random.default_rng(0).uniform([0, 0], [24, 12], (400, 2))
    points = np.column_stack([xy, np.full(len(xy), HIP_HEIGHT_M)])
    want = np.stack([reference_in_image(c, points)[1] for c in rig])
    assert np.array_equal(floor_sight(rig, xy), want)


@pytest.mark.parametrize(("count", "shape"), [(1, (1, 1)), (2, (2, 1)), (4, (2, 2)), (8, (4, 2))])
def test_cells_tile_the_floor_and_neighbours_share_the_overlap(rig, count, shape):
    cut = zones.cut(rig, FLOOR, count, overlap_m=2.5)
    assert len(cut) == count and zones.grid_shape(count, 24.0, 12.0) == shape
    xy = np.random.default_rng(1).uniform([0, 0], [24, 12], (2000, 2))
    xy = np.vstack([xy, [[24.0, 12.0], [0.0, 0.0], [12.0, 6.0]]])  # (the floor's corners and a cell corner)
    owners = np.stack([z.owns(xy) for z in cut])
    assert (owners.sum(axis=0) == 1).all()  # one owner each
    assert np.array_equal(zones.owner(cut, xy), owners.argmax(axis=0))
    for a in cut:
        for b in cut:
            if a.index < b.index and a.cell[2] == b.cell[0] and a.cell[1] == b.cell[1]:  # (x neighbours)
                assert b.region[0] == pytest.approx(b.cell[0] - 1.25) and a.region[2] == pytest.approx(a.cell[2] + 1.25)
                assert a.region[2] - b.region[0] == pytest.approx(2.5)


def test_a_camera_belongs_to_every_zone_whose_region_it_sees(rig):
    cut = zones.cut(rig, FLOOR, 4)
    step = zones.SAMPLE_M
    xs, ys = np.arange(step / 2, 24, step), np.arange(step / 2, 12, step)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    points = np.column_stack([grid, np.full(len(grid), HIP_HEIGHT_M)])
    for zone in cut:
        x0, y0, x1, y1 = zone.region
        inside = (grid[:, 0] >= x0) & (grid[:, 0] <= x1) & (grid[:, 1] >= y0) & (grid[:, 1] <= y1)
        want = tuple(i for i, c in enumerate(rig) if reference_in_image(c, points[inside])[1].any())
        assert zone.cameras == want
    assert all(0 < len(z.cameras) < len(rig) for z in cut)  # (each sees some, none all: a real cut)


def test_bad_zones_are_refused_with_the_value_and_what_is_valid(rig):
    with pytest.raises(ConfigError, match=r"--zones 0: must be at least 1"):
        zones.cut(rig, FLOOR, 0)
    with pytest.raises(ConfigError, match=r"zone overlap 1.5 m: must be at least 2.0 m"):
        zones.cut(rig, FLOOR, 2, overlap_m=1.5)
    with pytest.raises(ConfigError, match=r"--zones 12: cells of 6.0 x 4.0 m \(4 x 3\) are not wider"):
        zones.cut(rig, FLOOR, 12, overlap_m=5.0)
    one = [look_at_camera("only", (3.0, 3.0, 3.0), (3.0, 3.5, 0.0))]  # (sees one corner of the floor)
    with pytest.raises(ConfigError, match=r"--zones 2: zone 1 .* is seen by no camera; ask for fewer zones"):
        zones.cut(one, FLOOR, 2)


def test_auto_asks_for_one_zone_per_sixty_cameras():
    assert [zones.auto_count(n) for n in (1, 12, 89, 90, 240, 1000)] == [1, 1, 1, 2, 4, 17]


def test_auto_keeps_the_cut_with_the_fewest_zone_cameras_near_one_per_sixty(rig, monkeypatch):
    # About 7 zones asked for: 7 is prime, a row of 7 x 1 strips on the 24 m x 12 m floor; 6 (3 x 2) and 8 (4 x 2)
    # lie within the spread. Auto must be the cheapest of the three cuts (zone cameras), each cut on its own.
    monkeypatch.setattr(zones, "CAMERAS_PER_ZONE", len(rig) / 7)
    assert zones.auto_count(len(rig)) == 7
    costs = {n: sum(len(z.cameras) for z in zones.cut(rig, FLOOR, n)) for n in (6, 7, 8)}
    auto = zones.cut(rig, FLOOR, None)
    assert sum(len(z.cameras) for z in auto) == min(costs.values()) < costs[7]
    assert len(auto) == min(costs, key=lambda n: (costs[n], abs(n - 7)))
