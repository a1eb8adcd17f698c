"""Store layouts: floor, walls, shelf rows, entrance, exit and checkout, built as MuJoCo geometry.

`StoreConfig` is the `[store]` section of a scenario; a regular layout written as `[store.aisles]`
(`AislesConfig`) expands there into the shelves a hand-written layout lists. `StoreGeometry` checks it against
itself (shelves inside the floor and apart, doors on a wall and not blocked, every walkable area reachable from
the doors) and holds what the crowd needs: the obstacle rectangles, the doors, and a navigation grid with
distance fields to named goals.
"""

from __future__ import annotations

import enum
import heapq
import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from core.errors import ScenarioError
from core.jit import jit
from core.records import Box, BoxKind
from sim.config import bounded, check_ranges

MAX_FLOOR_M = 500.0  # the largest floor side, and so any position or size on it
# Navigation grid resolution; fine enough for 1 m aisles, coarse enough for fast path searches.
GRID_CELL_M = 0.1
# Thickness of the walls and of the floor slab (the floor's top face is z = 0).
WALL_THICKNESS_M = 0.1
FLOOR_THICKNESS_M = 0.1
# Height of the floor markings of the doors (too thin to hide a keypoint).
DOOR_MAT_HEIGHT_M = 0.005
# How far outside the wall people appear before walking in, and vanish after walking out.
OUTSIDE_DOOR_M = 0.5
# Distance from the wall of the point just inside a door where paths start and end.
INSIDE_DOOR_M = 0.8
# The narrowest aisle (and cross aisle) a `[store.aisles]` layout may leave: planned paths keep 0.45 m from each
# shelf face, so an aisle needs 0.9 m and a grid cell for anyone to walk it.
MIN_AISLE_M = 1.0


def _tidy(v: float) -> float:
    """4.2, not 4.200000000000001: a layout's computed coordinate, where the floor's own digits make it exact."""
    short = round(v, 9)
    return short if abs(short - v) < 1e-12 else v


@dataclass(frozen=True)
class ShelfConfig:
    """[[store.shelves]]: one shelf unit, a box standing on the floor.

    Attributes:
        center_m: (x, y) centre of its footprint on the floor.
        size_m: (x, y, height) full size before the yaw; the height at most the ceiling.
        yaw_deg: rotation about the vertical, counter-clockwise seen from above.
    """

    center_m: tuple[float, float] = bounded((0.0, 0.0), 0.0, MAX_FLOOR_M)
    size_m: tuple[float, float, float] = bounded((2.0, 0.5, 1.8), 0.0, MAX_FLOOR_M, low_open=True)
    yaw_deg: float = bounded(0.0, -360.0, 360.0)

    def __post_init__(self):
        check_ranges(self)


class AisleAxis(enum.Enum):
    """The floor axis a `[store.aisles]` layout's gondolas run along."""

    X = "x"
    Y = "y"


