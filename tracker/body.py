"""A target's joints that no camera has triangulated yet, inferred from its own body: a mean body model fitted
to the joints it has (translation, heading and the scale of its known bones), and the per-joint state codes
of the output (observed, predicted, inferred)."""

from __future__ import annotations

import numpy as np

from core.jit import jit, sort_prefix
from core.types import Skeleton
from tracker.types import JointState

_OBSERVED, _PREDICTED, _INFERRED = JointState.OBSERVED.value, JointState.PREDICTED.value, JointState.INFERRED.value
# A standing adult in the body frame (x forward, y left, z up), metres, by joint name: the mean body the
# unseen joints are taken from (COCO-17 names, and the Campus/Shelf head joints).
MEAN_BODY_M = {
    "nose": (0.10, 0.00, 1.62), "left_eye": (0.08, 0.03, 1.66), "right_eye": (0.08, -0.03, 1.66),
    "left_ear": (0.02, 0.07, 1.64), "right_ear": (0.02, -0.07, 1.64),
    "left_shoulder": (0.00, 0.19, 1.42), "right_shoulder": (0.00, -0.19, 1.42),
    "left_elbow": (0.00, 0.23, 1.13), "right_elbow": (0.00, -0.23, 1.13),
    "left_wrist": (0.02, 0.24, 0.87), "right_wrist": (0.02, -0.24, 0.87),
    "left_hip": (0.00, 0.11, 0.93), "right_hip": (0.00, -0.11, 0.93),
    "left_knee": (0.02, 0.11, 0.50), "right_knee": (0.02, -0.11, 0.50),
    "left_ankle": (0.00, 0.11, 0.07), "right_ankle": (0.00, -0.11, 0.07),
    "bottom_head": (0.02, 0.00, 1.52), "top_head": (0.02, 0.00, 1.78),
}

HEAD_BONES = (("left_shoulder", "nose"), ("right_shoulder", "nose"))
"""The body prior's extra bones with `TrackerConfig.head_bones`: the person's own neck and head proportions."""

SCALE_RANGE = (0.8, 1.25)
"""The fitted body scale is clipped to this range of the mean body's."""


def mean_body(skeleton: Skeleton) -> np.ndarray:
    """(J, 3) the mean body in the skeleton's joint order, metres; a joint the model lacks sits at the hips'
    height on the body axis."""
    return np.array([MEAN_BODY_M.get(name, (0.0, 0.0, 0.93)) for name in skeleton.joints], dtype=np.float64)


