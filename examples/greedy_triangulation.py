"""A per-frame greedy triangulation tracker: a complete plug-in for `crossview track --method` (docs/plugins.md).

On every frame it keeps the latest detections of each camera, then
1. matches each known person to at most one detection per camera, smallest mean reprojection distance first;
2. triangulates each person from the views matched to it (DLT, no motion model: views up to `WINDOW_S` apart
   are taken as one instant);
3. pairs the detections left over across cameras by mean epipolar distance, smallest first, and starts a
   person from each group of two or more views whose triangulation looks like a standing body.

    crossview track REC.mcap -o T.mcap --method examples.greedy_triangulation:GreedyTriangulationTracker
"""

from __future__ import annotations

import numpy as np

from tracker.geometry import fundamental_matrix, point_line_distance_px, project, undistort_points
from tracker.triangulation import triangulate
from tracker.types import Target, TrackerOutput

GATE_PX = 60.0  # mean reprojection distance under which a detection is a known person's, pixels
EPIPOLAR_GATE_PX = 25.0  # mean epipolar distance under which two detections are one person, pixels
WINDOW_S = 0.15  # a camera's latest detections are used while at most this old, seconds
MIN_JOINTS = 5  # joints a detection needs above the score threshold to be used
FORGET_S = 0.5  # a person not triangulated for this long is dropped, seconds
HEAD_HEIGHT_M = (1.0, 2.3)  # where the highest joint of a new person must be, metres


