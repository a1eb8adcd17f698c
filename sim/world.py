"""The store world in MuJoCo: store geometry plus one kinematic humanoid per body slot, posed over time.

The model holds the store's boxes and `crowd.people` humanoids (slots). A slot is reused when its
person leaves and a newcomer arrives: the slot's bodies are rescaled to the newcomer's height (every
length of `sim.humanoid` is proportional to height) and it gets a new, never reused person id. The
world is kinematic: `advance` sets qpos from the crowd's motion and computes the 17 keypoint sites by
its own forward kinematics of the keypoint chain (a compiled kernel; equal to MuJoCo's site positions to
~1e-15 m); MuJoCo's `mj_kinematics`, which is all `mj_ray` needs to see the bodies where they are, runs
when `data` is next asked for, so people-only simulation skips it.

Speed: the per-tick numeric work (posing, keypoints) runs in numba-compiled loops over plain floats, because
with a few dozen people numpy's per-call cost dominated; `sim.crowd`'s steering, hard constraints and gait and
`sim.store`'s A* are the same kind of loops run as plain Python (compiled, they made no whole command 1.3x
faster: docs/benchmarks.md, "Kernel ledger"). Kernels are compiled once per machine (cached on disk under
__pycache__) and loaded when the first world is built.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import mujoco
import numpy as np

from core.jit import jit
from core.records import Box, BoxKind, PoseTruth
from core.types import COCO17, Skeleton
from sim import gestures as gs
from sim import humanoid as hm
from sim.crowd import FULL_LIFT_STRIDE_M, STANCE_FRACTION, STEP_S, SWING_LIFT_M, Activity, Crowd
from sim.crowd import validate as validate_crowd
from sim.store import StoreGeometry

# Where the bodies of empty slots wait: far below the floor slab, where no camera ray can reach.
PARK_Z_M = -50.0
STAND_HIP_FRACTION = hm.STAND_HIP_FRACTION
# Lowest the pelvis goes in walking, as a fraction of the straight-leg hip height.
LOWEST_HIP_FRACTION = 0.94


@dataclass(frozen=True)
class _Snapshot:
    """The bodies at one crowd step: who is in each slot and their joint positions.

    Poses between two steps interpolate the joint positions linearly (the heading through the yaw
    angle, not the quaternion). Every interpolated pose is a body pose: bone lengths are fixed by the
    model and every hinge angle stays between two in-range values.
    """

    time_s: float
    person_id: np.ndarray  # (S,)
    qpos: np.ndarray  # (S, NQ)
    heading: np.ndarray  # (S,) unwrapped yaw


# MuJoCo's arena (its stack and constraint memory), megabytes: fixed, and per body slot. Left to MuJoCo, its size
# grows with the square of the bodies (11.7 GB at 500 people, more than the machine at 800: "Could not allocate
# memory"); with contacts off and no constraints, the kinematics need a few MB per hundred people.
ARENA_MB = 16
ARENA_MB_PER_SLOT = 0.25


class World:
    """The store, its people and their bodies in MuJoCo.

    Attributes:
        model, data: the MuJoCo model (store geoms then one humanoid per slot) and its data.
        boxes: the store's boxes (floor, walls, entrance, exit, shelves, checkout) for drawing and recording.
        skeleton: `tracker.types.COCO17`; keypoints come from the humanoids' sites in this order.
        store: the checked layout and its navigation grid.
        crowd: the people's motion.
    """

    def __init__(self, scenario, rng: np.random.Generator):
        """Builds the world of a scenario.

        Args:
            scenario: a `sim.scenario.Scenario`.
            rng: the crowd's generator (`sim.rng.child_rng(seed, "crowd")`); all randomness comes from it.

        Raises:
            ScenarioError: the layout or the crowd cannot work (overlapping shelves, a blocked door, more
                people than the floor holds, ...), naming the scenario key.
        """
        self.scenario = scenario
        self.store = StoreGeometry(scenario.store, name=scenario.where)
        validate_crowd(scenario.crowd, self.store, scenario.where)
        self.boxes: tuple[Box, ...] = self.store.boxes
        self.skeleton: Skeleton = COCO17
        self.slots = S = scenario.crowd.people
        J = len(hm.KEYPOINT_NAMES)
        self.model = mujoco.MjModel.from_xml_string(self._xml())
        self._data = mujoco.MjData(self.model)
        self._kinematics_stale = False
        m = self.model
        self._nq = hm.NQ
        root_adr = [m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"p{k}_root")] for k in range(S)]
        if root_adr != [k * hm.NQ for k in range(S)] or m.nq != S * hm.NQ:
            raise RuntimeError("humanoid qpos layout is not slot-contiguous")
        self._kp_sites = np.array([[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"p{k}_{n}")
                                    for n in hm.KEYPOINT_NAMES] for k in range(S)], dtype=np.int64).reshape(S, J)
        body_names = [m.body(b).name for b in range(m.nbody)]
        self._body_slot = np.full(m.nbody, -1, dtype=np.int64)
        self._body_local = np.full(m.nbody, -1, dtype=np.int64)
        for b, name in enumerate(body_names):
            if name.startswith("p") and "_" in name:
                slot, local = name[1:].split("_", 1)
                self._body_slot[b] = int(slot)
                self._body_local[b] = hm.B[local]
        self._geom_slot = self._body_slot[m.geom_bodyid]
        self._geom_local = self._body_local[m.geom_bodyid]
        self._site_slot = self._body_slot[m.site_bodyid]
        self._ref = {name: getattr(m, name).copy() for name in
                     ("body_pos", "geom_pos", "geom_size", "geom_rbound", "geom_aabb", "site_pos", "site_size")}
        self._slot_height = np.full(S, hm.REFERENCE_HEIGHT_M)
        self._sizes_version = 0  # counts slot resizes (the ray scene copies the geom sizes when it changes)
        self._body_constants()
        self._lo, self._hi = hm.HINGE_RANGES[:, 0].copy(), hm.HINGE_RANGES[:, 1].copy()
        self._heights: dict[int, float] = {}
        self.crowd = Crowd(scenario.crowd, self.store, rng)
        self._present = np.zeros(S, bool)
        self._person_ids = np.full(S, -1, dtype=np.int64)
        self._geom_person: tuple | None = None  # (present, person ids, geom person ids) of the last call
        self._ray_constants: tuple | None = None  # `ray_geom_constants`'s snapshots and what they were made of
        self._last_t = -math.inf
        self._sync_slots()
        self._prev = self._cur = self._snapshot()  # (also loads the compiled posing kernel)
        self._orders = None
        self._ids = np.zeros(0, dtype=np.int64)  # the person ids of the last `advance`
        self._fk_body = np.zeros((S, len(hm.BODIES)), dtype=np.int64)  # (S, 16) model body id per slot and body
        for b in range(m.nbody):
            if self._body_slot[b] >= 0:
                self._fk_body[self._body_slot[b], self._body_local[b]] = b
        if S and not np.array_equal(self._body_local[m.site_bodyid[self._kp_sites]], np.tile(_FK_KP_BODY, (S, 1))):
            raise RuntimeError("keypoint sites are not on the bodies sim.humanoid names")
        # The model's body and site offsets are views: they see the resizing.
        # (a plain tuple of its fields: `_pose_kernel` runs at every truth tick, and numba's dispatcher types a
        # plain tuple of arrays in C but a NamedTuple in Python, 0.48 against 0.97 us a call for six arrays)
        self._kinematics = tuple(Kinematics(self._fk_body, _FK_TABLES, _FK_HINGES, m.body_pos, self._kp_sites,
                                            m.site_pos))
        # Load (or compile) the per-tick kernel now rather than in the first `advance`.
        no_slot = np.zeros((0, hm.NQ))
        _pose_kernel(no_slot, no_slot, np.zeros(0), np.zeros(0), 0.0, np.zeros(0, dtype=bool), np.zeros(0),
                     np.zeros(0, dtype=np.int64), self._kinematics, np.empty((0, J, 3)))

    # -- model -------------------------------------------------------------------------------------

    def _store_geoms_xml(self) -> list[str]:
        geoms = []
        rgba = {BoxKind.FLOOR: ".55 .55 .5 1", BoxKind.WALL: ".8 .8 .75 1", BoxKind.SHELF: ".45 .3 .2 1",
                BoxKind.CHECKOUT: ".3 .4 .6 1", BoxKind.ENTRANCE: ".2 .7 .2 1", BoxKind.EXIT: ".7 .2 .2 1"}
        for i, box in enumerate(self.boxes):
            half = " ".join(f"{s / 2:.6g}" for s in box.size_m)
            pos = " ".join(f"{c:.6g}" for c in box.center_m)
            geoms.append(f'<geom name="{box.kind.value}{i}" type="box" pos="{pos}" size="{half}" '
                         f'euler="0 0 {box.yaw_rad:.9g}" rgba="{rgba[box.kind]}"/>')
        return geoms

    def _xml(self) -> str:
        geoms = self._store_geoms_xml()
        people = "".join(hm.humanoid_xml(f"p{k}_") for k in range(self.slots))
        return (
            '<mujoco model="store"><compiler angle="radian"/>'
            f'<size memory="{ARENA_MB + math.ceil(ARENA_MB_PER_SLOT * self.slots)}M"/>'
            '<option><flag contact="disable" gravity="disable"/></option>'
            '<default><geom contype="0" conaffinity="0" density="1000"/><site group="4"/></default>'
            f'<worldbody>{"".join(geoms)}{people}</worldbody></mujoco>'
        )

    def _resize(self, slot: int, height_m: float):
        """Rescales a slot's bodies, geoms and sites to a body height (all proportional to it)."""
        m = self.model
        scale = height_m / hm.REFERENCE_HEIGHT_M
        bodies = self._body_slot == slot
        geoms = self._geom_slot == slot
        sites = self._site_slot == slot
        m.body_pos[bodies] = self._ref["body_pos"][bodies] * scale
        for name, mask in (("geom_pos", geoms), ("geom_size", geoms), ("geom_rbound", geoms), ("geom_aabb", geoms),
                           ("site_pos", sites), ("site_size", sites)):
            getattr(m, name)[mask] = self._ref[name][mask] * scale
        self._slot_height[slot] = height_m
        self._sizes_version += 1

    def _sync_slots(self):
        """Rescales slots whose person changed in the latest crowd step."""
        changed = np.nonzero(self.crowd.person_id != self._person_ids)[0]
        for s in changed:
            pid = int(self.crowd.person_id[s])
            if pid >= 0:
                h = float(self.crowd.height[s])
                self._heights[pid] = h
                if h != self._slot_height[s]:
                    self._resize(int(s), h)
                    self._body_constants()
        if changed.size:  # (kept otherwise: `geom_person_ids` recomputes when this object changes)
            self._person_ids = self.crowd.person_id.copy()

    # -- public ------------------------------------------------------------------------------------

    def advance(self, t_s: float) -> PoseTruth:
        """Poses everybody for true time t_s and returns the keypoints of the people present.

        Args:
            t_s: true time, seconds since the scenario start; never less than in the previous call.

        Returns:
            PoseTruth with person_ids (P,) ascending and poses (P, 17, 3) metres (COCO-17 keypoint sites).
            The person_ids array is the same object as the previous call's while the same people are
            present: do not write into it.

        Raises:
            ValueError: t_s is earlier than the previous call's or negative.
        """
        if not t_s >= max(self._last_t, 0.0):
            raise ValueError(f"t_s: {t_s} must be >= 0 and >= the previous call's {self._last_t}")
        self._last_t = t_s
        crowd = self.crowd
        while crowd.time_s < t_s:
            self._prev = self._cur
            crowd.step()
            self._sync_slots()
            self._cur = self._snapshot()
            self._orders = None
        prev, cur = self._prev, self._cur
        if self._orders is None:
            # Who is present between the last two steps (someone who arrived or left in the step is parked)
            # and at the latest step, in ascending person id order.
            self._orders = []
            for present in ((cur.person_id >= 0) & (prev.person_id == cur.person_id), cur.person_id >= 0):
                # The same object as long as the same slots are present: `geom_person_ids` (and the ray
                # scene's owners) are then recomputed only when someone arrives or leaves.
                if np.array_equal(present, self._present):
                    present = self._present
                elif self._orders and np.array_equal(present, self._orders[0][0]):
                    present = self._orders[0][0]
                order = np.nonzero(present)[0]
                order = order[np.argsort(cur.person_id[order], kind="stable")]
                # The ids too, so that consumers tell two ticks with the same people apart by identity.
                ids = cur.person_id[order]
                for known in (self._ids, *(kept[2] for kept in self._orders)):
                    if np.array_equal(ids, known):
                        ids = known
                        break
                self._orders.append((present, order, ids))
        exact = cur.time_s <= t_s or prev is cur
        present, order, self._ids = self._orders[exact]
        # The keypoints by forward kinematics of the keypoint sites alone; MuJoCo's full kinematics (every
        # body, geom and site) runs when `data` is next asked for.
        poses = np.empty((len(order), self.skeleton.num_joints, 3))
        q0, h0, a = (cur.qpos, cur.heading, 0.0) if exact else (prev.qpos, prev.heading, (t_s - prev.time_s) / STEP_S)
        _pose_kernel(q0, cur.qpos, h0, cur.heading, a, present, self._data.qpos, order, self._kinematics, poses)
        self._kinematics_stale = True
        self._present = present
        return PoseTruth(t_s=float(t_s), person_ids=self._ids, poses=poses)

    @property
    def data(self) -> mujoco.MjData:
        """The MuJoCo data (`model`'s) posed at the last `advance`; its kinematics run on first access after it."""
        if self._kinematics_stale:
            mujoco.mj_kinematics(self.model, self._data)
            self._kinematics_stale = False
        return self._data

    def geom_groups(self) -> np.ndarray:
        """(K + 1,) int64 starts of the contiguous runs of geoms that move together (the store's, then one
        per person slot), ending with ngeom: the ray caster culls a whole run by one bounding sphere."""
        slot = self._geom_slot
        return np.concatenate([[0], np.nonzero(slot[1:] != slot[:-1])[0] + 1, [slot.size]]).astype(np.int64)

    def geom_person_ids(self) -> np.ndarray:
        """(ngeom,) int64: the person each geom's body belongs to now; -1 for store geoms and parked bodies.

        (Kept until who is present changes, which is at most once per crowd step: do not write into it.)"""
        cached = self._geom_person
        if cached is None or cached[0] is not self._present or cached[1] is not self._person_ids:
            ids = np.append(np.where(self._present, self._person_ids, -1), -1)  # index -1: store geoms
            cached = self._geom_person = (self._present, self._person_ids, ids[self._geom_slot].astype(np.int64))
        return cached[2]

    def ray_geom_constants(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What rays need of the geoms that changes only when a slot is resized or who is present changes:
        sizes (ngeom, 3), bounding radii (ngeom,) and owners (ngeom,) int64 (`geom_person_ids`).

        Read-only snapshots, the same objects until one of them changes (then new ones): a caller may keep
        them, and tell by identity that two ticks share them."""
        cached = self._ray_constants
        owner = self.geom_person_ids()
        if cached is not None and cached[0] == self._sizes_version and (
                cached[4] is owner or np.array_equal(cached[3], owner)):
            if cached[4] is not owner:
                cached = self._ray_constants = (*cached[:4], owner)
            return cached[1], cached[2], cached[3]
        if cached is not None and cached[0] == self._sizes_version:
            size, rbound = cached[1], cached[2]
        else:
            size, rbound = self.model.geom_size.copy(), self.model.geom_rbound.copy()
            size.flags.writeable = rbound.flags.writeable = False
        frozen = owner.copy()
        frozen.flags.writeable = False
        cached = self._ray_constants = (self._sizes_version, size, rbound, frozen, owner)
        return cached[1], cached[2], cached[3]

    def geom_body_ids(self) -> np.ndarray:
        """(ngeom,) int64: index in `sim.humanoid.BODIES` of each geom's body, -1 for store geoms.

        With `geom_person_ids` this says which limb of whom a ray hit, in the numbering of `keypoint_body_ids`.
        """
        return self._geom_local.copy()

    def keypoint_body_ids(self) -> np.ndarray:
        """(17,) int64: index in `sim.humanoid.BODIES` (0 pelvis, 1 torso, 2 neck, 3 head, 4-6 left upper arm,
        forearm, hand, 7-9 right, 10-12 left thigh, shin, foot, 13-15 right) of the body each COCO keypoint
        site hangs on: face points on the head, a shoulder on its upper arm, an elbow on its forearm, a
        wrist on its hand, a hip on its thigh, a knee on its shin, an ankle on its foot. The joint keypoints
        sit at the joint centre, so they may also lie inside the parent segment's geom (the shoulder in the
        torso's ellipsoid, the hip in the pelvis capsule, the knee in the thigh capsule, and so on);
        `keypoint_parent_body_ids` gives that parent.
        """
        return hm.KEYPOINT_BODY.copy()

    def keypoint_parent_body_ids(self) -> np.ndarray:
        """(17,) int64: index in `sim.humanoid.BODIES` of the parent of each keypoint's body (the torso for a
        shoulder, the pelvis for a hip, the upper arm for an elbow, the neck for the face points, ...): a
        joint keypoint at the joint centre also lies inside the parent segment's geom."""
        return hm.KEYPOINT_PARENT_BODY.copy()

    def height_m(self, person_id: int) -> float:
        """Body height of a person who has appeared so far. Raises KeyError for an unknown id."""
        return self._heights[int(person_id)]

    @property
    def present(self) -> np.ndarray:
        """(S,) bool, read-only: which body slots hold a person at the last `advance`."""
        view = self._present.view()
        view.flags.writeable = False
        return view

    def activities(self) -> dict[int, Activity]:
        """What each person present at the last `advance` is doing."""
        acts = self.crowd.activities()
        return {int(self._person_ids[s]): Activity(int(acts[s])) for s in np.nonzero(self._present)[0]}

    # -- posing ------------------------------------------------------------------------------------

    def _body_constants(self):
        """Per-slot lengths the posing needs, (S,) or (S, 2) arrays, from the slots' heights."""
        H = self._slot_height
        thigh, shin = hm.THIGH * H, hm.SHIN * H
        self._k = {
            "thigh": thigh[:, None], "shin": shin[:, None],
            "reach2": ((thigh + shin) * hm.MAX_LEG_STRETCH * 0.995)[:, None] ** 2,
            "hw": (hm.HIP_HALF_WIDTH * H)[:, None] * _SIDES,
            "ankle_h": (hm.ANKLE_HEIGHT * H)[:, None],
            "z_stand": hm.HIP_HEIGHT * H * STAND_HIP_FRACTION,
            "z_low": hm.HIP_HEIGHT * H * LOWEST_HIP_FRACTION,
        }
        # The same per slot for `_qpos_kernel` (S, 7): thigh, shin, reach², hip half width, ankle height,
        # standing and lowest hip heights.
        k = self._k
        self._k_rows = np.ascontiguousarray(np.column_stack([
            k["thigh"][:, 0], k["shin"][:, 0], k["reach2"][:, 0], k["hw"][:, 0], k["ankle_h"][:, 0], k["z_stand"],
            k["z_low"]]), dtype=float)

    def _snapshot(self) -> _Snapshot:
        crowd = self.crowd
        q = np.zeros((self.slots, hm.NQ))
        _qpos_kernel(crowd.pos, crowd.vel, crowd.heading, crowd.phase, crowd.feet, crowd.swing_len,
                     crowd.gestures.value, self._k_rows, self._lo, self._hi, q)
        return _Snapshot(crowd.time_s, crowd.person_id.copy(), q, crowd.heading.copy())