def prior_bones(skeleton: Skeleton, head_bones: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The bones of the body prior (`kernels.BodyPrior`), each oriented from the end nearer the hips (its parent)
    to the other (its child) and ordered outward, and the mirror of each.

    Nearer: fewer bones from a hip over the skeleton's bones (and `HEAD_BONES` with `head_bones`), then from a
    shoulder for a part the hips do not reach (Campus-14's arms); a part reached from neither (COCO-17's face
    without `HEAD_BONES`) keeps the skeleton's own order and comes last.

    Returns:
        (B, 2) int64 (parent, child) joint pairs; (B,) int64 the row of the bone with left and right swapped in
        both joint names, -1 for none (the bones of the middle).
    """
    names = list(skeleton.joints)
    pairs = [tuple(int(j) for j in bone) for bone in skeleton.bones]
    if head_bones:
        pairs += [(names.index(a), names.index(b)) for a, b in HEAD_BONES if a in names and b in names]
    try:
        roots = list(skeleton.hips)
    except ValueError:
        roots = []
    depth: dict[int, int] = {}
    # From the hips; then a part they do not reach from its shoulders (Campus-14's arms), deeper than all before.
    for seeds in (roots, [j for j, n in enumerate(names) if "shoulder" in n]):
        start = max(depth.values(), default=-1) + 1
        frontier = [j for j in seeds if j not in depth]
        depth.update({j: start for j in frontier})
        while frontier:
            nxt = []
            for j in frontier:
                for a, b in pairs:
                    for u, v in ((a, b), (b, a)):
                        if u == j and v not in depth:
                            depth[v] = depth[j] + 1
                            nxt.append(v)
            frontier = nxt
    far = len(names) + 1
    oriented = [(a, b) if depth.get(a, far) <= depth.get(b, far) else (b, a) for a, b in pairs]
    oriented.sort(key=lambda bone: depth.get(bone[0], far))  # stable: the skeleton's order among equals
    bones = np.array(oriented, dtype=np.int64).reshape(-1, 2)
    swap = {n: n.replace("left", "\0").replace("right", "left").replace("\0", "right") for n in names}
    where = {frozenset((names[a], names[b])): i for i, (a, b) in enumerate(oriented)}
    mirror = np.array([where.get(frozenset((swap[names[a]], swap[names[b]])), -1) for a, b in oriented],
                      dtype=np.int64)
    mirror[mirror == np.arange(mirror.size)] = -1
    return bones, mirror


LIMB_END_JOINTS = ("wrist", "ankle")
"""Name parts of the joints at the ends of the arms and legs: `limb_velocity_window_s`'s joints."""


def velocity_windows(skeleton: Skeleton, config) -> np.ndarray:
    """(J,) each joint's window of eq. (5)'s velocity fit, s: `config.limb_velocity_window_s` for the joints
    named with a `LIMB_END_JOINTS` part when it is positive, `config.velocity_window_s` for the others."""
    limb = float(config.limb_velocity_window_s)
    return np.array([limb if limb > 0 and any(part in name for part in LIMB_END_JOINTS)
                     else float(config.velocity_window_s) for name in skeleton.joints], dtype=np.float64)


def fill_unknown(pose: np.ndarray, model: np.ndarray, bones: np.ndarray) -> np.ndarray:
    """The pose with its unknown (NaN) joints taken from the mean body fitted to its known joints.

    The fit: scale = median ratio of the known bones to the model's (clipped to SCALE_RANGE, 1 without a known
    bone); heading = the rotation about z that best aligns the model's known joints with the pose's in the
    floor plane (2D Procrustes; none with fewer than two known joints); translation = the difference of the
    means of the known joints. Known joints are returned unchanged.

    Args:
        pose: (J, 3) metres, NaN unknown; at least one joint known.
        model: (J, 3) `mean_body`; bones: (B, 2) int64 joint pairs.

    Returns:
        (J, 3) pose without NaN.
    """
    out = np.ascontiguousarray(pose, dtype=np.float64).copy()[None]
    fill_poses(out, np.ascontiguousarray(model, dtype=np.float64), np.ascontiguousarray(bones, dtype=np.int64))
    return out[0]


@jit
def fill_poses(poses, model, bones):
    """`fill_unknown` of every pose of (T, J, 3) in place (compiled kernel); poses without a known joint or
    without an unknown one are left as they are."""
    T, J, B = poses.shape[0], poses.shape[1], bones.shape[0]
    ratios = np.empty(max(B, 1))
    for t in range(T):
        count = 0
        for j in range(J):
            if np.isfinite(poses[t, j, 0] + poses[t, j, 1] + poses[t, j, 2]):
                count += 1
        if count == 0 or count == J:
            continue
        n = 0
        for b in range(B):
            a, e = bones[b, 0], bones[b, 1]
            if np.isfinite(poses[t, a, 0] + poses[t, a, 1] + poses[t, a, 2] + poses[t, e, 0] + poses[t, e, 1]
                           + poses[t, e, 2]):
                got = np.sqrt((poses[t, a, 0] - poses[t, e, 0]) ** 2 + (poses[t, a, 1] - poses[t, e, 1]) ** 2
                              + (poses[t, a, 2] - poses[t, e, 2]) ** 2)
                ref = np.sqrt((model[a, 0] - model[e, 0]) ** 2 + (model[a, 1] - model[e, 1]) ** 2
                              + (model[a, 2] - model[e, 2]) ** 2)
                ratios[n] = got / max(ref, 1e-6)
                n += 1
        scale = 1.0
        if n:
            sort_prefix(ratios, n)
            scale = min(max((ratios[(n - 1) // 2] + ratios[n // 2]) / 2.0, SCALE_RANGE[0]), SCALE_RANGE[1])
        sm0 = sm1 = sm2 = dm0 = dm1 = dm2 = 0.0
        for j in range(J):
            if np.isfinite(poses[t, j, 0] + poses[t, j, 1] + poses[t, j, 2]):
                sm0 += model[j, 0] * scale
                sm1 += model[j, 1] * scale
                sm2 += model[j, 2] * scale
                dm0 += poses[t, j, 0]
                dm1 += poses[t, j, 1]
                dm2 += poses[t, j, 2]
        sm0, sm1, sm2, dm0, dm1, dm2 = sm0 / count, sm1 / count, sm2 / count, dm0 / count, dm1 / count, dm2 / count
        cross = dot = 0.0
        if count >= 2:
            for j in range(J):
                if np.isfinite(poses[t, j, 0] + poses[t, j, 1] + poses[t, j, 2]):
                    s0, s1 = model[j, 0] * scale - sm0, model[j, 1] * scale - sm1
                    d0, d1 = poses[t, j, 0] - dm0, poses[t, j, 1] - dm1
                    cross += s0 * d1 - s1 * d0
                    dot += s0 * d0 + s1 * d1
        yaw = np.arctan2(cross, dot) if count >= 2 else 0.0
        c, sn = np.cos(yaw), np.sin(yaw)
        for j in range(J):
            if not np.isfinite(poses[t, j, 0] + poses[t, j, 1] + poses[t, j, 2]):
                x, y, z = model[j, 0] * scale - sm0, model[j, 1] * scale - sm1, model[j, 2] * scale - sm2
                poses[t, j, 0] = c * x - sn * y + dm0
                poses[t, j, 1] = sn * x + c * y + dm1
                poses[t, j, 2] = z + dm2


@jit
def joint_states(seen_s, known, stamp_s, stale_after_s):
    """(T, J) `JointState` codes: OBSERVED when triangulated within `stale_after_s` of `stamp_s`, PREDICTED when
    triangulated earlier (carried with the body since), INFERRED when never triangulated (`fill_unknown`).
    Compiled: the tracker calls it every frame.

    Args:
        seen_s: (T, J) last time each joint was triangulated from observations (-inf never); known: (T, J) whether
            the tracker holds an estimate of the joint.
    """
    codes = np.empty(seen_s.shape, dtype=np.uint8)
    for t in range(seen_s.shape[0]):
        for j in range(seen_s.shape[1]):
            if not known[t, j]:
                codes[t, j] = _INFERRED
            elif stamp_s - seen_s[t, j] <= stale_after_s:
                codes[t, j] = _OBSERVED
            else:
                codes[t, j] = _PREDICTED
    return codes
