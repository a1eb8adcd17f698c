"""The synthetic 2D detector: projection, visibility, occlusion, noise, misses and false positives.

For a block of captures (`sim.simulate`), `Detector.block_visibility` (steps 1-2), `Detector.detection_rows_of`
(step 3) and `Detector.frames_from_rows` turn the true 3D poses at each camera's capture time into the frame
a bottom-up 2D pose detector (OpenPose-like) would deliver, plus the truth behind every row:

1. project every keypoint with the camera's lens model; joints behind the camera or outside the
   image are not detectable;
2. cast one ray per remaining keypoint from the camera centre against the MuJoCo bodies (compiled
   loops with MuJoCo's own ray formulas, the hits bit for bit those of `mujoco.mj_multiRay`, which
   tests/reference/rays.py calls as the reference): the first surface it meets tells whether the joint
   is visible, occluded (a shelf, a wall, another person) or self-occluded (another limb of the same
   person);
3. miss whole people (more often the more they are occluded), drop occluded joints, add noise
   scaled by the person's size in the image (heavy tailed, larger on occluded joints), gross errors,
   left/right swaps and fragments, then add duplicates and phantom skeletons.

Every effect has its own knob in [detector]; a knob left unset takes the value of the profile.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from core.projection import in_image_many_kernel, monotonic_radius
from core.records import CameraFrame, DetectionEffect, DetectionRows
from core.truth import tick_of
from core.types import COCO17, Camera, Skeleton
from sim.sensing.draws import (
    FRAGMENTS_COCO17,
    MIN_SCORE,
    TEMPLATE_COCO17,
    DrawnRows,
    DrawState,
    DrawTables,
    Views,
    draw_detections,
    frame_order,
    joint_groups,
    large_enough,
    left_right_permutation,
    person_size_px,
)
from sim.sensing.offsets import JointOffsets
from sim.sensing.profiles import DetectorConfig
from sim.sensing.rays import RAY_GEOM_TYPES, KeypointRays, RayHits, RayModel, Scenes, cast_keypoint_rays, count_views

_SCENE_ROWS = 64  # ticks per buffer of `Detector.scene_now` (about 7 blocks of store_layout2)


class _SceneBuffer:
    """Rows of geom positions (_SCENE_ROWS, G, 3) and rotations (_SCENE_ROWS, G, 9) that `scene_now` fills tick
    by tick; `used` rows are handed out, and once `retire` is set the next tick starts a new buffer (this one
    stays with the ticks that still hold rows of it)."""

    def __init__(self, G: int):
        self.pos = np.empty((_SCENE_ROWS, G, 3))
        self.mat = np.empty((_SCENE_ROWS, G, 9))
        self.used = 0
        self.retire = False


class SceneTick(NamedTuple):
    """What the ray caster needs of the bodies at one truth tick (`Detector.scene_now`).

    Attributes:
        xpos: (G, 3) geom positions, metres; xmat: (G, 9) geom rotations (row-major).
        size: (G, 3) geom sizes; rbound: (G,) bounding radii; owner: (G,) person of each geom (-1: store).
        buffer: the `_SceneBuffer` whose row `row` holds xpos and xmat (None: live arrays of the world).
        row: that row (-1 without a buffer).
    """

    xpos: np.ndarray
    xmat: np.ndarray
    size: np.ndarray
    rbound: np.ndarray
    owner: np.ndarray
    buffer: object
    row: int


class Detector:
    """A synthetic 2D pose detector for a rig of cameras.

    Args:
        config: the [detector] section.
        cameras: the rig.
        rng: the "detector" generator.
        skeleton: the keypoint layout of the poses (COCO-17).
    """

    def __init__(self, config: DetectorConfig, cameras: list[Camera], rng: np.random.Generator,
                 skeleton: Skeleton = COCO17):
        self.config = config
        self.params = config.params()
        self.cameras = list(cameras)
        self.skeleton = skeleton
        self._rng = rng
        coco = skeleton.name == COCO17.name
        self._fragments = FRAGMENTS_COCO17 if coco else tuple(
            tuple(range(s, min(s + 4, skeleton.num_joints))) for s in range(0, skeleton.num_joints, 4)
        )
        self._fragment_masks = np.zeros((len(self._fragments), skeleton.num_joints), dtype=bool)
        for i, part in enumerate(self._fragments):
            self._fragment_masks[i, list(part)] = True
        self._tables = DrawTables(self._fragment_masks, joint_groups(skeleton), left_right_permutation(skeleton))
        # The detector's own joints (offset from the truth's); their seed is the detector stream's first draw.
        self.offsets = JointOffsets(self.params, skeleton, int(rng.integers(2**62)))
        # What the draws remember per (camera, person): `_slot_of` maps person id x cameras + camera to a row.
        self._state = DrawState.empty(256, skeleton.num_joints)
        self._slot_of: dict[int, int] = {}
        self._template = TEMPLATE_COCO17 if coco else None
        self._centres = [np.ascontiguousarray(c.center_world) for c in self.cameras]
        self._scene_of = None  # the world `_scene_cache` was made of
        self._scene_buffer: _SceneBuffer | None = None  # where `scene_now` writes the next tick's geoms
        self._points_buf: np.ndarray | None = None  # `block_visibility`'s keypoints, reused block to block
        self._ray_held: tuple | None = None  # `_ray_scratch`'s arrays
        self._centre_array = np.array(self._centres, dtype=np.float64).reshape(-1, 3)
        # Per-camera constants stacked for projecting the captures of one truth tick at once.
        self._R = np.array([c.R_cam_from_world for c in self.cameras], dtype=np.float64).reshape(-1, 3, 3)
        self._t = np.array([c.t_cam_from_world for c in self.cameras], dtype=np.float64).reshape(-1, 3)
        self._K = np.array([c.K for c in self.cameras], dtype=np.float64).reshape(-1, 3, 3)
        self._dist = np.array([c.dist for c in self.cameras], dtype=np.float64).reshape(-1, 5)
        self._size = np.array([(c.width_px, c.height_px) for c in self.cameras], dtype=np.float64).reshape(-1, 2)
        self._max_radius = np.array([monotonic_radius(c.dist) for c in self.cameras], dtype=np.float64)
        # Which cameras have tangential distortion and skew (`in_image_many` adds those terms for a batch
        # only when some camera of it has them).
        self._tangential = [bool(np.any(d[2:4])) for d in self._dist]
        self._skew = [bool(k[0, 1]) for k in self._K]
        # Per camera: the size in pixels below which nobody is detected (min_person_frac of the image height).
        self.min_size_px = self.params.min_person_frac * self._size[:, 1]
        # Per camera: joints in the image, occluded, self-occluded (all person views no smaller than
        # min_size_px, detected or not).
        self.visibility_counts = np.zeros((len(self.cameras), 3), dtype=np.int64)

    def scene_now(self, world, copy: bool = True) -> SceneTick | None:
        """What rays need of `world`'s bodies now (None when occlusion is off), copied unless `copy` is False.

        The copies are cheap: the positions and rotations go to the next row of a `_SceneBuffer` (consecutive
        ticks' rows are then one slice for `block_visibility`, no stacking), and the sizes, radii and
        owners are `World.ray_geom_constants`'s read-only snapshots, shared by every tick until they
        change. Treat every array returned as read-only."""
        if world is None or not self.config.occlusion:
            return None
        self._scene(world)
        model, data = world.model, world.data
        if not copy:
            return SceneTick(data.geom_xpos, data.geom_xmat.reshape(-1, 9), model.geom_size, model.geom_rbound,
                             np.asarray(world.geom_person_ids(), dtype=np.int64), None, -1)
        size, rbound, owner = world.ray_geom_constants()
        xpos = data.geom_xpos
        buffer = self._scene_buffer
        if buffer is None or buffer.used == _SCENE_ROWS or buffer.pos.shape[1] != xpos.shape[0] or buffer.retire:
            buffer = self._scene_buffer = _SceneBuffer(xpos.shape[0])
        i = buffer.used
        buffer.pos[i] = xpos
        buffer.mat[i] = data.geom_xmat.reshape(-1, 9)
        buffer.used += 1
        return SceneTick(buffer.pos[i], buffer.mat[i], size, rbound, owner, buffer, i)

    def _scene_arrays(self, scenes: list[SceneTick]) -> Scenes:
        """The `scene_now` snapshots of several ticks as the ray caster takes them: positions (T, G, 3) and
        rotations (T, G, 9) (a slice of the buffer when `scene_now` wrote them to consecutive rows), the
        distinct sizes (U, G, 3), radii (U, G) and owners (U, G), and per tick its index in those (T,)."""
        T = len(scenes)
        first = scenes[0]
        buffer = first.buffer
        if buffer is not None and first.row + T <= buffer.used and all(
                scene.buffer is buffer and scene.row == first.row + i for i, scene in enumerate(scenes)):
            xpos, xmat = buffer.pos[first.row:first.row + T], buffer.mat[first.row:first.row + T]
            if buffer is self._scene_buffer and first.row + T == buffer.used and buffer.used > _SCENE_ROWS - 16:
                buffer.retire = True  # the next block starts a new buffer rather than straddle two
        else:
            xpos = np.stack([scene.xpos for scene in scenes])
            xmat = np.stack([scene.xmat for scene in scenes]).reshape(T, -1, 9)
        # The constant parts, once per distinct (sizes, radii, owners) triple (told apart by identity: the
        # world hands out the same snapshots until they change).
        distinct: list[SceneTick] = []
        const_of = np.empty(T, dtype=np.int64)
        for i, scene in enumerate(scenes):
            for u, seen in enumerate(distinct):
                if seen.size is scene.size and seen.rbound is scene.rbound and seen.owner is scene.owner:
                    const_of[i] = u
                    break
            else:
                const_of[i] = len(distinct)
                distinct.append(scene)
        size, rbound, owner = (np.stack([getattr(scene, k) for scene in distinct]) for k in ("size", "rbound", "owner"))
        return Scenes(xpos, xmat, size, rbound, owner.astype(np.int64, copy=False), const_of)

    def _ray_scratch(self, R: int, N: int, T: int, K: int) -> tuple:
        """Scratch arrays for the ray caster, kept between blocks (new ones of this size each block cost
        page faults): hit geoms (R, N) int32 and distances (R, N) (written, not read here), and the geom
        and group boxes (T, G + K, 6)."""
        G = len(self._scene_cache.geom_type)
        held = self._ray_held
        if held is None or held[0].size < R * N or held[2].shape[0] < T or held[2].shape[1] != G + K:
            size = max(R * N, 64 * 32 * 17)
            held = self._ray_held = (np.empty(size, dtype=np.int32), np.empty(size), np.empty((max(T, 16), G + K, 6)))
        return held[0][:R * N].reshape(R, N), held[1][:R * N].reshape(R, N), held[2][:T]

    def block_visibility(self, requests, scenes: list | None, scene_of: list[int]) -> tuple:
        """Projection and occlusion of the captures of several truth ticks, in two compiled passes.

        Args:
            requests: the captures (`Capture`); every pose (P, J, 3).
            scenes: `scene_now` of each tick (None: no ray casting), the world of the latest `_scene` call.
            scene_of: per request, the index of its tick in `scenes`; requests of one tick are one batch
                (the tangential and skew terms of the lens are added for a batch when a camera of it has them).

        Returns:
            Every request's people in turn: px (sum P, J, 2), in_img, occluded, self_occluded (sum P, J) and
            found_px (sum P, J, 2), the detector's own joints (`JointOffsets`) projected, for the people it may
            detect (NaN for the others); the occlusion flags of people smaller than the camera's `min_size_px`
            are False (no rays: they make no detection).
        """
        J = self.skeleton.num_joints
        n_req = len(requests)
        cams = np.array([r.camera for r in requests], dtype=np.int64)
        counts = [len(r.poses.person_ids) for r in requests]
        most = max(counts)
        N = most * J
        if min(counts) == most:
            # Into a buffer kept between blocks (the points never leave this call): a new array each block
            # cost page faults.
            if self._points_buf is None or self._points_buf.shape[0] < n_req or self._points_buf.shape[1] != N:
                self._points_buf = np.empty((max(n_req, 64), N, 3))
            points = self._points_buf[:n_req]
            np.concatenate([r.poses.poses for r in requests], out=points.reshape(n_req * most, J, 3))
            ids = np.concatenate([r.poses.person_ids for r in requests]).astype(np.int64, copy=False)
            ids = ids.reshape(n_req, most)
        else:  # someone arrived or left between two captures: pad with NaN (never in view)
            points = np.full((n_req, N, 3), np.nan)
            ids = np.full((n_req, most), -1, dtype=np.int64)
            for i, r in enumerate(requests):
                points[i, :counts[i] * J] = np.asarray(r.poses.poses, dtype=np.float64).reshape(-1, 3)
                ids[i, :counts[i]] = r.poses.person_ids
        cam_list = cams.tolist()
        batch_tangential, batch_skew = {}, {}
        for c, k in zip(cam_list, scene_of):
            batch_tangential[k] = batch_tangential.get(k, False) or self._tangential[c]
            batch_skew[k] = batch_skew.get(k, False) or self._skew[c]
        tangential = np.array([batch_tangential[k] for k in scene_of])
        skew = np.array([batch_skew[k] for k in scene_of])
        px = np.empty((n_req, N, 2))
        in_img = np.empty((n_req, N), dtype=bool)
        in_image_many_kernel(self._R, self._t, self._K, self._dist, self._size, self._max_radius, points, cams,
                             tangential, skew, px, in_img)
        occluded = np.zeros((n_req, N), dtype=bool)
        self_occluded = np.zeros((n_req, N), dtype=bool)
        cast = in_img
        if self.params.min_person_frac > 0:
            # No rays for the people too small to detect (`draw_detections` drops them): far across a large
            # store they are most of the views.
            large = large_enough(px.reshape(n_req * most, J, 2), np.repeat(self.min_size_px[cams], most))
            cast = in_img & np.repeat(large.reshape(n_req, most), J, axis=1)
        if scenes is not None and cast.any():
            model = self._scene_cache
            geomid, dist, bounds = self._ray_scratch(n_req, N, len(scenes), len(model.groups) - 1)
            rays = KeypointRays(self._centre_array[cams], points, cast, ids, np.asarray(scene_of, dtype=np.int64), cams)
            cast_keypoint_rays(rays, model, self._scene_arrays(scenes), float(self.config.self_hit_margin_m),
                               RayHits(occluded, self_occluded, geomid, dist), self.visibility_counts, bounds)
        else:
            count_views(cams, cast, occluded, self_occluded, self.visibility_counts)
        found = px
        if self.offsets.active:
            # The detector's own joints, for the person-views it may detect (the others take no draw: they keep
            # the truth's pixels), each view projected as a capture of its own. A person's offset is one world
            # vector per truth tick, shared by every camera capturing in that tick: the offset of the tick's
            # time, turned with the pose at its first capture (the captures of a tick lie within
            # 1 / TRUTH_RATE_HZ of each other, against the offset's `offset_time_s` of seconds).
            r_idx, p_idx = np.nonzero(cast.reshape(n_req, most, J).any(axis=2))
            found = px.copy()
            if len(r_idx):
                true = points.reshape(n_req, most, J, 3)[r_idx, p_idx]
                person = ids[r_idx, p_idx]
                tick_person = np.stack([np.asarray(scene_of, dtype=np.int64)[r_idx], person], axis=1)
                _, first, shared = np.unique(tick_person, axis=0, return_index=True, return_inverse=True)
                ticks = tick_of(np.array([r.capture_s for r in requests])[r_idx[first]])
                shifted = true + self.offsets.offsets(person[first], ticks, true[first])[shared.ravel()]
                views_px = np.empty((len(r_idx), J, 2))
                in_image_many_kernel(self._R, self._t, self._K, self._dist, self._size, self._max_radius, shifted,
                                     cams[r_idx], tangential[r_idx], skew[r_idx], views_px,
                                     np.empty((len(r_idx), J), dtype=bool))
                found.reshape(n_req, most, J, 2)[r_idx, p_idx] = views_px
        px, found = px.reshape(n_req, most, J, 2), found.reshape(n_req, most, J, 2)
        in_img, occluded, self_occluded = (a.reshape(n_req, most, J) for a in (in_img, occluded, self_occluded))
        if min(counts) == most:
            return (px.reshape(-1, J, 2), in_img.reshape(-1, J), occluded.reshape(-1, J),
                    self_occluded.reshape(-1, J), found.reshape(-1, J, 2))
        return tuple(np.concatenate([a[i, :P] for i, P in enumerate(counts)])
                     for a in (px, in_img, occluded, self_occluded, found))

    def _scene(self, world) -> RayModel:
        """What the ray caster needs of `world` that does not change while it runs (cached per world):
        (J, 2) body and parent body of each keypoint and, per geom, its body within its person, its type
        and the groups of geoms that move together (`World.geom_groups`)."""
        if self._scene_of is not world:
            bodies = np.asarray(world.keypoint_body_ids(), dtype=np.int64)
            if bodies.shape != (self.skeleton.num_joints,):
                raise ValueError(f"World.keypoint_body_ids(): expected ({self.skeleton.num_joints},), "
                                 f"got {bodies.shape}")
            parents = np.asarray(world.keypoint_parent_body_ids(), dtype=np.int64)
            geom_type = np.asarray(world.model.geom_type, dtype=np.int64)
            unsupported = sorted(set(geom_type.tolist()) - set(RAY_GEOM_TYPES))
            if unsupported:
                raise ValueError(f"world geoms: mjtGeom types {unsupported} are not supported by the keypoint ray "
                                 "caster (spheres, capsules, ellipsoids, cylinders and boxes are)")
            self._scene_cache = RayModel(np.ascontiguousarray(np.stack([bodies, parents], axis=1)),
                                         np.asarray(world.geom_body_ids(), dtype=np.int64), geom_type,
                                         np.asarray(world.geom_groups(), dtype=np.int64))
            self._scene_of = world
        return self._scene_cache

    def detection_rows_of(self, requests, px, in_img, occluded, self_occluded, found_px=None,
                          person_ids: list | None = None) -> tuple[DetectionRows, np.ndarray]:
        """`detection_rows` from the requests' visibility as `block_visibility` returns it (every request's
        people in turn; found_px None: the detector's joints are the true ones); person_ids: each request's
        people (None: its poses' ids), where the requests came without their poses.

        The requests of successive calls must come in capture-time order per camera: the draws remember each
        camera's errors and misses per person (`DrawState`)."""
        if not requests:
            return DetectionRows.empty(self.skeleton.num_joints), np.zeros(1, dtype=np.int64)
        if person_ids is None:
            person_ids = [r.poses.person_ids for r in requests]
        ids = np.concatenate(person_ids).astype(np.int64, copy=False)
        group = np.repeat(np.arange(len(requests)), [len(p) for p in person_ids])
        cams = np.array([r.camera for r in requests], dtype=np.int64)
        capture_s = np.array([r.capture_s for r in requests], dtype=np.float64)
        views = Views(ids, px, px if found_px is None else found_px, in_img, occluded, self_occluded, group,
                      np.ascontiguousarray(self.min_size_px[cams][group], dtype=np.float64),
                      self._slots(ids, cams[group]), capture_s[group])
        rows = self._detections(views)
        # Phantom skeletons: a Poisson number per frame (drawn for all frames at once), appended as rows.
        n_phantoms = self._rng.poisson(self.params.phantom_rate, len(requests))
        if n_phantoms.any() and self._template is not None:
            group = np.repeat(np.arange(len(requests)), n_phantoms)
            extra = self._phantoms(cams[group])
            keep = extra[0]
            extra = [e[keep] for e in extra[1:]] + [group[keep].astype(rows[-1].dtype)]
            rows = [np.concatenate([r, e]) for r, e in zip(rows, extra)]
        # Each frame's rows in a random order: sort by frame, then by a uniform key.
        order = np.empty(rows[-1].shape[0], dtype=np.int64)
        frame_order(rows[-1].astype(np.int64, copy=False), self._rng.random(rows[-1].shape[0]), len(requests), order)
        rows = [r[order] for r in rows]
        return DetectionRows(*rows[:-1]), np.searchsorted(rows[-1], np.arange(len(requests) + 1))

    def frames_from_rows(self, requests, rows: DetectionRows, bounds: np.ndarray) -> list[CameraFrame]:
        """The frames of `requests` from their `detection_rows` (no randomness: any process can do it)."""
        if not requests:
            return []
        bounds = bounds.tolist()
        frames = []
        for i, r in enumerate(requests):
            frames.append(CameraFrame.from_rows(self.cameras[r.camera].name, r.stamp_s, r.capture_s, r.delivery_s,
                                                rows, bounds[i], bounds[i + 1], r.poses))
        return frames

    def _slots(self, person_ids: np.ndarray, cams: np.ndarray) -> np.ndarray:
        """(P,) the `DrawState` row of each (person, camera) pair, new rows for pairs not seen before."""
        C = len(self.cameras)
        slot_of = self._slot_of
        keys = (person_ids * C + cams).tolist()
        for key in keys:
            if key not in slot_of:
                slot_of[key] = len(slot_of)
        if len(slot_of) > self._state.noise.shape[0]:  # grow by doubling, keeping what is remembered
            old = self._state
            grown = DrawState.empty(2 * len(slot_of), self.skeleton.num_joints)
            for kept, new in zip(old, grown):
                new[:len(kept)] = kept
            self._state = grown
        return np.array([slot_of[k] for k in keys], dtype=np.int64)

    def _detections(self, views: Views):
        """The detections of real people, drawn by one compiled loop (`draw_detections`; rows: people
        detected, then duplicates).

        Returns:
            ids (D,), keypoints (D, J, 2), scores (D, J), true px (D, J, 2), in_image, occluded,
            self_occluded (D, J), effects (D,), group (D,).
        """
        P, J = views.in_img.shape
        out = DrawnRows(np.empty(2 * P, dtype=np.int64), np.empty((2 * P, J, 2)), np.empty((2 * P, J)),
                        np.empty((2 * P, J, 2)), *(np.empty((2 * P, J), dtype=bool) for _ in range(3)),
                        np.empty(2 * P, dtype=np.int64), np.empty(2 * P, dtype=np.int64))
        views = Views(*(np.ascontiguousarray(v) for v in views))
        n = draw_detections(self._rng, views, self._state, self._tables, self.params, out)
        return [r[:n] for r in out]

    def _phantoms(self, cams: np.ndarray) -> list[np.ndarray]:
        """False-positive skeletons, one per entry of cams (N,): a person template standing on the floor where a
        random pixel's ray meets it, turned and scaled at random, reporting each joint inside the image with
        `phantom_keep_prob` plus a little noise; only those with 3 or more joints reported are kept.

        Returns:
            keep (N,) bool, then the rows' ids (N,) (-1), keypoints (N, J, 2), scores (N, J), true px (NaN),
            in_image, occluded, self_occluded (N, J) (False) and effects (N,) (`PHANTOM`).
        """
        rng, p, J, N = self._rng, self.params, self.skeleton.num_joints, len(cams)
        pixel = np.stack([rng.uniform(0, 1, N) * self._size[cams, 0], rng.uniform(0, 1, N) * self._size[cams, 1],
                          np.ones(N)], axis=1)
        yaw = rng.uniform(0, 2 * np.pi, N)
        scale = rng.uniform(0.85, 1.1, N)
        keep_joint = rng.random((N, J)) < p.phantom_keep_prob
        noise = rng.standard_normal((N, J, 2))
        score_noise = rng.standard_normal((N, J))
        # The pixel's ray (world frame) and where it meets the floor.
        ray = np.einsum("nji,nj->ni", self._R[cams], np.linalg.solve(self._K[cams], pixel[..., None])[..., 0])
        down = ray[:, 2] < -1e-6
        centre = self._centre_array[cams]
        foot = centre - ray * (centre[:, 2] / np.where(down, ray[:, 2], -1.0))[:, None]
        cos, sin = np.cos(yaw), np.sin(yaw)
        rot = np.zeros((N, 3, 3))
        rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1], rot[:, 2, 2] = cos, -sin, sin, cos, 1.0
        points = np.einsum("jb,nab->nja", self._template, rot) * scale[:, None, None] + foot[:, None, :]
        # `in_image` of each camera, by the compiled projection.
        px, inside = np.empty((N, J, 2)), np.empty((N, J), dtype=bool)
        in_image_many_kernel(self._R, self._t, self._K, self._dist, self._size, self._max_radius, points, cams,
                             np.array(self._tangential)[cams], np.array(self._skew)[cams], px, inside)
        shown = inside & keep_joint
        keep = down & (shown.sum(axis=1) >= 3)
        size = person_size_px(px)
        kp = np.where(shown[..., None], px + 0.03 * size[:, None, None] * noise, np.nan)
        scores = np.where(shown, np.clip(0.35 + p.score_std * score_noise, MIN_SCORE, 1.0), 0.0)
        false = np.zeros((N, J), dtype=bool)
        return [keep, np.full(N, -1, dtype=np.int64), kp, scores, np.full((N, J, 2), np.nan), false, false, false,
                np.full(N, int(DetectionEffect.PHANTOM), dtype=np.int64)]

