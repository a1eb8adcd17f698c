"""The synthetic 2D detector: projection, visibility, occlusion, noise, misses and false positives.

One call of `Detector.detect` turns the true 3D poses at a camera's capture time into the frame a
bottom-up 2D pose detector (OpenPose-like) would deliver, plus the truth behind every row:

1. project every keypoint with the camera's lens model; joints behind the camera or outside the
   image are not detectable;
2. cast one ray per remaining keypoint from the camera centre against the MuJoCo bodies (compiled
   loops with MuJoCo's own ray formulas, the hits bit for bit those of `mujoco.mj_multiRay`, which
   `cast_visibility` still calls as the reference): the first surface it meets tells whether the joint
   is visible, occluded (a shelf, a wall, another person) or self-occluded (another limb of the same
   person);
3. miss whole people (more often the more they are occluded), drop occluded joints, add noise
   scaled by the person's size in the image (heavy tailed, larger on occluded joints), gross errors,
   left/right swaps and fragments, then add duplicates and phantom skeletons.

Every effect has its own knob in [detector]; a knob left unset takes the value of the profile.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from core.jit import jit
from core.types import COCO17, Camera, Skeleton
from sim.cameras import in_image_many_kernel, monotonic_radius
from sim.config import bounded, check_ranges
from sim.types import CameraFrame, Capture, DetectionEffect, DetectionRows, PoseTruth


class DetectorProfile(enum.Enum):
    """Preset error models: `ideal` (exact joints, no misses), `typical` (OpenPose on Shelf), `harsh`."""

    IDEAL = "ideal"
    TYPICAL = "typical"
    HARSH = "harsh"


class DetectorParams(NamedTuple):
    """The effective error model (a profile with the scenario's knobs applied); the compiled draws take it as
    it is (a named tuple of numbers).

    Attributes:
        noise_frac: per-axis std of the joint noise core, as a fraction of the person's size in the image.
        noise_tail_dof: degrees of freedom of the Student-t noise (smaller: heavier tails; inf: Gaussian).
        occluded_noise_scale: noise multiplier on occluded joints.
        self_occluded_noise_scale: noise multiplier on self-occluded joints.
        gross_error_prob: per-joint probability of a jump of 0.2-0.5 of the person's size.
        miss_prob: probability of missing a fully visible person.
        miss_occlusion_gain: extra miss probability per unit occluded share of the person's joints.
        min_visible_joints: people with fewer visible (unoccluded, in-image) joints are never detected.
        min_person_frac: people smaller in the image than this fraction of its height (the larger side of
            their joints' box) are never detected.
        occluded_drop_prob: probability that an occluded joint is not reported.
        self_occluded_drop_prob: probability that a self-occluded joint is not reported.
        joint_drop_prob: probability that a visible joint is not reported.
        fragment_prob: probability that a detection keeps only one body part (fewer than 6 joints).
        swap_prob: probability that a detection has its left and right joints swapped.
        duplicate_prob: probability that a detection comes with a second, partial copy.
        phantom_rate: mean number of phantom skeletons per frame (Poisson).
        score_visible: mean score of a visible joint.
        score_occluded: mean score of an occluded joint.
        score_std: std of the joint scores.
    """

    noise_frac: float
    noise_tail_dof: float
    occluded_noise_scale: float
    self_occluded_noise_scale: float
    gross_error_prob: float
    miss_prob: float
    miss_occlusion_gain: float
    min_visible_joints: int
    min_person_frac: float
    occluded_drop_prob: float
    self_occluded_drop_prob: float
    joint_drop_prob: float
    fragment_prob: float
    swap_prob: float
    duplicate_prob: float
    phantom_rate: float
    score_visible: float
    score_occluded: float
    score_std: float


PROFILES: dict[DetectorProfile, DetectorParams] = {
    DetectorProfile.IDEAL: DetectorParams(
        noise_frac=0.0, noise_tail_dof=math.inf, occluded_noise_scale=1.0, self_occluded_noise_scale=1.0,
        gross_error_prob=0.0, miss_prob=0.0, miss_occlusion_gain=0.0, min_visible_joints=1, min_person_frac=0.0,
        occluded_drop_prob=0.0, self_occluded_drop_prob=0.0, joint_drop_prob=0.0, fragment_prob=0.0,
        swap_prob=0.0, duplicate_prob=0.0, phantom_rate=0.0, score_visible=1.0, score_occluded=1.0, score_std=0.0,
    ),
    # Calibrated against OpenPose (BODY25) detections on the Shelf dataset; see docs/sensor-model.md. Shelf's
    # people are all large: min_person_frac follows COCO instead (docs/sensor-model.md, "People too small to
    # detect").
    DetectorProfile.TYPICAL: DetectorParams(
        noise_frac=0.013, noise_tail_dof=5.0, occluded_noise_scale=1.6, self_occluded_noise_scale=1.3,
        gross_error_prob=0.001, miss_prob=0.03, miss_occlusion_gain=0.15, min_visible_joints=2, min_person_frac=0.1,
        occluded_drop_prob=0.4, self_occluded_drop_prob=0.1, joint_drop_prob=0.02, fragment_prob=0.07,
        swap_prob=0.002, duplicate_prob=0.01, phantom_rate=0.02, score_visible=0.8, score_occluded=0.45,
        score_std=0.12,
    ),
    DetectorProfile.HARSH: DetectorParams(
        noise_frac=0.022, noise_tail_dof=3.0, occluded_noise_scale=2.5, self_occluded_noise_scale=1.5,
        gross_error_prob=0.01, miss_prob=0.10, miss_occlusion_gain=0.4, min_visible_joints=4, min_person_frac=0.13,
        occluded_drop_prob=0.6, self_occluded_drop_prob=0.2, joint_drop_prob=0.05, fragment_prob=0.15,
        swap_prob=0.02, duplicate_prob=0.05, phantom_rate=0.2, score_visible=0.7, score_occluded=0.35,
        score_std=0.15,
    ),
}

MAX_PHANTOM_RATE = 100.0  # phantom skeletons per frame, on average


@dataclass(frozen=True)
class DetectorConfig:
    """[detector]: the error model of the 2D pose detector.

    `profile` picks the preset; every other key, when given, replaces that one parameter of the
    profile (see `DetectorParams` for their meaning).

    Attributes:
        profile: the preset error model: ideal (no errors), typical (calibrated to OpenPose on Shelf) or harsh.
        self_hit_margin_m: rays that end this close to a keypoint on its own body count as reaching it.
        occlusion: cast rays for occlusion by shelves, other people and the person's own body (false: every
            joint inside the image counts as visible).
    """

    profile: DetectorProfile = DetectorProfile.TYPICAL
    noise_frac: float | None = bounded(None, 0.0, 1.0)
    noise_tail_dof: float | None = bounded(None, 2.0, low_open=True, finite=False, unit="degrees of freedom")
    occluded_noise_scale: float | None = bounded(None, 1.0, 100.0, unit="times")
    self_occluded_noise_scale: float | None = bounded(None, 1.0, 100.0, unit="times")
    gross_error_prob: float | None = bounded(None, 0.0, 1.0)
    miss_prob: float | None = bounded(None, 0.0, 1.0)
    miss_occlusion_gain: float | None = bounded(None, 0.0, 10.0, unit="probability per occluded share")
    min_visible_joints: int | None = bounded(None, 1, 1000, unit="joints")
    min_person_frac: float | None = bounded(None, 0.0, 1.0, unit="fraction of the image height")
    occluded_drop_prob: float | None = bounded(None, 0.0, 1.0)
    self_occluded_drop_prob: float | None = bounded(None, 0.0, 1.0)
    joint_drop_prob: float | None = bounded(None, 0.0, 1.0)
    fragment_prob: float | None = bounded(None, 0.0, 1.0)
    swap_prob: float | None = bounded(None, 0.0, 1.0)
    duplicate_prob: float | None = bounded(None, 0.0, 1.0)
    phantom_rate: float | None = bounded(None, 0.0, MAX_PHANTOM_RATE, unit="skeletons per frame")
    score_visible: float | None = bounded(None, 0.0, 1.0, unit="score")
    score_occluded: float | None = bounded(None, 0.0, 1.0, unit="score")
    score_std: float | None = bounded(None, 0.0, 1.0, unit="score")
    self_hit_margin_m: float = bounded(0.2, 0.0, 2.0)
    occlusion: bool = True

    def __post_init__(self):
        check_ranges(self)

    def params(self) -> DetectorParams:
        """The profile's parameters with every knob that was set applied."""
        overrides = {name: getattr(self, name) for name in DetectorParams._fields if getattr(self, name) is not None}
        return PROFILES[self.profile]._replace(**overrides)


# Per-joint noise multipliers (COCO-17): wrists worst, knees and ankles best, as OpenPose on Shelf.
_JOINT_NOISE_COCO17 = np.array([0.8, 0.8, 0.8, 0.9, 0.9, 1.0, 1.0, 1.2, 1.2, 1.6, 1.6, 1.1, 1.1, 0.85, 0.85, 0.9, 0.9])
# Body parts a fragment may keep (COCO-17 indices), each fewer than 6 joints.
_FRAGMENTS_COCO17 = (
    (0, 1, 2, 3, 4), (5, 7, 9), (6, 8, 10), (5, 6, 7, 8), (11, 13, 15), (12, 14, 16), (11, 12, 13, 14),
    (0, 5, 6), (13, 14, 15, 16),
)
_GROSS_MIN_FRAC, _GROSS_MAX_FRAC = 0.2, 0.5
_SCENE_ROWS = 64  # ticks per buffer of `Detector.scene_now` (about 7 blocks of store_layout2)
_DUPLICATE_OFFSET_FRAC = 0.05
_DUPLICATE_KEEP = 0.6  # share of its joints a duplicate repeats
_DUPLICATE_SCORE = 0.6  # its scores, relative to the original's
_MIN_SCORE = 0.05
# A canonical standing COCO-17 person 1.7 m tall facing +x (body frame, metres), used for phantoms.
_TEMPLATE_COCO17 = np.array([
    [0.08, 0.0, 1.62], [0.07, 0.03, 1.66], [0.07, -0.03, 1.66], [0.0, 0.07, 1.64], [0.0, -0.07, 1.64],
    [0.0, 0.19, 1.42], [0.0, -0.19, 1.42], [0.0, 0.23, 1.13], [0.0, -0.23, 1.13], [0.05, 0.24, 0.86],
    [0.05, -0.24, 0.86], [0.0, 0.1, 0.92], [0.0, -0.1, 0.92], [0.02, 0.1, 0.5], [0.02, -0.1, 0.5],
    [0.0, 0.1, 0.08], [0.0, -0.1, 0.08],
])


# What `_draw_detections` writes: `DetectionRows`' arrays, then each row's capture in the block.
_DrawnRows = NamedTuple("_DrawnRows", [(name, np.ndarray) for name in (*DetectionRows._fields, "group")])


def person_size_px(keypoints_px: np.ndarray) -> np.ndarray:
    """The person's size in the image: the larger side of the bounding box of its true joints.

    Args:
        keypoints_px: (..., J, 2) true pixel positions, NaN where unknown.

    Returns:
        (...,) size in pixels (NaN when no joint is known).
    """
    kp = np.ascontiguousarray(keypoints_px, dtype=np.float64)
    sizes = _person_sizes(kp.reshape((int(np.prod(kp.shape[:-2])),) + kp.shape[-2:]))  # `_person_size` each
    return sizes.reshape(kp.shape[:-2])


def left_right_permutation(skeleton: Skeleton) -> np.ndarray:
    """(J,) joint order that swaps every left_* joint with its right_* partner."""
    order = np.arange(skeleton.num_joints)
    for i, name in enumerate(skeleton.joints):
        for a, b in (("left_", "right_"), ("right_", "left_")):
            if name.startswith(a) and b + name[len(a):] in skeleton.joints:
                order[i] = skeleton.index(b + name[len(a):])
    return order


def cast_visibility(model, data, origin: np.ndarray, points: np.ndarray, point_person: np.ndarray,
                    point_bodies: np.ndarray, geom_person: np.ndarray, geom_body: np.ndarray,
                    self_hit_margin_m: float):
    """Occlusion of keypoints seen from one point, one `mj_multiRay` batch (the reference the detector's
    compiled ray caster is tested against).

    Args:
        model, data: the MuJoCo model and data holding the bodies at the capture time.
        origin: (3,) camera centre, metres.
        points: (N, 3) keypoints, metres.
        point_person: (N,) person id of each keypoint.
        point_bodies: (N, 2) the body each keypoint hangs on and its parent body (a joint keypoint sits
            inside both segments' geoms), in the numbering of `geom_body`.
        geom_person: (ngeom,) person id of each geom, -1 for the store.
        geom_body: (ngeom,) body of each geom within its person.
        self_hit_margin_m: hits on the keypoint's own segments this close to the keypoint count as reaching it.

    Returns:
        (N,) bool occluded (first hit: store or another person) and (N,) bool self-occluded (first
        hit: another limb of the same person, or its own segments far from the keypoint).
    """
    import mujoco

    n = points.shape[0]
    if n == 0:
        return np.zeros(0, dtype=bool), np.zeros(0, dtype=bool)
    vec = points - origin
    length = np.sqrt(np.einsum("ij,ij->i", vec, vec))
    unit = vec / length[:, None]
    geomid = np.empty(n, dtype=np.int32)
    dist = np.empty(n)
    mujoco.mj_multiRay(model, data, np.asarray(origin, dtype=np.float64), unit.ravel(), None, 1, -1,
                       geomid, dist, None, n, float(length.max()))
    return classify_hits(geomid, dist, length, point_person, point_bodies, geom_person, geom_body, self_hit_margin_m)


def classify_hits(geomid: np.ndarray, dist: np.ndarray, length: np.ndarray, point_person: np.ndarray,
                  point_bodies: np.ndarray, geom_person: np.ndarray, geom_body: np.ndarray,
                  self_hit_margin_m: float):
    """Occluded and self-occluded flags from the first hits of rays cast at keypoints.

    Args:
        geomid, dist: (N,) first geom hit by each ray (-1: none) and its distance.
        length: (N,) distance from the ray origin to the keypoint.
        point_person, point_bodies, geom_person, geom_body, self_hit_margin_m: as in `cast_visibility`.

    Returns:
        (N,) bool occluded and (N,) bool self-occluded, as `cast_visibility`.
    """
    hit = (geomid >= 0) & (dist >= 0) & (dist < length)
    g = np.maximum(geomid, 0)
    same_person = hit & (geom_person[g] == point_person)
    hit_body = geom_body[g][:, None]
    own_near = same_person & (hit_body == point_bodies).any(axis=1) & (length - dist <= self_hit_margin_m)
    return hit & ~same_person, same_person & ~own_near


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
        self._swap = left_right_permutation(skeleton)
        coco = skeleton.name == COCO17.name
        self._joint_noise = _JOINT_NOISE_COCO17 if coco else np.ones(skeleton.num_joints)
        self._fragments = _FRAGMENTS_COCO17 if coco else tuple(
            tuple(range(s, min(s + 4, skeleton.num_joints))) for s in range(0, skeleton.num_joints, 4)
        )
        self._fragment_masks = np.zeros((len(self._fragments), skeleton.num_joints), dtype=bool)
        for i, part in enumerate(self._fragments):
            self._fragment_masks[i, list(part)] = True
        self._template = _TEMPLATE_COCO17 if coco else None
        self._centres = [np.ascontiguousarray(c.center_world) for c in self.cameras]
        self._scene_rows: tuple | None = None  # `scene_now`'s buffer: positions, rotations, rows handed out
        self._scene_retire = False
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

    def visibility(self, camera_index: int, world, poses: PoseTruth):
        """Projection and occlusion of everybody's joints in one camera (`visibility_many` of one capture).

        Args:
            camera_index: which camera.
            world: a `sim.world.World` advanced to the poses' time (or None to skip ray casting).
            poses: the true poses, (P, J, 3).

        Returns:
            px (P, J, 2) distorted true pixels, in_img (P, J), occluded (P, J), self_occluded (P, J).
        """
        return self.visibility_many(world, [Capture(camera_index, poses, poses.t_s, poses.t_s, poses.t_s)])[0]

    def visibility_many(self, world, requests) -> list[tuple]:
        """`visibility` of several captures whose bodies are all in `world`'s data (one truth tick): the
        projections and every ray of the tick in one compiled pass each.

        Args:
            world: the world (or None to skip ray casting).
            requests: the captures (`Capture`).

        Returns:
            Per request: px (P, J, 2), in_img, occluded, self_occluded (P, J).
        """
        if not requests:
            return []
        J = self.skeleton.num_joints
        for r in requests:
            if np.shape(r.poses.poses)[1:] != (J, 3):
                raise ValueError(f"visibility: poses of shape {np.shape(r.poses.poses)}, expected (P, {J}, 3)")
        scenes = [self.scene_now(world, copy=False)] if world is not None else None
        px, in_img, occluded, self_occluded = self.block_visibility(requests, scenes, [0] * len(requests))
        bounds = np.cumsum([0] + [len(r.poses.person_ids) for r in requests]).tolist()
        return [(px[a:b], in_img[a:b], occluded[a:b], self_occluded[a:b]) for a, b in zip(bounds[:-1], bounds[1:])]

    def scene_now(self, world, copy: bool = True) -> tuple | None:
        """What rays need of `world`'s bodies now (None when occlusion is off): geom positions (G, 3),
        rotations (G, 9), sizes (G, 3), bounding radii (G,) and owners (G,), copied unless `copy` is False.

        The copies are cheap: the positions and rotations go to the next rows of a buffer (consecutive
        ticks' rows are then one slice for `block_visibility`, no stacking), and the sizes, radii and
        owners are `World.ray_geom_constants`'s read-only snapshots, shared by every tick until they
        change. Treat every array returned as read-only."""
        if world is None or not self.config.occlusion:
            return None
        self._scene(world)
        model, data = world.model, world.data
        if not copy:
            return (data.geom_xpos, data.geom_xmat, model.geom_size, model.geom_rbound,
                    np.asarray(world.geom_person_ids(), dtype=np.int64))
        constants = getattr(world, "ray_geom_constants", None)
        if constants is not None:
            size, rbound, owner = constants()
        else:
            size, rbound = np.array(model.geom_size), np.array(model.geom_rbound)
            owner = np.array(world.geom_person_ids(), dtype=np.int64)
        xpos, xmat = data.geom_xpos, data.geom_xmat
        rows = self._scene_rows
        if rows is None or len(rows[2]) == _SCENE_ROWS or rows[0].shape[1] != xpos.shape[0] or self._scene_retire:
            rows = self._new_scene_rows(xpos.shape[0])
        buf_pos, buf_mat, handed, row_of = rows
        i = len(handed)
        buf_pos[i] = xpos
        buf_mat[i] = xmat.reshape(-1, 9)
        pos_row = buf_pos[i]
        handed.append(pos_row)  # (kept: the ids in row_of stay unique)
        row_of[id(pos_row)] = i
        return pos_row, buf_mat[i], size, rbound, owner

    def _new_scene_rows(self, G: int) -> tuple:
        """A new buffer for `scene_now` (the current one is left to the ticks that still hold rows of it)."""
        self._scene_retire = False
        self._scene_rows = (np.empty((_SCENE_ROWS, G, 3)), np.empty((_SCENE_ROWS, G, 9)), [], {})
        return self._scene_rows

    def _scene_arrays(self, scenes: list) -> tuple:
        """The `scene_now` snapshots of several ticks as the ray caster takes them: positions (T, G, 3) and
        rotations (T, G, 9) (a slice of the buffer when `scene_now` wrote them to consecutive rows), the
        distinct sizes (U, G, 3), radii (U, G) and owners (U, G), and per tick its index in those (T,)."""
        T = len(scenes)
        xpos = xmat = None
        rows = self._scene_rows
        if rows is not None:
            buf_pos, buf_mat, handed, row_of = rows
            first = row_of.get(id(scenes[0][0]), -1)
            if (first >= 0 and first + T <= len(handed)
                    and all(scene[0] is handed[first + i] for i, scene in enumerate(scenes))):
                xpos, xmat = buf_pos[first:first + T], buf_mat[first:first + T]
                if first + T == len(handed) and len(handed) > _SCENE_ROWS - 16:
                    self._scene_retire = True  # the next block starts a new buffer rather than straddle two
        if xpos is None:
            xpos = np.stack([scene[0] for scene in scenes])
            xmat = np.stack([scene[1] for scene in scenes]).reshape(T, -1, 9)
        # The constant parts, once per distinct (sizes, radii, owners) triple (alive here, so ids are unique).
        distinct: dict = {}
        const_of = np.empty(T, dtype=np.int64)
        for i, scene in enumerate(scenes):
            const_of[i] = distinct.setdefault((id(scene[2]), id(scene[3]), id(scene[4])), len(distinct))
        if len(distinct) == 1:
            size, rbound, owner = (np.asarray(scenes[0][k])[None] for k in (2, 3, 4))
        else:
            firsts = [const_of.tolist().index(u) for u in range(len(distinct))]
            size, rbound, owner = (np.stack([scenes[f][k] for f in firsts]) for k in (2, 3, 4))
        return xpos, xmat, size, rbound, owner.astype(np.int64, copy=False), const_of

    def _ray_scratch(self, R: int, N: int, T: int, K: int) -> tuple:
        """Scratch arrays for the ray caster, kept between blocks (new ones of this size each block cost
        page faults): hit geoms (R, N) int32 and distances (R, N) (written, not read here), and the geom
        and group boxes (T, G + K, 6)."""
        G = len(self._scene_cache[2])
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
            Every request's people in turn: px (sum P, J, 2), in_img, occluded, self_occluded (sum P, J); the
            occlusion flags of people smaller than the camera's `min_size_px` are False (no rays: they make no
            detection).
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
        px = np.empty((n_req, N, 2))
        in_img = np.empty((n_req, N), dtype=bool)
        in_image_many_kernel(self._R, self._t, self._K, self._dist, self._size, self._max_radius, points, cams,
                             np.array([batch_tangential[k] for k in scene_of]),
                             np.array([batch_skew[k] for k in scene_of]), px, in_img)
        occluded = np.zeros((n_req, N), dtype=bool)
        self_occluded = np.zeros((n_req, N), dtype=bool)
        cast = in_img
        if self.params.min_person_frac > 0:
            # No rays for the people too small to detect (`_draw_detections` drops them): far across a large
            # store they are most of the views.
            large = large_enough(px.reshape(n_req * most, J, 2), np.repeat(self.min_size_px[cams], most))
            cast = in_img & np.repeat(large.reshape(n_req, most), J, axis=1)
        if scenes is not None and cast.any():
            kp_bodies, geom_body, geom_type, groups = self._scene_cache
            xpos, xmat, size, rbound, owner, const_of = self._scene_arrays(scenes)
            geomid, dist, bounds = self._ray_scratch(n_req, N, len(scenes), len(groups) - 1)
            _cast_keypoint_rays(self._centre_array[cams], points, cast, ids, J, kp_bodies, geom_type, geom_body,
                                groups, xpos, xmat, size, rbound, owner, const_of,
                                np.asarray(scene_of, dtype=np.int64), float(self.config.self_hit_margin_m), occluded,
                                self_occluded, geomid, dist, cams, self.visibility_counts, bounds)
        else:
            _count_views(cams, cast, occluded, self_occluded, self.visibility_counts)
        px = px.reshape(n_req, most, J, 2)
        in_img, occluded, self_occluded = (a.reshape(n_req, most, J) for a in (in_img, occluded, self_occluded))
        if min(counts) == most:
            return (px.reshape(-1, J, 2), in_img.reshape(-1, J), occluded.reshape(-1, J),
                    self_occluded.reshape(-1, J))
        return tuple(np.concatenate([a[i, :P] for i, P in enumerate(counts)])
                     for a in (px, in_img, occluded, self_occluded))

    def _scene(self, world) -> tuple:
        """What the ray caster needs of `world` that does not change while it runs (cached per world):
        (J, 2) body and parent body of each keypoint and, per geom, its body within its person, its type
        and the groups of geoms that move together (`World.geom_groups`, else runs of one person's geoms)."""
        if getattr(self, "_scene_of", None) is not world:
            bodies = np.asarray(world.keypoint_body_ids(), dtype=np.int64)
            if bodies.shape != (self.skeleton.num_joints,):
                raise ValueError(f"World.keypoint_body_ids(): expected ({self.skeleton.num_joints},), "
                                 f"got {bodies.shape}")
            parents = getattr(world, "keypoint_parent_body_ids", None)
            parents = np.asarray(parents(), dtype=np.int64) if parents is not None else _parent_bodies(bodies)
            geom_type = np.asarray(world.model.geom_type, dtype=np.int64)
            unsupported = sorted(set(geom_type.tolist()) - set(_RAY_GEOM_TYPES))
            if unsupported:
                raise ValueError(f"world geoms: mjtGeom types {unsupported} are not supported by the keypoint ray "
                                 "caster (spheres, capsules, ellipsoids, cylinders and boxes are)")
            if hasattr(world, "geom_groups"):
                groups = np.asarray(world.geom_groups(), dtype=np.int64)
            else:
                person = np.asarray(world.geom_person_ids())
                groups = np.concatenate([[0], np.nonzero(person[1:] != person[:-1])[0] + 1, [person.size]])
            self._scene_cache = (np.ascontiguousarray(np.stack([bodies, parents], axis=1)),
                                 np.asarray(world.geom_body_ids(), dtype=np.int64), geom_type, groups)
            self._scene_of = world
        return self._scene_cache

    def _cast(self, world, origins: np.ndarray, points: np.ndarray, mask: np.ndarray, person: np.ndarray):
        """Occluded and self-occluded flags (R, N) of keypoints points (R, N, 3) seen from origins (R, 3),
        where mask (R, N); person (R, N // J) is the person id of each row of J keypoints. Also the nearest
        geom hit before each keypoint (R, N) (-1: none) and its distance."""
        kp_bodies, geom_body, geom_type, groups = self._scene(world)
        xpos, xmat, size, rbound, owner = self.scene_now(world, copy=False)
        shape = mask.shape
        occluded, self_occluded = np.empty(shape, dtype=bool), np.empty(shape, dtype=bool)
        geomid, dist = np.empty(shape, dtype=np.int32), np.empty(shape)
        _cast_keypoint_rays(
            np.ascontiguousarray(origins, dtype=np.float64), np.ascontiguousarray(points, dtype=np.float64),
            np.ascontiguousarray(mask), np.ascontiguousarray(person, dtype=np.int64), self.skeleton.num_joints,
            kp_bodies, geom_type, geom_body, groups, xpos[None], xmat[None], size[None], rbound[None], owner[None],
            np.zeros(1, dtype=np.int64), np.zeros(shape[0], dtype=np.int64), float(self.config.self_hit_margin_m),
            occluded, self_occluded, geomid, dist, np.zeros(shape[0], dtype=np.int64), np.zeros((1, 3), dtype=np.int64),
            np.empty((1, len(geom_type) + len(groups) - 1, 6)))
        return occluded, self_occluded, geomid, dist

    def detect_visible(self, requests, visibilities) -> list[CameraFrame]:
        """The frames of captures whose visibility is already known (`visibility_many` of the same poses, or
        a dataset's true 2D joints), with the detector's errors drawn for all of them at once.

        Args:
            requests: the captures (`Capture`).
            visibilities: per capture, px (P, J, 2), in_img, occluded, self_occluded (P, J).
        """
        if not requests:
            return []
        rows, bounds = self.detection_rows_of(requests, *(np.concatenate([v[k] for v in visibilities])
                                                           for k in range(4)))
        return self.frames_from_rows(requests, rows, bounds)

    def detection_rows_of(self, requests, px, in_img, occluded, self_occluded,
                          person_ids: list | None = None) -> tuple[DetectionRows, np.ndarray]:
        """`detection_rows` from the requests' visibility as `block_visibility` returns it (every request's
        people in turn); person_ids: each request's people (None: its poses' ids), where the requests
        came without their poses."""
        if not requests:
            return DetectionRows.empty(self.skeleton.num_joints), np.zeros(1, dtype=np.int64)
        if person_ids is None:
            person_ids = [r.poses.person_ids for r in requests]
        ids = np.concatenate(person_ids).astype(np.int64, copy=False)
        group = np.repeat(np.arange(len(requests)), [len(p) for p in person_ids])
        cams = np.array([r.camera for r in requests], dtype=np.int64)
        rows = self._detections(ids, px, in_img, occluded, self_occluded, group, self.min_size_px[cams][group])
        # Phantom skeletons: a Poisson number per frame (drawn for all frames at once), appended as rows.
        n_phantoms = self._rng.poisson(self.params.phantom_rate, len(requests))
        phantoms = [(i, ph) for i in np.repeat(np.arange(len(requests)), n_phantoms)
                    for ph in [self._phantom(requests[i].camera)] if ph is not None]
        if phantoms:
            extra = [np.stack([ph[k] for _, ph in phantoms]) for k in range(8)]
            extra.append(np.array([i for i, _ in phantoms], dtype=rows[-1].dtype))
            rows = [np.concatenate([r, e]) for r, e in zip(rows, extra)]
        # Each frame's rows in a random order: sort by frame, then by a uniform key.
        order = np.empty(rows[-1].shape[0], dtype=np.int64)
        _frame_order(rows[-1].astype(np.int64, copy=False), self._rng.random(rows[-1].shape[0]), len(requests), order)
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

    def _detections(self, person_ids, px, in_img, occluded, self_occluded, group, min_px):
        """The detections of real people, drawn by one compiled loop (`_draw_detections`; rows: people
        detected, then duplicates).

        Args:
            person_ids: (P,) ids; px (P, J, 2); in_img, occluded, self_occluded (P, J); group (P,) the
                request each row belongs to; min_px (P,) the size below which it is not detected.

        Returns:
            ids (D,), keypoints (D, J, 2), scores (D, J), true px (D, J, 2), in_image, occluded,
            self_occluded (D, J), effects (D,), group (D,).
        """
        P, J = in_img.shape
        out = _DrawnRows(np.empty(2 * P, dtype=np.int64), np.empty((2 * P, J, 2)), np.empty((2 * P, J)),
                         np.empty((2 * P, J, 2)), *(np.empty((2 * P, J), dtype=bool) for _ in range(3)),
                         np.empty(2 * P, dtype=np.int64), np.empty(2 * P, dtype=np.int64))
        n = _draw_detections(self._rng, np.ascontiguousarray(person_ids, dtype=np.int64), px, in_img, occluded,
                             self_occluded, np.ascontiguousarray(group, dtype=np.int64),
                             np.ascontiguousarray(min_px, dtype=np.float64), self._fragment_masks,
                             self._joint_noise, self._swap, self.params, out)
        return [r[:n] for r in out]

    def _phantom(self, camera_index: int):
        """A false-positive skeleton: a person template standing somewhere on the floor in view of a camera."""
        rng = self._rng
        p = self.params
        J = self.skeleton.num_joints
        if self._template is None:
            return None
        camera = self.cameras[camera_index]
        # Pick a pixel, follow its ray to the floor and stand the template there.
        pixel = np.array([rng.uniform(0, camera.width_px), rng.uniform(0, camera.height_px), 1.0])
        ray = camera.R_cam_from_world.T @ np.linalg.solve(camera.K, pixel)
        centre = self._centres[camera_index]
        if ray[2] >= -1e-6:
            return None
        foot = centre - ray * (centre[2] / ray[2])
        yaw = rng.uniform(0, 2 * np.pi)
        rot = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
        points = self._template * rng.uniform(0.85, 1.1) @ rot.T + foot
        # `in_image` of the camera, by the compiled projection (the same pixels; far less overhead).
        px, inside = np.empty((1, J, 2)), np.empty((1, J), dtype=bool)
        in_image_many_kernel(self._R, self._t, self._K, self._dist, self._size, self._max_radius, points[None],
                             np.array([camera_index]), np.array([self._tangential[camera_index]]),
                             np.array([self._skew[camera_index]]), px, inside)
        px, inside = px[0], inside[0]
        keep = inside & (rng.random(J) < 0.7)
        if keep.sum() < 3:
            return None
        kp = np.where(keep[:, None], px + 0.03 * person_size_px(px) * rng.standard_normal((J, 2)), np.nan)
        scores = np.where(keep, np.clip(0.35 + p.score_std * rng.standard_normal(J), _MIN_SCORE, 1.0), 0.0)
        nan = np.full((J, 2), np.nan)
        false = np.zeros(J, dtype=bool)
        return (-1, kp, scores, nan, false, false, false, int(DetectionEffect.PHANTOM))


