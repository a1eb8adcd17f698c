"""Where a detector finds a joint: not where the scoring truth has it, but offset from it by a per-person,
slowly varying, heavy-tailed amount that turns with the body and is the same for every camera.

Real detectors agree with each other across cameras on a point that is not the annotated joint (OpenPose on
Shelf: its detections of a joint agree across five views to about 5 px, yet triangulate 5-8 cm from the
annotated wrists, hips and top of the head; docs/sensor-model.md). A simulator whose detector is noisy around
the scorer's own joints makes that offset zero by construction, and flatters every tracker. Here each person's
joint j carries an offset

    o_j(t) = B_j(pose) (offset_m[g] · s_j ⊙ u_j(t)) + lift_m[g] · z

with g the joint's group, B_j the frame of the joint's body segment (the limb from its parent joint, or the
torso), s_j a Student-t scale per axis (heavy tails across people and joints), u_j(t) a unit-variance random
process with correlation exp(-|Δt| / offset_time_s) per axis (random Fourier features of that kernel) and z
the world's up.

People a detector keeps getting wrong (`difficult_rate` of them, drawn systematically over the people in the
order they enter, so that any N people in a row hold floor or ceil of rate x N of them whatever the seed:
`is_difficult`) have their offsets scaled by `difficult_offset_scale` and one arm, chosen per person, grossly
wrong during bad episodes: its wrist `difficult_error_m` from the truth's (its elbow half that), in a direction
drawn per person in the forearm's frame, the same for every camera (so a tracker cannot vote it away), the
arm in a bad episode while a second unit-variance process of the same kind is above the level it exceeds a
share `difficult_share` of the time. Everything about a person is drawn from the person's id and the
detector's seed alone, so the offsets do not depend on which camera asks, in which process, or in which order.

The offsets live on the truth's ticks (`core.truth.TRUTH_RATE_HZ`): one per person and tick, shared by every
camera capturing in it. Each feature's cos(ω_k t + φ_k) is a phasor turned by ω_k / TRUTH_RATE_HZ from tick to
tick (`fourier_sums`): its cosine and sine are evaluated at every `ANCHOR_TICKS`-th tick and rotated from there,
so that a person costs one complex product per feature and tick, not a cosine of a large angle (the offsets
were a third of the simulation's geometry). The value at a tick is the same bits whoever asks: the anchor and
the number of turns depend on the tick alone. It agrees with the cosines evaluated directly to within the
rounding of their angles (ω t is large for the Cauchy's fast features): 5e-11 of the unit-variance process in
the first 30 s, 1e-8 an hour in (under a nanometre of offset).
"""

from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np

from core.jit import jit
from core.truth import TRUTH_RATE_HZ
from core.types import Skeleton
from sim.sensing.draws import joint_groups
from sim.sensing.profiles import DetectorParams

_FEATURES = 6  # random Fourier features per axis: enough for a near-Gaussian marginal
ANCHOR_TICKS = 32  # the features' phasors are evaluated directly at every ANCHOR_TICKS-th tick, turned between
_SIDES = ("left_", "right_")
_PARENT = {"elbow": "shoulder", "wrist": "elbow", "knee": "hip", "ankle": "knee"}
_PHASE_KEY = 0x0D1FF1C  # the detector seed's stream for the phase of the difficult people's systematic draw
_DIFFICULT_KEY = 1  # a person's stream for its difficulty's draws: [seed, person id, _DIFFICULT_KEY]


def is_difficult(person_ids: np.ndarray, rate: float, phase: float) -> np.ndarray:
    """(N,) bool: person k is one the detector keeps getting wrong when floor(rate (k + 1) + phase) >
    floor(rate k + phase) (a systematic draw at `rate` with a random start `phase` in [0, 1)): any N consecutive
    ids hold floor or ceil of rate x N such people."""
    k = np.asarray(person_ids, dtype=np.float64)
    return np.floor(rate * (k + 1.0) + phase) > np.floor(rate * k + phase)


