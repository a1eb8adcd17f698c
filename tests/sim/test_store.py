"""Store layouts: checks of the scenario's fixtures, obstacle geometry against a plain reference, paths."""

import math

import numpy as np
import pytest
import scipy.ndimage
import scipy.sparse
import scipy.sparse.csgraph

from core.errors import ScenarioError
from core.records import BoxKind
from sim import scenario as sc
from sim.store import ShelfConfig, StoreConfig, StoreGeometry, _distance_to_blocked, rect_distance
from tests.reference import store as store_reference

SHIPPED = ("store_layout1", "store_layout2", "supermarket")


def _store(**kw) -> StoreConfig:
    base = dict(width_m=8.0, depth_m=6.0, ceiling_m=3.0)
    base.update(kw)
    return StoreConfig(**base)


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_layouts_build_with_every_kind_of_box(name):
    scenario = sc.load(name)
    store = StoreGeometry(scenario.store, name=name)
    kinds = {b.kind for b in store.boxes}
    assert {BoxKind.FLOOR, BoxKind.WALL, BoxKind.ENTRANCE, BoxKind.EXIT} <= kinds
    if name != "store_layout1":
        assert {BoxKind.SHELF, BoxKind.CHECKOUT} <= kinds
    else:
        assert BoxKind.SHELF not in kinds  # layout 1 of the paper has no obstacles


def test_supermarket_floor_is_at_least_150_m2():
    s = sc.load("supermarket").store
    assert s.width_m * s.depth_m >= 150.0


def test_overlapping_shelves_name_both_keys():
    config = _store(shelves=(ShelfConfig((3.0, 3.0), (2.0, 0.6, 1.8)), ShelfConfig((3.5, 3.2), (2.0, 0.6, 1.8))))
    with pytest.raises(ScenarioError, match=r"store.shelves\[1\]: overlaps store.shelves\[0\]"):
        StoreGeometry(config)


def test_yawed_shelves_that_only_look_close_do_not_overlap():
    # Two 45-degree shelves whose bounding boxes overlap but whose footprints do not.
    a = ShelfConfig((3.0, 3.0), (2.0, 0.4, 1.8), 45.0)
    b = ShelfConfig((3.0 + 0.7, 3.0 - 0.7), (2.0, 0.4, 1.8), 45.0)
    StoreGeometry(_store(shelves=(a, b)))


def test_entrance_inside_a_shelf_is_an_error():
    config = _store(shelves=(ShelfConfig((0.3, 1.5), (0.6, 2.0, 1.8)),), entrance_m=(0.0, 1.5))
    with pytest.raises(ScenarioError, match=r"store.entrance_m: .*store.shelves\[0\]"):
        StoreGeometry(config)


def test_door_off_the_walls_is_an_error():
    with pytest.raises(ScenarioError, match=r"store.exit_m: .* is not on a wall"):
        StoreGeometry(_store(exit_m=(3.0, 3.0)))


def test_shelf_outside_the_floor_is_an_error():
    with pytest.raises(ScenarioError, match=r"store.shelves\[0\]: footprint .* outside the floor"):
        StoreGeometry(_store(shelves=(ShelfConfig((7.8, 3.0), (1.0, 0.6, 1.8)),)))


def test_exit_walled_off_by_shelves_is_an_error():
    wall = ShelfConfig((4.0, 3.0), (0.6, 6.0, 1.8))
    with pytest.raises(ScenarioError, match="cannot be reached"):
        StoreGeometry(_store(shelves=(wall,), entrance_m=(0.0, 3.0), exit_m=(8.0, 3.0)))


def test_distance_to_blocked_cells_equals_scipys_exact_transform_bit_for_bit():
    rng = np.random.default_rng(3)
    grids = [StoreGeometry(sc.load(name).store, name=name).free for name in SHIPPED]
    for _ in range(200):
        nx, ny = rng.integers(1, 90, 2)
        free = rng.random((nx, ny)) < rng.uniform(0.3, 0.999)
        free[rng.integers(nx), rng.integers(ny)] = False
        grids.append(free)
    for free in grids:
        np.testing.assert_array_equal(_distance_to_blocked(free), scipy.ndimage.distance_transform_edt(free))
    assert np.isinf(_distance_to_blocked(np.ones((3, 4), bool))).all()