def _parent_bodies(bodies: np.ndarray) -> np.ndarray:
    """(J,) parent segment of each keypoint's body for `sim.humanoid`'s numbering (the body itself otherwise)."""
    from sim import humanoid

    table = getattr(humanoid, "KEYPOINT_PARENT_BODY", None)
    if table is not None and np.array_equal(bodies, humanoid.KEYPOINT_BODY):
        return np.asarray(table, dtype=np.int64)
    if np.array_equal(bodies, getattr(humanoid, "KEYPOINT_BODY", None)):
        # A joint keypoint sits at its segment's proximal end, inside the parent segment too.
        B = humanoid.B
        parent = {B["head"]: B["neck"], B["left_upper_arm"]: B["torso"], B["right_upper_arm"]: B["torso"],
                  B["left_forearm"]: B["left_upper_arm"], B["right_forearm"]: B["right_upper_arm"],
                  B["left_hand"]: B["left_forearm"], B["right_hand"]: B["right_forearm"],
                  B["left_thigh"]: B["pelvis"], B["right_thigh"]: B["pelvis"], B["left_shin"]: B["left_thigh"],
                  B["right_shin"]: B["right_thigh"], B["left_foot"]: B["left_shin"], B["right_foot"]: B["right_shin"]}
        return np.array([parent.get(int(b), int(b)) for b in bodies], dtype=np.int64)
    return bodies.copy()


