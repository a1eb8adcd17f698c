"""Store layouts: checks of the scenario's fixtures, obstacle geometry against a plain reference, paths."""

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest
import scipy.ndimage
import scipy.sparse
import scipy.sparse.csgraph

from core.errors import ScenarioError
from core.records import BoxKind
from sim import scenario as sc
from sim.crowd import Crowd, CrowdConfig
from sim.store import (
    AisleAxis,
    AislesConfig,
    CheckoutLanesConfig,
    Obstacle,
    ShelfConfig,
    StoreConfig,
    StoreGeometry,
    _distance_to_blocked,
    rect_distance,
)
from tests.reference import store as store_reference

SHIPPED = ("store_layout1", "store_layout2", "supermarket")
TRAPPED = Path(__file__).resolve().parent / "data" / "trapped_back_half.toml"
# 8-connected, as the planner moves.
EIGHT = np.ones((3, 3), dtype=int)


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


def test_push_out_agrees_with_the_plain_rectangle_distance():
    shelves = (ShelfConfig((3.0, 2.0), (2.0, 0.6, 1.8), 30.0), ShelfConfig((6.0, 4.0), (0.5, 2.0, 1.8)))
    store = StoreGeometry(_store(shelves=shelves))
    rng = np.random.default_rng(0)
    pts = rng.uniform([0, 0], [8, 6], size=(500, 2))
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
            assert store_reference.obstacle_distance(store, samples).min() >= store.nav_clearance_m - 0.1


# ---------------------------------------------------------------- the store builder: [store.aisles] and reachability


def test_the_convenience_store_expands_to_the_shelves_written_by_hand():
    # Issue 44's store worked out by hand: 18 m - 3 gondolas x 1.2 m leaves 14.4 m, 4 aisles of 3.6 m; the
    # gondolas 9 m long stand in the middle of the 12 m - 0.6 m before the back wall shelf (1.2 m cross aisles).
    by_hand = (ShelfConfig((4.2, 5.7), (1.2, 9.0, 1.6)), ShelfConfig((9.0, 5.7), (1.2, 9.0, 1.6)),
               ShelfConfig((13.8, 5.7), (1.2, 9.0, 1.6)), ShelfConfig((9.0, 11.7), (18.0, 0.6, 2.0)))
    loaded = sc.load("convenience")
    assert loaded.store == StoreConfig(width_m=18.0, depth_m=12.0, ceiling_m=3.2, shelves=by_hand)
    assert (loaded.crowd.people, loaded.store.ceiling_m, loaded.detector.profile.value) == (30, 3.2, "typical")
    built = StoreGeometry(loaded.store, name="convenience")
    assert built.boxes == StoreGeometry(StoreConfig(width_m=18.0, depth_m=12.0, ceiling_m=3.2, shelves=by_hand)).boxes
    # Written out by `scenarios --show`, it loads back as the same store, with no [store.aisles] left to expand twice.
    again = sc._from_text(sc.resolved_toml(loaded), {}, "shown.toml", "shown")
    shown = sc.resolved_toml(loaded)
    assert again.store == loaded.store and "\n[store.aisles]" not in shown
    assert ("# store.shelves[0] on: the file's [store.aisles], expanded\n\n[[store.shelves]]\n"
            "center_m = [4.2, 5.7]") in shown
    assert dataclasses.replace(loaded.store, ceiling_m=3.0).shelves == by_hand
    # An override (or a sweep's axis) of the layout's keys expands anew: 5 aisles on a 20 m floor are
    # (20 - 4 x 1.2) / 5 = 3.04 m wide.
    wider = sc.load("convenience", {"store.aisles.count": 5, "store.width_m": 20.0}).store
    assert [s.center_m for s in wider.shelves] == [(3.64, 5.7), (7.88, 5.7), (12.12, 5.7), (16.36, 5.7), (10.0, 11.7)]