def test_connected_agrees_with_shortest_paths_over_the_8_connected_free_cells():
    """Against scipy's Dijkstra on the grid graph (an edge between free cells one step apart, diagonals too)."""
    rng = np.random.default_rng(4)
    store = StoreGeometry(sc.load("store_layout2").store, name="store_layout2")
    for _ in range(5):
        store.free = rng.random(store.free.shape) < 0.62  # (a maze of many components; `connected` reads free)
        store._components = StoreGeometry._components_of(store.free)
        nx, ny = store.free.shape
        index = np.arange(nx * ny).reshape(nx, ny)
        rows, cols = [], []
        for dx, dy in ((1, 0), (0, 1), (1, 1), (1, -1)):
            a = (slice(0, nx - dx), slice(max(0, -dy), ny - max(0, dy)))
            b = (slice(dx, nx), slice(max(0, dy), ny - max(0, -dy)))
            both = store.free[a] & store.free[b]
            rows.append(index[a][both])
            cols.append(index[b][both])
        rows, cols = np.concatenate(rows), np.concatenate(cols)
        graph = scipy.sparse.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(nx * ny, nx * ny))
        cells = rng.integers(0, [nx, ny], size=(40, 2))
        reach = scipy.sparse.csgraph.dijkstra(graph, directed=False, indices=index[cells[:, 0], cells[:, 1]])
        points = (cells + 0.5) * 0.1
        for i, p in enumerate(points):
            for k, q in enumerate(points):
                expected = bool(store.free[tuple(cells[i])] and store.free[tuple(cells[k])]
                                and np.isfinite(reach[i, index[tuple(cells[k])]]))
                assert store.connected(p, q) == expected


def test_bad_values_in_a_scenario_file_name_the_key(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[store]\nwidth_m = 6.0\ndepth_m = 5.0\n[[store.shelves]]\ncenter_m = [3.0, 2.5]\n"
                    "size_m = [2.0, -0.5, 1.8]\n")
    with pytest.raises(ScenarioError, match=r"bad.toml: .*size_m"):
        sc.load(path)


def test_obstacle_distance_and_push_out_agree_with_the_plain_rectangle_reference():
    shelves = (ShelfConfig((3.0, 2.0), (2.0, 0.6, 1.8), 30.0), ShelfConfig((6.0, 4.0), (0.5, 2.0, 1.8)))
    store = StoreGeometry(_store(shelves=shelves))
    rng = np.random.default_rng(0)
    pts = rng.uniform([0, 0], [8, 6], size=(500, 2))
    reference = np.min([rect_distance(pts, o.center, o.half, o.yaw) for o in store.obstacles], axis=0)
    np.testing.assert_allclose(store.obstacle_distance(pts), reference, atol=1e-12)
    # Each obstacle alone: pushed points end up exactly the clearance away (or were already farther).
    for ob in store.obstacles:
        single = StoreGeometry(_store(shelves=(ShelfConfig(tuple(ob.center), (*(2 * ob.half), 1.0),
                                                           math.degrees(ob.yaw)),)))
        pushed = store_reference.push_out(single, pts, 0.3)
        d_before = rect_distance(pts, ob.center, ob.half, ob.yaw)
        d_after = rect_distance(pushed, ob.center, ob.half, ob.yaw)
        moved = d_before < 0.3
        np.testing.assert_allclose(d_after[moved], 0.3, atol=1e-9)  # m
        np.testing.assert_array_equal(pushed[~moved], pts[~moved])


@pytest.mark.parametrize("name", ["store_layout2", "supermarket"])
def test_paths_go_around_the_shelves(name):
    store = StoreGeometry(sc.load(name).store, name=name)
    rng = np.random.default_rng(1)
    fi, fj = np.nonzero(store.free)
    cells = store.cell_centers[fi, fj]
    for _ in range(15):
        a, b = cells[rng.integers(len(cells), size=2)]
        path = [a] + store.plan(a, b)
        np.testing.assert_allclose(path[-1], b)
        for p, q in zip(path[:-1], path[1:]):
            samples = p + np.linspace(0, 1, 50)[:, None] * (q - p)
            # Straight legs stay on the free grid, which keeps the planning clearance to within a cell.
            assert store.obstacle_distance(samples).min() >= store.nav_clearance_m - 0.1
