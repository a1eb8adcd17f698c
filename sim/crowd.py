"""Crowd motion: paths around shelves, gait, browsing, arrivals and departures.

The crowd advances in fixed steps of `STEP_S` of simulated time, whatever the pattern of calls that
asks for poses, so the same scenario and seed give the same motion bit for bit. Each step:

1. arrivals through the entrance and departures through the exit;
2. each person's wish: follow the planned path (grid shortest path, string-pulled; `StoreGeometry.plan`)
   toward a shelf, a place to stand, the checkout or the exit, or stand still facing a shelf;
3. local avoidance: steer off predicted close passes with other people (time to closest approach);
4. integration with bounded acceleration and turn rate;
5. hard constraints: pelvis centres at least `SEPARATION_M` apart, at least `SHELF_CLEARANCE_M` from
   shelf faces and inside the walls; a person whose step would break them keeps the last valid position;
6. gait: the phase advances with a cadence that follows speed; a foot is locked to the floor in stance
   and swings from where it left the floor to where the body will be at touchdown.

`Crowd.state` holds everything `sim.world` needs to pose the bodies, one row per body slot.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from sim.humanoid import HIP_HALF_WIDTH, SUPPORTED_HEIGHT_M, sample_heights
from sim.store import StoreGeometry, rect_distance

# Crowd time step. Poses between steps are interpolated, so this bounds how far anyone moves unseen.
STEP_S = 0.05
# Hard limits the crowd keeps at every step (interpolation between steps loses a few centimetres at most).
SEPARATION_M = 0.5
SHELF_CLEARANCE_M = 0.3
WALL_CLEARANCE_M = 0.3
# Distance people like to keep when passing each other.
COMFORT_M = 0.75
# Fraction of the gait cycle a foot is locked to the floor (the rest is heel-off and swing).
STANCE_FRACTION = 0.45
# Peak foot lift in swing and the swing length over which it reaches it.
SWING_LIFT_M = 0.09
FULL_LIFT_STRIDE_M = 0.3
MAX_ACCEL_M_S2 = 1.5
MAX_TURN_RAD_S = 3.0
# A walker who has not moved for this long gives up on the current goal.
STUCK_S = 4.0


class Activity(enum.IntEnum):
    """What a person is doing (also what the statistics count)."""

    WALK = 0
    STAND = 1
    BROWSE = 2
    CHECKOUT = 3


@dataclass(frozen=True)
class CrowdConfig:
    """[crowd]: who walks through the store and how.

    Attributes:
        people: people in the store at once (the number of body slots); a leaver is replaced by a newcomer.
        start_inside: at t = 0 everybody is already inside; otherwise they arrive one by one.
        height_range_m: (min, max) body heights drawn from an adult mixture (women and men).
        heights_m: fixed heights of the first people (ids 0, 1, ...); the rest are drawn.
        speed_range_m_s: (min, max) preferred walking speeds.
        mean_visit_s: mean time from arrival to heading for the exit.
        mean_arrival_gap_s: mean delay before a newcomer replaces a leaver.
        browse_share: chance that the next goal is a shelf (the rest are places to stand).
        stand_s, browse_s, checkout_s: (min, max) durations of standing, browsing, paying.
        area_per_person_m2: walkable floor each person needs; more people than the floor holds is an error.
    """

    people: int = 4
    start_inside: bool = True
    height_range_m: tuple[float, float] = (1.50, 1.95)
    heights_m: tuple[float, ...] = ()
    speed_range_m_s: tuple[float, float] = (0.6, 1.6)
    mean_visit_s: float = 180.0
    mean_arrival_gap_s: float = 10.0
    browse_share: float = 0.6
    stand_s: tuple[float, float] = (2.0, 8.0)
    browse_s: tuple[float, float] = (5.0, 15.0)
    checkout_s: tuple[float, float] = (5.0, 15.0)
    area_per_person_m2: float = 1.0

    def __post_init__(self):
        lo, hi = SUPPORTED_HEIGHT_M
        if not 0 <= self.people <= 500:
            raise ValueError(f"people: {self.people} must be in [0, 500]")
        a, b = self.height_range_m
        if not (lo <= a < b <= hi):
            raise ValueError(f"height_range_m: {self.height_range_m} must satisfy {lo} <= min < max <= {hi} m")
        for i, h in enumerate(self.heights_m):
            if not lo <= h <= hi:
                raise ValueError(f"heights_m[{i}]: {h} m is outside the supported body heights [{lo}, {hi}] m")
        a, b = self.speed_range_m_s
        if not (0.3 <= a <= b <= 2.0):
            raise ValueError(f"speed_range_m_s: {self.speed_range_m_s} must satisfy 0.3 <= min <= max <= 2.0 m/s")
        for name in ("mean_visit_s", "mean_arrival_gap_s", "area_per_person_m2"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: {getattr(self, name)} must be > 0")
        if not 0 <= self.browse_share <= 1:
            raise ValueError(f"browse_share: {self.browse_share} must be in [0, 1]")
        for name in ("stand_s", "browse_s", "checkout_s"):
            a, b = getattr(self, name)
            if not 0 < a <= b:
                raise ValueError(f"{name}: {getattr(self, name)} must satisfy 0 < min <= max")


def validate(config: CrowdConfig, store: StoreGeometry, name: str = "scenario") -> None:
    """Cross-checks the crowd against the store.

    Raises:
        ScenarioError: more people than the walkable floor holds.
    """
    from sim.scenario import ScenarioError

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

    __slots__ = ("activity", "path", "goal_kind", "goal", "goal_heading", "until", "depart_at", "reaches",
                 "stuck", "leaving", "in_door", "checked_out")

    def __init__(self):
        self.activity = Activity.WALK
        self.path: list[np.ndarray] = []
        self.goal_kind = Activity.STAND
        self.goal: np.ndarray | None = None
        self.goal_heading: float | None = None
        self.until = 0.0
        self.depart_at = math.inf
        self.reaches: list[tuple[float, float, float, float]] = []  # (start, end, height, side)
        self.stuck = 0.0
        self.leaving = False
        self.in_door = False
        self.checked_out = False


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
        reach: (S,) how far the browsing arm is raised, 0..1; reach_height (S,) its target height; reach_side
            (S,) +1 left arm, -1 right arm.
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
        self.reach = np.zeros(S)
        self.reach_height = np.ones(S)
        self.reach_side = np.ones(S)
        self.look = np.zeros(S)
        self.arrivals = 0
        self.departures = 0
        self.agents = [_Agent() for _ in range(S)]
        self._spots = store.browse_spots()
        checkout = [o for o in store.obstacles if o.key == "store.checkout_m"]
        self._checkout_spots = []
        if checkout:
            ob = checkout[0]
            for side in (-1.0, 1.0):
                p = ob.center + np.array([0.0, side * (ob.half[1] + 0.5)])
                i, j = store.cell_of(p)
                if store.free[i, j]:
                    self._checkout_spots.append((p, math.atan2(-side, 0.0)))
        fi, fj = np.nonzero(store.free)
        self._free_cells = store.cell_centers[fi, fj]
        self._next_arrival = math.inf
        self._pending_arrivals = 0
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
        self.reach[s] = 0.0
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
        for k, a in enumerate(self.agents):
            if k != s and self.person_id[k] >= 0 and a.goal is not None and np.linalg.norm(a.goal - p) < 0.8:
                return True
        return False

    def _choose_goal(self, s: int, first: list[np.ndarray] | None = None):
        """Picks the next goal (shelf, place to stand, checkout or exit) and plans the path to it."""
        agent = self.agents[s]
        rng = self.rng
        store = self.store
        heading = None
        if agent.leaving or self.time_s >= agent.depart_at:
            agent.leaving = True
            if self._checkout_spots and not agent.checked_out:
                goal, heading = self._checkout_spots[int(rng.integers(len(self._checkout_spots)))]
                kind = Activity.CHECKOUT
            else:
                goal, kind = store.exit.inside, Activity.WALK
        else:
            goal, kind = None, Activity.STAND
            if self._spots and rng.random() < self.config.browse_share:
                for _ in range(8):
                    p, h, _shelf = self._spots[int(rng.integers(len(self._spots)))]
                    if not self._taken(p, s):
                        goal, heading, kind = p, h, Activity.BROWSE
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
        path = store.plan(start, goal)
        agent.path = (first or []) + path
        if agent.leaving and kind == Activity.WALK:
            agent.path.append(store.exit.outside)
        agent.goal = np.asarray(goal, float)
        agent.goal_kind = kind
        agent.goal_heading = heading
        agent.activity = Activity.WALK
        agent.stuck = 0.0

    def _start_activity(self, s: int, kind: Activity):
        agent = self.agents[s]
        cfg = self.config
        rng = self.rng
        agent.activity = kind
        agent.path = []
        if kind == Activity.STAND:
            agent.until = self.time_s + rng.uniform(*cfg.stand_s)
        elif kind in (Activity.BROWSE, Activity.CHECKOUT):
            lo, hi = cfg.browse_s if kind == Activity.BROWSE else cfg.checkout_s
            agent.until = self.time_s + rng.uniform(lo, hi)
            agent.reaches = []
            t = self.time_s + 1.2  # turn to the shelf first
            top = 1.0 if kind == Activity.CHECKOUT else 1.85
            while t + 3.0 < agent.until:
                dur = rng.uniform(1.8, 3.0)
                agent.reaches.append((t, t + dur, rng.uniform(0.35, top) if kind == Activity.BROWSE else 0.95,
                                      1.0 if rng.random() < 0.5 else -1.0))
                t += dur + rng.uniform(0.8, 3.0)
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
        # 2. Wishes.
        want = np.zeros((S, 2))
        want_heading = self.heading.copy()
        for s in np.nonzero(active)[0]:
            agent = self.agents[s]
            if agent.activity == Activity.WALK:
                while agent.path:
                    target = agent.path[0]
                    d = np.linalg.norm(target - self.pos[s])
                    last = len(agent.path) == 1
                    if d < (0.15 if last else 0.35):
                        agent.path.pop(0)
                        continue
                    break
                if not agent.path:
                    if agent.leaving and agent.goal_kind == Activity.WALK:
                        self._depart(s)
                        active[s] = False
                        continue
                    self._start_activity(s, agent.goal_kind)
                else:
                    target = agent.path[0]
                    delta = target - self.pos[s]
                    d = float(np.hypot(delta[0], delta[1]))
                    remaining = d + sum(np.linalg.norm(b - a) for a, b in zip(agent.path[:-1], agent.path[1:]))
                    speed = min(self.speed_pref[s], 0.35 + 0.8 * remaining)
                    want[s] = delta / max(d, 1e-9) * speed
                    agent.stuck = agent.stuck + dt if np.hypot(*self.vel[s]) < 0.15 else 0.0
                    if agent.stuck > STUCK_S:
                        self._choose_goal(s)
            if agent.activity != Activity.WALK:
                if agent.goal_heading is not None:
                    want_heading[s] = agent.goal_heading
                if t >= agent.until:
                    if agent.activity == Activity.CHECKOUT:
                        agent.goal = self.store.exit.inside
                    self._choose_goal(s)
        # 3. Local avoidance against predicted close passes.
        idx = np.nonzero(active)[0]
        if len(idx) > 1:
            want[idx] += self._avoid(self.pos[idx], want[idx], self.vel[idx])
            cap = self.speed_pref[idx] * 1.1
            norm = np.hypot(want[idx, 0], want[idx, 1])
            want[idx] *= np.minimum(1.0, cap / np.maximum(norm, 1e-9))[:, None]
        # 4. Integration with bounded acceleration.
        dv = want - self.vel
        dvn = np.hypot(dv[:, 0], dv[:, 1])
        dv *= np.minimum(1.0, MAX_ACCEL_M_S2 * dt / np.maximum(dvn, 1e-9))[:, None]
        old = self.pos.copy()
        new = self.pos + (self.vel + dv) * dt
        new[~active] = old[~active]
        # 5. Hard constraints.
        new = self._constrain(new, old, active)
        self.vel = (new - old) / dt
        self.pos = new
        speed = np.hypot(self.vel[:, 0], self.vel[:, 1])
        moving = speed > 0.3
        want_heading = np.where(moving, np.arctan2(self.vel[:, 1], self.vel[:, 0]), want_heading)
        turn = (want_heading - self.heading + math.pi) % (2 * math.pi) - math.pi
        turn = np.clip(turn, -MAX_TURN_RAD_S * dt, MAX_TURN_RAD_S * dt)
        self.heading = self.heading + turn
        self.omega = turn / dt
        # 6. Gait.
        self._gait(speed, active)
        self._arms(active)

    def _avoid(self, pos: np.ndarray, want: np.ndarray, vel: np.ndarray) -> np.ndarray:
        """(n, 2) velocity corrections that steer each person off predicted close passes."""
        r = pos[None, :, :] - pos[:, None, :]  # (i, j): j relative to i
        w = want[:, None, :] - vel[None, :, :]  # i's wish relative to j's motion
        ww = np.einsum("ijk,ijk->ij", w, w)
        tau = np.clip(np.einsum("ijk,ijk->ij", r, w) / np.maximum(ww, 1e-9), 0.0, 2.5)
        miss = r - w * tau[..., None]
        md = np.hypot(miss[..., 0], miss[..., 1])
        n = len(pos)
        np.fill_diagonal(md, np.inf)
        # Steer away from the point of closest approach, harder when it is close and soon.
        urgency = np.clip((COMFORT_M - md) / COMFORT_M, 0.0, 1.0) / (0.5 + tau)
        # Head-on: miss vector ~0, pass on the right.
        right = np.stack([w[..., 1], -w[..., 0]], axis=-1) / np.sqrt(np.maximum(ww, 1e-9))[..., None]
        away = np.where((md < 0.05)[..., None], -right, miss / np.maximum(md, 1e-9)[..., None])
        corr = -(away * urgency[..., None]).sum(axis=1) * 0.9
        # Short-range push so that nobody leans on a neighbour.
        d = np.hypot(r[..., 0], r[..., 1])
        np.fill_diagonal(d, np.inf)
        push = np.clip((COMFORT_M - d) / (COMFORT_M - SEPARATION_M), 0.0, 1.5)
        corr -= (r / np.maximum(d, 1e-9)[..., None] * push[..., None]).sum(axis=1) * 0.4
        del n
        return corr

    def _wall_bounds(self, s: int) -> tuple[np.ndarray, np.ndarray]:
        """(2,) lower and upper bound of slot s's pelvis position (doors open the wall for people passing)."""
        W, D = self.store.config.width_m, self.store.config.depth_m
        lo = np.array([WALL_CLEARANCE_M, WALL_CLEARANCE_M])
        hi = np.array([W - WALL_CLEARANCE_M, D - WALL_CLEARANCE_M])
        agent = self.agents[s]
        if agent.in_door or agent.leaving:
            for door in (self.store.entrance, self.store.exit):
                rel = self.pos[s] - door.center
                n = door.inward
                tangent = np.array([-n[1], n[0]])
                along = rel @ tangent
                if abs(along) <= door.width / 2 - WALL_CLEARANCE_M + 1e-9 and rel @ n < 1.0:
                    axis = 0 if n[0] else 1
                    reach = 1.2
                    if n[axis] > 0:
                        lo[axis] = -reach
                    else:
                        hi[axis] = hi[axis] + WALL_CLEARANCE_M + reach
        return lo, hi

    def _constrain(self, new: np.ndarray, old: np.ndarray, active: np.ndarray) -> np.ndarray:
        """Projects the step onto the hard constraints; anyone still in violation keeps `old`."""
        idx = np.nonzero(active)[0]
        if not len(idx):
            return new
        lo = np.empty((len(idx), 2))
        hi = np.empty((len(idx), 2))
        for k, s in enumerate(idx):
            lo[k], hi[k] = self._wall_bounds(s)
        p = new[idx].copy()
        obstacles = self.store.obstacles
        for _ in range(3):
            # Pairs.
            r = p[None, :, :] - p[:, None, :]
            d = np.hypot(r[..., 0], r[..., 1])
            np.fill_diagonal(d, np.inf)
            overlap = np.clip(SEPARATION_M + 0.01 - d, 0.0, None)
            if overlap.any():
                p -= (r / np.maximum(d, 1e-9)[..., None] * overlap[..., None] * 0.5).sum(axis=1)
            # Shelves: push out along the rectangle's outward normal.
            for ob in obstacles:
                p = _push_out(p, ob.center, ob.half, ob.yaw, SHELF_CLEARANCE_M + 0.01)
            p = np.clip(p, lo, hi)
        out = new.copy()
        out[idx] = p
        # Final check: any remaining violation reverts that person's step (old positions were valid).
        while True:
            q = out[idx]
            bad = np.zeros(len(idx), bool)
            for ob in obstacles:
                bad |= rect_distance(q, ob.center, ob.half, ob.yaw) < SHELF_CLEARANCE_M
            bad |= np.any((q < lo - 1e-9) | (q > hi + 1e-9), axis=1)
            r = q[None, :, :] - q[:, None, :]
            d = np.hypot(r[..., 0], r[..., 1])
            np.fill_diagonal(d, np.inf)
            bad |= np.any(d < SEPARATION_M, axis=1)
            bad &= np.any(out[idx] != old[idx], axis=1)
            if not bad.any():
                return out
            out[idx[bad]] = old[idx[bad]]

    def _gait(self, speed: np.ndarray, active: np.ndarray):
        """Advances the gait phase and moves the feet (locked in stance, swinging otherwise)."""
        dt = STEP_S
        v_eff = speed + 0.3 * np.abs(self.omega)
        cadence = cadence_steps_s(v_eff, self.height)
        self.stride = 2.0 * v_eff / cadence
        rate = cadence / 2.0  # cycles per second
        old_phase = self.phase
        self.phase = np.where(active, self.phase + rate * dt, self.phase)
        c, s = np.cos(self.heading), np.sin(self.heading)
        fwd = np.stack([c, s], axis=-1)
        left = np.stack([-s, c], axis=-1)
        hw = HIP_HALF_WIDTH * self.height
        for leg, (offset, side) in enumerate(((0.0, 1.0), (0.5, -1.0))):
            p_old = (old_phase + offset) % 1.0
            p_new = (self.phase + offset) % 1.0
            wrapped = np.floor(self.phase + offset) > np.floor(old_phase + offset)
            lifted = (p_old < STANCE_FRACTION) & (p_new >= STANCE_FRACTION)
            # Where the foot lands: ahead by half the stance travel, at the body's predicted position.
            t_left = (1.0 - p_new) / rate
            landing = (self.pos + self.vel * t_left[:, None] + fwd * (self.stride * STANCE_FRACTION / 2)[:, None]
                       + left * (side * hw)[:, None])
            lift_now = lifted & active
            self.liftoff[lift_now, leg] = self.feet[lift_now, leg]
            swing = (p_new >= STANCE_FRACTION) & active
            progress = (p_new - STANCE_FRACTION) / (1.0 - STANCE_FRACTION)
            # Touchdown this step: lock the foot where the swing was heading, shifted by the stance already done.
            touch = wrapped & active
            landed = (self.pos + fwd * (self.stride * (STANCE_FRACTION / 2 - p_new))[:, None]
                      + left * (side * hw)[:, None])
            start = self.liftoff[:, leg]
            ease = progress**3 * (progress * (progress * 6 - 15) + 10)
            swing_xy = start + (landing - start) * ease[:, None]
            self.swing_len[swing, leg] = np.hypot(*(landing[swing] - start[swing]).T)
            self.feet[swing, leg] = swing_xy[swing]
            self.feet[touch, leg] = np.where(
                (self.swing_len[touch, leg] > 1e-3)[:, None], landed[touch], self.feet[touch, leg])

    def _arms(self, active: np.ndarray):
        """Browsing reaches and where people look."""
        t = self.time_s
        for s in np.nonzero(active)[0]:
            agent = self.agents[s]
            r = 0.0
            if agent.activity in (Activity.BROWSE, Activity.CHECKOUT):
                for start, end, height, side in agent.reaches:
                    if start <= t <= end:
                        up = min(0.7, (end - start) / 3)
                        r = min(1.0, (t - start) / up, (end - t) / up)
                        self.reach_height[s] = height
                        self.reach_side[s] = side
                        break
            self.reach[s] = r

    def activities(self) -> np.ndarray:
        """(S,) `Activity` of each slot (WALK for empty slots)."""
        return np.array([a.activity for a in self.agents], dtype=np.int64)