def test_aisles_along_x_are_the_layout_along_y_transposed():
    rng = np.random.default_rng(5)
    for _ in range(12):
        aisles = AislesConfig(count=int(rng.integers(1, 6)), gondola_length_m=float(rng.uniform(2.0, 6.0)),
                              gondola_width_m=float(rng.uniform(0.6, 1.5)), back_wall_shelf=bool(rng.integers(2)),
                              side_wall_shelves=bool(rng.integers(2)),
                              front_aisle_m=None if rng.integers(2) else float(rng.uniform(1.0, 1.5)))
        w, d = float(rng.uniform(16.0, 22.0)), float(rng.uniform(9.0, 12.0))
        along_y = aisles.shelves(w, d, 3.0)
        along_x = dataclasses.replace(aisles, along=AisleAxis.X).shelves(d, w, 3.0)
        assert [(s.center_m[::-1], (*s.size_m[1::-1], s.size_m[2])) for s in along_y] == [
            (s.center_m, s.size_m) for s in along_x]
        # Every aisle between neighbouring units across the floor is equally wide, and at least 1 m.
        side = aisles.wall_shelf_depth_m if aisles.side_wall_shelves else 0.0
        gondolas = sorted(s.center_m[0] for s in along_y[:aisles.count - 1])
        edges = [side] + [e for c in gondolas for e in (c - aisles.gondola_width_m / 2, c + aisles.gondola_width_m / 2)]
        widths = np.diff(edges + [w - side])[::2]
        np.testing.assert_allclose(widths, widths[0], atol=1e-5)
        assert len(widths) == aisles.count and widths[0] >= 1.0


@pytest.mark.parametrize(("aisles", "expected"), [
    (AislesConfig(count=10), r"aisles.count: 10 aisles between 9 gondolas 1.2 m wide do not fit across the floor's "
                             r"18 m \(0.72 m each; an aisle needs >= 1 m, so at most 8 aisles\)"),
    (AislesConfig(gondola_length_m=10.0), r"aisles.gondola_length_m: 10 m gondolas .* \(at most 9.40 m\)"),
    (AislesConfig(gondola_length_m=9.0, front_aisle_m=2.0), r"aisles.front_aisle_m: 2 m leaves 0.40 m"),
    (AislesConfig(gondola_height_m=3.5), r"aisles.gondola_height_m: 3.5 m is above ceiling_m = 3"),
])
def test_an_aisles_layout_that_does_not_fit_the_floor_names_the_key(aisles, expected):
    with pytest.raises(ValueError, match=expected):
        StoreConfig(width_m=18.0, depth_m=12.0, aisles=aisles)
    # The widest that fits is accepted (8 aisles; 9.4 m gondolas).
    StoreConfig(width_m=18.0, depth_m=12.0, aisles=AislesConfig(count=8))
    StoreConfig(width_m=18.0, depth_m=12.0, aisles=AislesConfig(gondola_length_m=9.4))


def test_a_shelf_the_aisles_expanded_to_is_named_as_theirs():
    # Side wall shelves against the default doors on the x = 0 wall: the shelf is one the user did not write.
    config = StoreConfig(width_m=18.0, depth_m=12.0, shelves=(ShelfConfig((9.0, 0.5), (2.0, 0.4, 1.0)),),
                         aisles=AislesConfig(side_wall_shelves=True))
    assert config.first_expanded == 1 and len(config.shelves) == 1 + 3 + 1 + 2
    with pytest.raises(ScenarioError, match=r"store.entrance_m: .* against store.shelves\[5\] \(of store.aisles\)$"):
        StoreGeometry(config)


def test_the_wall_to_wall_shelf_trapping_the_back_half_is_refused_at_load_naming_it():
    with pytest.raises(ScenarioError, match=r"trapped_back_half.toml: store.shelves\[0\]: closes off 14.8 m² of "
                                            r"walkable floor in x \[0.3, 7.7\] x y \[3.7, 5.7\] m from the doors"):
        sc.load(TRAPPED)


def test_an_exit_walled_off_names_the_shelf_that_closes_it():
    shelves = (ShelfConfig((1.5, 1.0), (1.0, 0.5, 1.8)), ShelfConfig((4.0, 3.0), (0.6, 6.0, 1.8)))
    with pytest.raises(ScenarioError, match=r"store.exit_m: cannot be reached .* \(store.shelves\[1\] closes it off\)"):
        StoreGeometry(_store(shelves=shelves, entrance_m=(0.0, 3.0), exit_m=(8.0, 3.0)))


