"""The all-pairs epipolar baseline of the supplement (Algorithm S1), with the Tracker's streaming API.

On every frame it re-associates the latest frame of each camera from scratch: epipolar affinity between all
pairs of detections of different cameras (eq. S2), graph partitioning (eq. S3-S5), and a triangulation of every
cluster of at least two views. Algorithm S1 has no identities; to give its output the tracker's shape, each
frame's poses are linked to the previous output by the Hungarian algorithm on mean joint distance (a pose
farther than `_LINK_DISTANCE_M` from all previous ones gets a new id). Every output target is CONFIRMED. As the
cross-view tracker's, its outputs hold no unknown joint: a joint this frame's cluster did not triangulate keeps
the identity's last estimate (PREDICTED), and one never triangulated is inferred from the pose's own body
(`tracker.body.fill_poses`, INFERRED); each target carries the per-joint states.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from core.types import COCO17, Camera, Frame, Skeleton, camera_index
from tracker import affinity as aff
from tracker.body import fill_poses, joint_states, mean_body
from tracker.config import TrackerConfig
from tracker.geometry import fundamental_matrix, undistort_points
from tracker.initialization import PlausibilityLimits, check_plausible, partition_graph, reconstruct
from tracker.triangulation import row_norm_code
from tracker.types import Target, TargetState, TrackerOutput

logger = logging.getLogger(__name__)

_LINK_DISTANCE_M = 0.5  # largest mean joint distance between consecutive poses of one identity
_DEFAULT_CONFIG = TrackerConfig()


class BaselineTracker:
    """Algorithm S1 over the latest frame of each camera, same API as `tracker.Tracker`.

    Args:
        cameras: the calibrated cameras; config: parameters (alpha_epipolar_px, init_window_s, init_* limits,
            lambda_t_per_s, score_threshold, lost_after_s are used); skeleton: the joint layout.
    """

    def __init__(self, cameras: Sequence[Camera], config: TrackerConfig = _DEFAULT_CONFIG,
                 skeleton: Skeleton = COCO17):
        self._index = camera_index(cameras, "BaselineTracker")
        self.cameras = list(cameras)
        self.config = config
        self.skeleton = skeleton
        C, J = len(cameras), skeleton.num_joints
        self._P = np.stack([c.P for c in cameras]) if C else np.zeros((0, 3, 4))
        self._reconstruction_row_norm = row_norm_code(config, reconstruction=True)
        self._F = {(a, b): fundamental_matrix(cameras[a], cameras[b]) for a in range(C) for b in range(C) if a != b}
        self._latest_px: list[np.ndarray] = [np.zeros((0, J, 2)) for _ in range(C)]
        self._latest_s = np.full(C, -np.inf)
        self._newest_s = -np.inf
        self._limits = PlausibilityLimits(config.init_max_reprojection_px, config.init_min_joints_3d,
                                          config.init_max_bone_m, config.init_min_top_m, config.init_max_top_m,
                                          config.init_min_bottom_m)
        self._prev_ids = np.zeros(0, dtype=np.int64)
        self._prev_poses = np.zeros((0, J, 3))
        self._prev_s = np.zeros(0)
        self._prev_seen = np.zeros((0, J))  # (N, J) when each joint of an identity was last triangulated
        self._mean_body = mean_body(skeleton)
        self._bones = np.ascontiguousarray(np.asarray(skeleton.bones, dtype=np.int64).reshape(-1, 2))
        self._next_id = 0
        self.last_output = TrackerOutput(0.0, "", [], np.zeros(0, dtype=np.int64))

    def update(self, frame: Frame) -> list[Target]:
        """Processes one camera frame and returns the poses of the current clusters at `frame.stamp_s`."""
        D, J = frame.keypoints_px.shape[0], self.skeleton.num_joints
        if D and frame.keypoints_px.shape[1] != J:
            raise ValueError(f"Frame {frame.camera}@{frame.stamp_s}: {frame.keypoints_px.shape[1]} joints, "
                             f"the skeleton {self.skeleton.name} has {J}")
        assigned = np.full(D, -1, dtype=np.int64)
        t = float(frame.stamp_s)
        c = self._index.get(frame.camera)
        if c is None or not np.isfinite(t) or t <= self._latest_s[c] or t < self._newest_s - self.config.max_lateness_s:
            logger.warning("baseline: dropping frame %s@%s (unknown camera, bad or stale stamp)", frame.camera, t)
            self.last_output = TrackerOutput(t if np.isfinite(t) else 0.0, frame.camera, [], assigned)
            return []
        self._newest_s = max(self._newest_s, t)
        scores = np.clip(np.nan_to_num(frame.scores, nan=0.0), 0.0, 1.0)
        ok = np.all(np.isfinite(frame.keypoints_px), axis=-1) & (scores >= self.config.score_threshold) & (scores > 0)
        kp = np.where(ok[..., None], frame.keypoints_px, np.nan) if D else np.zeros((0, J, 2))
        self._latest_px[c] = undistort_points(self.cameras[c], kp)
        self._latest_s[c] = t

        cams = [k for k in range(len(self.cameras))
                if self._latest_px[k].shape[0] and abs(t - self._latest_s[k]) <= self.config.init_window_s]
        node_cam = np.concatenate([np.full(self._latest_px[k].shape[0], k) for k in cams]) if cams else np.zeros(0, int)
        node_pos = np.concatenate([np.arange(self._latest_px[k].shape[0]) for k in cams]) if cams else np.zeros(0, int)
        offsets = np.concatenate([[0], np.cumsum([self._latest_px[k].shape[0] for k in cams])]).astype(int)
        A = np.full((node_cam.size, node_cam.size), -np.inf)
        for ia, ka in enumerate(cams):
            for ib in range(ia + 1, len(cams)):
                kb = cams[ib]
                block = aff.epipolar_affinity(self._latest_px[ka], self._latest_px[kb], self._F[(ka, kb)],
                                              self.config.alpha_epipolar_px, self.config.init_min_common_joints)
                A[offsets[ia]:offsets[ia + 1], offsets[ib]:offsets[ib + 1]] = block
                A[offsets[ib]:offsets[ib + 1], offsets[ia]:offsets[ia + 1]] = block.T
        poses, members = [], []
        for cluster in partition_graph(A, self.config.milp_max_nodes):
            if cluster.size < self.config.min_views:
                continue
            ks, ds = node_cam[cluster], node_pos[cluster]
            pts = np.stack([self._latest_px[k][d] for k, d in zip(ks, ds)])
            pose = reconstruct(self._P[ks], pts, self._latest_s[ks], t, self.config.lambda_t_per_s,
                               self.config.min_views, self._reconstruction_row_norm)
            if check_plausible(pose, self._P[ks], pts, self.skeleton, self._limits) is None:
                poses.append(pose)
                members.append(ds[ks == c])
        ids, seen_s = self._link(poses, t)
        for new_id, dets in zip(ids, members):
            assigned[dets] = new_id
        out = np.stack(poses) if poses else np.zeros((0, J, 3))
        codes = joint_states(seen_s, np.isfinite(out[..., 0]), t, self.config.stale_after_s)
        fill_poses(out, self._mean_body, self._bones)  # (a copy: the identities keep what was triangulated)
        targets = [Target(int(i), p, t, TargetState.CONFIRMED, code) for i, p, code in zip(ids, out, codes)]
        self.last_output = TrackerOutput(t, frame.camera, targets, assigned)
        return targets

    def _link(self, poses: list[np.ndarray], t: float) -> tuple[list[int], np.ndarray]:
        """Identity of each pose: Hungarian match to the recent previous poses on mean joint distance.

        Fills, in place, the joints of a linked pose that are NaN with that identity's previous estimate.

        Returns:
            the ids, and (N, J) when each joint of each pose was last triangulated (-inf: never).
        """
        recent = (t - self._prev_s) <= self.config.lost_after_s
        prev_ids, prev_poses, prev_s = self._prev_ids[recent], self._prev_poses[recent], self._prev_s[recent]
        prev_seen = self._prev_seen[recent]
        seen = np.where(np.isfinite(np.stack(poses)[..., 0]), t, -np.inf) if poses else prev_seen[:0]
        ids = [-1] * len(poses)
        if poses and prev_ids.size:
            dist = np.linalg.norm(np.stack(poses)[:, None] - prev_poses[None], axis=-1)  # (N, Tp, J)
            shared = np.isfinite(dist)  # joints both poses hold; none shared: no link (NaN, not a warning)
            with np.errstate(invalid="ignore", divide="ignore"):
                mean = np.where(shared, dist, 0.0).sum(axis=-1) / shared.sum(axis=-1)
            cost = np.where(np.isfinite(mean), mean, 1e6)
            rows, cols = linear_sum_assignment(cost)
            for r, col in zip(rows, cols):
                if cost[r, col] < _LINK_DISTANCE_M:
                    ids[r] = int(prev_ids[col])
                    # A joint this frame's clusters did not triangulate keeps its last estimate, as the
                    # cross-view tracker's joints do (a once-known joint never turns NaN).
                    poses[r] = np.where(np.isfinite(poses[r]), poses[r], prev_poses[col])
                    seen[r] = np.maximum(seen[r], prev_seen[col])
        for i, value in enumerate(ids):
            if value < 0:
                ids[i] = self._next_id
                self._next_id += 1
        keep = ~np.isin(prev_ids, ids)
        self._prev_ids = np.concatenate([prev_ids[keep], np.asarray(ids, dtype=np.int64)])
        self._prev_poses = np.concatenate([prev_poses[keep], np.stack(poses) if poses else prev_poses[:0]])
        self._prev_s = np.concatenate([prev_s[keep], np.full(len(poses), t)])
        self._prev_seen = np.concatenate([prev_seen[keep], seen])
        return ids, seen