# -- ray casting ---------------------------------------------------------------------------------------
# Keypoint rays are cast by compiled loops that evaluate MuJoCo's own ray-primitive formulas (the
# quadratic of `mj_ray` for spheres, capsules, ellipsoids and cylinders, the slab faces for boxes) term
# by term in the same order, so every hit distance is the one `mujoco.mj_multiRay` returns, and the
# nearest hit is chosen as MuJoCo chooses it (geoms in model order, a later geom only when strictly
# nearer). What differs is the culling, which never drops a geom that has a hit nearer than the keypoint
# (the only hits the flags depend on), so the nearest hit and its ties come out the same. Per instant the
# geoms are binned by the floor cells (`_GRID_CELL_M`) their boxes overlap, each cell keeping its highest
# box top; a ray walks the cells its segment crosses from the camera on, skips a cell whose top is below
# the segment there, and stops at the first cell boundary past its nearest hit (a hit lies in the cell of
# its point, and its geom's box overlaps that cell). In a cell, a geom is skipped when the segment from the
# camera to the keypoint (to the nearest hit so far) misses its bounding sphere, a box geom also when the
# box around the segment misses its box; ties go to the geom first in model order. tests/sim checks the
# flags and the hits against `mj_multiRay` in the store. This replaced one `mj_multiRay` call per capture,
# whose per-call set-up (the bounding angles of every geom) cost more than its rays, and then per-person
# candidate lists, whose boxes (camera to person) held most of a crowded store.