def test_an_area_two_shelves_close_together_names_both():
    # Two shelves from wall to wall, one behind the other: taking either away leaves the back still closed.
    shelves = (ShelfConfig((4.0, 2.5), (8.0, 0.4, 1.8)), ShelfConfig((4.0, 4.0), (8.0, 0.4, 1.8)))
    with pytest.raises(ScenarioError, match=r": store.shelves\[1\] and store.shelves\[0\] together: closes off "
                                            r"8.1 m² of walkable floor in x \[0.3, 7.7\] x y \[4.6, 5.7\] m"):
        StoreGeometry(_store(shelves=shelves, entrance_m=(2.0, 0.0), exit_m=(6.0, 0.0)))


# ---------------------------------------------------------------- the store builder: [store.checkout_lanes]

LANES_TOML = """
[store]
width_m = 12.0
depth_m = 12.0
entrance_m = [1.5, 0.0]
exit_m = [10.5, 0.0]

[store.aisles]
count = 3
gondola_length_m = 5.0
front_aisle_m = 4.0

[store.checkout_lanes]
count = 3
front_gap_m = 1.2
counter_length_m = 1.8
"""


def test_checkout_lanes_expand_to_the_counters_worked_out_by_hand(tmp_path):
    # docs/scenarios.md's example by hand: a row of 3 x (1.2 m lane + 0.8 m counter) = 6 m in the middle of the
    # 12 m floor starts at x = 3; counter k's centre is 3 + 2k + 1.2 + 0.4, its near end 1.2 m off the front wall.
    path = tmp_path / "lanes.toml"
    path.write_text(LANES_TOML)
    loaded = sc.load(path)
    store = StoreGeometry(loaded.store, name="lanes")
    counters = [b for b in store.boxes if b.kind is BoxKind.CHECKOUT]
    assert [(tuple(map(float, b.center_m)), tuple(map(float, b.size_m)), b.yaw_rad) for b in counters] == [
        ((4.6, 2.1, 0.45), (0.8, 1.8, 0.9), 0.0), ((6.6, 2.1, 0.45), (0.8, 1.8, 0.9), 0.0),
        ((8.6, 2.1, 0.45), (0.8, 1.8, 0.9), 0.0)]
    assert [o.key for o in store.obstacles[-3:]] == [f"store.checkout_lanes[{k}]" for k in range(3)]
    # `scenarios --show` writes the table back (it loads as the same store) and lists the counters as comments.
    shown = sc.resolved_toml(loaded)
    assert sc._from_text(shown, {}, "shown.toml", "shown").store == loaded.store
    assert "#   store.checkout_lanes[2]: [8.6, 2.1], [0.8, 1.8, 0.9]" in shown
    # Shoppers pay in the lanes: 0.5 m off the middle of each counter's long faces, facing it, at its height.
    tills = Crowd(CrowdConfig(people=4), store, np.random.default_rng(0))._checkout_spots
    assert [(tuple(np.round(p, 6)), round(math.degrees(h)) % 360, top) for p, h, top in tills] == [
        ((3.7, 2.1), 0, 0.9), ((5.5, 2.1), 180, 0.9), ((5.7, 2.1), 0, 0.9), ((7.5, 2.1), 180, 0.9),
        ((7.7, 2.1), 0, 0.9), ((9.5, 2.1), 180, 0.9)]


def test_checkout_lanes_along_x_are_the_row_along_y_transposed_and_every_lane_is_as_wide_as_asked():
    rng = np.random.default_rng(11)
    for _ in range(12):
        lanes = CheckoutLanesConfig(count=int(rng.integers(1, 6)), lane_width_m=float(rng.uniform(1.0, 2.0)),
                                    counter_width_m=float(rng.uniform(0.5, 1.0)),
                                    counter_length_m=float(rng.uniform(1.0, 3.0)),
                                    front_gap_m=float(rng.uniform(1.0, 2.0)),
                                    start_m=None if rng.integers(2) else float(rng.uniform(0.0, 2.0)))
        w, d = float(rng.uniform(14.0, 20.0)), float(rng.uniform(8.0, 12.0))
        along_y = lanes.counters(w, d, 3.0)
        along_x = dataclasses.replace(lanes, along=AisleAxis.X).counters(d, w, 3.0)
        assert [(c[::-1], (*size[1::-1], size[2])) for c, size in along_y] == [(c, size) for c, size in along_x]
        # Across the floor: the row's start, then lane, counter, lane, counter, ...
        start = (w - lanes.count * (lanes.lane_width_m + lanes.counter_width_m)) / 2 if lanes.start_m is None \
            else lanes.start_m
        edges = [start] + [e for c, _ in along_y for e in (c[0] - lanes.counter_width_m / 2,
                                                           c[0] + lanes.counter_width_m / 2)]
        np.testing.assert_allclose(np.diff(edges)[::2], lanes.lane_width_m, atol=1e-6)
        np.testing.assert_allclose([c[1] - size[1] / 2 for c, size in along_y], lanes.front_gap_m, atol=1e-9)


