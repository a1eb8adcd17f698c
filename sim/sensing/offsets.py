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
the world's up. Everything about a person is drawn from the person's id and the detector's seed alone, so the
offsets do not depend on which camera asks, in which process, or in which order.
"""

from __future__ import annotations

import math

import numpy as np

from core.types import Skeleton
from sim.sensing.draws import joint_groups
from sim.sensing.profiles import DetectorParams

_FEATURES = 6  # random Fourier features per axis: enough for a near-Gaussian marginal
_SIDES = ("left_", "right_")
_PARENT = {"elbow": "shoulder", "wrist": "elbow", "knee": "hip", "ankle": "knee"}


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
        self.active = bool(self.std_m.any() or self.lift_m.any())
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
        self._torso = tuple(index.get(n, -1) for n in ("left_hip", "right_hip", "left_shoulder", "right_shoulder"))
        self._slot_of: dict[int, int] = {}
        # Per person (a row each): the features' angular frequencies (rad/s) and phases, (S, J, 3, 2, K), and
        # each axis's amplitude (S, J, 3): offset_m x the person's Student-t scale x sqrt(2 / K).
        self._fourier = np.empty((0, self._J, 3, 2, _FEATURES))
        self._amplitude_m = np.empty((0, self._J, 3))

    def offsets(self, person_ids: np.ndarray, t_s: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """(N, J, 3) where the detector's joints lie relative to the truth's, metres (world frame).

        Args:
            person_ids: (N,) int64 the person of each pose (>= 0).
            t_s: (N,) the time of each pose, seconds.
            poses: (N, J, 3) the true poses, metres.
        """
        N = len(person_ids)
        if N == 0 or not self.active:
            return np.zeros((N, self._J, 3))
        slots = self._slots(person_ids)
        # u(t) = sqrt(2 / K) Σ_k cos(ω_k t + φ_k), ω_k ~ Cauchy(0, 1 / time): unit variance, correlation
        # exp(-|Δt| / time) (the spectral density of that kernel is the Cauchy's).
        fourier = self._fourier[slots]  # (N, J, 3, 2, K)
        angle = fourier[..., 0, :] * np.asarray(t_s, dtype=np.float64)[:, None, None, None]
        angle += fourier[..., 1, :]
        local = np.cos(angle, out=angle).sum(axis=-1) * self._amplitude_m[slots]  # (N, J, 3)
        world = np.einsum("njab,njb->nja", self._frames(np.asarray(poses, dtype=np.float64)), local)
        world[..., 2] += self.lift_m
        return world

    def _slots(self, person_ids: np.ndarray) -> np.ndarray:
        """Each person's row of the drawn constants, drawing them for people not seen before."""
        slot_of = self._slot_of
        new = [pid for pid in dict.fromkeys(person_ids.tolist()) if pid not in slot_of]
        if new:
            J = self._J
            fourier, scale = np.empty((len(new), J, 3, 2, _FEATURES)), np.empty((len(new), J, 3))
            for i, pid in enumerate(new):
                rng = np.random.default_rng([self._seed, pid])
                omega = rng.standard_cauchy((J, 3, _FEATURES))
                fourier[i, :, :, 0] = omega / self._time_s if self._time_s > 0 else 0.0
                fourier[i, :, :, 1] = rng.uniform(0.0, 2.0 * np.pi, (J, 3, _FEATURES))
                # Student-t scale mixture: N(0, 1) x sqrt(dof / chi2(dof)) is Student-t.
                scale[i] = np.sqrt(self._dof / rng.chisquare(self._dof, (J, 3))) if math.isfinite(self._dof) else 1.0
                slot_of[pid] = len(self._fourier) + i
            self._fourier = np.concatenate([self._fourier, fourier])
            amplitude = self.std_m[None, :, None] * scale * math.sqrt(2.0 / _FEATURES)
            self._amplitude_m = np.concatenate([self._amplitude_m, amplitude])
        return np.array([slot_of[pid] for pid in person_ids.tolist()], dtype=np.int64)

    def _frames(self, poses: np.ndarray) -> np.ndarray:
        """(N, J, 3, 3) each joint's segment frame, columns (along the segment, across the body, their cross):
        a limb joint's segment runs from its parent joint; the other joints take the torso's (mid-hip to
        mid-shoulder). The identity where a frame cannot be built (no torso, a degenerate segment)."""
        N, J = poses.shape[:2]
        frames = np.broadcast_to(np.eye(3), (N, J, 3, 3)).copy()
        lh, rh, ls, rs = self._torso
        if min(self._torso) < 0:
            return frames
        across = poses[:, lh] - poses[:, rh]  # (N, 3), the body's left
        along = np.broadcast_to(((poses[:, ls] + poses[:, rs]) / 2 - (poses[:, lh] + poses[:, rh]) / 2)[:, None],
                                (N, J, 3)).copy()
        limb = self._parent >= 0
        along[:, limb] = poses[:, limb] - poses[:, self._parent[limb]]
        a = along / np.linalg.norm(along, axis=-1, keepdims=True)
        c = across[:, None, :] - np.einsum("nja,na->nj", a, across)[..., None] * a
        c /= np.linalg.norm(c, axis=-1, keepdims=True)
        b = np.cross(a, c)
        built = np.stack([a, c, b], axis=-1)
        ok = np.isfinite(built).all(axis=(-1, -2))
        frames[ok] = built[ok]
        return frames
