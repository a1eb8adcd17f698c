"""What people do with their arms, gaze and weight: a schedule of joint-space motions per person, drawn from
the crowd's generator and evaluated at every crowd step.

Standing at a shelf, a person reaches to a height on it, searches, brings an item to the chest, turns it over
and puts it back or keeps it; standing elsewhere they hold a phone at the chest or the ear, talk with their
hands, look at something they hold or wait with their hands at rest; at the checkout they reach to the counter
and handle their purchase. Everybody glances around and standing people shift their weight from foot to foot;
walkers sometimes text on the way (their other arm keeps swinging).

Each person has three tracks that run independently: the arms (with the trunk bend and the head's pitch that
a reach or a look at the hands needs), the gaze (neck and trunk twist, head nod and tilt) and the weight (a
sideways shift of the pelvis over one foot). A track moves from wherever it is to its next target along a
minimum-jerk profile (Flash and Hogan, J. Neurosci. 1985: the smooth bell-shaped speed of human reaching),
holds it, then the next motion starts from wherever the track is, so the joints never jump. Hands that handle
something move on top of that in two sinusoids at frequencies f and GOLDEN f (a quasi-periodic figure that
never repeats), whose amplitudes ramp with the same profile.

Amplitudes and timings: reach durations of 0.6-1.2 s, as people reach; the sizes of the hand movements are
set from the wrist speeds of real actors at a shelf (Shelf dataset, 25 fps): standing people's wrists move a
median 0.14 m/s over one second (store_layout2, 3 min: 0.137 m/s). Frame to frame the real wrists move a
median 0.33 m/s, the synthetic ones 0.19 m/s; the rest of the real figure is most likely the annotation's own
noise (1 cm of independent error in each frame's 3D point alone gives about 0.5 m/s over 0.04 s), which the
truth of a synthetic person does not have, so the sizes are set from the one-second figure.
`crossview.measure.world_stats.measure` (`crossview world-stats`) reports both for a scenario.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from core.jit import jit
from sim import humanoid as hm
from sim.types import Activity

# Channels of a person's motion state (angles in radians, the shift in metres), in this order:
# per arm (left from LEFT_ARM, right from RIGHT_ARM) shoulder flexion, shoulder abduction, shoulder internal
# rotation, elbow flexion, wrist flexion; per arm the weight (0..1) of this pose against the gait's arm swing;
# trunk flexion and neck flexion added to the gait's; neck twist (+ to the left), trunk twist, head nod, head
# tilt; sideways shift of the pelvis (+ toward the left foot).
ARM_DOF = 5
LEFT_ARM, RIGHT_ARM = 0, ARM_DOF
W_LEFT, W_RIGHT = 10, 11
SPINE_FLEX, NECK_FLEX = 12, 13
NECK_TWIST, SPINE_TWIST, HEAD_NOD, HEAD_TILT = 14, 15, 16, 17
SHIFT = 18
NUM_CHANNELS = 19
# The tracks and their channels: arms (with trunk bend and head pitch), gaze, weight.
ARMS, GAZE, WEIGHT = 0, 1, 2
TRACKS = ((0, 14), (14, 18), (18, 19))

# Arm poses (shoulder flex, abduction, internal rotation, elbow flex, wrist flex), radians. REST is the
# gait's arm at zero speed (`sim.world`), so standing still and walking slowly meet without a jump.
REST = (0.0, 0.07, 0.0, 0.25, 0.1)
HANDS_FRONT = (0.25, 0.0, 0.55, 1.25, 0.0)  # hands together in front of the belly
INSPECT = (0.45, 0.1, 0.45, 1.6, 0.3)  # an item held at chest height, about 0.3 m in front
PHONE_CHEST = (0.35, 0.05, 0.5, 1.9, -0.3)
PHONE_EAR = (0.55, 0.45, 0.9, 2.45, 0.2)
GESTURE = (0.3, 0.15, 0.2, 1.1, 0.0)  # forearm forward, moving as one talks
# Per pose (same order as the poses, radians, before the scenario's `crowd.hand_motion_scale` and the
# person's own liveliness): the amplitudes of the first handling sinusoid (the second has half of them), and
# the std of the small moves to a new pose near the held one (`Gestures._hold`).
HANDLE_A, HANDLE_F = (0.05, 0.03, 0.12, 0.08, 0.2), (0.2, 0.1, 0.3, 0.4, 0.3)  # an item in the hands
SEARCH_A, SEARCH_F = (0.03, 0.02, 0.06, 0.04, 0.15), (0.2, 0.12, 0.15, 0.2, 0.2)  # feeling along a shelf
PHONE_A, PHONE_F = (0.02, 0.01, 0.03, 0.04, 0.1), (0.08, 0.05, 0.12, 0.15, 0.15)  # scrolling and typing
EAR_A, EAR_F = (0.01, 0.01, 0.02, 0.02, 0.04), (0.05, 0.05, 0.08, 0.08, 0.05)
GESTURE_A, GESTURE_F = (0.1, 0.06, 0.12, 0.18, 0.15), (0.35, 0.15, 0.3, 0.45, 0.3)  # talking with the hands
IDLE_A, IDLE_F = (0.02, 0.01, 0.02, 0.03, 0.03), (0.12, 0.05, 0.12, 0.25, 0.1)  # hands at rest move a little
ZERO = (0.0,) * ARM_DOF
# Those small moves take FIDGET_MOVE_S and rest FIDGET_HOLD_S (seconds, min and max).
FIDGET_MOVE_S = (0.4, 1.0)
FIDGET_HOLD_S = (0.0, 0.4)
# The second sinusoid's frequency ratio (irrational: the figure never closes).
GOLDEN = (1 + 5 ** 0.5) / 2
# Liveliness: each person's amplitudes are scaled by a factor drawn from this range.
LIVELINESS = (0.25, 0.7)

# Reaching: the wrist goes this far in front of the pelvis (people stand `StoreGeometry.browse_spots`'s 0.5 m
# from a shelf face; the fingers reach about 0.15 m beyond the wrist), plus up to REACH_DEPTH_M into the shelf.
REACH_FORWARD_M = 0.36
REACH_DEPTH_M = 0.1
# Lowest and highest shelf heights people reach to: the bottom board, and the top of the shelf or a little
# above the head (as a fraction of the body height), whichever is lower.
LOWEST_REACH_M = 0.3
HIGHEST_REACH_FRAC = 1.1
# The trunk bends for what lies below this height, by TRUNK_BEND_RAD_M per metre below, at most MAX_TRUNK_BEND_RAD.
BEND_BELOW_M = 0.9
TRUNK_BEND_RAD_M = 1.6
MAX_TRUNK_BEND_RAD = 0.9
# Eye height as a fraction of the body height (the head looks at what the hands do).
EYE_FRAC = 0.93
# Pitch of the head of someone looking at their own hands in front of the chest or at a phone, radians.
LOOK_AT_HANDS_RAD = 0.4
LOOK_AT_PHONE_RAD = 0.55

# Durations, seconds (min, max): a move to the next pose, holds.
REACH_MOVE_S = (0.6, 1.2)
SEARCH_HOLD_S = (0.4, 1.2)
BRING_MOVE_S = (0.6, 1.0)
INSPECT_HOLD_S = (1.5, 5.0)
PUT_BACK_SHARE = 0.5  # of items picked up: the rest are kept (lowered to the side, as into a basket)
PUT_BACK_HOLD_S = (0.2, 0.6)
TWO_HANDS_SHARE = 0.5  # of items inspected with both hands
REST_HOLD_S = (0.5, 2.5)
STAND_HOLD_S = (2.0, 6.0)
STAND_MOVE_S = (0.5, 1.0)
TURN_TO_SHELF_S = 1.0  # a browser first turns to the shelf
COUNTER_M = 0.95  # counter height where a store has no checkout box (`store.checkout_size_m`'s default is 0.9)
RIGHT_HAND_SHARE = 0.7  # of one-handed actions done with the right hand
# Standing away from shelves: phone at the chest, at the ear, talking with the hands, looking at something
# held, hands at rest (shares).
STAND_SHARES = (0.3, 0.1, 0.25, 0.15, 0.2)
# Walkers who text on the way (share of walks), how long, and how quickly the arms go back to swinging.
WALK_PHONE_SHARE = 0.12
WALK_PHONE_S = (3.0, 10.0)
TO_SWING_S = 0.5
# Gaze: a glance turns the neck (and a third as much the trunk) this far to either side, nods and tilts the
# head, moves in GLANCE_MOVE_S and holds GLANCE_HOLD_S, then looks ahead again.
GLANCE_TWIST_RAD = (0.3, 1.0)
GLANCE_NOD_RAD = (-0.15, 0.25)
GLANCE_TILT_RAD = 0.1
GLANCE_MOVE_S = (0.5, 0.9)
GLANCE_HOLD_S = (0.5, 2.0)
# Weight shifts of someone standing: the pelvis moves this far toward one foot in SHIFT_MOVE_S and stays
# SHIFT_HOLD_S: slowly and most of the time, as standing people sway (their hips then move a median 0.006-0.008
# m/s, within the 0.5-1 cm/s that a quietly standing body's centre of mass sways at).
SHIFT_M = (0.02, 0.06)
SHIFT_MOVE_S = (0.8, 2.0)
SHIFT_HOLD_S = (0.0, 1.0)



class Segment(NamedTuple):
    """A planned motion of one track: move to `target` in move_s, then hold it for hold_s."""

    target: np.ndarray  # (n,) the track's channels
    move_s: float
    hold_s: float
    amp_a: np.ndarray  # (n,) amplitudes of the first sinusoid at the target
    amp_b: np.ndarray  # (n,) and of the second
    hz: float | None  # frequency of the sinusoids from now on (None: keep the current one)


# Plain ints (an enum member's lookup is slow in per-person loops).
_WALK, _BROWSE, _CHECKOUT = int(Activity.WALK), int(Activity.BROWSE), int(Activity.CHECKOUT)


def reach_pose(height_m: float, target_m: float, forward_m: float) -> tuple[tuple[float, ...], float, float]:
    """The arm pose that puts the wrist at a height in front of a standing person (two-link inverse kinematics
    in the sagittal plane), with the trunk bend a low target needs and the head pitch that looks at it.

    Args:
        height_m: body height.
        target_m: wanted wrist height above the floor.
        forward_m: wanted wrist distance in front of the pelvis.

    Returns:
        (arm pose (5,) in the order of REST, trunk flexion, neck flexion added to the gait's 0.12), radians.
        The wrist lands on the target in front of the shoulder (no abduction or rotation); a target out of
        reach gives the arm pointing straight at it, nearly stretched.
    """
    H = height_m
    spine = min(max(BEND_BELOW_M - target_m, 0.0) * TRUNK_BEND_RAD_M, MAX_TRUNK_BEND_RAD)
    lumbar_z = hm.HIP_HEIGHT * hm.STAND_HIP_FRACTION * H + hm.LUMBAR_ABOVE_HIP * H
    shoulder_x = hm.SHOULDER_ABOVE_LUMBAR * H * math.sin(spine)
    shoulder_z = lumbar_z + hm.SHOULDER_ABOVE_LUMBAR * H * math.cos(spine)
    dx, dz = forward_m - shoulder_x, target_m - shoulder_z
    a, b = hm.UPPER_ARM * H, hm.FOREARM * H
    r = min(max(math.hypot(dx, dz), abs(a - b) + 1e-6), 0.98 * (a + b))
    # Law of cosines: the elbow's flexion, then the upper arm's angle from straight down (forward positive).
    elbow = math.pi - math.acos(min(max((a * a + b * b - r * r) / (2 * a * b), -1.0), 1.0))
    toward = math.atan2(dx, -dz)
    flex_world = toward - math.atan2(b * math.sin(elbow), a + b * math.cos(elbow))
    # The shoulder hinge is relative to the trunk, which leans forward by `spine`.
    flex = flex_world + spine
    down = math.atan2(EYE_FRAC * H - target_m, forward_m + 0.15)
    neck = min(max(down - 0.12 - spine, -0.5), 0.7)
    return (flex, 0.0, 0.0, elbow, 0.2), spine, neck


def _arms(left, right, w_left: float, w_right: float, spine: float = 0.0, neck: float = 0.0):
    """The arms track's channels (14,) from two arm poses, their weights, trunk and neck flexion."""
    return np.array([*left, *right, w_left, w_right, spine, neck])


class Moves(NamedTuple):
    """The moves every slot's channels are making (S slots, K channels), as `_evaluate` reads them.

    Attributes:
        frm, to: (S, K) each channel's minimum-jerk move from frm to to.
        t0, t1: (S, K) its start and end, s.
        a_frm, a_to, b_frm, b_to: (S, K) the two sinusoids' amplitudes, moving with the same weight.
        freq: (S,) the sinusoids' frequency, Hz.
    """

    frm: np.ndarray
    to: np.ndarray
    t0: np.ndarray
    t1: np.ndarray
    a_frm: np.ndarray
    a_to: np.ndarray
    b_frm: np.ndarray
    b_to: np.ndarray
    freq: np.ndarray


class Channels(NamedTuple):
    """What `_evaluate` writes per slot and channel (S, K): the move's value (base), the sinusoids' amplitudes
    (amp_a, amp_b) and the channel (value)."""

    base: np.ndarray
    amp_a: np.ndarray
    amp_b: np.ndarray
    value: np.ndarray


class Gestures:
    """Everybody's arm, gaze and weight motion, one row per body slot.

    Attributes:
        value: (S, NUM_CHANNELS) the channels at the latest `update` (what `sim.world` poses).
    """

    def __init__(self, slots: int, rng: np.random.Generator, config):
        """Args: slots: body slots; rng: the crowd's generator; config: the `CrowdConfig`."""
        S = slots
        self.rng = rng
        self.config = config
        self.frm = np.zeros((S, NUM_CHANNELS))
        self.to = np.zeros((S, NUM_CHANNELS))
        self.t0 = np.zeros((S, NUM_CHANNELS))
        self.t1 = np.zeros((S, NUM_CHANNELS))
        self.a_frm = np.zeros((S, NUM_CHANNELS))
        self.a_to = np.zeros((S, NUM_CHANNELS))
        self.b_frm = np.zeros((S, NUM_CHANNELS))
        self.b_to = np.zeros((S, NUM_CHANNELS))
        self.freq = np.ones(S)
        self.phase = np.zeros(S)
        self.base = np.zeros((S, NUM_CHANNELS))
        self.amp_a = np.zeros((S, NUM_CHANNELS))
        self.amp_b = np.zeros((S, NUM_CHANNELS))
        self.value = np.zeros((S, NUM_CHANNELS))
        self.until = np.full((S, 3), np.inf)
        self.queues: list[list[list[Segment]]] = [[[], [], []] for _ in range(S)]
        self.context = np.full(S, -1, dtype=np.int64)
        self.person = np.full(S, -1, dtype=np.int64)
        self.liveliness = np.ones(S)
        self.reach_top = np.zeros(S)  # top of the shelf or counter a person stands at (0: none)
        self.height = np.full(S, hm.REFERENCE_HEIGHT_M)
        # The same arrays as the kernel takes them (they are written in place, never replaced).
        self._moves = Moves(self.frm, self.to, self.t0, self.t1, self.a_frm, self.a_to, self.b_frm, self.b_to,
                            self.freq)
        self._channels = Channels(self.base, self.amp_a, self.amp_b, self.value)
        _evaluate(0.0, 0.0, self._moves, self.phase, self._channels)

    def update(self, t_s: float, dt_s: float, person_id: np.ndarray, activity: np.ndarray, height: np.ndarray):
        """Advances everybody's motion to t_s (dt_s after the previous update) and plans what comes next.

        Args:
            t_s: the crowd's time.
            dt_s: time since the previous update (the sinusoids' phases advance by it).
            person_id: (S,) person in each slot (-1: empty).
            activity: (S,) `Activity` value of each slot.
            height: (S,) body heights.
        """
        _evaluate(t_s, dt_s, self._moves, self.phase, self._channels)
        new = np.nonzero((person_id != self.person) & (person_id >= 0))[0]
        for s in new.tolist():
            self._reset(s, int(person_id[s]), float(height[s]), t_s)
        changed = (activity != self.context) & (person_id >= 0)
        due = (self.until <= t_s) | changed[:, None]
        due &= (person_id >= 0)[:, None]
        for s, track in zip(*np.nonzero(due)):
            s, track = int(s), int(track)
            if changed[s] and track != GAZE:
                self.queues[s][track].clear()
            queue = self.queues[s][track]
            if not queue:
                queue.extend(self._plan(s, track, int(activity[s])))
            self._start(s, track, t_s, queue.pop(0))
        self.context[:] = activity
        self.person[:] = person_id

    def set_reach_top(self, slot: int, top_m: float):
        """The top of the shelf or counter the person in `slot` is about to stand at (0: none)."""
        self.reach_top[slot] = top_m

    # -- one slot -----------------------------------------------------------------------------------

    def _reset(self, s: int, pid: int, height_m: float, t_s: float):
        """A newcomer in slot s: arms swinging with the gait, looking ahead, weight on both feet."""
        rng = self.rng
        self.frm[s] = self.to[s] = self.base[s] = self.value[s] = 0.0
        for arr in (self.a_frm, self.a_to, self.b_frm, self.b_to, self.amp_a, self.amp_b):
            arr[s] = 0.0
        self.t0[s] = self.t1[s] = t_s
        self.phase[s] = rng.uniform(0.0, 2 * math.pi)
        self.liveliness[s] = rng.uniform(*LIVELINESS) * self.config.hand_motion_scale
        self.height[s] = height_m
        self.queues[s] = [[], [], []]
        self.until[s] = t_s
        self.context[s] = -1
        self.person[s] = pid

    def _start(self, s: int, track: int, t_s: float, segment: Segment):
        lo, hi = TRACKS[track]
        target, move_s, hold_s, amp_a, amp_b, hz = segment
        self.frm[s, lo:hi] = self.base[s, lo:hi]
        self.to[s, lo:hi] = target
        self.t0[s, lo:hi] = t_s
        self.t1[s, lo:hi] = t_s + move_s
        self.a_frm[s, lo:hi] = self.amp_a[s, lo:hi]
        self.b_frm[s, lo:hi] = self.amp_b[s, lo:hi]
        self.a_to[s, lo:hi] = amp_a
        self.b_to[s, lo:hi] = amp_b
        if hz is not None:
            self.freq[s] = hz
        self.until[s, track] = t_s + move_s + hold_s

    def _plan(self, s: int, track: int, activity: int) -> list[Segment]:
        if track == GAZE:
            return self._glance(activity)
        if track == WEIGHT:
            return self._weight(activity)
        if activity == _WALK:
            return self._walk_arms()
        if activity == _BROWSE:
            return self._shelf(s)
        if activity == _CHECKOUT:
            return self._counter(s)
        return self._stand(s)

    def _amp(self, s: int, left, right=ZERO) -> np.ndarray:
        """(14,) amplitudes (or fidget sizes) of the arms track: per arm values scaled by the person's liveliness."""
        return _arms(left, right, 0.0, 0.0) * self.liveliness[s]

    def _hz(self) -> float:
        return float(self.rng.uniform(*self.config.handling_hz))

    def _right_handed(self) -> bool:
        """Whether the right hand does it (people are mostly right-handed)."""
        return bool(self.rng.random() < RIGHT_HAND_SHARE)

    def _hold(self, s: int, target: np.ndarray, move_s: float, hold_s: float, amp: np.ndarray, amp_b: np.ndarray,
              fidget: np.ndarray) -> list[Segment]:
        """Move to `target` (arms track), then hold it for hold_s while the hands handle something: the two
        sinusoids of amplitudes amp and amp_b, and every FIDGET_MOVE_S + FIDGET_HOLD_S a small move to the
        target plus a normal draw of std `fidget` (14,) per channel (turning an item over, re-gripping a phone,
        the next gesture)."""
        rng = self.rng
        out = [Segment(target, move_s, 0.0, amp, amp_b, self._hz())]
        left = hold_s
        while left > 0:
            move, hold = rng.uniform(*FIDGET_MOVE_S), rng.uniform(*FIDGET_HOLD_S)
            out.append(Segment(target + rng.standard_normal(target.size) * fidget, move,
                               min(hold, max(left - move, 0.0)), amp, amp_b, None))
            left -= move + hold
        return out

    def _one_hand(self, s: int, pose, amp, fidget, right: bool, other=REST, other_amp=IDLE_A, other_fidget=IDLE_F):
        """(target, amplitudes, fidget sizes) of the arms track with `pose` on one hand and `other` on the
        other; the second sinusoid has half the first's amplitudes."""
        if right:
            return _arms(other, pose, 1.0, 1.0), self._amp(s, other_amp, amp), self._amp(s, other_fidget, fidget)
        return _arms(pose, other, 1.0, 1.0), self._amp(s, amp, other_amp), self._amp(s, fidget, other_fidget)

    def _shelf(self, s: int) -> list[Segment]:
        """At a shelf: reach to a height on it, search, bring the item to the chest, turn it over, then put it
        back or keep it, and rest a moment."""
        rng, H = self.rng, self.height[s]
        u = rng.uniform
        top = min(self.reach_top[s] or H, HIGHEST_REACH_FRAC * H)
        h = u(LOWEST_REACH_M, max(top, LOWEST_REACH_M + 0.1))
        forward = REACH_FORWARD_M + u(0.0, REACH_DEPTH_M)
        arm, spine, neck = reach_pose(H, h, forward)
        right = self._right_handed()
        out = []
        if self.context[s] != _BROWSE:  # just arrived: turn to the shelf first, arms at rest
            target, amp, fidget = self._one_hand(s, REST, IDLE_A, IDLE_F, right)
            out += self._hold(s, target, u(*STAND_MOVE_S), TURN_TO_SHELF_S, amp, amp * 0.5, fidget)
        reach, amp, fidget = self._one_hand(s, arm, SEARCH_A, SEARCH_F, right)
        reach[SPINE_FLEX], reach[NECK_FLEX] = spine, neck
        out += self._hold(s, reach, u(*REACH_MOVE_S), u(*SEARCH_HOLD_S), amp, amp * 0.5, fidget)
        both = rng.random() < TWO_HANDS_SHARE
        other, other_amp, other_fidget = (INSPECT, HANDLE_A, HANDLE_F) if both else (REST, IDLE_A, IDLE_F)
        target, amp, fidget = self._one_hand(s, INSPECT, HANDLE_A, HANDLE_F, right, other, other_amp, other_fidget)
        target[NECK_FLEX] = LOOK_AT_HANDS_RAD
        out += self._hold(s, target, u(*BRING_MOVE_S), u(*INSPECT_HOLD_S), amp, amp * 0.5, fidget)
        if rng.random() < PUT_BACK_SHARE:
            _, amp, fidget = self._one_hand(s, arm, SEARCH_A, SEARCH_F, right)
            out += self._hold(s, reach, u(*REACH_MOVE_S), u(*PUT_BACK_HOLD_S), amp, amp * 0.5, fidget)
        target, amp, fidget = self._one_hand(s, REST, IDLE_A, IDLE_F, right, REST, IDLE_A, IDLE_F)
        out += self._hold(s, target, u(*STAND_MOVE_S), u(*REST_HOLD_S), amp, amp * 0.5, fidget)
        return out

    def _counter(self, s: int) -> list[Segment]:
        """At the checkout: put things on the counter, then handle the purchase or a card low in front."""
        rng, H = self.rng, self.height[s]
        u = rng.uniform
        top = self.reach_top[s] or COUNTER_M
        arm, spine, neck = reach_pose(H, top + u(0.05, 0.15), REACH_FORWARD_M + u(0.0, REACH_DEPTH_M))
        right = self._right_handed()
        target, amp, fidget = self._one_hand(s, arm, SEARCH_A, SEARCH_F, right)
        target[SPINE_FLEX], target[NECK_FLEX] = spine, neck
        out = self._hold(s, target, u(*REACH_MOVE_S), u(*SEARCH_HOLD_S), amp, amp * 0.5, fidget)
        target, amp, fidget = self._one_hand(s, INSPECT, HANDLE_A, HANDLE_F, right, INSPECT, HANDLE_A, HANDLE_F)
        target[NECK_FLEX] = LOOK_AT_HANDS_RAD
        return out + self._hold(s, target, u(*BRING_MOVE_S), u(*INSPECT_HOLD_S), amp, amp * 0.5, fidget)

    def _stand(self, s: int) -> list[Segment]:
        """Standing away from shelves: one of phone at the chest or ear, talking, looking at something held, rest."""
        rng = self.rng
        kind = int(rng.choice(len(STAND_SHARES), p=STAND_SHARES))
        right = self._right_handed()
        neck = 0.0
        if kind == 0:
            target, amp, fidget = self._one_hand(s, PHONE_CHEST, PHONE_A, PHONE_F, right)
            neck = LOOK_AT_PHONE_RAD
        elif kind == 1:
            target, amp, fidget = self._one_hand(s, PHONE_EAR, EAR_A, EAR_F, right)
        elif kind == 2:
            other = (GESTURE, GESTURE_A, GESTURE_F) if rng.random() < 0.5 else (REST, IDLE_A, IDLE_F)
            target, amp, fidget = self._one_hand(s, GESTURE, GESTURE_A, GESTURE_F, right, *other)
        elif kind == 3:
            target, amp, fidget = self._one_hand(s, INSPECT, HANDLE_A, HANDLE_F, right, INSPECT, HANDLE_A, HANDLE_F)
            neck = LOOK_AT_HANDS_RAD
        else:
            pose = HANDS_FRONT if rng.random() < 0.5 else REST
            target, amp, fidget = self._one_hand(s, pose, IDLE_A, IDLE_F, right, pose, IDLE_A, IDLE_F)
        target[NECK_FLEX] = neck
        return self._hold(s, target, rng.uniform(*STAND_MOVE_S), rng.uniform(*STAND_HOLD_S), amp, amp * 0.5, fidget)

    def _walk_arms(self) -> list[Segment]:
        """Walking: the arms swing with the gait; some walkers text on the way with one hand."""
        rng = self.rng
        swing = _arms(REST, REST, 0.0, 0.0)
        zero = swing * 0.0
        if rng.random() >= WALK_PHONE_SHARE:
            return [Segment(swing, TO_SWING_S, math.inf, zero, zero, None)]
        right = self._right_handed()
        target = _arms(REST, PHONE_CHEST, 0.0, 1.0) if right else _arms(PHONE_CHEST, REST, 1.0, 0.0)
        target[NECK_FLEX] = LOOK_AT_PHONE_RAD * 0.6
        amp = _arms(ZERO, PHONE_A, 0.0, 0.0) if right else _arms(PHONE_A, ZERO, 0.0, 0.0)
        return [Segment(target, TO_SWING_S, rng.uniform(*WALK_PHONE_S), amp, amp * 0.5, self._hz()),
                Segment(swing, TO_SWING_S, math.inf, zero, zero, None)]

    def _glance(self, activity: int) -> list[Segment]:
        """A look to one side (and back ahead), at the config's rate."""
        rng = self.rng
        u = rng.uniform
        zero = np.zeros(4)
        rate = self.config.look_rate_hz
        wait = rng.exponential(1 / rate) if rate > 0 else math.inf
        if rate <= 0:
            return [Segment(zero, u(*GLANCE_MOVE_S), wait, zero, zero, None)]
        twist = u(*GLANCE_TWIST_RAD) * (1.0 if rng.random() < 0.5 else -1.0)
        look = np.array([twist, twist / 3, u(*GLANCE_NOD_RAD), u(-GLANCE_TILT_RAD, GLANCE_TILT_RAD)])
        return [Segment(look, u(*GLANCE_MOVE_S), u(*GLANCE_HOLD_S), zero, zero, None),
                Segment(zero, u(*GLANCE_MOVE_S), wait, zero, zero, None)]

    def _weight(self, activity: int) -> list[Segment]:
        """Standing: the weight moves onto one foot and stays a while; walking: the gait's own sway."""
        rng = self.rng
        zero = np.zeros(1)
        if activity == _WALK:
            return [Segment(zero, TO_SWING_S, math.inf, zero, zero, None)]
        shift = rng.uniform(*SHIFT_M) * (1.0 if rng.random() < 0.5 else -1.0)
        return [Segment(np.array([shift]), rng.uniform(*SHIFT_MOVE_S), rng.uniform(*SHIFT_HOLD_S), zero, zero, None)]


@jit
def _evaluate(t, dt, moves, phase, channels):
    """Every slot's channels at time t, s: per channel a minimum-jerk move from frm to to (S, K) over [t0, t1]
    (`Moves`; the weight e = 10u³ - 15u⁴ + 6u⁵ of u, the fraction of the move done), then held, plus the two
    sinusoids sin(phase) and sin(GOLDEN phase + 1) with amplitudes moving from a_frm/b_frm to a_to/b_to with
    the same weight. phase (S,) advances by 2 pi freq dt first (dt, s). The `Channels` get the move's value and
    the amplitudes at t (base, amp_a, amp_b) and the channels (value)."""
    frm, to, t0, t1 = moves.frm, moves.to, moves.t0, moves.t1
    a_frm, a_to, b_frm, b_to, freq = moves.a_frm, moves.a_to, moves.b_frm, moves.b_to, moves.freq
    base, amp_a, amp_b, out = channels.base, channels.amp_a, channels.amp_b, channels.value
    two_pi = 2 * math.pi
    for s in range(frm.shape[0]):
        phase[s] += two_pi * freq[s] * dt
        sa = math.sin(phase[s])
        sb = math.sin(GOLDEN * phase[s] + 1.0)
        for k in range(frm.shape[1]):
            span = t1[s, k] - t0[s, k]
            u = 1.0 if span <= 0.0 else min(max((t - t0[s, k]) / span, 0.0), 1.0)
            e = u * u * u * (u * (u * 6.0 - 15.0) + 10.0)
            b = frm[s, k] + (to[s, k] - frm[s, k]) * e
            aa = a_frm[s, k] + (a_to[s, k] - a_frm[s, k]) * e
            ab = b_frm[s, k] + (b_to[s, k] - b_frm[s, k]) * e
            base[s, k], amp_a[s, k], amp_b[s, k] = b, aa, ab
            out[s, k] = b + aa * sa + ab * sb