@jit
def _qpos_kernel(pos, vel, heading_, phase_, feet, swing_len, motion, k, lo, hi, q):
    """Fills q (S, NQ) with joint positions from the crowd's state (`Crowd` attributes of the same names:
    pelvis ground point, velocity, heading, gait phase, feet, swing lengths) and motion (S, NUM_CHANNELS), the
    arms, gaze and weight channels of `sim.gestures`.

    The pelvis follows the crowd's ground point and heading, shifted sideways over the stance foot in walking
    and by the weight channel in standing; each ankle goes where the crowd put its foot (lifted in swing) by
    two-link inverse kinematics (`tests/reference/humanoid.py` has it as numpy); the pelvis drops as far as
    needed (within limits) to keep both feet in reach; each arm blends the gait's swing against the legs with
    its gesture pose by the arm's weight channel; trunk and neck add the gesture channels to the gait's lean
    and counter-rotation. k (S, 7): per slot thigh, shin, squared leg reach, hip half width, ankle height,
    standing and lowest hip heights. Hinges are clipped to [lo, hi].
    """
    pi = math.pi
    two_pi = 2 * math.pi
    lift_gain = SWING_LIFT_M / FULL_LIFT_STRIDE_M
    swing_scale = 1 / (1 - STANCE_FRACTION)
    for n in range(pos.shape[0]):
        x, y, heading, phase = pos[n, 0], pos[n, 1], heading_[n], phase_[n]
        speed = math.sqrt(vel[n, 0] * vel[n, 0] + vel[n, 1] * vel[n, 1])
        thigh, shin, reach2, hw, ankle_h = k[n, 0], k[n, 1], k[n, 2], k[n, 3], k[n, 4]
        z_stand, z_low = k[n, 5], k[n, 6]
        c, s = math.cos(heading), math.sin(heading)
        walk = min(speed * (1 / 0.6), 1.0)
        ph = two_pi * phase
        sin_ph, cos_ph = math.sin(ph), math.cos(ph)
        # Pelvis over the stance foot while walking, plus the weight shift of someone standing.
        sway = 0.02 * walk * sin_ph + motion[n, gs.SHIFT]
        px, py = x - s * sway, y + c * sway
        # Per leg (0 left, 1 right): foot minus hip joint (world), ankle height, lift, swing fraction.
        rx = [0.0, 0.0]
        ry = [0.0, 0.0]
        az = [0.0, 0.0]
        lift = [0.0, 0.0]
        sin_u = [0.0, 0.0]
        z_leg = 1e9
        for leg in range(2):
            side = 1.0 - 2.0 * leg
            rx[leg] = feet[n, leg, 0] - (px - s * hw * side)
            ry[leg] = feet[n, leg, 1] - (py + c * hw * side)
            # Foot height: lifted in swing, in proportion to how far the foot travels.
            u = max((phase + 0.5 * leg) % 1.0 - STANCE_FRACTION, 0.0) * swing_scale
            sin_u[leg] = math.sin(pi * u)
            lift[leg] = lift_gain * min(swing_len[n, leg], FULL_LIFT_STRIDE_M) * sin_u[leg]
            az[leg] = ankle_h + lift[leg]
            z_leg = min(z_leg, az[leg] + math.sqrt(max(reach2 - rx[leg] * rx[leg] - ry[leg] * ry[leg], 0.0)))
        z = min(max(z_leg, z_low), z_stand)
        q[n, 0], q[n, 1], q[n, 2] = px, py, z
        q[n, 3], q[n, 6] = math.cos(0.5 * heading), math.sin(0.5 * heading)
        # Legs: ankle target in the pelvis frame, two-link inverse kinematics.
        for leg in range(2):
            side = 1.0 - 2.0 * leg
            dx, dy, dz = rx[leg] * c + ry[leg] * s, ry[leg] * c - rx[leg] * s, az[leg] - z
            down = math.sqrt(dy * dy + dz * dz)
            r = min(max(math.sqrt(dx * dx + down * down), abs(thigh - shin) + 1e-6), (thigh + shin) * MAX_LEG_STRETCH)
            flex = math.atan2(dx, down) + math.acos(
                max(min((thigh * thigh + r * r - shin * shin) / (2 * thigh * r), 1.0), -1.0))
            knee = pi - math.acos(min(max((thigh * thigh + shin * shin - r * r) / (2 * thigh * shin), -1.0), 1.0))
            q[n, C_HIP_ABD + leg * LEG_STRIDE] = side * math.atan2(dy, -dz)
            q[n, C_HIP_FLEX + leg * LEG_STRIDE] = flex
            q[n, C_KNEE + leg * LEG_STRIDE] = knee
            # Foot flat on the floor, toes down a little in swing.
            q[n, C_ANKLE + leg * LEG_STRIDE] = flex - knee + (0.25 * sin_u[leg] if lift[leg] > 0 else 0.0)
        # Trunk and head: slight forward lean with speed, counter-rotation with the stride, and the gestures'
        # bend (for low shelves), pitch (looking at the hands), twist and tilt (glances).
        q[n, C_SPINE_FLEX] = 0.06 * speed + motion[n, gs.SPINE_FLEX]
        q[n, C_SPINE_TWIST] = -0.08 * walk * cos_ph + motion[n, gs.SPINE_TWIST]
        q[n, C_SPINE_LATERAL] = 0.03 * walk * sin_ph
        q[n, C_NECK_FLEX] = 0.12 - 0.06 * speed + motion[n, gs.NECK_FLEX]
        q[n, C_NECK_TWIST] = motion[n, gs.NECK_TWIST]
        q[n, C_HEAD_NOD] = motion[n, gs.HEAD_NOD]
        q[n, C_HEAD_TILT] = motion[n, gs.HEAD_TILT]
        # Arms: the swing opposite to the legs (`gs.REST` at zero speed), blended by each arm's weight
        # channel with its gesture pose (internal rotation turns the left arm about -z, the right about +z).
        swing0 = -0.4 * min(speed * (1 / 1.3), 1.2) * cos_ph
        for leg in range(2):
            side = 1.0 - 2.0 * leg
            swing = swing0 * side
            m0 = gs.LEFT_ARM + leg * gs.ARM_DOF
            w = min(max(motion[n, gs.W_LEFT + leg], 0.0), 1.0)
            rest = 1.0 - w
            q[n, C_SHOULDER_FLEX + leg * ARM_STRIDE] = rest * swing + w * motion[n, m0]
            q[n, C_SHOULDER_ABD + leg * ARM_STRIDE] = rest * gs.REST[1] + w * motion[n, m0 + 1]
            q[n, C_SHOULDER_ROT + leg * ARM_STRIDE] = -side * w * motion[n, m0 + 2]
            q[n, C_ELBOW + leg * ARM_STRIDE] = rest * (gs.REST[3] + 0.25 * max(swing, 0.0)) + w * motion[n, m0 + 3]
            q[n, C_WRIST + leg * ARM_STRIDE] = rest * gs.REST[4] + w * motion[n, m0 + 4]
        for j in range(lo.shape[0]):
            q[n, 7 + j] = min(max(q[n, 7 + j], lo[j]), hi[j])