@pytest.mark.parametrize(("lanes", "expected"), [
    (CheckoutLanesConfig(count=10), r"checkout_lanes.count: 10 lanes 1.2 m wide beside counters 0.8 m wide "
                                    r"\(20.00 m\) do not fit across the floor's 18 m \(at most 9 lanes\)"),
    (CheckoutLanesConfig(start_m=13.0), r"checkout_lanes.start_m: a row 6.00 m wide from 13 m ends past the "
                                        r"floor's 18 m across \(at most 12.00 m\)"),
    (CheckoutLanesConfig(counter_length_m=10.0), r"checkout_lanes.counter_length_m: 10 m counters from "
                                                 r"front_gap_m = 1.5 m leave 0.50 m .* \(at most 9.50 m\)"),
    (CheckoutLanesConfig(counter_height_m=3.5), r"checkout_lanes.counter_height_m: 3.5 m is above ceiling_m = 3"),
])
def test_checkout_lanes_that_do_not_fit_the_floor_name_the_key(lanes, expected):
    with pytest.raises(ValueError, match=expected):
        StoreConfig(width_m=18.0, depth_m=12.0, checkout_lanes=lanes)
    # The most that fit are accepted: 9 lanes across 18 m, a row from 12 m, 9.5 m counters.
    for fits in (dict(count=9), dict(start_m=12.0), dict(counter_length_m=9.5)):
        StoreConfig(width_m=18.0, depth_m=12.0, checkout_lanes=CheckoutLanesConfig(**fits))


def test_a_row_of_checkout_lanes_that_fits_cuts_off_no_floor():
    # Lanes, the front gap and the floor behind the counters are all >= 1 m, so a row alone closes nothing off:
    # on an empty floor it is accepted, with every free cell in the entrance's component (scipy's labels), or
    # refused naming the door it stands in front of.
    rng = np.random.default_rng(12)
    accepted = 0
    for _ in range(25):
        w, d = float(rng.uniform(8.0, 16.0)), float(rng.uniform(6.0, 10.0))
        lanes = CheckoutLanesConfig(count=int(rng.integers(1, 5)), lane_width_m=float(rng.uniform(1.0, 1.6)),
                                    counter_width_m=float(rng.uniform(0.5, 1.0)),
                                    counter_length_m=float(rng.uniform(1.0, d - 3.5)),
                                    front_gap_m=float(rng.uniform(1.0, 2.0)),
                                    along=AisleAxis.X if rng.integers(2) else AisleAxis.Y)
        try:
            store = StoreGeometry(_store(width_m=w, depth_m=d, checkout_lanes=lanes))
        except ValueError as e:
            assert re.match(r"checkout_lanes\.(count|counter_length_m): ", str(e)), e
            continue
        except ScenarioError as e:
            assert re.search(r": store\.(entrance|exit)_m: door at .* store\.checkout_lanes\[\d\]", str(e)), e
            continue
        labels, _ = scipy.ndimage.label(store.free, structure=EIGHT)
        assert set(np.unique(labels[store.free])) == {labels[store.cell_of(store.entrance.inside)]}
        assert sum(b.kind is BoxKind.CHECKOUT for b in store.boxes) == lanes.count
        accepted += 1
    assert accepted >= 10, accepted