class GreedyTriangulationTracker:
    """Made as ``GreedyTriangulationTracker(cameras, config, skeleton)``; uses `config.score_threshold` only."""

    def __init__(self, cameras, config, skeleton):
        self.cameras = list(cameras)
        self.index = {camera.name: c for c, camera in enumerate(self.cameras)}
        self.P = np.stack([camera.P for camera in self.cameras])  # (C, 3, 4)
        self.F = {(a, b): fundamental_matrix(self.cameras[a], self.cameras[b])
                  for a in range(len(self.cameras)) for b in range(len(self.cameras)) if a != b}
        self.score_threshold = config.score_threshold
        self.num_joints = skeleton.num_joints
        self.latest: dict[int, tuple[float, np.ndarray, np.ndarray]] = {}  # camera -> (stamp, (D, J, 2), rows)
        self.people: dict[int, tuple[np.ndarray, float]] = {}  # id -> (pose (J, 3), last triangulated at)
        self.next_id = 0
        self.last_output = TrackerOutput(0.0, "", [], np.zeros(0, dtype=np.int64))

    def update(self, frame):
        t, c = frame.stamp_s, self.index[frame.camera]
        px = undistort_points(self.cameras[c], frame.keypoints_px)
        px[~(frame.scores >= self.score_threshold)] = np.nan
        rows = np.flatnonzero(np.isfinite(px[..., 0]).sum(axis=1) >= MIN_JOINTS)
        self.latest[c] = (t, px[rows], rows)
        views = [(cam, d) for cam, (s, pts, _) in self.latest.items() if t - s <= WINDOW_S for d in range(len(pts))]
        owner = self._match_people(views)
        self._triangulate(owner, t)
        self._start_people([v for v in views if v not in owner], owner, t)
        self.people = {p: (pose, seen) for p, (pose, seen) in self.people.items() if t - seen <= FORGET_S}
        assigned = np.full(frame.num_detections, -1, dtype=np.int64)
        for (cam, d), person in owner.items():
            if cam == c and person in self.people:
                assigned[rows[d]] = person
        targets = [Target(id=p, pose=pose.copy(), stamp_s=t) for p, (pose, _) in sorted(self.people.items())]
        self.last_output = TrackerOutput(t, frame.camera, targets, assigned)
        return targets

    def _points(self, view) -> np.ndarray:
        cam, d = view
        return self.latest[cam][1][d]  # (J, 2) undistorted pixels, NaN unused

    def _match_people(self, views) -> dict:
        """Greedy one-to-one matching of people to views (one view per camera per person) by reprojection."""
        if not self.people or not views:
            return {}
        people = list(self.people)
        poses = np.stack([self.people[p][0] for p in people])  # (T, J, 3)
        cams = np.array([cam for cam, _ in views])
        projected = project(self.P, poses)[cams]  # (N, T, J, 2): each person seen by each view's camera
        distances = np.linalg.norm(projected - np.stack([self._points(v) for v in views])[:, None], axis=-1)
        common = np.isfinite(distances)  # (N, T, J)
        mean = np.where(common, distances, 0.0).sum(axis=-1) / np.maximum(common.sum(axis=-1), 1)  # (N, T)
        n, k = np.nonzero((common.sum(axis=-1) >= MIN_JOINTS) & (mean < GATE_PX))
        owner, taken = {}, set()
        for i in np.argsort(mean[n, k], kind="stable"):  # smallest distance first
            view, person = views[n[i]], people[k[i]]
            if view not in owner and (person, view[0]) not in taken:
                owner[view] = person
                taken.add((person, view[0]))
        return owner

    def _triangulate(self, owner: dict, t: float) -> None:
        """Each matched person from its views (one DLT call for all), where at least `MIN_JOINTS` joints have
        two views; a joint with fewer keeps its last position."""
        people = sorted(set(owner.values()))
        if not people:
            return
        points = np.full((len(people), self.num_joints, len(self.cameras), 2), np.nan)  # (T, J, C, 2)
        for view, person in owner.items():
            points[people.index(person), :, view[0]] = self._points(view)
        for person, pose in zip(people, triangulate(self.P, points)):  # (J, 3) each, NaN below two views
            if np.isfinite(pose[:, 0]).sum() >= MIN_JOINTS:
                self.people[person] = (np.where(np.isfinite(pose), pose, self.people[person][0]), t)

    def _epipolar_px(self, u, v) -> float:
        a, b = self._points(u), self._points(v)
        ha = np.concatenate([a, np.ones((len(a), 1))], axis=1)
        hb = np.concatenate([b, np.ones((len(b), 1))], axis=1)
        d = point_line_distance_px(b, ha @ self.F[u[0], v[0]].T) + point_line_distance_px(a, hb @ self.F[v[0], u[0]].T)
        common = np.isfinite(d)
        return float(d[common].mean() / 2) if common.sum() >= MIN_JOINTS else np.inf

    def _start_people(self, free, owner: dict, t: float) -> None:
        """Groups the views no person took (one per camera, every pair under the epipolar gate), greedily."""
        pairs = sorted((self._epipolar_px(u, v), i, j) for i, u in enumerate(free) for j, v in enumerate(free)
                       if u[0] < v[0])
        group_of: dict[int, list[int]] = {}
        for distance, i, j in pairs:
            if distance >= EPIPOLAR_GATE_PX:
                break
            if i in group_of and j in group_of:
                continue
            group = group_of.get(i) or group_of.get(j) or []
            new = j if i in group_of else i
            if any(free[k][0] == free[new][0] or self._epipolar_px(free[k], free[new]) >= EPIPOLAR_GATE_PX
                   for k in group):
                continue
            for k in (i, j):
                if k not in group:
                    group.append(k)
                group_of[k] = group
        for group in {id(g): g for g in group_of.values()}.values():
            points = np.full((self.num_joints, len(self.cameras), 2), np.nan)
            for k in group:
                points[:, free[k][0]] = self._points(free[k])
            pose = triangulate(self.P, points)
            top = np.nanmax(pose[:, 2]) if np.isfinite(pose[:, 2]).sum() >= MIN_JOINTS else np.nan
            if HEAD_HEIGHT_M[0] <= top <= HEAD_HEIGHT_M[1]:
                self.people[self.next_id] = (pose, t)
                for k in group:
                    owner[free[k]] = self.next_id
                self.next_id += 1