_MJ_MINVAL = 1e-15  # mjMINVAL: MuJoCo's smallest denominator
_GEOM_SPHERE, _GEOM_CAPSULE, _GEOM_ELLIPSOID, _GEOM_CYLINDER, _GEOM_BOX = 2, 3, 4, 5, 6  # mjtGeom
_RAY_GEOM_TYPES = (_GEOM_SPHERE, _GEOM_CAPSULE, _GEOM_ELLIPSOID, _GEOM_CYLINDER, _GEOM_BOX)
# Slack on the bounding spheres of the culling, far above the rounding of the hit distances.
_CULL_SLACK_M = 1e-6
# The floor grid of the ray casting: cell side, most cells along a side, and the slack of its bounds (far
# above the rounding of the cell walk, far below anything a cell's contents depend on).
_GRID_CELL_M = 0.5
_GRID_MAX_CELLS = 256
_GRID_SLACK_M = 1e-6


@jit
def _quadratic_roots(a, b, c):
    """Roots of a x² + 2 b x + c = 0 (both -1 when the discriminant is below mjMINVAL) and the smallest
    non-negative one (-1 when none), as MuJoCo's ray code solves it."""
    det = b * b - a * c
    if det < _MJ_MINVAL:
        return -1.0, -1.0, -1.0
    det = math.sqrt(det)
    x0 = (-b - det) / a
    x1 = (-b + det) / a
    if x0 >= 0:
        return x0, x1, x0
    if x1 >= 0:
        return x0, x1, x1
    return x0, x1, -1.0