@dataclass(frozen=True)
class AislesConfig:
    """[store.aisles]: a regular layout, expanded at load into [[store.shelves]] (after those written by hand).

    The gondolas (double-sided shelf runs) stand side by side from the front wall toward the back wall, with
    `count` aisles of one width between them and the side walls (or the side wall shelves); the cross aisles
    at both ends of the gondolas keep the rest of the floor's length. A layout that leaves an aisle or a cross
    aisle narrower than 1 m is refused, naming the key. `crossview scenarios --show` prints the expanded shelves.

    Attributes:
        count: aisles across the floor; count - 1 gondolas stand between them (1: wall shelves only).
        along: the axis the gondolas run along: "y" from the front wall y = 0 toward the back wall y = depth, "x"
            from the front wall x = 0 toward the back wall x = width.
        gondola_length_m: length of each gondola along `along`.
        gondola_width_m: width of each gondola (both of its faces hold goods).
        gondola_height_m: height of the gondolas, at most the ceiling.
        front_aisle_m: clear floor between the front wall and the gondolas' near ends; left out, the gondolas
            stand in the middle between the front wall and the back wall shelf (or the back wall).
        back_wall_shelf: a wall shelf along the whole back wall.
        side_wall_shelves: wall shelves along both side walls (the walls the gondolas run along), from the front
            wall to the back wall shelf; a door on a side wall then needs a gap, so place the doors on the front
            wall.
        wall_shelf_depth_m: depth of the wall shelves from the wall.
        wall_shelf_height_m: height of the wall shelves, at most the ceiling.
    """

    count: int = bounded(4, 1, 100, unit="aisles")
    along: AisleAxis = AisleAxis.Y
    gondola_length_m: float = bounded(6.0, 0.0, MAX_FLOOR_M, low_open=True)
    gondola_width_m: float = bounded(1.2, 0.0, MAX_FLOOR_M, low_open=True)
    gondola_height_m: float = bounded(1.6, 0.0, 20.0, low_open=True)
    front_aisle_m: float | None = bounded(None, MIN_AISLE_M, MAX_FLOOR_M)
    back_wall_shelf: bool = True
    side_wall_shelves: bool = False
    wall_shelf_depth_m: float = bounded(0.6, 0.0, MAX_FLOOR_M, low_open=True)
    wall_shelf_height_m: float = bounded(2.0, 0.0, 20.0, low_open=True)

    def __post_init__(self):
        check_ranges(self)

    def shelves(self, width_m: float, depth_m: float, ceiling_m: float) -> tuple[ShelfConfig, ...]:
        """The shelf units of this layout on a [0, width] x [0, depth] floor: the gondolas across the floor, then
        the back wall shelf, then the side wall shelves.

        Raises:
            ValueError: the layout does not fit the floor or the ceiling; the message names the key (`aisles.`...)
                and what would fit.
        """
        for key in ("gondola_height_m", "wall_shelf_height_m"):
            if getattr(self, key) > ceiling_m:
                raise ValueError(f"aisles.{key}: {getattr(self, key):g} m is above ceiling_m = {ceiling_m:g}")
        length, across = (depth_m, width_m) if self.along is AisleAxis.Y else (width_m, depth_m)
        side = self.wall_shelf_depth_m if self.side_wall_shelves else 0.0
        back = self.wall_shelf_depth_m if self.back_wall_shelf else 0.0
        gondolas, gw, gl = self.count - 1, self.gondola_width_m, self.gondola_length_m
        aisle = (across - 2 * side - gondolas * gw) / self.count
        if aisle < MIN_AISLE_M:
            most = max(0, int((across - 2 * side + gw) // (MIN_AISLE_M + gw)))
            raise ValueError(f"aisles.count: {self.count} aisles between {gondolas} gondolas {gw:g} m wide do not fit "
                             f"across the floor's {across:g} m{' between the side wall shelves' if side else ''} "
                             f"({aisle:.2f} m each; an aisle needs >= {MIN_AISLE_M:g} m, so at most {most} aisles)")
        room = length - back  # from the front wall to the back wall shelf
        if room < MIN_AISLE_M:
            raise ValueError(f"aisles.wall_shelf_depth_m: a back wall shelf {back:g} m deep leaves {room:.2f} m of the "
                             f"floor's {length:g} m along {self.along.value}, need >= {MIN_AISLE_M:g} m")
        if gondolas and gl > room - 2 * MIN_AISLE_M:
            raise ValueError(f"aisles.gondola_length_m: {gl:g} m gondolas leave less than {MIN_AISLE_M:g} m of cross "
                             f"aisle at an end of the floor's {length:g} m along {self.along.value}"
                             f"{' before the back wall shelf' if back else ''} (at most "
                             f"{room - 2 * MIN_AISLE_M:.2f} m)")
        front = (room - gl) / 2 if self.front_aisle_m is None else self.front_aisle_m
        if gondolas and room - front - gl < MIN_AISLE_M:
            raise ValueError(f"aisles.front_aisle_m: {front:g} m leaves {room - front - gl:.2f} m of cross aisle "
                             f"behind the gondolas, need >= {MIN_AISLE_M:g} m (at most "
                             f"{room - gl - MIN_AISLE_M:.2f} m)")
        # (centre along `along`, centre across, size along, size across, height) of each unit
        units = [(front + gl / 2, side + k * aisle + (k - 1) * gw + gw / 2, gl, gw, self.gondola_height_m)
                 for k in range(1, gondolas + 1)]
        if back:
            units.append((length - back / 2, across / 2, back, across, self.wall_shelf_height_m))
        if side:
            units += [(room / 2, c, room, side, self.wall_shelf_height_m) for c in (side / 2, across - side / 2)]

        def shelf(a: float, c: float, size_a: float, size_c: float, height: float) -> ShelfConfig:
            xy, size = ((c, a), (size_c, size_a)) if self.along is AisleAxis.Y else ((a, c), (size_a, size_c))
            return ShelfConfig(tuple(_tidy(v) for v in xy), (*(_tidy(v) for v in size), height))

        return tuple(shelf(*unit) for unit in units)


# A checkout counter a `[store.checkout_lanes]` row expands to: ((x, y) centre, (x, y, height) size).
Counter = tuple[tuple[float, float], tuple[float, float, float]]


@dataclass(frozen=True)
class CheckoutLanesConfig:
    """[store.checkout_lanes]: a row of checkout counters near the front wall, each with its lane beside it.

    The counters run along `along` from `front_gap_m` off the front wall and stand side by side across the
    floor from `start_m`: a lane, a counter, a lane, a counter, ... (`count` of each, so the row is
    count x (lane_width_m + counter_width_m) wide). Shoppers pay standing in the lane at the middle of a
    counter's long face (either face); with every till taken they leave without paying. A row that does not
    fit the floor (across it, or leaving under 1 m behind the counters) is refused, naming the key; counters
    are checked with the shelves at load (apart from them, doors free, all floor reachable).

    Attributes:
        count: checkout lanes, one counter each.
        along: the axis the counters run along, as `[store.aisles]`'s: "y" from the front wall y = 0, "x" from
            the front wall x = 0.
        start_m: where the row starts across the floor (the first lane's outer edge; x when `along` is "y");
            left out, the row stands in the middle of the floor's width across.
        front_gap_m: clear floor between the front wall and the counters' near ends.
        counter_length_m: length of each counter along `along`.
        counter_width_m: width of each counter across.
        counter_height_m: height of the counters, at most the ceiling.
        lane_width_m: clear width of each lane, between a counter and the one before it (or the row's start).
    """

    count: int = bounded(3, 1, 50, unit="lanes")
    along: AisleAxis = AisleAxis.Y
    start_m: float | None = bounded(None, 0.0, MAX_FLOOR_M)
    front_gap_m: float = bounded(1.5, MIN_AISLE_M, MAX_FLOOR_M)
    counter_length_m: float = bounded(2.0, 0.0, MAX_FLOOR_M, low_open=True)
    counter_width_m: float = bounded(0.8, 0.0, MAX_FLOOR_M, low_open=True)
    counter_height_m: float = bounded(0.9, 0.0, 20.0, low_open=True)
    lane_width_m: float = bounded(1.2, MIN_AISLE_M, MAX_FLOOR_M)

    def __post_init__(self):
        check_ranges(self)

    def counters(self, width_m: float, depth_m: float, ceiling_m: float) -> tuple[Counter, ...]:
        """The counters of this row on a [0, width] x [0, depth] floor, from `start_m` across: ((x, y) centre,
        (x, y, height) size) each.

        Raises:
            ValueError: the row does not fit the floor or the ceiling; the message names the key
                (`checkout_lanes.`...) and what would fit.
        """
        if self.counter_height_m > ceiling_m:
            raise ValueError(f"checkout_lanes.counter_height_m: {self.counter_height_m:g} m is above ceiling_m = "
                             f"{ceiling_m:g}")
        length, across = (depth_m, width_m) if self.along is AisleAxis.Y else (width_m, depth_m)
        step = self.lane_width_m + self.counter_width_m
        row = self.count * step
        if row > across + 1e-9:
            raise ValueError(f"checkout_lanes.count: {self.count} lanes {self.lane_width_m:g} m wide beside counters "
                             f"{self.counter_width_m:g} m wide ({row:.2f} m) do not fit across the floor's "
                             f"{across:g} m (at most {int((across + 1e-9) // step)} lanes)")
        start = (across - row) / 2 if self.start_m is None else self.start_m
        if start + row > across + 1e-9:
            raise ValueError(f"checkout_lanes.start_m: a row {row:.2f} m wide from {start:g} m ends past the floor's "
                             f"{across:g} m across (at most {across - row:.2f} m)")
        behind = length - self.front_gap_m - self.counter_length_m
        if behind < MIN_AISLE_M:
            raise ValueError(f"checkout_lanes.counter_length_m: {self.counter_length_m:g} m counters from "
                             f"front_gap_m = {self.front_gap_m:g} m leave {behind:.2f} m of the floor's {length:g} m "
                             f"along {self.along.value} behind them, need >= {MIN_AISLE_M:g} m (at most "
                             f"{length - self.front_gap_m - MIN_AISLE_M:.2f} m)")
        a = self.front_gap_m + self.counter_length_m / 2  # centre along `along`
        out = []
        for k in range(self.count):
            c = start + k * step + self.lane_width_m + self.counter_width_m / 2
            xy, size = (((c, a), (self.counter_width_m, self.counter_length_m)) if self.along is AisleAxis.Y
                        else ((a, c), (self.counter_length_m, self.counter_width_m)))
            out.append((tuple(_tidy(v) for v in xy), (*(_tidy(v) for v in size), self.counter_height_m)))
        return tuple(out)


@dataclass(frozen=True)
class StoreConfig:
    """[store]: the floor rectangle [0, width] x [0, depth], ceiling height and fixtures.

    Attributes:
        width_m: floor extent along world x.
        depth_m: floor extent along world y.
        ceiling_m: ceiling height; cameras hang below it.
        wall_height_m: height of the walls around the floor, at most the ceiling.
        shelves: shelf units ([[store.shelves]] tables).
        aisles: a regular layout of gondolas and wall shelves ([store.aisles]), expanded into `shelves` after those
            written by hand (the loaded scenario holds the expanded shelves, and no `aisles`).
        entrance_m: (x, y) centre of the entrance, on a wall; left out, it is on the x = 0 wall at a quarter
            of the depth.
        exit_m: (x, y) centre of the exit, on a wall; left out, on the x = 0 wall at three quarters of the depth.
        door_width_m: clear width of both doors.
        checkout_m: (x, y) centre of the checkout counter; left out, the store has none.
        checkout_size_m: (x, y, height) of the checkout counter.
        checkout_lanes: a row of checkout counters with their lanes ([store.checkout_lanes]), besides or instead of
            `checkout_m`'s counter; the counters are checked with the shelves at load.
    """

    width_m: float = bounded(4.0, 2.0, MAX_FLOOR_M)
    depth_m: float = bounded(3.0, 2.0, MAX_FLOOR_M)
    ceiling_m: float = bounded(3.0, 2.0, 20.0)  # people are up to 1.95 m tall
    wall_height_m: float = bounded(2.2, 0.5, 20.0)
    shelves: tuple[ShelfConfig, ...] = ()
    aisles: AislesConfig | None = None
    entrance_m: tuple[float, float] | None = bounded(None, 0.0, MAX_FLOOR_M)
    exit_m: tuple[float, float] | None = bounded(None, 0.0, MAX_FLOOR_M)
    door_width_m: float = bounded(1.0, 0.7, 5.0)
    checkout_m: tuple[float, float] | None = bounded(None, 0.0, MAX_FLOOR_M)
    checkout_size_m: tuple[float, float, float] = bounded((1.4, 0.6, 0.9), 0.0, MAX_FLOOR_M, low_open=True)
    checkout_lanes: CheckoutLanesConfig | None = None
    # Index of the first shelf that `aisles` expanded to (None: all written by hand), for error messages only.
    first_expanded: int | None = field(default=None, init=False, compare=False, repr=False)

    def __post_init__(self):
        check_ranges(self)
        if self.wall_height_m > self.ceiling_m:
            raise ValueError(f"wall_height_m: {self.wall_height_m} must be <= ceiling_m = {self.ceiling_m}")
        if self.aisles is not None:
            # One layout path: the expanded shelves are what a hand-written layout lists, and the config is then
            # one (so that `dataclasses.replace` does not expand it twice).
            expanded = self.aisles.shelves(self.width_m, self.depth_m, self.ceiling_m)
            object.__setattr__(self, "first_expanded", len(self.shelves))
            object.__setattr__(self, "shelves", self.shelves + expanded)
            object.__setattr__(self, "aisles", None)
        if self.checkout_lanes is not None:
            self.checkout_lanes.counters(self.width_m, self.depth_m, self.ceiling_m)  # raises where it does not fit
        for i, shelf in enumerate(self.shelves):
            if shelf.size_m[2] > self.ceiling_m:
                raise ValueError(f"shelves[{i}].size_m: height {shelf.size_m[2]} is above ceiling_m = {self.ceiling_m}")


@dataclass(frozen=True)
class Obstacle:
    """A yawed rectangle people keep clear of (a shelf or the checkout counter).

    Attributes:
        key: the scenario key it comes from, for error messages.
        center: (2,) footprint centre, metres.
        half: (2,) half extents along the rectangle's own axes.
        yaw: rotation about z, radians.
        height: top of the box above the floor.
        till_normal: (2,) for a checkout counter, the normal of the faces shoppers pay at (standing 0.5 m off
            either face's middle); None for a shelf.
    """

    key: str
    center: np.ndarray
    half: np.ndarray
    yaw: float
    height: float
    till_normal: np.ndarray | None = None

    def corners(self) -> np.ndarray:
        """(4, 2) footprint corners, counter-clockwise."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        R = np.array([[c, -s], [s, c]])
        local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * self.half
        return self.center + local @ R.T


@dataclass(frozen=True)
class Door:
    """An entrance or an exit: a gap in a wall.

    Attributes:
        key: scenario key.
        center: (2,) door centre on the wall line.
        inward: (2,) unit normal pointing into the store.
        width: clear width.
    """

    key: str
    center: np.ndarray
    inward: np.ndarray
    width: float

    @property
    def inside(self) -> np.ndarray:
        """(2,) where paths through this door start or end inside the store."""
        return self.center + INSIDE_DOOR_M * self.inward

    @property
    def outside(self) -> np.ndarray:
        """(2,) where people appear or vanish, just outside the wall."""
        return self.center - OUTSIDE_DOOR_M * self.inward


def _xy(point) -> str:
    """A point for an error message: (1.5, 2)."""
    return "(" + ", ".join(f"{float(v):.4g}" for v in point) + ")"


def _error(name: str, message: str):

    return ScenarioError(f"{name}: {message}")


def rect_distance(points: np.ndarray, center: np.ndarray, half: np.ndarray, yaw: float) -> np.ndarray:
    """Distance from points to a yawed rectangle (0 inside).

    Args:
        points: (..., 2) points, metres.
        center, half, yaw: the rectangle.

    Returns:
        (...,) distances, metres.
    """
    c, s = math.cos(yaw), math.sin(yaw)
    d = points - center
    local = np.stack([d[..., 0] * c + d[..., 1] * s, -d[..., 0] * s + d[..., 1] * c], axis=-1)
    outside = np.maximum(np.abs(local) - half, 0.0)
    return np.hypot(outside[..., 0], outside[..., 1])


def _distance_to_blocked(free: np.ndarray) -> np.ndarray:
    """(nx, ny) Euclidean distance in cells from every cell to the nearest blocked one (0 on blocked cells; inf
    everywhere when none is blocked), as `scipy.ndimage.distance_transform_edt(free)` gives it, bit for bit
    (a test compares them).

    OpenCV's precise mask is the exact transform (Felzenszwalb and Huttenlocher) in float32; the squared
    distances are whole numbers, so rounding the float32 result's square recovers them exactly, and their
    float64 square roots are scipy's. (OpenCV instead of scipy.ndimage: a third of a second less to import.)
    """
    if free.all():
        return np.full(free.shape, np.inf)
    d = cv2.distanceTransform(free.astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE).astype(np.float64)
    return np.sqrt(np.rint(d * d))


def _rects_overlap(a: Obstacle, b: Obstacle) -> bool:
    """Separating-axis test of two yawed rectangles (touching counts as apart)."""
    ca, cb = a.corners(), b.corners()
    for rect in (a, b):
        for yaw in (rect.yaw, rect.yaw + math.pi / 2):
            axis = np.array([math.cos(yaw), math.sin(yaw)])
            pa, pb = ca @ axis, cb @ axis
            if pa.max() <= pb.min() + 1e-9 or pb.max() <= pa.min() + 1e-9:
                return False
    return True


class StoreGeometry:
    """The checked layout of a store and its navigation grid.

    Attributes:
        config: the `[store]` section.
        obstacles: shelves, then the checkout counter, then the checkout lanes' counters.
        entrance, exit: the doors.
        free: (nx, ny) bool navigation grid, True where a pelvis may plan to be.
        boxes: every box of the store for drawing and recording.
    """

    def __init__(self, config: StoreConfig, nav_clearance_m: float = 0.45, wall_clearance_m: float = 0.35,
                 name: str = "store"):
        """Builds and checks the layout.

        Args:
            config: the `[store]` section.
            nav_clearance_m: distance planned paths keep from shelf faces.
            wall_clearance_m: distance planned paths keep from walls.
            name: scenario name for error messages.

        Raises:
            ScenarioError: shelves outside the floor or overlapping, a door off the walls or blocked, walkable
                floor that no door reaches (naming the shelf that closes it off).
        """
        self.config = config
        self.name = name
        W, D = config.width_m, config.depth_m
        obstacles = []
        for i, shelf in enumerate(config.shelves):
            expanded = config.first_expanded is not None and i >= config.first_expanded
            key = f"store.shelves[{i}]{' (of store.aisles)' if expanded else ''}"
            obstacles.append(Obstacle(key, np.array(shelf.center_m, float), np.array(shelf.size_m[:2], float) / 2,
                                      math.radians(shelf.yaw_deg), shelf.size_m[2]))
        if config.checkout_m is not None:
            obstacles.append(Obstacle("store.checkout_m", np.array(config.checkout_m, float),
                                      np.array(config.checkout_size_m[:2], float) / 2, 0.0, config.checkout_size_m[2],
                                      np.array([0.0, 1.0])))
        if config.checkout_lanes is not None:
            lanes = config.checkout_lanes
            normal = np.array([1.0, 0.0] if lanes.along is AisleAxis.Y else [0.0, 1.0])  # the long faces, in the lanes
            for k, (center, size) in enumerate(lanes.counters(W, D, config.ceiling_m)):
                obstacles.append(Obstacle(f"store.checkout_lanes[{k}]", np.array(center, float),
                                          np.array(size[:2], float) / 2, 0.0, size[2], normal))
        self.obstacles = tuple(obstacles)
        # The same rectangles as arrays, for vectorised distance and push-out.
        self._ob_center = np.array([o.center for o in obstacles]).reshape(-1, 2)
        self._ob_half = np.array([o.half for o in obstacles]).reshape(-1, 2)
        self._ob_cos = np.cos([o.yaw for o in obstacles])
        self._ob_sin = np.sin([o.yaw for o in obstacles])
        for i, ob in enumerate(self.obstacles):
            corners = ob.corners()
            if corners.min() < -1e-9 or corners[:, 0].max() > W + 1e-9 or corners[:, 1].max() > D + 1e-9:
                raise self._err(ob.key, f"footprint {np.round(corners, 2).tolist()} extends outside the floor "
                                        f"[0, {W}] x [0, {D}] m")
            for other in self.obstacles[:i]:
                if _rects_overlap(ob, other):
                    raise self._err(ob.key, f"overlaps {other.key}")
        self.entrance = self._door("store.entrance_m", config.entrance_m, (0.0, 0.25 * D))
        self.exit = self._door("store.exit_m", config.exit_m, (0.0, 0.75 * D))
        gap = np.linalg.norm(self.entrance.center - self.exit.center)
        if gap < config.door_width_m:
            raise self._err("store.exit_m", f"door at {_xy(self.exit.center)} overlaps store.entrance_m (centres "
                                            f"{gap:.2f} m apart, need >= door_width_m = {config.door_width_m})")
        self.nav_clearance_m = nav_clearance_m
        self.wall_clearance_m = wall_clearance_m
        self._build_grid()
        for door in (self.entrance, self.exit):
            if not self.free[self.cell_of(door.inside)]:
                blocker = self._nearest_obstacle(door.inside)
                raise self._err(door.key, f"door at {_xy(door.center)} is blocked by {blocker} "
                                          f"(keep {INSIDE_DOOR_M + nav_clearance_m:.2f} m in front of a door clear)")
        if not self.connected(self.entrance.inside, self.exit.inside):
            closing = self._closing(self._components == self._components[self.cell_of(self.exit.inside)])
            raise self._err("store.exit_m", f"cannot be reached from store.entrance_m around the shelves "
                                            f"({closing} closes it off)")
        self._check_reachable()
        self.boxes = self._boxes()

    def _check_reachable(self) -> None:
        """Raises ScenarioError naming the obstacle that closes off walkable floor no door reaches."""
        reached = self._components[self.cell_of(self.entrance.inside)]
        labels, counts = np.unique(self._components[(self._components != 0) & (self._components != reached)],
                                   return_counts=True)
        if not len(labels):
            return
        cut_off = self._components == labels[int(np.argmax(counts))]
        cells = self.cell_centers[cut_off]
        low, high = cells.min(axis=0) - GRID_CELL_M / 2, cells.max(axis=0) + GRID_CELL_M / 2
        raise self._err(self._closing(cut_off), f"closes off {cut_off.sum() * GRID_CELL_M**2:.1f} m² of walkable "
                                                f"floor in x [{low[0]:.1f}, {high[0]:.1f}] x y [{low[1]:.1f}, "
                                                f"{high[1]:.1f}] m from the doors (people must reach every walkable "
                                                f"area: leave a passage >= {MIN_AISLE_M:g} m wide)")

    def _closing(self, cut_off: np.ndarray) -> str:
        """The key of the obstacle whose removal joins the cells `cut_off` (nx, ny) to the entrance's, trying those
        nearest to them first. Where no one obstacle does, the obstacles that do together (`a and b together`):
        the nearest bordering obstacle is taken away and the search repeated from the larger area it opens."""
        start, cell = self.cell_of(self.entrance.inside), tuple(int(v[0]) for v in np.nonzero(cut_off))
        removed: list[int] = []
        while True:
            cells = self.cell_centers[cut_off]
            gap = {k: float(rect_distance(cells, o.center, o.half, o.yaw).min()) for k, o in enumerate(self.obstacles)
                   if k not in removed}
            near = [k for k in sorted(gap, key=gap.get) if gap[k] < self.nav_clearance_m + 2 * GRID_CELL_M]
            if not near:
                return " and ".join(self.obstacles[k].key for k in removed) + " together" if removed else "the walls"
            for k in near:
                kept = [o for i, o in enumerate(self.obstacles) if i != k and i not in removed]
                labels = self._components_of(self._free_grid(kept))
                if labels[start] != 0 and labels[start] == labels[cell]:
                    keys = [self.obstacles[i].key for i in (*removed, k)]
                    return keys[0] if len(keys) == 1 else " and ".join(keys) + " together"
            removed.append(near[0])
            kept = [o for i, o in enumerate(self.obstacles) if i not in removed]
            labels = self._components_of(self._free_grid(kept))
            cut_off = labels == labels[cell]

    def _err(self, key: str, message: str):
        return _error(f"{self.name}: {key}", message)

    def _nearest_obstacle(self, point: np.ndarray) -> str:
        if not self.obstacles:
            return "the walls"
        d = [rect_distance(point, o.center, o.half, o.yaw) for o in self.obstacles]
        return self.obstacles[int(np.argmin(d))].key

    def _door(self, key: str, value, default) -> Door:
        W, D = self.config.width_m, self.config.depth_m
        p = np.array(default if value is None else value, dtype=float)
        half = self.config.door_width_m / 2
        walls = [  # (distance to the wall line, along-wall coordinate, wall length, inward normal)
            (abs(p[0]), p[1], D, (1.0, 0.0)),
            (abs(p[0] - W), p[1], D, (-1.0, 0.0)),
            (abs(p[1]), p[0], W, (0.0, 1.0)),
            (abs(p[1] - D), p[0], W, (0.0, -1.0)),
        ]
        dist, along, length, inward = min(walls, key=lambda w: w[0])
        if dist > 0.05:
            raise self._err(key, f"{_xy(p)} is not on a wall of the [0, {W}] x [0, {D}] m floor "
                                 "(one coordinate must be 0 or the floor's width/depth)")
        if not half + 0.2 <= along <= length - half - 0.2:
            raise self._err(key, f"{_xy(p)}: a door {self.config.door_width_m} m wide must keep 0.2 m from the "
                                 f"corners (along-wall coordinate in [{half + 0.2:.2f}, {length - half - 0.2:.2f}])")
        inward = np.array(inward)
        center = p + dist * inward * (1 if np.dot(p - np.array([W / 2, D / 2]), inward) < 0 else -1)
        door = Door(key, center, inward, self.config.door_width_m)
        for ob in self.obstacles:
            mouth = door.center + np.outer(np.linspace(0.0, INSIDE_DOOR_M, 9), inward)
            if np.any(rect_distance(mouth, ob.center, ob.half, ob.yaw) < 0.3):
                raise self._err(key, f"door at {_xy(center)} lies inside or against {ob.key}")
        return door

    def obstacle_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The footprints as contiguous arrays for the crowd's loops: centres (O, 2), half extents (O, 2),
        cos and sin of the yaws (O,)."""
        return tuple(np.ascontiguousarray(a, dtype=float) for a in (self._ob_center, self._ob_half, self._ob_cos,
                                                                     self._ob_sin))

    # -- navigation grid -------------------------------------------------------------------------

    def _build_grid(self):
        W, D = self.config.width_m, self.config.depth_m
        self.nx, self.ny = int(math.ceil(W / GRID_CELL_M)), int(math.ceil(D / GRID_CELL_M))
        xs = (np.arange(self.nx) + 0.5) * GRID_CELL_M
        ys = (np.arange(self.ny) + 0.5) * GRID_CELL_M
        self.cell_centers = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1)  # (nx, ny, 2)
        self.free = free = self._free_grid(self.obstacles)
        # The free cells' 8-connected components (0: blocked): which doors and goals reach each other.
        self._components = self._components_of(free)
        self.free_area_m2 = float(free.sum()) * GRID_CELL_M**2
        # Distance from every cell to the nearest blocked cell: used to smooth paths away from corners.
        self.clearance = _distance_to_blocked(free) * GRID_CELL_M

    def _free_grid(self, obstacles) -> np.ndarray:
        """(nx, ny) bool: the cells a pelvis may plan to be with these obstacles (`free`): clear of the walls, except
        in front of the doors, and `nav_clearance_m` from every obstacle."""
        W, D = self.config.width_m, self.config.depth_m
        P = self.cell_centers
        c = self.wall_clearance_m
        free = (P[..., 0] >= c) & (P[..., 0] <= W - c) & (P[..., 1] >= c) & (P[..., 1] <= D - c)
        near = np.zeros(P.shape[:2], dtype=bool)  # within the clearance of an obstacle

        def window(points: np.ndarray, margin: float) -> tuple[slice, slice]:
            """The cells whose centres may lie within `margin` of the box around `points` (k, 2): the rest of the
            grid cannot change, so only these are computed."""
            i0, j0 = np.maximum(np.floor((points.min(axis=0) - margin) / GRID_CELL_M - 1).astype(int), 0)
            i1, j1 = np.ceil((points.max(axis=0) + margin) / GRID_CELL_M + 1).astype(int)
            return slice(i0, i1), slice(j0, j1)

        for ob in obstacles:
            w = window(ob.corners(), self.nav_clearance_m)
            near[w] |= rect_distance(P[w], ob.center, ob.half, ob.yaw) < self.nav_clearance_m
        free &= ~near
        # Doors: let the approach corridor through the wall clearance.
        for door in (self.entrance, self.exit):
            tangent = np.array([-door.inward[1], door.inward[0]])
            deep = INSIDE_DOOR_M + 0.1
            w = window(door.center + np.array([-1.0, 1.0])[:, None] * tangent * door.width / 2 + np.array(
                [[0.0], [deep]]) * door.inward, 0.0)
            rel = P[w] - door.center
            along = np.abs(rel @ tangent)
            depth = rel @ door.inward
            free[w] |= (along <= door.width / 2 - 0.2) & (depth >= 0) & (depth <= deep) & ~near[w]
        return free

    def cell_of(self, point) -> tuple[int, int]:
        """Grid cell (i, j) containing a point (clamped to the grid)."""
        i = min(max(int(point[0] / GRID_CELL_M), 0), self.nx - 1)
        j = min(max(int(point[1] / GRID_CELL_M), 0), self.ny - 1)
        return i, j

    def nearest_free(self, point) -> np.ndarray:
        """(2,) centre of the free cell nearest to a point."""
        i, j = self.cell_of(point)
        if self.free[i, j]:
            return self.cell_centers[i, j].copy()
        fi, fj = np.nonzero(self.free)
        k = int(np.argmin((fi - i) ** 2 + (fj - j) ** 2))
        return self.cell_centers[fi[k], fj[k]].copy()

    @staticmethod
    def _components_of(free: np.ndarray) -> np.ndarray:
        """(nx, ny) int32 label of each free cell's 8-connected component (0 on blocked cells)."""
        return cv2.connectedComponents(free.astype(np.uint8), connectivity=8, ltype=cv2.CV_32S)[1]

    def connected(self, a, b) -> bool:
        """Whether a path over free cells (8-connected, as `plan` moves) joins the cells of points a and b."""
        ca, cb = self._components[self.cell_of(a)], self._components[self.cell_of(b)]
        return bool(ca != 0 and ca == cb)

    def line_free(self, a, b) -> bool:
        """Whether the straight segment a-b stays on free cells (sampled every half cell)."""
        return segment_free(self.free, float(a[0]), float(a[1]), float(b[0]), float(b[1]), GRID_CELL_M)

    def plan(self, start: np.ndarray, goal: np.ndarray) -> list[np.ndarray]:
        """A path from start to goal around the obstacles: grid shortest path, then string-pulled.

        The grid search is A* over the 8-connected free cells (octile distance to the goal, which never
        overestimates, so the path is a shortest one); the smoothing keeps only the waypoints needed
        for straight segments that stay on free cells.

        Returns:
            waypoints (each (2,)), ending at the goal; empty if the goal is unreachable.
        """
        i, j = self.cell_of(start)
        if not self.free[i, j]:
            i, j = self.cell_of(self.nearest_free(start))
        gi, gj = self.cell_of(goal)
        cells = astar(self.free, i * self.ny + j, gi * self.ny + gj, GRID_CELL_M).tolist()
        if not cells:
            return []
        # String pulling over every third cell: keep a waypoint only where the straight view from the
        # previous one ends.
        picks = cells[::3] if (len(cells) - 1) % 3 == 0 else cells[::3] + [cells[-1]]
        flat = self.cell_centers.reshape(-1, 2)
        pts = [flat[c] for c in picks]
        pts.append(np.asarray(goal, float))
        out = [np.asarray(start, float)]
        for k in range(1, len(pts)):
            if not self.line_free(out[-1], pts[k]):
                out.append(pts[k - 1])
        out.append(np.asarray(goal, float))
        return out[1:]

    # -- boxes -----------------------------------------------------------------------------------

    def _boxes(self) -> tuple[Box, ...]:
        cfg = self.config
        W, D, H, T = cfg.width_m, cfg.depth_m, cfg.wall_height_m, WALL_THICKNESS_M
        boxes = [Box(BoxKind.FLOOR, (W / 2, D / 2, -FLOOR_THICKNESS_M / 2), (W + 2 * T, D + 2 * T, FLOOR_THICKNESS_M))]
        # Each wall as segments between the door gaps.
        walls = [  # (start point, direction, length, outward offset)
            (np.array([0.0, 0.0]), np.array([1.0, 0.0]), W, np.array([0.0, -T / 2])),
            (np.array([0.0, D]), np.array([1.0, 0.0]), W, np.array([0.0, T / 2])),
            (np.array([0.0, 0.0]), np.array([0.0, 1.0]), D, np.array([-T / 2, 0.0])),
            (np.array([W, 0.0]), np.array([0.0, 1.0]), D, np.array([T / 2, 0.0])),
        ]
        for start, direction, length, offset in walls:
            gaps = []
            for door in (self.entrance, self.exit):
                rel = door.center - start
                if abs(rel @ np.array([-direction[1], direction[0]])) < 1e-6:
                    a = rel @ direction
                    gaps.append((a - door.width / 2, a + door.width / 2))
            edges = [-T] + [g for gap in sorted(gaps) for g in gap] + [length + T]
            for a, b in zip(edges[0::2], edges[1::2]):
                if b - a > 1e-6:
                    mid = start + direction * (a + b) / 2 + offset
                    size = (b - a, T) if direction[0] else (T, b - a)
                    boxes.append(Box(BoxKind.WALL, (mid[0], mid[1], H / 2), (size[0], size[1], H)))
        for door, kind in ((self.entrance, BoxKind.ENTRANCE), (self.exit, BoxKind.EXIT)):
            c = door.center + door.inward * (INSIDE_DOOR_M / 2)
            along = door.width if door.inward[1] else INSIDE_DOOR_M
            across = INSIDE_DOOR_M if door.inward[1] else door.width
            boxes.append(Box(kind, (c[0], c[1], DOOR_MAT_HEIGHT_M / 2), (along, across, DOOR_MAT_HEIGHT_M)))
        for ob in self.obstacles:
            kind = BoxKind.SHELF if ob.till_normal is None else BoxKind.CHECKOUT
            boxes.append(Box(kind, (ob.center[0], ob.center[1], ob.height / 2),
                             (2 * ob.half[0], 2 * ob.half[1], ob.height), ob.yaw))
        return tuple(boxes)

    def browse_spots(self, standoff_m: float = 0.5) -> list[tuple[np.ndarray, float, int]]:
        """Places to stand in front of a shelf: (pelvis position (2,), heading toward the shelf, shelf index).

        One spot per metre along each long face that is reachable, standing `standoff_m` from the face.
        """
        spots = []
        for k, ob in enumerate(self.obstacles):
            if ob.till_normal is not None:  # a checkout counter: paid at, not browsed
                continue
            c, s = math.cos(ob.yaw), math.sin(ob.yaw)
            ax, ay = np.array([c, s]), np.array([-s, c])
            for axis, other, h_along, h_across in ((ax, ay, ob.half[0], ob.half[1]), (ay, ax, ob.half[1], ob.half[0])):
                n = max(1, int(2 * h_along // 1.0))
                for side in (-1.0, 1.0):
                    normal = other * side
                    for u in (np.arange(n) + 0.5) / n * 2 - 1:
                        p = ob.center + axis * u * h_along + normal * (h_across + standoff_m)
                        i, j = self.cell_of(p)
                        if 0 <= p[0] <= self.config.width_m and 0 <= p[1] <= self.config.depth_m:
                            near = self.cell_centers[i, j]
                            if self.free[i, j] and np.linalg.norm(near - p) < 0.2:
                                spots.append((p, math.atan2(-normal[1], -normal[0]), k))
        return spots


@jit
def segment_free(free, ax, ay, bx, by, cell):
    """Whether the segment (ax, ay)-(bx, by) stays on the True cells of free (nx, ny), sampled every half cell."""
    dx, dy = bx - ax, by - ay
    n = max(2, int(math.sqrt(dx * dx + dy * dy) / (cell * 0.5)) + 1)
    inv = 1 / cell
    for k in range(n):
        u = k / (n - 1)
        i, j = int((ax + u * dx) * inv), int((ay + u * dy) * inv)  # truncation, as astype
        if i < 0 or j < 0 or i >= free.shape[0] or j >= free.shape[1] or not free[i, j]:
            return False
    return True


@jit
def astar(free, start, goal, cell):
    """(L,) int64 flat cells (i * ny + j) of a shortest 8-connected path over the True cells of free (nx, ny)
    from start to goal, both included; empty if there is none. Edges cost cell or cell * sqrt(2); ties
    in the open list go to the earlier pushed cell, so the result is deterministic."""
    nx, ny = free.shape
    if not (free[start // ny, start % ny] and free[goal // ny, goal % ny]):
        return np.zeros(0, dtype=np.int64)
    cost = np.full(nx * ny, np.inf)
    parent = np.full(nx * ny, -1, dtype=np.int64)
    closed = np.zeros(nx * ny, dtype=np.bool_)
    gi, gj = goal // ny, goal % ny
    diag = cell * math.sqrt(2.0)
    cost[start] = 0.0
    heap = [(0.0, 0, start)]
    pushed = 0
    while heap:
        _, _, k = heapq.heappop(heap)
        if closed[k]:
            continue
        closed[k] = True
        if k == goal:
            break
        i, j = k // ny, k % ny
        for di in range(-1, 2):
            for dj in range(-1, 2):
                i2, j2 = i + di, j + dj
                if (di == 0 and dj == 0) or i2 < 0 or j2 < 0 or i2 >= nx or j2 >= ny or not free[i2, j2]:
                    continue
                k2 = i2 * ny + j2
                if closed[k2]:
                    continue
                c = cost[k] + (diag if di != 0 and dj != 0 else cell)
                if c < cost[k2]:
                    cost[k2] = c
                    parent[k2] = k
                    ai, aj = abs(gi - i2), abs(gj - j2)
                    h = cell * (max(ai, aj) - min(ai, aj)) + diag * min(ai, aj)  # octile distance
                    pushed += 1
                    heapq.heappush(heap, (c + h, pushed, k2))
    if not closed[goal]:
        return np.zeros(0, dtype=np.int64)
    n = 1
    k = goal
    while k != start:
        k = parent[k]
        n += 1
    path = np.empty(n, dtype=np.int64)
    k = goal
    for m in range(n - 1, -1, -1):
        path[m] = k
        k = parent[k]
    return path