def test_a_lane_walled_in_by_shelves_is_refused_naming_its_counter():
    # The first lane runs along the x = 0 wall; shelves written by hand close both its ends, so only its counter
    # stands between the lane and the store. The named counter's removal joins the lane (scipy's labels).
    shelves = (ShelfConfig((0.6, 0.675), (1.2, 0.55, 1.6)), ShelfConfig((0.6, 3.2), (1.2, 0.4, 1.6)))
    config = _store(shelves=shelves, entrance_m=(4.0, 0.0), exit_m=(6.0, 0.0),
                    checkout_lanes=CheckoutLanesConfig(count=1, start_m=0.0, front_gap_m=1.0, counter_length_m=2.0))
    with pytest.raises(ScenarioError, match=r"store: store.checkout_lanes\[0\]: closes off 0.6 m² of walkable floor "
                                            r"in x \[0.3, 0.8\] x y \[1.4, 2.5\] m from the doors"):
        StoreGeometry(config)
    bare = StoreGeometry(_store(entrance_m=(4.0, 0.0), exit_m=(6.0, 0.0)))
    counter = Obstacle("counter", np.array([1.6, 2.0]), np.array([0.4, 1.0]), 0.0, 0.9)
    obstacles = [Obstacle(f"s{i}", np.array(s.center_m), np.array(s.size_m[:2]) / 2, 0.0, s.size_m[2])
                 for i, s in enumerate(shelves)]
    entrance = bare.cell_of(bare.entrance.inside)
    lane = bare.cell_of((0.5, 2.0))
    with_counter, _ = scipy.ndimage.label(store_reference.free_grid(bare, [*obstacles, counter]), structure=EIGHT)
    without, _ = scipy.ndimage.label(store_reference.free_grid(bare, obstacles), structure=EIGHT)
    assert with_counter[lane] != with_counter[entrance] and without[lane] == without[entrance] != 0


@pytest.mark.parametrize("name", [*SHIPPED, "hypermarket", "convenience"])
def test_the_grid_computed_in_windows_is_the_plain_grid_of_every_cell(name):
    store = StoreGeometry(sc.load(name).store, name=name)
    np.testing.assert_array_equal(store.free, store_reference.free_grid(store, store.obstacles))


def test_refused_exactly_where_scipys_labels_find_floor_no_door_reaches():
    """Random shelves across an 8 m x 6 m floor with both doors in front: refused iff scipy.ndimage.label (8-connected)
    finds free cells outside the entrance's component of the plain grid, and the named shelf's removal joins them."""
    rng = np.random.default_rng(8)
    refused = accepted = 0
    for _ in range(40):
        shelves = []
        for _ in range(int(rng.integers(1, 4))):
            length = float(rng.choice([8.0, rng.uniform(5.0, 8.0)]))
            x = float(rng.uniform(length / 2, 8.0 - length / 2))
            shelves.append(ShelfConfig((x, float(rng.uniform(2.0, 5.4))), (length, 0.4, 1.6)))
        config = _store(shelves=tuple(shelves), entrance_m=(2.0, 0.0), exit_m=(6.0, 0.0))
        try:
            store = StoreGeometry(config)
        except ScenarioError as e:
            if "closes" not in str(e):
                continue  # (overlapping shelves)
            error = str(e)
        else:
            error = None
        bare = StoreGeometry(dataclasses.replace(config, shelves=()))
        obstacles = [Obstacle(f"store.shelves[{i}]", np.array(s.center_m), np.array(s.size_m[:2]) / 2, 0.0, s.size_m[2])
                     for i, s in enumerate(shelves)]
        free = store_reference.free_grid(bare, obstacles)
        labels, _ = scipy.ndimage.label(free, structure=EIGHT)
        start = labels[bare.cell_of(bare.entrance.inside)]
        cut_off = (labels != 0) & (labels != start)
        assert (error is not None) == bool(cut_off.any()), error
        if error is None:
            accepted += 1
            np.testing.assert_array_equal(store.free, free)
            continue
        refused += 1
        # The named shelves (one, or several "together") are the ones whose removal reaches the largest cut-off area.
        named = {int(k) for k in re.findall(r"store.shelves\[(\d+)\]", error.split(": closes off")[0])}
        largest = labels == int(np.argmax(np.bincount(labels[cut_off])))
        kept = [ob for i, ob in enumerate(obstacles) if i not in named]
        without, _ = scipy.ndimage.label(store_reference.free_grid(bare, kept), structure=EIGHT)
        assert (without[largest] == without[bare.cell_of(bare.entrance.inside)]).all(), error
    assert refused >= 5 and accepted >= 5, (refused, accepted)