@jit
def _ray_sphere(cx, cy, cz, radius_sq, px, py, pz, vx, vy, vz):
    dx, dy, dz = px - cx, py - cy, pz - cz
    a = vx * vx + vy * vy + vz * vz
    b = vx * dx + vy * dy + vz * dz
    c = dx * dx + dy * dy + dz * dz - radius_sq
    return _quadratic_roots(a, b, c)[2]


@jit
def _ray_geom(g, kinds, xpos, xmat, sizes, px, py, pz, vx, vy, vz):
    """Distance along the ray (p, v) to geom g of type kinds[g] at xpos[g] (3,) with rotation xmat[g] (9,) and
    size sizes[g] (3,); -1: no hit. (Scalars read once: faster than passing row views.)"""
    kind = kinds[g]
    p0, p1, p2 = xpos[g, 0], xpos[g, 1], xpos[g, 2]
    m0, m1, m2, m3, m4, m5, m6, m7, m8 = (xmat[g, 0], xmat[g, 1], xmat[g, 2], xmat[g, 3], xmat[g, 4], xmat[g, 5],
                                          xmat[g, 6], xmat[g, 7], xmat[g, 8])
    s0, s1, s2 = sizes[g, 0], sizes[g, 1], sizes[g, 2]
    if kind == _GEOM_SPHERE:
        return _ray_sphere(p0, p1, p2, s0 * s0, px, py, pz, vx, vy, vz)
    if kind == _GEOM_CAPSULE:
        outer = s0 + s1
        if _ray_sphere(p0, p1, p2, outer * outer, px, py, pz, vx, vy, vz) < 0:
            return -1.0
    elif kind == _GEOM_CYLINDER:
        if _ray_sphere(p0, p1, p2, s0 * s0 + s1 * s1, px, py, pz, vx, vy, vz) < 0:
            return -1.0
    elif kind == _GEOM_BOX:
        if _ray_sphere(p0, p1, p2, s0 * s0 + s1 * s1 + s2 * s2, px, py, pz, vx, vy, vz) < 0:
            return -1.0
    # The ray in the geom's frame: mat' (p - pos) and mat' v.
    dx, dy, dz = px - p0, py - p1, pz - p2
    l0 = m0 * dx + m3 * dy + m6 * dz
    l1 = m1 * dx + m4 * dy + m7 * dz
    l2 = m2 * dx + m5 * dy + m8 * dz
    w0 = m0 * vx + m3 * vy + m6 * vz
    w1 = m1 * vx + m4 * vy + m7 * vz
    w2 = m2 * vx + m5 * vy + m8 * vz
    if kind == _GEOM_ELLIPSOID:
        i0, i1, i2 = 1 / (s0 * s0), 1 / (s1 * s1), 1 / (s2 * s2)
        a = i0 * w0 * w0 + i1 * w1 * w1 + i2 * w2 * w2
        b = i0 * w0 * l0 + i1 * w1 * l1 + i2 * w2 * l2
        c = i0 * l0 * l0 + i1 * l1 * l1 + i2 * l2 * l2 - 1
        return _quadratic_roots(a, b, c)[2]
    x = -1.0
    if kind == _GEOM_BOX:
        for i in range(3):
            li, wi, si = (l0, w0, s0) if i == 0 else ((l1, w1, s1) if i == 1 else (l2, w2, s2))
            if abs(wi) <= _MJ_MINVAL:
                continue
            # The two other axes of face i.
            la, wa, sa = (l1, w1, s1) if i == 0 else (l0, w0, s0)
            lb, wb, sb = (l1, w1, s1) if i == 2 else (l2, w2, s2)
            for side in (-1.0, 1.0):
                sol = (side * si - li) / wi
                if sol >= 0 and abs(la + sol * wa) <= sa and abs(lb + sol * wb) <= sb and (x < 0 or sol < x):
                    x = sol
        return x
    # Capsule and cylinder: the round side first.
    a = w0 * w0 + w1 * w1
    b = w0 * l0 + w1 * l1
    c = l0 * l0 + l1 * l1 - s0 * s0
    if kind == _GEOM_CYLINDER:
        if abs(w2) > _MJ_MINVAL:  # flat ends
            for side in (-1.0, 1.0):
                sol = (side * s1 - l2) / w2
                if sol >= 0:
                    e0, e1 = l0 + sol * w0, l1 + sol * w1
                    if e0 * e0 + e1 * e1 <= s0 * s0 and (x < 0 or sol < x):
                        x = sol
        sol = _quadratic_roots(a, b, c)[2]
        if sol >= 0 and abs(l2 + sol * w2) <= s1 and (x < 0 or sol < x):
            x = sol
        return x
    sol = _quadratic_roots(a, b, c)[2]
    if sol >= 0 and abs(l2 + sol * w2) <= s1:
        x = sol
    # The two hemispherical caps, each only on its own side of the round part.
    a = w0 * w0 + w1 * w1 + w2 * w2
    for side in (1.0, -1.0):
        e2 = l2 - s1 if side > 0 else l2 + s1
        b = w0 * l0 + w1 * l1 + w2 * e2
        c = l0 * l0 + l1 * l1 + e2 * e2 - s0 * s0
        r0, r1, _ = _quadratic_roots(a, b, c)
        for r in (r0, r1):
            if r >= 0 and (l2 + r * w2 >= s1 if side > 0 else l2 + r * w2 <= -s1) and (x < 0 or r < x):
                x = r
    return x