def _push_out(p: np.ndarray, center: np.ndarray, half: np.ndarray, yaw: float, clearance: float) -> np.ndarray:
    """Moves points (n, 2) out of a yawed rectangle grown by `clearance`, along the nearest face normal."""
    c, s = math.cos(yaw), math.sin(yaw)
    d = p - center
    lx = d[:, 0] * c + d[:, 1] * s
    ly = -d[:, 0] * s + d[:, 1] * c
    qx = np.clip(lx, -half[0], half[0])
    qy = np.clip(ly, -half[1], half[1])
    ox, oy = lx - qx, ly - qy
    dist = np.hypot(ox, oy)
    inside_box = dist < 1e-12
    if not (np.any(dist < clearance)):
        return p
    # Outside the core rectangle but within the clearance: push radially from the nearest point.
    scale = np.where(dist > 1e-12, clearance / np.maximum(dist, 1e-12), 1.0)
    nx = np.where(dist < clearance, qx + ox * scale, lx)
    ny = np.where(dist < clearance, qy + oy * scale, ly)
    # Inside the core rectangle: leave through the nearest face.
    if inside_box.any():
        gx = half[0] - np.abs(lx)
        gy = half[1] - np.abs(ly)
        use_x = gx < gy
        nx = np.where(inside_box & use_x, np.sign(lx + 1e-12) * (half[0] + clearance), nx)
        ny = np.where(inside_box & ~use_x, np.sign(ly + 1e-12) * (half[1] + clearance), ny)
    return center + np.stack([nx * c - ny * s, nx * s + ny * c], axis=-1)