_SIDES = np.array([1.0, -1.0])
# qpos columns (NQ layout of `sim.humanoid`) the posing writes; the right limb is the left one plus the stride.
C_SPINE_FLEX, C_SPINE_LATERAL, C_SPINE_TWIST, C_NECK_FLEX, C_NECK_TWIST = (
    7 + hm.J[name] for name in ("spine_flex", "spine_lateral", "spine_twist", "neck_flex", "neck_twist"))
C_HIP_ABD, C_HIP_FLEX, C_KNEE, C_ANKLE = (7 + hm.J[f"left_{n}"] for n in ("hip_abd", "hip_flex", "knee", "ankle"))
LEG_STRIDE = hm.J["right_hip_abd"] - hm.J["left_hip_abd"]
C_HEAD_NOD, C_HEAD_TILT = 7 + hm.J["head_nod"], 7 + hm.J["head_tilt"]
C_SHOULDER_FLEX, C_SHOULDER_ABD, C_SHOULDER_ROT, C_ELBOW, C_WRIST = (
    7 + hm.J[f"left_{n}"] for n in ("shoulder_flex", "shoulder_abd", "shoulder_rot", "elbow", "wrist"))
ARM_STRIDE = hm.J["right_shoulder_flex"] - hm.J["left_shoulder_flex"]
MAX_LEG_STRETCH = hm.MAX_LEG_STRETCH
if any(hm.J[f"right_{n}"] - hm.J[f"left_{n}"] != LEG_STRIDE for n in ("hip_flex", "knee", "ankle")) or any(
        hm.J[f"right_{n}"] - hm.J[f"left_{n}"] != ARM_STRIDE
        for n in ("shoulder_abd", "shoulder_rot", "elbow", "wrist")):
    raise RuntimeError("humanoid hinge layout: right limbs are not the left ones shifted")