@jit
def _scene_bounds(geom_type, groups, geom_xpos, geom_xmat, geom_size, geom_rbound, bounds):
    """Boxes (lo, hi) around every geom (a box's own corners, the bounding sphere of the others), then
    around every group, into bounds (G + K, 6): a ray whose segment misses them cannot hit them before
    its keypoint."""
    K, G = groups.shape[0] - 1, geom_type.shape[0]
    for g in range(G):
        for i in range(3):
            half = geom_rbound[g]
            if geom_type[g] == _GEOM_BOX:
                half = (abs(geom_xmat[g, 3 * i]) * geom_size[g, 0] + abs(geom_xmat[g, 3 * i + 1]) * geom_size[g, 1]
                        + abs(geom_xmat[g, 3 * i + 2]) * geom_size[g, 2])
            bounds[g, i] = geom_xpos[g, i] - half - _CULL_SLACK_M
            bounds[g, 3 + i] = geom_xpos[g, i] + half + _CULL_SLACK_M
    for k in range(K):
        for i in range(3):
            bounds[G + k, i], bounds[G + k, 3 + i] = np.inf, -np.inf
        for g in range(groups[k], groups[k + 1]):
            for i in range(3):
                bounds[G + k, i] = min(bounds[G + k, i], bounds[g, i])
                bounds[G + k, 3 + i] = max(bounds[G + k, 3 + i], bounds[g, 3 + i])


@jit
def _grid_extent(origins, points, mask):
    """The floor rectangle (x0, y0, x1, y1) holding every segment from a capture's camera centre to a keypoint
    it casts (origins (R, 3), points (R, N, 3), mask (R, N)), and the lowest height any of them reaches:
    geoms outside it cannot meet a ray of the block."""
    x0 = y0 = z0 = np.inf
    x1 = y1 = -np.inf
    for r in range(points.shape[0]):
        any_cast = False
        for n in range(points.shape[1]):
            if mask[r, n]:
                any_cast = True
                x0, x1 = min(x0, points[r, n, 0]), max(x1, points[r, n, 0])
                y0, y1 = min(y0, points[r, n, 1]), max(y1, points[r, n, 1])
                z0 = min(z0, points[r, n, 2])
        if any_cast:
            x0, x1 = min(x0, origins[r, 0]), max(x1, origins[r, 0])
            y0, y1 = min(y0, origins[r, 1]), max(y1, origins[r, 1])
            z0 = min(z0, origins[r, 2])
    return x0 - _GRID_SLACK_M, y0 - _GRID_SLACK_M, x1 + _GRID_SLACK_M, y1 + _GRID_SLACK_M, z0 - _GRID_SLACK_M


@jit
def _grid_cells(lo, hi, origin, cell, n):
    """First and last cell index (clamped to [0, n)) of the interval [lo, hi] on a grid axis."""
    a = int(math.floor((lo - origin) / cell))
    b = int(math.floor((hi - origin) / cell))
    return max(a, 0), min(b, n - 1)


@jit
def _build_grid(geom_box, x0, y0, z0, cell, nx, ny, starts, tops, entries, fill_entries):
    """Bins the geoms by the floor cells their boxes geom_box (G, 6) overlap (geoms wholly below z0 or
    outside the grid left out): cell c holds entries[starts[c]:starts[c + 1]], in geom order, and tops[c]
    is the highest box top in it (-inf when empty). Without fill_entries, only counts. Returns the total."""
    ncell = nx * ny
    starts[:] = 0
    tops[:] = -np.inf
    G = geom_box.shape[0]
    x1, y1 = x0 + nx * cell, y0 + ny * cell
    fill = starts[:ncell].copy()
    for stage in range(2 if fill_entries else 1):
        for g in range(G):
            if (geom_box[g, 5] < z0 or geom_box[g, 3] < x0 or geom_box[g, 0] > x1 or geom_box[g, 4] < y0
                    or geom_box[g, 1] > y1):
                continue
            ia, ib = _grid_cells(geom_box[g, 0], geom_box[g, 3], x0, cell, nx)
            ja, jb = _grid_cells(geom_box[g, 1], geom_box[g, 4], y0, cell, ny)
            for j in range(ja, jb + 1):
                for c in range(j * nx + ia, j * nx + ib + 1):
                    if stage == 0:  # count
                        starts[c + 1] += 1
                        tops[c] = max(tops[c], geom_box[g, 5])
                    else:  # fill
                        entries[fill[c]] = g
                        fill[c] += 1
        if stage == 0:
            for c in range(ncell):
                starts[c + 1] += starts[c]
            fill = starts[:ncell].copy()
    return starts[ncell]