class JointOffsets:
    """The detector's joints for one detector (one seed).

    Args:
        params: the error model (`offset_m`, `offset_tail_dof`, `offset_time_s`, `lift_m`).
        skeleton: the joint layout of the poses.
        seed: the detector's seed for offsets (each person's draws come from it and the person's id).
    """

    def __init__(self, params: DetectorParams, skeleton: Skeleton, seed: int):
        group = joint_groups(skeleton)
        self.std_m = np.asarray(params.offset_m, dtype=np.float64)[group]  # (J,)
        self.lift_m = np.asarray(params.lift_m, dtype=np.float64)[group]  # (J,)
        self._rate = float(params.difficult_rate)
        self._difficult_scale = float(params.difficult_offset_scale)
        self._difficult_m = float(params.difficult_error_m)
        share = float(params.difficult_share)
        # The level a unit-variance (near-Gaussian) process exceeds the share `difficult_share` of the time.
        self._episode_level = math.inf if share <= 0.0 else -math.inf if share >= 1.0 else \
            NormalDist().inv_cdf(1.0 - share)
        self._phase = float(np.random.default_rng([int(seed), _PHASE_KEY]).random())
        self._difficulty = self._rate > 0.0 and (self._difficult_scale != 1.0 or (
            self._difficult_m > 0.0 and share > 0.0))
        self.active = bool(self.std_m.any() or self.lift_m.any() or self._difficulty)
        self._dof = float(params.offset_tail_dof)
        self._time_s = float(params.offset_time_s)
        self._seed = int(seed)
        self._J = skeleton.num_joints
        names = list(skeleton.joints)
        index = {n: i for i, n in enumerate(names)}
        # Each joint's parent joint (-1: the torso's frame), and the torso's joints (-1: none).
        self._parent = np.full(self._J, -1, dtype=np.int64)
        for i, name in enumerate(names):
            for side in _SIDES:
                for child, parent in _PARENT.items():
                    if name == side + child and side + parent in index:
                        self._parent[i] = index[side + parent]
        self._torso = np.array([index.get(n, -1) for n in ("left_hip", "right_hip", "left_shoulder", "right_shoulder")],
                               dtype=np.int64)
        # Each side's arm (elbow, wrist) for a difficult person's gross error (-1: the layout lacks it).
        self._arms = [(index.get(side + "elbow", -1), index.get(side + "wrist", -1)) for side in _SIDES]
        self._slot_of: dict[int, int] = {}
        # Per person (a row each): the features' angular frequencies (rad/s), phases and turn per tick
        # (cos, sin of ω / TRUTH_RATE_HZ), (S, J, 3, 4, K), and each axis's amplitude (S, J, 3): offset_m x the
        # person's Student-t scale x sqrt(2 / K).
        self._fourier = np.empty((0, self._J, 3, 4, _FEATURES))
        self._amplitude_m = np.empty((0, self._J, 3))
        # Per person: the bad episodes' process (S, 1, 3, 4, K; its first axis is used) and the gross error of the
        # chosen arm in the segment frames (S, J, 3), zero for people who are not difficult.
        self._episode = np.empty((0, 1, 3, 4, _FEATURES))
        self._gross_m = np.empty((0, self._J, 3))
        self._any_difficult = False

    def offsets(self, person_ids: np.ndarray, ticks: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """(N, J, 3) where the detector's joints lie relative to the truth's, metres (world frame).

        Args:
            person_ids: (N,) int64 the person of each pose (>= 0).
            ticks: (N,) int64 the truth tick of each pose (`core.truth.tick_of`; tick k is k / TRUTH_RATE_HZ s).
            poses: (N, J, 3) the true poses, metres.
        """
        N = len(person_ids)
        if N == 0 or not self.active:
            return np.zeros((N, self._J, 3))
        slots = self._slots(person_ids)
        ticks = np.asarray(ticks, dtype=np.int64)
        # u(t) = sqrt(2 / K) Σ_k cos(ω_k t + φ_k), ω_k ~ Cauchy(0, 1 / time): unit variance, correlation
        # exp(-|Δt| / time) (the spectral density of that kernel is the Cauchy's).
        local = np.empty((N, self._J, 3))
        fourier_sums(slots, ticks, np.lexsort((ticks, slots)), self._fourier, ANCHOR_TICKS, TRUTH_RATE_HZ, local)
        local *= self._amplitude_m[slots]  # (N, J, 3)
        if self._any_difficult:
            episode = np.empty((N, 1, 3))
            fourier_sums(slots, ticks, np.lexsort((ticks, slots)), self._episode, ANCHOR_TICKS, TRUTH_RATE_HZ,
                         episode)
            bad = episode[:, 0, 0] * math.sqrt(2.0 / _FEATURES) > self._episode_level  # (N,)
            local += self._gross_m[slots] * bad[:, None, None]
        world = np.empty((N, self._J, 3))
        segment_frames_to_world(np.ascontiguousarray(poses, dtype=np.float64), self._parent, self._torso, local,
                                self.lift_m, world)
        return world

    def _slots(self, person_ids: np.ndarray) -> np.ndarray:
        """Each person's row of the drawn constants, drawing them for people not seen before."""
        slot_of = self._slot_of
        new = [pid for pid in dict.fromkeys(person_ids.tolist()) if pid not in slot_of]
        if new:
            J = self._J
            fourier, scale = np.empty((len(new), J, 3, 4, _FEATURES)), np.empty((len(new), J, 3))
            episode, gross = np.zeros((len(new), 1, 3, 4, _FEATURES)), np.zeros((len(new), J, 3))
            difficult = is_difficult(np.array(new), self._rate, self._phase) if self._difficulty \
                else np.zeros(len(new), dtype=bool)
            for i, pid in enumerate(new):
                rng = np.random.default_rng([self._seed, pid])
                omega = rng.standard_cauchy((J, 3, _FEATURES))
                fourier[i, :, :, 0] = omega / self._time_s if self._time_s > 0 else 0.0
                fourier[i, :, :, 1] = rng.uniform(0.0, 2.0 * np.pi, (J, 3, _FEATURES))
                fourier[i, :, :, 2] = np.cos(fourier[i, :, :, 0] / TRUTH_RATE_HZ)
                fourier[i, :, :, 3] = np.sin(fourier[i, :, :, 0] / TRUTH_RATE_HZ)
                # Student-t scale mixture: N(0, 1) x sqrt(dof / chi2(dof)) is Student-t.
                scale[i] = np.sqrt(self._dof / rng.chisquare(self._dof, (J, 3))) if math.isfinite(self._dof) else 1.0
                if difficult[i]:
                    scale[i] *= self._difficult_scale
                    self._draw_difficulty(np.random.default_rng([self._seed, pid, _DIFFICULT_KEY]), episode[i],
                                          gross[i])
                slot_of[pid] = len(self._fourier) + i
            self._fourier = np.concatenate([self._fourier, fourier])
            self._episode = np.concatenate([self._episode, episode])
            self._gross_m = np.concatenate([self._gross_m, gross])
            self._any_difficult = self._any_difficult or bool(difficult.any())
            amplitude = self.std_m[None, :, None] * scale * math.sqrt(2.0 / _FEATURES)
            self._amplitude_m = np.concatenate([self._amplitude_m, amplitude])
        return np.array([slot_of[pid] for pid in person_ids.tolist()], dtype=np.int64)

    def _draw_difficulty(self, rng: np.random.Generator, episode: np.ndarray, gross: np.ndarray) -> None:
        """A difficult person's bad episodes' process (written into `episode`, (1, 3, 4, K)) and its chosen
        arm's gross error in the segment frames (into `gross`, (J, 3)): the wrist `difficult_error_m` away in a
        uniformly drawn direction, the elbow half as far in the same one."""
        omega = rng.standard_cauchy(_FEATURES)
        episode[0, 0, 0] = omega / self._time_s if self._time_s > 0 else 0.0
        episode[0, 0, 1] = rng.uniform(0.0, 2.0 * np.pi, _FEATURES)
        episode[0, 0, 2] = np.cos(episode[0, 0, 0] / TRUTH_RATE_HZ)
        episode[0, 0, 3] = np.sin(episode[0, 0, 0] / TRUTH_RATE_HZ)
        elbow, wrist = self._arms[int(rng.integers(2))]
        direction = rng.standard_normal(3)
        direction /= max(float(np.linalg.norm(direction)), 1e-12)
        if wrist >= 0:
            gross[wrist] = self._difficult_m * direction
        if elbow >= 0:
            gross[elbow] = 0.5 * self._difficult_m * direction


@jit
def fourier_sums(slots, ticks, order, fourier, anchor_ticks, rate_hz, out):
    """out[i, j, a] = Σ_k cos(ω_k t + φ_k) of row i's person (`slots[i]`, a row of `fourier`) at its tick
    (t = ticks[i] / rate_hz), for every joint j and axis a (`JointOffsets.offsets`).

    Each feature's (cos, sin) is evaluated at the anchor tick (ticks[i] // anchor_ticks) * anchor_ticks and
    turned by (cos, sin)(ω / rate_hz) once per tick from there. The rows are visited in `order` (by person,
    then tick), so a person's turns are shared by its rows of one anchor; the value of a row depends only on
    its person and tick.

    Args:
        slots, ticks: (N,) int64; order: (N,) the rows sorted by slot, then tick.
        fourier: (S, J, 3, 4, K) per person ω (rad/s), φ, cos(ω / rate_hz), sin(ω / rate_hz).
        out: (N, J, 3) written.
    """
    J, K = fourier.shape[1], fourier.shape[4]
    c = np.empty((J, 3, K))
    s = np.empty((J, 3, K))
    slot, at, anchor = -1, 0, -1
    for n in range(order.shape[0]):
        i = order[n]
        k = ticks[i]
        start = (k // anchor_ticks) * anchor_ticks
        if slots[i] != slot or start != anchor:
            slot, anchor, at = slots[i], start, start
            t = start / rate_hz
            for j in range(J):
                for a in range(3):
                    for f in range(K):
                        angle = fourier[slot, j, a, 0, f] * t + fourier[slot, j, a, 1, f]
                        c[j, a, f] = math.cos(angle)
                        s[j, a, f] = math.sin(angle)
        while at < k:
            for j in range(J):
                for a in range(3):
                    for f in range(K):
                        turn_c, turn_s = fourier[slot, j, a, 2, f], fourier[slot, j, a, 3, f]
                        cf = c[j, a, f]
                        c[j, a, f] = cf * turn_c - s[j, a, f] * turn_s
                        s[j, a, f] = s[j, a, f] * turn_c + cf * turn_s
            at += 1
        for j in range(J):
            for a in range(3):
                total = 0.0
                for f in range(K):
                    total += c[j, a, f]
                out[i, j, a] = total


@jit
def segment_frames_to_world(poses, parent, torso, local, lift_m, out):
    """out[n, j] = B_j local[n, j] + lift_m[j] z, B_j the frame of joint j's body segment in pose n, columns
    (along the segment, across the body, their cross): a limb joint's segment runs from its parent joint
    (parent[j] >= 0), the other joints take the torso's (mid-hip to mid-shoulder; torso: the left and right
    hip and shoulder joints). The identity where a frame cannot be built (no torso, a degenerate segment).

    Args:
        poses: (N, J, 3) the true poses, m; parent: (J,) int64; torso: (4,) int64 (-1: the layout lacks it).
        local: (N, J, 3) the offsets in the segment frames, m; lift_m: (J,) up the world's z, m.
        out: (N, J, 3) written, m.
    """
    N, J = poses.shape[0], poses.shape[1]
    lh, rh, ls, rs = torso[0], torso[1], torso[2], torso[3]
    has_torso = lh >= 0 and rh >= 0 and ls >= 0 and rs >= 0
    across = np.zeros(3)
    spine = np.zeros(3)
    a = np.empty(3)
    c = np.empty(3)
    for n in range(N):
        if has_torso:
            for x in range(3):
                across[x] = poses[n, lh, x] - poses[n, rh, x]  # the body's left
                spine[x] = (poses[n, ls, x] + poses[n, rs, x]) / 2 - (poses[n, lh, x] + poses[n, rh, x]) / 2
        for j in range(J):
            built = has_torso
            if built:
                for x in range(3):
                    a[x] = poses[n, j, x] - poses[n, parent[j], x] if parent[j] >= 0 else spine[x]
                norm = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
                built = norm > 0.0 and norm < math.inf
            if built:
                for x in range(3):
                    a[x] = a[x] / norm
                along = a[0] * across[0] + a[1] * across[1] + a[2] * across[2]
                for x in range(3):
                    c[x] = across[x] - along * a[x]
                norm = math.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
                built = norm > 0.0 and norm < math.inf
            if built:
                for x in range(3):
                    c[x] = c[x] / norm
                u, v, w = local[n, j, 0], local[n, j, 1], local[n, j, 2]
                out[n, j, 0] = a[0] * u + c[0] * v + (a[1] * c[2] - a[2] * c[1]) * w
                out[n, j, 1] = a[1] * u + c[1] * v + (a[2] * c[0] - a[0] * c[2]) * w
                out[n, j, 2] = a[2] * u + c[2] * v + (a[0] * c[1] - a[1] * c[0]) * w
            else:
                for x in range(3):
                    out[n, j, x] = local[n, j, x]
            out[n, j, 2] += lift_m[j]