class Kinematics(NamedTuple):
    """The model's constants that `_pose_kernel`'s forward kinematics reads (S slots, 16 bodies, 17 keypoints).

    Attributes:
        body: (S, 16) int64 model body ids.
        tables: (16 + 17, 3) int64 per local body its parent, first hinge and hinge count, then per keypoint
            its local body (`_FK_TABLES`).
        hinges: (H, 3) int64 qpos column, axis (0 x, 1 y, 2 z) and sign of each hinge (`_FK_HINGES`).
        body_pos: (nbody, 3) the model's body offsets in their parent frames, m.
        kp_sites: (S, 17) int64 model site ids of the keypoints.
        site_pos: (nsite, 3) the model's site offsets in their body frames, m.
    """

    body: np.ndarray
    tables: np.ndarray
    hinges: np.ndarray
    body_pos: np.ndarray
    kp_sites: np.ndarray
    site_pos: np.ndarray


@jit
def _pose_kernel(q0, q1, h0, h1, a, present, qpos, order, kinematics, out):
    """Poses the bodies between two crowd steps and computes the keypoint sites of those present.

    qpos (S * NQ,) becomes the joint positions a (0..1) of the way from q0 to q1 (S, NQ), with the
    pelvis yaw quaternion from the interpolated unwrapped headings h0 -> h1 (S,) and the slots not
    present (S,) parked below the floor. out (P, 17, 3) gets the keypoint sites of slots order (P,) by
    the same forward kinematics as MuJoCo's: a free pelvis, then per body its offset in the parent frame
    and its hinges in order (the humanoid's bodies, joints and sites have no rotation or offset of their
    own, and every hinge axis is a signed unit axis).

    kinematics: the fields of the model's `Kinematics` (after resizing), named again here.
    """
    kinematics = Kinematics(*kinematics)
    body, tables, hinges = kinematics.body, kinematics.tables, kinematics.hinges
    body_pos, kp_sites, site_pos = kinematics.body_pos, kinematics.kp_sites, kinematics.site_pos
    S, nq = q0.shape
    for s in range(S):
        for j in range(nq):
            qpos[s * nq + j] = q0[s, j] + (q1[s, j] - q0[s, j]) * a
        heading = h0[s] + (h1[s] - h0[s]) * a
        qpos[s * nq + 3] = math.cos(0.5 * heading)
        qpos[s * nq + 6] = math.sin(0.5 * heading)
        if not present[s]:
            qpos[s * nq + 2] = PARK_Z_M
    nb = body.shape[1]
    R = np.empty((nb, 3, 3))
    P = np.empty((nb, 3))
    for n in range(order.shape[0]):
        s = order[n]
        base = s * nq
        w, x, y, z = qpos[base + 3], qpos[base + 4], qpos[base + 5], qpos[base + 6]
        norm = math.sqrt(w * w + x * x + y * y + z * z)
        w, x, y, z = w / norm, x / norm, y / norm, z / norm
        R[0, 0, 0], R[0, 0, 1], R[0, 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
        R[0, 1, 0], R[0, 1, 1], R[0, 1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
        R[0, 2, 0], R[0, 2, 1], R[0, 2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
        P[0, 0], P[0, 1], P[0, 2] = qpos[base], qpos[base + 1], qpos[base + 2]
        for b in range(1, nb):
            pa = tables[b, 0]
            bp = body_pos[body[s, b]]
            for r in range(3):
                P[b, r] = P[pa, r] + R[pa, r, 0] * bp[0] + R[pa, r, 1] * bp[1] + R[pa, r, 2] * bp[2]
                for c in range(3):
                    R[b, r, c] = R[pa, r, c]
            for h in range(tables[b, 1], tables[b, 1] + tables[b, 2]):
                angle = qpos[base + hinges[h, 0]] * hinges[h, 2]
                if angle == 0.0:
                    continue  # (hinges at rest: hip rotation always, the others often)
                c, sn = math.cos(angle), math.sin(angle)
                # Right-multiplying by a turn about unit axis k mixes the other two columns u, v.
                u, v = (hinges[h, 1] + 1) % 3, (hinges[h, 1] + 2) % 3
                for r in range(3):
                    ru, rv = R[b, r, u], R[b, r, v]
                    R[b, r, u] = ru * c + rv * sn
                    R[b, r, v] = rv * c - ru * sn
        for k in range(out.shape[1]):
            b = tables[nb + k, 0]
            sp = site_pos[kp_sites[s, k]]
            for r in range(3):
                out[n, k, r] = P[b, r] + R[b, r, 0] * sp[0] + R[b, r, 1] * sp[1] + R[b, r, 2] * sp[2]


def _hinge_tables():
    """Per local body of `sim.humanoid` (BODIES order): parent, first hinge and hinge count; per hinge its
    qpos column and axis (from a standalone humanoid, whose layout every slot repeats)."""
    m = mujoco.MjModel.from_xml_string(hm.standalone_xml())
    names = [m.body(b).name[2:] for b in range(1, m.nbody)]  # "p_" prefix; body 0 is the world
    if tuple(names) != hm.BODIES:
        raise RuntimeError("humanoid bodies are not in sim.humanoid.BODIES order")
    parent = np.array([-1 if b == 0 else m.body_parentid[b + 1] - 1 for b in range(len(names))], dtype=np.int64)
    first = np.zeros(len(names), dtype=np.int64)
    num = np.zeros(len(names), dtype=np.int64)
    qcol = []
    for b in range(len(names)):
        first[b] = len(qcol)
        for j in range(m.body_jntadr[b + 1], m.body_jntadr[b + 1] + m.body_jntnum[b + 1]):
            if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
                if np.any(m.jnt_pos[j]):
                    raise RuntimeError("humanoid hinges are expected at their body origin")
                axis = m.jnt_axis[j]
                k = int(np.argmax(np.abs(axis)))
                if abs(axis[k]) != 1.0:
                    raise RuntimeError("humanoid hinge axes are expected along x, y or z")
                qcol.append((m.jnt_qposadr[j], k, int(axis[k])))
        num[b] = len(qcol) - first[b]
    if np.any(m.body_quat[1:] != [1, 0, 0, 0]) or np.any(m.site_quat != [1, 0, 0, 0]):
        raise RuntimeError("humanoid bodies and sites are expected unrotated")
    kp_body = np.array([m.site_bodyid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"p_{n}")] - 1
                        for n in hm.KEYPOINT_NAMES], dtype=np.int64)
    tables = np.zeros((len(names) + len(kp_body), 3), dtype=np.int64)
    tables[:len(names)] = np.column_stack([parent, first, num])
    tables[len(names):, 0] = kp_body
    return tables, np.array(qcol, dtype=np.int64).reshape(-1, 3)


# Per local body (parent, first hinge, hinge count) then per keypoint (its body); per hinge (qpos column, axis, sign).
_FK_TABLES, _FK_HINGES = _hinge_tables()
_FK_KP_BODY = _FK_TABLES[len(hm.BODIES):, 0].copy()
