"""The tracker's target arrays as one named value, the way its compiled kernels take them (`TargetRows`)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class TargetRows(NamedTuple):
    """The live targets' state that the kernels read and write in place, a row per target (T targets,
    C cameras, J joints, H history slots).

    The tracker's `_TargetRowStore` owns the arrays (and the lifecycle's own: ids, states, birth times) and hands out
    this tuple of their current views. numba compiles a NamedTuple of arrays as a struct of them, but its
    dispatch looks at every field on every call (a few tenths of a microsecond each), so the tuple holds only
    what the kernels use.

    Attributes:
        last_update_s: (T,) time of the last matched frame, s.
        num_updates: (T,) int64 matched frames so far.
        pos: (T, J, 3) X_t' per joint, m (NaN never triangulated).
        joint_s: (T, J) t', the time X_t' refers to, s (-inf never).
        seen_s: (T, J) last time the joint was triangulated from observations, s (-inf never).
        vel: (T, J, 3) V_t' per joint, m/s (eq. 5).
        obs_px: (T, C, J, 2) last matched undistorted joint per camera, pixels (eq. 2, 6).
        obs_s: (T, C, J) its stamp, s (NaN none).
        cam_s: (T, C) stamp of the last frame of each camera matched to the target, s (NaN none).
        hist_pos: (T, H, J, 3) ring buffer of past joint estimates for the velocity fit, m.
        hist_s: (T, H, J) their times, s (NaN empty).
        hist_next: (T,) int64 the ring's next slot.
        expected: (T,) decayed count of frames of cameras that should have seen the target.
        sighted: (T,) of those, decayed count of the frames that matched it.
        evidence_s: (T,) time of the last count, s.
        bone_samples: (T, K, B) ring buffer of the lengths of the body prior's B bones measured in the target's
            confident frames (`kernels.Priors`), m (NaN empty).
        bone_next: (T,) int64 that ring's next slot.
        bone_sampled_s: (T,) time of the last sample, s (-inf none).
        bone_len: (T, B) the person's bone lengths, the median of their samples (pooled with the mirror bone's
            with `bone_symmetry`), m; NaN until `bone_prior_min_samples` samples.
    """

    last_update_s: np.ndarray
    num_updates: np.ndarray
    pos: np.ndarray
    joint_s: np.ndarray
    seen_s: np.ndarray
    vel: np.ndarray
    obs_px: np.ndarray
    obs_s: np.ndarray
    cam_s: np.ndarray
    hist_pos: np.ndarray
    hist_s: np.ndarray
    hist_next: np.ndarray
    expected: np.ndarray
    sighted: np.ndarray
    evidence_s: np.ndarray
    bone_samples: np.ndarray
    bone_next: np.ndarray
    bone_sampled_s: np.ndarray
    bone_len: np.ndarray

    @staticmethod
    def empty(T: int, C: int, J: int, H: int, B: int = 0, K: int = 1) -> TargetRows:
        """T targets that nothing has been seen of yet (B bones of the body prior, K samples of each)."""
        return TargetRows(
            last_update_s=np.zeros(T), num_updates=np.zeros(T, dtype=np.int64), pos=np.full((T, J, 3), np.nan),
            joint_s=np.full((T, J), -np.inf), seen_s=np.full((T, J), -np.inf), vel=np.zeros((T, J, 3)),
            obs_px=np.full((T, C, J, 2), np.nan), obs_s=np.full((T, C, J), np.nan), cam_s=np.full((T, C), np.nan),
            hist_pos=np.full((T, H, J, 3), np.nan), hist_s=np.full((T, H, J), np.nan),
            hist_next=np.zeros(T, dtype=np.int64), expected=np.zeros(T), sighted=np.zeros(T),
            evidence_s=np.zeros(T), bone_samples=np.full((T, K, B), np.nan),
            bone_next=np.zeros(T, dtype=np.int64), bone_sampled_s=np.full(T, -np.inf), bone_len=np.full((T, B), np.nan))

    def copy(self) -> TargetRows:
        """A copy of every array (the kernels write in place)."""
        return TargetRows._make(array.copy() for array in self)