@jit
def _cast_keypoint_rays(origins, points, mask, person, J, kp_bodies, geom_type, geom_body, groups, scene_xpos,
                        scene_xmat, scene_size, scene_rbound, scene_person, const_of, scene_of, margin, occluded,
                        self_occluded, geomid, dist, cams, counts, bounds):
    """Occlusion flags of keypoints seen from camera centres (see the section comment).

    origins (R, 3): the camera centre of each capture; points (R, N, 3) keypoints, mask (R, N) which to
    cast, person (R, N // J) person id of each row of J keypoints; kp_bodies (J, 2) body and parent body
    of each keypoint; geom_type, geom_body (G,); groups (K + 1,) starts of contiguous geom groups (a
    person's geoms, the store's); scene_xpos, scene_xmat (T, G, ...) the geoms' positions and
    rotations (rows of 9) at T instants; scene_size, scene_rbound, scene_person (U, G, ...) their sizes,
    bounding radii and owners (U sets; const_of (T,) the set of each instant); scene_of (R,) the instant of
    each capture;
    margin: self_hit_margin_m.
    Writes occluded, self_occluded (R, N) bool and the nearest hit geomid (R, N) int32 (-1: none nearer
    than the keypoint) and its distance dist (R, N); adds each capture's keypoints cast, occluded and
    self-occluded to its camera's row cams[r] of counts (C, 3). bounds: scratch, (T, G + K, 6) at least.
    """
    T, G = scene_xpos.shape[0], geom_type.shape[0]
    for s in range(T):
        u = const_of[s]
        _scene_bounds(geom_type, groups, scene_xpos[s], scene_xmat[s], scene_size[u], scene_rbound[u], bounds[s])
    # One floor grid per instant over the rectangle the block's rays cross.
    x0, y0, x1, y1, z0 = _grid_extent(origins, points, mask)
    if not x1 > x0:  # nothing to cast
        x0, y0, x1, y1 = 0.0, 0.0, 1.0, 1.0
    cell = max(_GRID_CELL_M, (x1 - x0) / _GRID_MAX_CELLS, (y1 - y0) / _GRID_MAX_CELLS)
    nx, ny = max(int(math.ceil((x1 - x0) / cell)), 1), max(int(math.ceil((y1 - y0) / cell)), 1)
    ncell = nx * ny
    starts = np.empty((T, ncell + 1), dtype=np.int64)
    tops = np.empty((T, ncell))
    offset = np.zeros(T + 1, dtype=np.int64)
    counting = np.empty(0, dtype=np.int64)
    for s in range(T):
        offset[s + 1] = offset[s] + _build_grid(bounds[s, :G], x0, y0, z0, cell, nx, ny, starts[s], tops[s], counting,
                                                  False)
    entries = np.empty(offset[T], dtype=np.int64)
    for s in range(T):
        _build_grid(bounds[s, :G], x0, y0, z0, cell, nx, ny, starts[s], tops[s],
                    entries[offset[s]:offset[s + 1]], True)
    seen = np.full(G, -1, dtype=np.int64)  # the last ray that tested each geom
    ray = 0
    for r in range(points.shape[0]):
        s = scene_of[r]
        u = const_of[s]
        geom_xpos, geom_xmat, geom_size, geom_rbound = scene_xpos[s], scene_xmat[s], scene_size[u], scene_rbound[u]
        geom_person, geom_box = scene_person[u], bounds[s, :G]
        cell_start, cell_top, cell_geoms = starts[s], tops[s], entries[offset[s]:offset[s + 1]]
        ox, oy, oz = origins[r, 0], origins[r, 1], origins[r, 2]
        cast_here = occluded_here = self_occluded_here = 0
        for n in range(points.shape[1]):
            occluded[r, n] = False
            self_occluded[r, n] = False
            geomid[r, n] = -1
            dist[r, n] = -1.0
            if not mask[r, n]:
                continue
            cast_here += 1
            ray += 1
            px, py, pz = points[r, n, 0], points[r, n, 1], points[r, n, 2]
            vx, vy, vz = px - ox, py - oy, pz - oz
            length = math.sqrt(vx * vx + vy * vy + vz * vz)
            ux, uy, uz = vx / length, vy / length, vz / length
            lo_x, lo_y, lo_z = min(ox, px), min(oy, py), min(oz, pz)
            hi_x, hi_y, hi_z = max(ox, px), max(oy, py), max(oz, pz)
            # The cells the segment crosses, from the camera on (a 2D grid walk); in each, the distances
            # t_in..t_out along the ray. Only hits nearer than `reach` matter: the keypoint, then the nearest
            # hit so far; ties go to the geom first in model order, as in MuJoCo.
            best, best_g, reach = -1.0, -1, length
            i, j = _grid_cells(ox, ox, x0, cell, nx)[0], _grid_cells(oy, oy, y0, cell, ny)[0]
            step_i, step_j = (1 if ux > 0 else -1), (1 if uy > 0 else -1)
            next_x = x0 + (i + (1 if ux > 0 else 0)) * cell
            next_y = y0 + (j + (1 if uy > 0 else 0)) * cell
            t_x = (next_x - ox) / ux if ux != 0 else np.inf
            t_y = (next_y - oy) / uy if uy != 0 else np.inf
            dt_x = cell / abs(ux) if ux != 0 else np.inf
            dt_y = cell / abs(uy) if uy != 0 else np.inf
            t_in = 0.0
            while True:
                t_out = min(t_x, t_y, length)
                # The segment's lowest point in this cell, against the highest geom top in it.
                if min(oz + t_in * uz, oz + t_out * uz) <= cell_top[j * nx + i] + _GRID_SLACK_M:
                    for e in range(cell_start[j * nx + i], cell_start[j * nx + i + 1]):
                        g = cell_geoms[e]
                        if seen[g] == ray:
                            continue
                        seen[g] = ray
                        # (For a geom bounded by its sphere, the box test adds nothing to the sphere test.)
                        if geom_type[g] == _GEOM_BOX and (
                                hi_x < geom_box[g, 0] or lo_x > geom_box[g, 3] or hi_y < geom_box[g, 1]
                                or lo_y > geom_box[g, 4] or hi_z < geom_box[g, 2] or lo_z > geom_box[g, 5]):
                            continue
                        dx, dy, dz = geom_xpos[g, 0] - ox, geom_xpos[g, 1] - oy, geom_xpos[g, 2] - oz
                        along = dx * ux + dy * uy + dz * uz
                        radius = geom_rbound[g] + _CULL_SLACK_M
                        if (along + radius < 0 or along - radius > reach
                                or dx * dx + dy * dy + dz * dz - along * along > radius * radius):
                            continue
                        x = _ray_geom(g, geom_type, geom_xpos, geom_xmat, geom_size, ox, oy, oz, ux, uy, uz)
                        if x >= 0 and (best < 0 or x < best or (x == best and g < best_g)):
                            best, best_g = x, g
                            reach = min(reach, best)
                # Every hit in a later cell is at least t_out away.
                if t_out >= length:
                    break
                if best >= 0 and best < t_out - _GRID_SLACK_M:
                    break
                if t_x < t_y:
                    i += step_i
                    t_in, t_x = t_x, t_x + dt_x
                else:
                    j += step_j
                    t_in, t_y = t_y, t_y + dt_y
                if i < 0 or i >= nx or j < 0 or j >= ny:
                    break
            if best_g < 0 or not best < length:
                continue
            geomid[r, n] = best_g
            dist[r, n] = best
            q = n // J
            if geom_person[best_g] != person[r, q]:
                occluded[r, n] = True
                occluded_here += 1
            else:
                body = geom_body[best_g]
                k = n - q * J
                near = (body == kp_bodies[k, 0] or body == kp_bodies[k, 1]) and length - best <= margin
                self_occluded[r, n] = not near
                self_occluded_here += not near
        c = cams[r]
        counts[c, 0] += cast_here
        counts[c, 1] += occluded_here
        counts[c, 2] += self_occluded_here


@jit
def _frame_order(frame, key, n_frames, order):
    """np.lexsort((key, frame)) into order (D,): rows by frame (0 <= frame < n_frames), each frame's by key,
    ties in input order (a counting sort, then an insertion sort of each frame's few rows)."""
    start = np.zeros(n_frames + 1, dtype=np.int64)
    for d in range(frame.shape[0]):
        start[frame[d] + 1] += 1
    for f in range(n_frames):
        start[f + 1] += start[f]
    fill = start[:n_frames].copy()
    for d in range(frame.shape[0]):
        order[fill[frame[d]]] = d
        fill[frame[d]] += 1
    for f in range(n_frames):
        for i in range(start[f] + 1, start[f + 1]):
            d = order[i]
            k = i - 1
            while k >= start[f] and key[order[k]] > key[d]:
                order[k + 1] = order[k]
                k -= 1
            order[k + 1] = d


@jit
def _count_views(cams, in_img, occluded, self_occluded, counts):
    """Adds each capture's joints in the image, occluded and self-occluded ((R, N) bool) to its camera's row
    of counts (C, 3); cams (R,) the camera of each capture."""
    for r in range(in_img.shape[0]):
        c = cams[r]
        for n in range(in_img.shape[1]):
            counts[c, 0] += in_img[r, n]
            counts[c, 1] += occluded[r, n]
            counts[c, 2] += self_occluded[r, n]


