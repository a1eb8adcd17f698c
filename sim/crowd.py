"""Crowd motion: paths around shelves, gait, browsing, arrivals and departures.

The crowd advances in fixed steps of `STEP_S` of simulated time, whatever the pattern of calls that
asks for poses, so the same scenario and seed give the same motion bit for bit. Each step:

1. arrivals through the entrance and departures through the exit;
2. each person's wish: follow the planned path (grid shortest path, string-pulled; `StoreGeometry.plan`)
   toward a shelf, a place to stand, the checkout or the exit at a pace that varies along the way, now and
   then stopping on the way turned to one side, or stand still facing a shelf;
3. local avoidance: steer off predicted close passes with other people (time to closest approach);
4. integration with bounded acceleration and turn rate;
5. hard constraints: pelvis centres at least `SEPARATION_M` apart, at least `SHELF_CLEARANCE_M` from
   shelf faces and inside the walls; a person whose step would break them keeps the last valid position;
6. gait: the phase advances with a cadence that follows speed; a foot is locked to the floor in stance
   and swings from where it left the floor to where the body will be at touchdown;
7. arms, gaze and weight: what each person does with their hands, where they look and which foot bears
   their weight (`sim.gestures`).

`Crowd.state` holds everything `sim.world` needs to pose the bodies, one row per body slot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from core.errors import ScenarioError
from core.jit import jit
from sim.config import bounded, check_ranges
from sim.gestures import Gestures
from sim.humanoid import HIP_HALF_WIDTH, SUPPORTED_HEIGHT_M, sample_heights
from sim.store import StoreGeometry, astar, segment_free
from sim.types import Activity

# Crowd time step. Poses between steps are interpolated, so this bounds how far anyone moves unseen.
STEP_S = 0.1
# Hard limits the crowd keeps at every step (interpolation between steps loses a few centimetres at most).
SEPARATION_M = 0.5
SHELF_CLEARANCE_M = 0.32
WALL_CLEARANCE_M = 0.3
# A projection moves people this much beyond the hard limits, so that they do not hit them again next step.
PROJECTION_MARGIN_M = 0.06
# Distance people like to keep when passing each other.
COMFORT_M = 0.8
# Walkers keep this far from shelf faces when they can, pushed off at up to SHELF_PUSH_M_S.
SHELF_COMFORT_M = 0.45
SHELF_PUSH_M_S = 0.6
# Gains (m/s per unit urgency) of steering off a predicted close pass and of the short-range push.
AVOID_GAIN = 1.6
PUSH_GAIN = 0.8
# Fraction of the gait cycle a foot is locked to the floor (the rest is heel-off and swing).
STANCE_FRACTION = 0.45
# Peak foot lift in swing and the swing length over which it reaches it.
SWING_LIFT_M = 0.09
FULL_LIFT_STRIDE_M = 0.3
MAX_ACCEL_M_S2 = 2.0
# How far outside a door people may be pushed; leavers vanish once this far outside the exit.
OUTSIDE_REACH_M = 1.2
VANISH_DEPTH_M = 0.25
# Fastest anybody moves, walking or pushed aside.
MAX_SPEED_M_S = 2.0
MAX_TURN_RAD_S = 3.0
# A walker who has not moved for this long gives up on the current goal (a stop on the way is shorter).
STUCK_S = 4.0
# Small steps of someone standing (at a shelf, a place, the counter): now and then (exponential gaps of mean
# SHUFFLE_GAP_S) a step of SHUFFLE_S toward a point within SHUFFLE_RADIUS_M of where they started to stand, as
# people shift their feet, turn a little or edge along a shelf. Set from real actors standing at Shelf's shelf
# (25 fps): their hips move a median 0.087 m/s over one second, p95 0.32 (`crossview world-stats` reports the
# same figures, `hip_speed_standing_1s_*`; docs/scenarios.md).
SHUFFLE_GAP_S = 1.0
SHUFFLE_S = (0.8, 1.6)
SHUFFLE_RADIUS_M = 0.3
# A walker's pace is redrawn after this long (seconds, min and max).
PACE_HOLD_S = (2.0, 6.0)
# Walkers stop on the way only with at least this much path left, and turn this far (radians) to look.
PAUSE_CLEAR_M = 1.5
PAUSE_TURN_RAD = (0.4, 1.3)
# A group (`CrowdConfig.group_size`): the others stand between GROUP_GAP_M and GROUP_RADIUS_M from the goal of
# the group's first person, as friends or a family stand around the shelf one of them looks at.
GROUP_GAP_M = 0.6
GROUP_RADIUS_M = 1.3
# Bounds of the [crowd] section: people at once, and any duration of a visit or an activity (a day).
MAX_PEOPLE = 2000
_MAX_TIME_S = 86400.0


# The same as a plain module constant: an enum member's class attribute lookup is slow in per-person loops.
_WALK = Activity.WALK


@dataclass(frozen=True)
class CrowdConfig:
    """[crowd]: who walks through the store and how.

    Attributes:
        people: people in the store at once (the number of body slots); a leaver is replaced by a newcomer.
        start_inside: at t = 0 everybody is already inside; otherwise they arrive one by one.
        height_range_m: (min, max) body heights drawn from an adult mixture (women and men), min < max.
        heights_m: fixed heights of the first people (ids 0, 1, ...); the rest are drawn.
        speed_range_m_s: (min, max) preferred walking speeds, min <= max.
        mean_visit_s: mean time from arrival to heading for the exit.
        mean_arrival_gap_s: mean delay before a newcomer replaces a leaver.
        browse_share: chance that the next goal is a shelf (the rest are places to stand).
        stand_s: (min, max) time a person stands at a place, min <= max.
        browse_s: (min, max) time a person browses a shelf, min <= max.
        checkout_s: (min, max) time a person pays at the checkout, min <= max.
        area_per_person_m2: walkable floor each person needs; more people than the floor holds is an error.
        pace_range: (min, max) a walker's pace as a fraction of their preferred speed, redrawn every 2 to 6 s
            of walking, min <= max.
        pause_rate_hz: how often a walker stops on the way to look at something, per second of walking (0:
            never).
        pause_s: (min, max) how long such a stop lasts, min <= max (shorter than the 4 s after which a walker
            who does not move gives up the goal).
        look_rate_hz: how often a person glances to one side (neck and trunk twist), per second.
        handling_hz: (min, max) frequency of the hand movements of someone handling an item, a phone or
            talking with their hands, min <= max.
        hand_motion_scale: scale of the sizes of those hand movements (1: standing people's wrists move a
            median 0.14 m/s over one second, as real actors' at a shelf; 0: hands still while they hold a pose).
        group_size: people who go about together (the people of consecutive body slots): the first picks where
            to go and the others set off with them at once at their pace, to places 0.6 to 1.3 m around that goal,
            and stand there until the first moves on; each leaves on their own time (1: everybody alone).
    """

    people: int = bounded(4, 0, MAX_PEOPLE, unit="people")
    start_inside: bool = True
    height_range_m: tuple[float, float] = bounded((1.50, 1.95), *SUPPORTED_HEIGHT_M)
    heights_m: tuple[float, ...] = bounded((), *SUPPORTED_HEIGHT_M)
    speed_range_m_s: tuple[float, float] = bounded((0.6, 1.6), 0.3, 2.0)
    mean_visit_s: float = bounded(180.0, 0.0, _MAX_TIME_S, low_open=True)
    mean_arrival_gap_s: float = bounded(10.0, 0.0, _MAX_TIME_S, low_open=True)
    browse_share: float = bounded(0.6, 0.0, 1.0, unit="fraction")
    stand_s: tuple[float, float] = bounded((2.0, 8.0), 0.0, _MAX_TIME_S, low_open=True)
    browse_s: tuple[float, float] = bounded((5.0, 15.0), 0.0, _MAX_TIME_S, low_open=True)
    checkout_s: tuple[float, float] = bounded((5.0, 15.0), 0.0, _MAX_TIME_S, low_open=True)
    area_per_person_m2: float = bounded(1.0, 0.0, 100.0, low_open=True)
    pace_range: tuple[float, float] = bounded((0.85, 1.1), 0.3, 1.5, unit="fraction of the preferred speed")
    pause_rate_hz: float = bounded(0.05, 0.0, 10.0, unit="Hz")
    pause_s: tuple[float, float] = bounded((0.8, 3.0), 0.0, STUCK_S, low_open=True, high_open=True)
    look_rate_hz: float = bounded(0.2, 0.0, 10.0, unit="Hz")
    handling_hz: tuple[float, float] = bounded((0.6, 1.4), 0.0, 5.0, low_open=True, unit="Hz")
    hand_motion_scale: float = bounded(1.0, 0.0, 3.0, unit="times")
    group_size: int = bounded(1, 1, 20, unit="people")

    def __post_init__(self):
        check_ranges(self)
        if not self.height_range_m[0] < self.height_range_m[1]:
            raise ValueError(f"height_range_m: {self.height_range_m} must have min < max")
        for name in ("speed_range_m_s", "stand_s", "browse_s", "checkout_s", "pace_range", "pause_s", "handling_hz"):
            a, b = getattr(self, name)
            if not a <= b:
                raise ValueError(f"{name}: {getattr(self, name)} must have min <= max")


def validate(config: CrowdConfig, store: StoreGeometry, name: str = "scenario") -> None:
    """Cross-checks the crowd against the store.

    Raises:
        ScenarioError: more people than the walkable floor holds.
    """

    need = config.people * config.area_per_person_m2
    if need > store.free_area_m2:
        raise ScenarioError(
            f"{name}: crowd.people: {config.people} people need {need:.0f} m² of walkable floor "
            f"({config.area_per_person_m2} m² each) but the store has {store.free_area_m2:.1f} m²; "
            f"use at most {int(store.free_area_m2 // config.area_per_person_m2)} people or a larger store"
        )


def cadence_steps_s(speed_m_s: np.ndarray, height_m: np.ndarray) -> np.ndarray:
    """Steps per second for a walking speed: faster walkers step both longer and quicker.

    1.2 + 0.6 v steps/s gives about 1.56 steps/s (0.38 m steps) at 0.6 m/s, 1.98 (0.66 m) at 1.3 m/s and
    2.16 (0.74 m) at 1.6 m/s for a 1.75 m adult; taller people step proportionally slower.
    """
    return (1.2 + 0.6 * speed_m_s) * np.sqrt(1.75 / height_m)


class _Agent:
    """Per-person bookkeeping that is not numeric state (goals, paths, timers)."""

    __slots__ = ("activity", "path", "rest", "goal_kind", "goal", "goal_heading", "goal_top", "until", "depart_at",
                 "stuck", "leaving", "in_door", "checked_out", "pace", "pace_until", "next_pause", "pause_until",
                 "pause_heading", "anchor", "shuffle_vel", "shuffle_until", "next_shuffle")

    def __init__(self):
        self.activity = Activity.WALK
        self.path: list[tuple[float, float]] = []
        self.rest: list[float] = []  # path length after each waypoint
        self.goal_kind = Activity.STAND
        self.goal: np.ndarray | None = None
        self.goal_heading: float | None = None
        self.goal_top = 0.0  # top of the shelf or counter at the goal (0: none)
        self.until = 0.0
        self.depart_at = math.inf
        self.stuck = 0.0
        self.pace = 1.0  # fraction of the preferred speed
        self.pace_until = 0.0
        self.next_pause = math.inf  # when a walker next stops on the way
        self.pause_until = -math.inf
        self.pause_heading = 0.0
        self.leaving = False
        self.in_door = False
        self.checked_out = False
        self.anchor = (0.0, 0.0)  # where a standing person started to stand
        self.shuffle_vel = (0.0, 0.0)  # the wished velocity of a small step
        self.shuffle_until = -math.inf
        self.next_shuffle = math.inf


class Crowd:
    """Everybody's motion over time, one body slot per person present.

    Attributes:
        slots: number of body slots (`config.people`).
        time_s: time of the current step.
        person_id: (S,) id of the person in each slot, -1 for an empty slot.
        height: (S,) body height of the person in each slot.
        pos, vel: (S, 2) pelvis ground position and velocity.
        heading: (S,) facing direction, radians, unwrapped (continuous over turns).
        phase: (S,) gait phase in cycles, unwrapped; the left foot is in stance for frac(phase) < STANCE_FRACTION.
        stride: (S,) stride length (distance per gait cycle) at the current speed.
        feet: (S, 2, 2) world xy of the left and right ankles.
        swing_len: (S, 2) length of each foot's current swing (0 when it stays put).
        gestures: what everybody does with their arms, gaze and weight (`sim.gestures`); `gestures.value`
            (S, NUM_CHANNELS) holds the joint angles and the shift `sim.world` poses.
        arrivals, departures: counts so far.
    """

    def __init__(self, config: CrowdConfig, store: StoreGeometry, rng: np.random.Generator):
        self.config = config
        self.store = store
        self.rng = rng
        S = self.slots = config.people
        self.time_s = 0.0
        self.step_index = 0
        self.next_id = 0
        self.person_id = np.full(S, -1, dtype=np.int64)
        self.height = np.full(S, 1.75)
        self.speed_pref = np.full(S, 1.2)
        self.pos = np.zeros((S, 2))
        self.vel = np.zeros((S, 2))
        self.heading = np.zeros(S)
        self.omega = np.zeros(S)
        self.phase = np.zeros(S)
        self.stride = np.zeros(S)
        self.feet = np.zeros((S, 2, 2))
        self.liftoff = np.zeros((S, 2, 2))
        self.swing_len = np.zeros((S, 2))
        # The same arrays as the gait kernel takes them (written in place, never replaced).
        self._gait = Gait(self.phase, self.stride, self.feet, self.liftoff, self.swing_len)
        self.gestures = Gestures(S, rng, config)
        # The standing people's small steps draw from a stream of their own (spawned: the crowd's stream is
        # not advanced), so that they do not change where anybody goes.
        self._shuffle_rng = rng.spawn(1)[0]
        self.arrivals = 0
        self.departures = 0
        self.agents = [_Agent() for _ in range(S)]
        self._spots = store.browse_spots()
        self._obstacles = store.obstacle_arrays()
        _warm_up()
        # The tills: (where a shopper stands, heading, the counter's top), 0.5 m off the middle of each paying face.
        self._checkout_spots = []
        for ob in store.obstacles:
            if ob.till_normal is None:
                continue
            n = ob.till_normal
            for side in (-1.0, 1.0):
                p = ob.center + n * side * (float(np.abs(n) @ ob.half) + 0.5)
                i, j = store.cell_of(p)
                if store.free[i, j]:
                    self._checkout_spots.append((p, math.atan2(-side * n[1], -side * n[0]), ob.height))
        fi, fj = np.nonzero(store.free)
        cells = store.cell_centers[fi, fj]
        # Places to start or stand: free cells away from the walls (the door corridors are free too).
        margin = WALL_CLEARANCE_M + 0.1
        inner = np.all((cells >= margin) & (cells <= [store.config.width_m - margin, store.config.depth_m - margin]),
                       axis=1)
        self._free_cells = cells[inner]
        self._next_arrival = math.inf
        self._pending_arrivals = 0
        self._upper = np.array([store.config.width_m, store.config.depth_m]) - WALL_CLEARANCE_M
        self._lo_bounds = np.full((S, 2), WALL_CLEARANCE_M)  # the walls' bounds for everybody away from a door
        self._hi_bounds = np.tile(self._upper, (S, 1))
        # Entrance then exit: (centre, inward normal, width) in plain floats.
        self._doors = tuple((tuple(d.center.tolist()), tuple(d.inward.tolist()), float(d.width))
                            for d in (store.entrance, store.exit))
        if config.start_inside:
            for s in range(S):
                self._spawn(s, inside=True)
        else:
            self._pending_arrivals = S
            self._next_arrival = 0.0

    # -- people coming and going -----------------------------------------------------------------

    def _new_person(self, s: int):
        cfg = self.config
        pid = self.next_id
        self.next_id += 1
        self.person_id[s] = pid
        if pid < len(cfg.heights_m):
            self.height[s] = cfg.heights_m[pid]
        else:
            self.height[s] = sample_heights(self.rng, 1, *cfg.height_range_m)[0]
        lo, hi = cfg.speed_range_m_s
        self.speed_pref[s] = float(np.clip(self.rng.normal(1.15, 0.22), lo, hi))
        agent = self.agents[s] = _Agent()
        return agent

    def _spawn(self, s: int, inside: bool) -> bool:
        """Puts a new person in slot s: anywhere free inside (t = 0) or just outside the entrance."""
        active = self.person_id >= 0
        if inside:
            for _ in range(200):
                p = self._free_cells[self.rng.integers(len(self._free_cells))]
                if not active.any() or np.min(np.linalg.norm(self.pos[active] - p, axis=1)) >= 0.9:
                    break
            else:
                return False
            agent = self._new_person(s)
            self.pos[s] = p
            self.heading[s] = self.rng.uniform(-math.pi, math.pi)
            agent.depart_at = self.time_s + self.rng.uniform(0.1, 1.5) * self.config.mean_visit_s
        else:
            door = self.store.entrance
            if active.any() and np.min(np.linalg.norm(self.pos[active] - door.outside, axis=1)) < 1.0:
                return False
            if active.any() and np.min(np.linalg.norm(self.pos[active] - door.inside, axis=1)) < 0.8:
                return False
            agent = self._new_person(s)
            self.pos[s] = door.outside
            self.heading[s] = math.atan2(door.inward[1], door.inward[0])
            agent.in_door = True
            agent.depart_at = self.time_s + self.rng.exponential(self.config.mean_visit_s)
            self.arrivals += 1
        self.vel[s] = 0.0
        self.omega[s] = 0.0
        self.phase[s] = self.rng.uniform(0.0, 1.0)
        self.stride[s] = 0.0
        c, sn = math.cos(self.heading[s]), math.sin(self.heading[s])
        lateral = np.array([-sn, c]) * HIP_HALF_WIDTH * self.height[s]
        self.feet[s, 0] = self.pos[s] + lateral
        self.feet[s, 1] = self.pos[s] - lateral
        self.liftoff[s] = self.feet[s]
        self.swing_len[s] = 0.0
        if agent.in_door:
            self._choose_goal(s, first=[door.inside])
        else:
            self._start_activity(s, Activity.STAND)
        return True

    def _depart(self, s: int):
        self.person_id[s] = -1
        self.agents[s] = _Agent()
        self.departures += 1
        self._pending_arrivals += 1
        if self._next_arrival == math.inf:
            self._next_arrival = self.time_s + self.rng.exponential(self.config.mean_arrival_gap_s)

    # -- goals and activities --------------------------------------------------------------------

    def _taken(self, p: np.ndarray, s: int) -> bool:
        px, py = float(p[0]), float(p[1])
        for k, (a, pid) in enumerate(zip(self.agents, self.person_id.tolist())):
            if k != s and pid >= 0 and a.goal is not None and math.hypot(a.goal[0] - px, a.goal[1] - py) < 0.8:
                return True
        return False

    def _choose_goal(self, s: int, first: list[np.ndarray] | None = None):
        """Picks the next goal (shelf, place to stand, checkout or exit) and plans the path to it."""
        agent = self.agents[s]
        rng = self.rng
        store = self.store
        heading = None
        top = 0.0
        if agent.leaving or self.time_s >= agent.depart_at:
            agent.leaving = True
            open_tills = [spot for spot in self._checkout_spots if not self._taken(spot[0], s)]
            if open_tills and not agent.checked_out:
                # Pay at a free till; with every till busy, leave without queueing (self-checkout).
                goal, heading, top = open_tills[int(rng.integers(len(open_tills)))]
                kind = Activity.CHECKOUT
            else:
                goal, kind = store.exit.inside, Activity.WALK
        else:
            goal, kind = None, Activity.STAND
            leader = self._leader(s)
            if leader is not None:  # walking with the group's first person, at their pace
                goal = self._beside(s, self.agents[leader].goal)
                self.speed_pref[s] = self.speed_pref[leader]
            elif self._spots and rng.random() < self.config.browse_share:
                for _ in range(8):
                    p, h, shelf = self._spots[int(rng.integers(len(self._spots)))]
                    if not self._taken(p, s):
                        goal, heading, kind = p, h, Activity.BROWSE
                        top = store.obstacles[shelf].height
                        break
            if goal is None:
                for _ in range(20):
                    p = self._free_cells[int(rng.integers(len(self._free_cells)))]
                    if np.linalg.norm(p - self.pos[s]) > 1.5 and not self._taken(p, s) and store.clearance[
                            store.cell_of(p)] > 0.3:
                        goal = p
                        break
                else:
                    goal = self.pos[s].copy()
        start = first[-1] if first else self.pos[s]
        near_exit = kind == Activity.WALK and agent.leaving and np.linalg.norm(self.pos[s] - store.exit.center) < 1.5
        path = [] if near_exit else store.plan(start, goal)
        path = (first or []) + path
        if agent.leaving and kind == Activity.WALK:
            path.append(store.exit.outside)
        agent.path = [(float(x), float(y)) for x, y in path]
        seg = [math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(agent.path[:-1], agent.path[1:])]
        agent.rest = [sum(seg[k:]) for k in range(len(agent.path))]
        agent.goal = np.asarray(goal, float)
        agent.goal_kind = kind
        agent.goal_heading = heading
        agent.goal_top = top
        agent.activity = Activity.WALK
        agent.stuck = 0.0
        agent.pace_until = self.time_s
        rate = self.config.pause_rate_hz
        agent.next_pause = self.time_s + rng.exponential(1 / rate) if rate > 0 else math.inf
        if self.config.group_size > 1 and not agent.leaving and s % self.config.group_size == 0:
            # The group's first person moves on: the others set off with them.
            for f in range(s + 1, min(s + self.config.group_size, self.slots)):
                if self._leader(f) == s:
                    self._choose_goal(f)

    def _leader(self, s: int) -> int | None:
        """The slot of the first person of s's group whom s follows now (None: s goes alone): someone present
        with a goal who is not leaving, while s is through the door and not leaving either."""
        g = self.config.group_size
        first = s - s % g
        if g == 1 or first == s or self.person_id[first] < 0:
            return None
        lead, agent = self.agents[first], self.agents[s]
        if lead.leaving or lead.goal is None or agent.leaving or agent.in_door:
            return None
        return first

    def _beside(self, s: int, goal: np.ndarray) -> np.ndarray:
        """A free place to stand for s between GROUP_GAP_M and GROUP_RADIUS_M from goal (goal's nearest free place
        when none is)."""
        d = np.linalg.norm(self._free_cells - goal, axis=1)
        near = np.flatnonzero((d >= GROUP_GAP_M) & (d <= GROUP_RADIUS_M))
        for k in self.rng.permutation(near)[:20].tolist():
            if not self._taken(self._free_cells[k], s):
                return self._free_cells[k].copy()
        return self._free_cells[int(np.argmin(d))].copy()

    def _start_activity(self, s: int, kind: Activity):
        agent = self.agents[s]
        cfg = self.config
        rng = self.rng
        agent.activity = kind
        agent.path = []
        agent.rest = []
        agent.anchor = tuple(self.pos[s].tolist())
        agent.shuffle_until = -math.inf
        agent.next_shuffle = self.time_s + self._shuffle_rng.exponential(SHUFFLE_GAP_S)
        if kind == Activity.STAND:
            agent.until = self.time_s + rng.uniform(*cfg.stand_s)
        elif kind in (Activity.BROWSE, Activity.CHECKOUT):
            lo, hi = cfg.browse_s if kind == Activity.BROWSE else cfg.checkout_s
            agent.until = self.time_s + rng.uniform(lo, hi)
        self.gestures.set_reach_top(s, agent.goal_top if kind != Activity.STAND else 0.0)
        if kind == Activity.CHECKOUT:
            agent.checked_out = True

    # -- one step --------------------------------------------------------------------------------

    def step(self):
        """Advances everybody by STEP_S."""
        dt = STEP_S
        self.step_index += 1
        self.time_s = self.step_index * STEP_S
        t = self.time_s
        # 1. Arrivals.
        if self._pending_arrivals and t >= self._next_arrival:
            free_slots = np.nonzero(self.person_id < 0)[0]
            if len(free_slots) and self._spawn(int(free_slots[0]), inside=False):
                self._pending_arrivals -= 1
                self._next_arrival = (t + self.rng.exponential(self.config.mean_arrival_gap_s)
                                      if self._pending_arrivals else math.inf)
        active = self.person_id >= 0
        S = self.slots
        # 2. Wishes: walk the path, or stand and face the goal (plain floats: this loop runs per person).
        want = np.zeros((S, 2))
        want_heading = self.heading.copy()
        speed_now = np.hypot(self.vel[:, 0], self.vel[:, 1]).tolist()
        positions = self.pos.tolist()
        preferred = self.speed_pref.tolist()
        (exit_x, exit_y), (exit_nx, exit_ny) = self.store.exit.center.tolist(), self.store.exit.inward.tolist()
        for s in np.nonzero(active)[0].tolist():
            agent = self.agents[s]
            px, py = positions[s]
            if agent.leaving and (px - exit_x) * exit_nx + (py - exit_y) * exit_ny < -VANISH_DEPTH_M:
                # Out through the exit: gone.
                self._depart(s)
                active[s] = False
                continue
            if agent.activity == _WALK:
                while agent.path:
                    tx, ty = agent.path[0]
                    d = math.hypot(tx - px, ty - py)
                    if d < (0.15 if len(agent.path) == 1 else 0.35) or (d < 1.0 and self._passed(agent, px, py)):
                        agent.path.pop(0)
                        agent.rest.pop(0)
                        continue
                    break
                if not agent.path:
                    if agent.leaving and agent.goal_kind == Activity.WALK:
                        self._depart(s)
                        active[s] = False
                        continue
                    self._start_activity(s, agent.goal_kind)
                elif self._pausing(s, agent, t, d + agent.rest[0]):
                    want_heading[s] = agent.pause_heading
                else:
                    speed = min(preferred[s] * agent.pace, 0.35 + 0.8 * (d + agent.rest[0])) / d
                    want[s] = ((tx - px) * speed, (ty - py) * speed)
                    agent.stuck = agent.stuck + dt if speed_now[s] < 0.15 else 0.0
                    if agent.stuck > STUCK_S:
                        self._choose_goal(s)
            if agent.activity != _WALK:
                if agent.goal_heading is not None:
                    want_heading[s] = agent.goal_heading
                if t >= agent.next_shuffle:
                    self._shuffle(agent, px, py, t)
                if t < agent.shuffle_until:
                    want[s] = agent.shuffle_vel
                if t >= agent.until:
                    self._choose_goal(s)
        # 3. Local avoidance against predicted close passes; near a shelf, no steering into it and a gentle
        # push away from its face (`_steer_kernel`).
        if np.count_nonzero(active) > 1:
            # People standing still hold their place; walkers steer around them.
            walking = np.array([a.activity == _WALK for a in self.agents]) & active
            _steer_kernel(self.pos, want, self.vel, active, walking, self.speed_pref, *self._obstacles)
        # 4. Integration with bounded acceleration.
        old = self.pos
        new = np.empty_like(old)
        _accelerate_kernel(want, self.vel, old, active, new)
        # 5. Hard constraints.
        new = self._constrain(new, old, active)
        # 6. Velocity and heading from the step taken, then the gait.
        self.pos = new
        _turn_and_gait_kernel(old, new, want_heading, active, self.height, self.vel, self.heading, self.omega,
                              self._gait)
        self.gestures.update(t, dt, self.person_id, self.activities(), self.height)

    def _shuffle(self, agent: _Agent, px: float, py: float, t: float) -> None:
        """A standing person's next small step (`SHUFFLE_GAP_S`): toward a point within SHUFFLE_RADIUS_M of
        where they started to stand, over a duration drawn from SHUFFLE_S."""
        rng = self._shuffle_rng
        r, angle, duration = (SHUFFLE_RADIUS_M * math.sqrt(rng.random()), rng.uniform(0.0, 2.0 * math.pi),
                              rng.uniform(*SHUFFLE_S))
        tx, ty = agent.anchor[0] + r * math.cos(angle), agent.anchor[1] + r * math.sin(angle)
        agent.shuffle_vel = ((tx - px) / duration, (ty - py) / duration)
        agent.shuffle_until = t + duration
        agent.next_shuffle = t + duration + rng.exponential(SHUFFLE_GAP_S)

    def _pausing(self, s: int, agent: _Agent, t: float, left_m: float) -> bool:
        """Whether a walker stands still on the way now (stopping to look at something, turned to one side),
        and their pace: redrawn every PACE_HOLD_S, a stop started at `next_pause` unless near the goal or a door."""
        rng, cfg = self.rng, self.config
        if t >= agent.pace_until:
            agent.pace = rng.uniform(*cfg.pace_range)
            agent.pace_until = t + rng.uniform(*PACE_HOLD_S)
        if t < agent.pause_until:
            return True
        if t >= agent.next_pause:
            agent.next_pause = math.inf
            if left_m > PAUSE_CLEAR_M and not (agent.in_door or agent.leaving):
                agent.pause_until = t + rng.uniform(*cfg.pause_s)
                agent.pause_heading = float(self.heading[s]) + rng.uniform(*PAUSE_TURN_RAD) * (
                    1.0 if rng.random() < 0.5 else -1.0)
                agent.next_pause = agent.pause_until + rng.exponential(1 / cfg.pause_rate_hz)
                agent.stuck = 0.0
                return True
            agent.next_pause = t + rng.exponential(1 / cfg.pause_rate_hz)
        return False

    def _passed(self, agent: _Agent, px: float, py: float) -> bool:
        """Whether someone pushed off their path is already past its next waypoint (closer to the one after)."""
        if len(agent.path) < 2:
            return False
        (ax, ay), (bx, by) = agent.path[0], agent.path[1]
        if math.hypot(bx - px, by - py) >= math.hypot(bx - ax, by - ay):
            return False
        # The last leg out through the exit leaves the grid; elsewhere the shortcut must be clear.
        return len(agent.path) == 2 and agent.leaving or self.store.line_free((px, py), (bx, by))

    def _wall_bounds(self, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, 2) lower and upper bounds of the pelvis positions of slots idx (doors open the wall)."""
        lo = self._lo_bounds[:len(idx)].copy()
        hi = self._hi_bounds[:len(idx)].copy()
        agents = self.agents
        for k, s in enumerate(idx.tolist()):
            agent = agents[s]
            if not (agent.in_door or agent.leaving):
                continue
            px, py = self.pos[s].tolist()
            for (cx, cy), (nx, ny), width in self._doors:
                rx, ry = px - cx, py - cy
                depth = rx * nx + ry * ny
                along = rx * -ny + ry * nx
                half_gap = width / 2 - WALL_CLEARANCE_M
                axis = 0 if nx else 1
                in_doorway = depth < WALL_CLEARANCE_M - 1e-6 and abs(along) <= width / 2
                if in_doorway or (depth < 1.0 and abs(along) <= half_gap):
                    # In front of the door, in the doorway or outside: the wall opens here.
                    if (nx, ny)[axis] > 0:
                        lo[k, axis] = -OUTSIDE_REACH_M
                    else:
                        hi[k, axis] += WALL_CLEARANCE_M + OUTSIDE_REACH_M
                if in_doorway:
                    # In the doorway or outside: between the door posts.
                    t = 1 - axis
                    lo[k, t] = max(lo[k, t], (cx, cy)[t] - half_gap)
                    hi[k, t] = min(hi[k, t], (cx, cy)[t] + half_gap)
            (cx, cy), (nx, ny), _ = self._doors[0]
            if agent.in_door and (px - cx) * nx + (py - cy) * ny > 0.6:
                agent.in_door = False
        return lo, hi

    def _violations(self, q: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """(n,) whether each of the points (n, 2) breaks a hard constraint."""
        bad = np.empty(len(q), dtype=bool)
        _violations_kernel(np.ascontiguousarray(q), lo, hi, *self._obstacles, bad)
        return bad

    def _constrain(self, new: np.ndarray, old: np.ndarray, active: np.ndarray) -> np.ndarray:
        """Projects the step onto the hard constraints; anyone still in violation keeps `old`."""
        idx = np.nonzero(active)[0]
        if not len(idx):
            return new
        lo, hi = self._wall_bounds(idx)
        p = new[idx]
        if not self._violations(p, lo, hi).any():
            return new  # the usual case; nobody moves faster than MAX_SPEED_M_S without a projection
        _project_kernel(p, lo, hi, *self._obstacles)
        out = new.copy()
        out[idx] = p
        # Nobody is shoved faster than anybody walks: a longer push is no step at all.
        shove = out[idx] - old[idx]
        too_far = shove[:, 0] ** 2 + shove[:, 1] ** 2 > (MAX_SPEED_M_S * STEP_S) ** 2
        out[idx[too_far]] = old[idx[too_far]]
        # Any remaining violation reverts that person's step (old positions were valid).
        while True:
            bad = self._violations(out[idx], lo, hi) & np.any(out[idx] != old[idx], axis=1)
            if not bad.any():
                return out
            out[idx[bad]] = old[idx[bad]]

    def activities(self) -> np.ndarray:
        """(S,) `Activity` of each slot (WALK for empty slots)."""
        return np.array([a.activity for a in self.agents], dtype=np.int64)


# -- kernels (plain floats and loops: a few dozen people make numpy's per-call cost dominate; compiled, they
# made no whole command 1.3x faster: docs/benchmarks.md, "Kernel ledger") ---------------------------------


@jit
def _obstacle_distance(x, y, center, half, cos, sin):
    """Distance from the point (x, y) to the nearest footprint (inf without any); as `rect_distance`."""
    best = np.inf
    for o in range(center.shape[0]):
        dx, dy = x - center[o, 0], y - center[o, 1]
        lx, ly = dx * cos[o] + dy * sin[o], -dx * sin[o] + dy * cos[o]
        ox, oy = max(abs(lx) - half[o, 0], 0.0), max(abs(ly) - half[o, 1], 0.0)
        best = min(best, math.sqrt(ox * ox + oy * oy))
    return best


@jit
def _steer_kernel(pos, want, vel, active, walking, speed_pref, center, half, cos, sin):
    """In place: each active person's wish want (S, 2) steered off predicted close passes with the other
    active people (walkers only: time to closest approach against everybody's current motion, plus a
    short-range push), kept from heading into a shelf within SHELF_COMFORT_M and pushed off its face,
    then capped at 1.1 times the preferred speed."""
    n = pos.shape[0]
    for i in range(n):
        if not active[i]:
            continue
        wx0, wy0 = want[i, 0], want[i, 1]
        if walking[i]:
            cx = cy = 0.0
            for j in range(n):
                if j == i or not active[j]:
                    continue
                rx, ry = pos[j, 0] - pos[i, 0], pos[j, 1] - pos[i, 1]  # j relative to i
                wx, wy = wx0 - vel[j, 0], wy0 - vel[j, 1]  # i's wish relative to j's motion
                ww = max(wx * wx + wy * wy, 1e-9)
                tau = min(max((rx * wx + ry * wy) / ww, 0.0), 2.5)
                mx, my = rx - wx * tau, ry - wy * tau
                md = math.sqrt(mx * mx + my * my)
                d = math.sqrt(rx * rx + ry * ry)
                # Steer away from the point of closest approach, harder when it is close and soon.
                urgency = max(COMFORT_M - md, 0.0) / (COMFORT_M * (0.5 + tau))
                if md < 0.05:  # head-on (miss vector ~0): pass on the right
                    inv = urgency / math.sqrt(ww)
                    ax, ay = -wy * inv, wx * inv
                else:
                    inv = urgency / max(md, 1e-9)
                    ax, ay = mx * inv, my * inv
                # Short-range push so that nobody leans on a neighbour.
                push = min(max(COMFORT_M - d, 0.0) / (COMFORT_M - SEPARATION_M), 1.5) / max(d, 1e-9)
                cx += -AVOID_GAIN * ax - PUSH_GAIN * rx * push
                cy += -AVOID_GAIN * ay - PUSH_GAIN * ry * push
            wx0 += cx
            wy0 += cy
        # Near a shelf: the sum over footprints within SHELF_COMFORT_M of the outward normal times
        # (1 - d / SHELF_COMFORT_M).
        awx = awy = 0.0
        for o in range(center.shape[0]):
            dx, dy = pos[i, 0] - center[o, 0], pos[i, 1] - center[o, 1]
            lx, ly = dx * cos[o] + dy * sin[o], -dx * sin[o] + dy * cos[o]
            ox, oy = lx - min(max(lx, -half[o, 0]), half[o, 0]), ly - min(max(ly, -half[o, 1]), half[o, 1])
            dist = math.sqrt(ox * ox + oy * oy)
            if dist < SHELF_COMFORT_M:
                weight = (SHELF_COMFORT_M - dist) / (SHELF_COMFORT_M * max(dist, 1e-9))
                ox, oy = ox * weight, oy * weight
                awx += ox * cos[o] - oy * sin[o]
                awy += ox * sin[o] + oy * cos[o]
        norm = max(math.sqrt(awx * awx + awy * awy), 1e-9)
        ux, uy = awx / norm, awy / norm
        into = min(wx0 * ux + wy0 * uy, 0.0)
        push = SHELF_PUSH_M_S if walking[i] else 0.0
        wx0 += -ux * into + awx * push
        wy0 += -uy * into + awy * push
        scale = min(1.0, speed_pref[i] * 1.1 / max(math.sqrt(wx0 * wx0 + wy0 * wy0), 1e-9))
        want[i, 0], want[i, 1] = wx0 * scale, wy0 * scale


@jit
def _violations_kernel(q, lo, hi, center, half, cos, sin, bad):
    """bad (n,): whether each point of q (n, 2) is outside its wall bounds lo/hi (n, 2), closer than
    SHELF_CLEARANCE_M to a footprint, or closer than SEPARATION_M to another point."""
    n = q.shape[0]
    for i in range(n):
        x, y = q[i, 0], q[i, 1]
        b = x < lo[i, 0] - 1e-9 or y < lo[i, 1] - 1e-9 or x > hi[i, 0] + 1e-9 or y > hi[i, 1] + 1e-9
        if not b:
            b = _obstacle_distance(x, y, center, half, cos, sin) < SHELF_CLEARANCE_M
        if not b:
            for j in range(n):
                dx, dy = q[j, 0] - x, q[j, 1] - y
                if j != i and dx * dx + dy * dy < SEPARATION_M * SEPARATION_M:
                    b = True
                    break
        bad[i] = b


@jit
def _project_kernel(p, lo, hi, center, half, cos, sin):
    """Moves the points p (n, 2) in place toward the hard constraints: up to three rounds of pushing
    pairs apart to SEPARATION_M + PROJECTION_MARGIN_M (half each), pushing points out of every footprint
    grown by SHELF_CLEARANCE_M + PROJECTION_MARGIN_M (as `tests/reference/store.py`'s `push_out`) and clipping to the
    wall bounds lo/hi (n, 2)."""
    n = p.shape[0]
    clearance = SHELF_CLEARANCE_M + PROJECTION_MARGIN_M
    shift = np.zeros((n, 2))
    for k in range(3):
        moved = False
        for i in range(n):
            sx = sy = 0.0
            for j in range(n):
                if j == i:
                    continue
                rx, ry = p[j, 0] - p[i, 0], p[j, 1] - p[i, 1]
                d = math.sqrt(rx * rx + ry * ry)
                if d < SEPARATION_M + PROJECTION_MARGIN_M:
                    f = (SEPARATION_M + PROJECTION_MARGIN_M - d) * 0.5 / max(d, 1e-9)
                    sx += rx * f
                    sy += ry * f
                    moved = True
            shift[i, 0], shift[i, 1] = sx, sy
        for i in range(n):
            p[i, 0] -= shift[i, 0]
            p[i, 1] -= shift[i, 1]
            x, y = p[i, 0], p[i, 1]
            # Outside a footprint's core: radially from its nearest point; inside: through the nearest face.
            for o in range(center.shape[0]):
                hx, hy = half[o, 0], half[o, 1]
                dx, dy = x - center[o, 0], y - center[o, 1]
                lx, ly = dx * cos[o] + dy * sin[o], -dx * sin[o] + dy * cos[o]
                qx, qy = min(max(lx, -hx), hx), min(max(ly, -hy), hy)
                ox, oy = lx - qx, ly - qy
                dist = math.sqrt(ox * ox + oy * oy)
                if dist >= clearance:
                    continue
                moved = True
                if dist < 1e-12:
                    if hx - abs(lx) < hy - abs(ly):
                        nx, ny = (hx + clearance if lx >= 0 else -hx - clearance), ly
                    else:
                        nx, ny = lx, (hy + clearance if ly >= 0 else -hy - clearance)
                else:
                    scale = clearance / dist
                    nx, ny = qx + ox * scale, qy + oy * scale
                ex, ey = nx - lx, ny - ly
                p[i, 0] += ex * cos[o] - ey * sin[o]
                p[i, 1] += ex * sin[o] + ey * cos[o]
        if k and not moved:
            break  # already within the walls: the remaining rounds would change nothing
        for i in range(n):
            p[i, 0] = min(max(p[i, 0], lo[i, 0]), hi[i, 0])
            p[i, 1] = min(max(p[i, 1], lo[i, 1]), hi[i, 1])


@jit
def _accelerate_kernel(want, vel, pos, active, new):
    """new (S, 2): where everybody active would be after STEP_S moving from pos toward the wished velocity
    want (S, 2) with acceleration at most MAX_ACCEL_M_S2 from vel; the inactive stay at pos."""
    dt = STEP_S
    for s in range(pos.shape[0]):
        if not active[s]:
            new[s, 0], new[s, 1] = pos[s, 0], pos[s, 1]
            continue
        dvx, dvy = want[s, 0] - vel[s, 0], want[s, 1] - vel[s, 1]
        scale = min(1.0, MAX_ACCEL_M_S2 * dt / max(math.sqrt(dvx * dvx + dvy * dvy), 1e-9))
        new[s, 0] = pos[s, 0] + (vel[s, 0] + dvx * scale) * dt
        new[s, 1] = pos[s, 1] + (vel[s, 1] + dvy * scale) * dt


class Gait(NamedTuple):
    """Everybody's gait state (S slots), which `_gait_kernel` advances in place.

    Attributes:
        phase: (S,) the gait phase, cycles.
        stride: (S,) the distance per gait cycle, m.
        feet: (S, 2, 2) each foot's floor position, m.
        liftoff: (S, 2, 2) where each foot left the floor, m.
        swing_len: (S, 2) each swing's length, m.
    """

    phase: np.ndarray
    stride: np.ndarray
    feet: np.ndarray
    liftoff: np.ndarray
    swing_len: np.ndarray


@jit
def _turn_and_gait_kernel(old, new, want_heading, active, height, vel, heading, omega, gait):
    """In place: vel (S, 2) from the step old -> new (S, 2); the heading (S,) turns, at most MAX_TURN_RAD_S,
    toward the direction of motion above 0.3 m/s or else toward want_heading (S,), omega is its rate;
    then `_gait_kernel` moves the `Gait`."""
    dt = STEP_S
    speed = np.empty(old.shape[0])
    for s in range(old.shape[0]):
        vel[s, 0], vel[s, 1] = (new[s, 0] - old[s, 0]) / dt, (new[s, 1] - old[s, 1]) / dt
        speed[s] = math.sqrt(vel[s, 0] * vel[s, 0] + vel[s, 1] * vel[s, 1])
        target = math.atan2(vel[s, 1], vel[s, 0]) if speed[s] > 0.3 else want_heading[s]
        turn = (target - heading[s] + math.pi) % (2 * math.pi) - math.pi
        turn = min(max(turn, -MAX_TURN_RAD_S * dt), MAX_TURN_RAD_S * dt)
        heading[s] += turn
        omega[s] = turn / dt
    _gait_kernel(speed, omega, height, active, heading, new, vel, gait)


@jit
def _gait_kernel(speed, omega, height, active, heading, pos, vel, gait):
    """Advances the gait phase (S,) and moves the feet (S, 2, 2) of the `Gait` in place.

    A foot is locked to the floor in stance; at lift-off its position is kept (liftoff) and it swings
    (minimum-jerk easing) toward where it lands: ahead by half the stance travel, at the body's
    predicted position; at touchdown it is locked where the swing was heading, less the stance already
    done. swing_len (S, 2) is each swing's length, stride (S,) the distance per gait cycle.
    """
    phase, stride, feet, liftoff, swing_len = gait.phase, gait.stride, gait.feet, gait.liftoff, gait.swing_len
    dt = STEP_S
    for s in range(speed.shape[0]):
        v_eff = speed[s] + 0.3 * abs(omega[s])
        cadence = (1.2 + 0.6 * v_eff) * math.sqrt(1.75 / height[s])  # as `cadence_steps_s`
        stride[s] = 2.0 * v_eff / cadence
        if not active[s]:
            continue
        rate = cadence / 2.0  # cycles per second
        old = phase[s]
        new = old + rate * dt
        phase[s] = new
        c, sn = math.cos(heading[s]), math.sin(heading[s])
        ahead = stride[s] * STANCE_FRACTION / 2
        for leg in range(2):
            offset = 0.5 * leg
            lateral = HIP_HALF_WIDTH * height[s] * (1.0 - 2.0 * leg)
            p_old, p_new = (old + offset) % 1.0, (new + offset) % 1.0
            if p_old < STANCE_FRACTION <= p_new:
                liftoff[s, leg, 0], liftoff[s, leg, 1] = feet[s, leg, 0], feet[s, leg, 1]
            if p_new >= STANCE_FRACTION:
                t_left = (1.0 - p_new) / rate
                lx = pos[s, 0] + vel[s, 0] * t_left + c * ahead - sn * lateral
                ly = pos[s, 1] + vel[s, 1] * t_left + sn * ahead + c * lateral
                u = (p_new - STANCE_FRACTION) / (1.0 - STANCE_FRACTION)
                ease = u * u * u * (u * (u * 6 - 15) + 10)
                spx, spy = lx - liftoff[s, leg, 0], ly - liftoff[s, leg, 1]
                swing_len[s, leg] = math.sqrt(spx * spx + spy * spy)
                feet[s, leg, 0], feet[s, leg, 1] = liftoff[s, leg, 0] + spx * ease, liftoff[s, leg, 1] + spy * ease
            if math.floor(new + offset) > math.floor(old + offset) and swing_len[s, leg] > 1e-3:
                back = stride[s] * (STANCE_FRACTION / 2 - p_new)
                feet[s, leg, 0] = pos[s, 0] + c * back - sn * lateral
                feet[s, leg, 1] = pos[s, 1] + sn * back + c * lateral


_WARM = []


def _warm_up():
    """Loads (or, the first time on a machine, compiles) the kernels for the argument types the steps use,
    so that the first steps run as fast as the others."""
    if _WARM:
        return
    pts, obs = np.zeros((2, 2)), (np.zeros((1, 2)), np.ones((1, 2)), np.ones(1), np.zeros(1))
    flags = np.zeros(2, dtype=bool)
    _steer_kernel(pts, pts.copy(), pts, flags, flags, np.ones(2), *obs)
    _violations_kernel(pts, pts, pts, *obs, flags.copy())
    _project_kernel(pts.copy(), pts, pts, *obs)
    one = np.ones(2)
    _accelerate_kernel(pts, pts, pts, flags, np.empty((2, 2)))
    _turn_and_gait_kernel(pts, pts, one, flags, one, pts.copy(), one.copy(), one.copy(),
                          Gait(np.zeros(2), np.zeros(2), np.zeros((2, 2, 2)), np.zeros((2, 2, 2)), np.zeros((2, 2))))
    grid = np.ones((2, 2), dtype=bool)
    segment_free(grid, 0.05, 0.05, 0.15, 0.15, 0.1)
    astar(grid, 0, 3, 0.1)
    _WARM.append(True)
