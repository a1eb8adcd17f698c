"""Two-link leg inverse kinematics as a plain numpy function: the formula `sim.world`'s compiled pose kernel
applies per slot, checked here against MuJoCo's own kinematics."""

from __future__ import annotations

import math

import numpy as np

from sim.humanoid import MAX_LEG_STRETCH


def leg_ik(d: np.ndarray, thigh: np.ndarray, shin: np.ndarray, sign: float) -> tuple[np.ndarray, ...]:
    """Hip and knee angles that put the ankle at `d` from the hip (two-link inverse kinematics).

    Args:
        d: (..., 3) ankle target minus hip joint centre, in the pelvis frame, metres.
        thigh, shin: segment lengths, broadcastable against d[..., 0].
        sign: +1 for the left leg, -1 for the right (the abduction axis is mirrored); broadcastable too.

    Returns:
        hip_abd, hip_flex, knee: (...,) radians; a target out of reach gives the nearest reachable pose.
    """
    dx, dy, dz = d[..., 0], d[..., 1], d[..., 2]
    abd = sign * np.arctan2(dy, -dz)
    down = np.sqrt(dy * dy + dz * dz)
    r = np.minimum(np.maximum(np.sqrt(dx * dx + down * down), np.abs(thigh - shin) + 1e-6),
                   (thigh + shin) * MAX_LEG_STRETCH)
    # Law of cosines: the hip angle between thigh and hip-ankle line, and the knee's interior angle.
    flex = np.arctan2(dx, down) + np.arccos(np.minimum((thigh * thigh + r * r - shin * shin) / (2 * thigh * r), 1.0))
    knee = math.pi - np.arccos(np.maximum((thigh * thigh + shin * shin - r * r) / (2 * thigh * shin), -1.0))
    return abd, flex, knee