_FRAGMENT, _GROSS_ERROR, _LEFT_RIGHT_SWAP, _DUPLICATE = (int(e) for e in (
    DetectionEffect.FRAGMENT, DetectionEffect.GROSS_ERROR, DetectionEffect.LEFT_RIGHT_SWAP, DetectionEffect.DUPLICATE))


@jit
def _person_size(px, p):
    """The size in the image of person-view px[p] (J, 2): the larger side of the bounding box of its known
    joints, NaN with none (`person_size_px` of any shape, compiled)."""
    high0 = high1 = -np.inf
    low0 = low1 = np.inf
    for j in range(px.shape[1]):
        x, y = px[p, j, 0], px[p, j, 1]
        if not np.isnan(x):
            high0, low0 = max(high0, x), min(low0, x)
        if not np.isnan(y):
            high1, low1 = max(high1, y), min(low1, y)
    extent = max(-np.inf, high0 - low0, high1 - low1)
    return extent if np.isfinite(extent) else np.nan


@jit
def _person_sizes(px):
    """(P,) `_person_size` of every person-view of px (P, J, 2)."""
    out = np.empty(px.shape[0])
    for p in range(px.shape[0]):
        out[p] = _person_size(px, p)
    return out


@jit
def large_enough(px, min_px):
    """(P,) whether each person-view of px (P, J, 2) is at least min_px[p] in the image (`person_size_px`)."""
    out = np.empty(px.shape[0], dtype=np.bool_)
    for p in range(px.shape[0]):
        out[p] = _person_size(px, p) >= min_px[p]
    return out


@jit
def _draw_detections(rng, person_ids, px, in_img, occluded, self_occluded, group, min_px, fragment_masks,
                     joint_noise, swap_order, model, out):
    """The detections of real people (`Detector._detections`): every draw from `rng` (a numpy Generator,
    whose stream numba reads and advances as numpy would) and what it does, person-view by person-view,
    each value drawn only where it is used.

    Per person-view (rows of px (P, J, 2), in_img, occluded, self_occluded (P, J), person_ids and group
    (P,)): never detected with fewer than `min_visible` visible joints in the image or smaller than
    min_px (P,) in it (`person_size_px`), else missed with probability miss + gain x its occluded share;
    a detection reports each joint in the image unless
    dropped (by the joint's occlusion), may keep only one body part (fragment), has Student-t noise
    scaled by the person's size in the image (`person_size_px`), the joint's noise factor and its
    occlusion, gross jumps of a uniform fraction of that size in a uniform direction, clipped normal
    scores, and may have left and right swapped; joints not reported are NaN with score 0. A detection
    with a joint reported may come with a duplicate: a second copy shifted by a normal offset of
    `_DUPLICATE_OFFSET_FRAC` of the size, repeating each joint with probability `_DUPLICATE_KEEP`, at
    `_DUPLICATE_SCORE` of the scores.

    model: the `DetectorParams`. Writes the rows (detections in person-view order, then their duplicates)
    into `out` (a `_DrawnRows` of 2P rows) and returns how many it wrote.
    """
    ids, kp, scores, true_px, out_in, out_occluded, out_self, effects, out_group = out
    dof = model.noise_tail_dof
    heavy = math.isfinite(dof)
    P, J = in_img.shape
    n_parts = fragment_masks.shape[0]
    reported = np.empty(J, dtype=np.bool_)
    value = np.empty((J, 2))
    score = np.empty(J)
    n = 0
    originals = np.empty(P, dtype=np.int64)  # rows of the detections, for their duplicates
    sizes = np.empty(P)
    for p in range(P):
        n_in = n_visible = n_occluded = 0
        for j in range(J):
            n_in += in_img[p, j]
            n_visible += in_img[p, j] and not occluded[p, j]
            n_occluded += occluded[p, j]
        if n_in == 0 or n_visible < model.min_visible_joints:
            continue
        size = _person_size(px, p)
        if not size >= min_px[p]:  # too small to detect (NaN: no joint known)
            continue
        if rng.random() < model.miss_prob + model.miss_occlusion_gain * n_occluded / n_in:
            continue
        effect = 0
        for j in range(J):
            drop = model.occluded_drop_prob if occluded[p, j] else (
                model.self_occluded_drop_prob if self_occluded[p, j] else model.joint_drop_prob)
            reported[j] = in_img[p, j] and rng.random() >= drop
        # Fragments keep one body part (if it holds a reported joint).
        if rng.random() < model.fragment_prob:
            part = rng.integers(0, n_parts)
            any_part = False
            for j in range(J):
                any_part = any_part or (reported[j] and fragment_masks[part, j])
            if any_part:
                for j in range(J):
                    reported[j] = reported[j] and fragment_masks[part, j]
                effect |= _FRAGMENT
        any_reported = False
        for j in range(J):
            if not reported[j]:
                value[j, 0] = value[j, 1] = np.nan
                score[j] = 0.0
                continue
            any_reported = True
            scale = model.noise_frac * size * joint_noise[j]
            scale = scale * (model.occluded_noise_scale if occluded[p, j] else (
                model.self_occluded_noise_scale if self_occluded[p, j] else 1.0))
            z0, z1 = rng.standard_normal(), rng.standard_normal()
            if heavy:  # Student-t: the normal core over the root of a chi-square / dof
                stretch = math.sqrt(dof / rng.chisquare(dof))
                z0, z1 = z0 * stretch, z1 * stretch
            value[j, 0], value[j, 1] = px[p, j, 0] + scale * z0, px[p, j, 1] + scale * z1
            if rng.random() < model.gross_error_prob:
                angle = rng.uniform(0.0, 2.0 * np.pi)
                jump = rng.uniform(_GROSS_MIN_FRAC, _GROSS_MAX_FRAC) * size
                value[j, 0] += jump * math.cos(angle)
                value[j, 1] += jump * math.sin(angle)
                effect |= _GROSS_ERROR
            base = model.score_occluded if occluded[p, j] else model.score_visible
            score[j] = min(max(base + model.score_std * rng.standard_normal(), _MIN_SCORE), 1.0)
        if not any_reported:
            continue
        swap = rng.random() < model.swap_prob
        if swap:
            effect |= _LEFT_RIGHT_SWAP
        for j in range(J):
            k = swap_order[j] if swap else j
            kp[n, j, 0], kp[n, j, 1], scores[n, j] = value[k, 0], value[k, 1], score[k]
            true_px[n, j, 0], true_px[n, j, 1] = px[p, j, 0], px[p, j, 1]
            out_in[n, j], out_occluded[n, j], out_self[n, j] = in_img[p, j], occluded[p, j], self_occluded[p, j]
        ids[n], effects[n], out_group[n] = person_ids[p], effect, group[p]
        originals[n], sizes[n] = p, size
        n += 1
    # Duplicates: a second, partial, shifted and less confident copy of a detection.
    D = n
    for d in range(D):
        if not rng.random() < model.duplicate_prob:
            continue
        p = originals[d]
        shift0 = _DUPLICATE_OFFSET_FRAC * sizes[d] * rng.standard_normal()
        shift1 = _DUPLICATE_OFFSET_FRAC * sizes[d] * rng.standard_normal()
        for j in range(J):
            repeat = not np.isnan(kp[d, j, 0]) and rng.random() < _DUPLICATE_KEEP
            kp[n, j, 0] = kp[d, j, 0] + shift0 if repeat else np.nan
            kp[n, j, 1] = kp[d, j, 1] + shift1 if repeat else np.nan
            scores[n, j] = scores[d, j] * _DUPLICATE_SCORE if repeat else 0.0
            true_px[n, j, 0], true_px[n, j, 1] = px[p, j, 0], px[p, j, 1]
            out_in[n, j], out_occluded[n, j], out_self[n, j] = in_img[p, j], occluded[p, j], self_occluded[p, j]
        ids[n], effects[n], out_group[n] = ids[d], effects[d] | _DUPLICATE, out_group[d]
        n += 1
    return n
