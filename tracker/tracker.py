"""The cross-view tracker of Chen et al. (CVPR 2020), Algorithm 1: the one stateful class of the package.

Frames arrive one camera at a time in delivery order. For each frame: undistort, match the detections to the
targets in 3-space (eq. 1-5, Hungarian), update the matched targets by incremental triangulation (eq. 6-11),
and cluster the unmatched detections of the latest frame of each camera into new targets (eq. S1-S5).

Target state lives in arrays (T targets, C cameras, J joints, H history slots), not in per-target objects.

Input policy (bad input never raises; it is dropped or cleaned with a logged warning):
- a frame from an unknown camera, with a non-finite stamp, stamped at or before an earlier frame of the same
  camera, or stamped more than `max_lateness_s` before the newest stamp processed is dropped (warning); the
  output is then the targets predicted to the frame's stamp and every detection is -1;
- a frame stamped earlier than the newest stamp (within `max_lateness_s`) is processed at its own stamp;
  negative time differences are clipped to zero in the time weights;
- NaN or infinite coordinates, and NaN scores, make that joint missing; scores are clipped to [0, 1];
  joints scored below `score_threshold` are ignored; an empty frame only advances the lifecycle.
A frame whose joint count differs from the skeleton's is a programming error: ValueError.
"""

from __future__ import annotations

import logging
import statistics
from collections.abc import Sequence

import numpy as np

from core.errors import ConfigError
from core.types import COCO17, Camera, Frame, Skeleton, camera_index
from tracker import affinity as aff
from tracker import lifecycle
from tracker.association import associate
from tracker.body import mean_body, prior_bones, velocity_windows
from tracker.config import BONE_SAMPLES, TrackerConfig, Triangulation
from tracker.geometry import fundamental_matrix, ray_directions, undistort_detections, world_from_pixel_matrix
from tracker.initialization import PlausibilityLimits, check_plausible, consensus_views, partition_graph, reconstruct
from tracker.kernels import (
    BodyLimits,
    Priors,
    UpdateParams,
    has_body,
    implausible_bodies,
    output_poses,
    split_detections,
    update_matched,
)
from tracker.rows import Rows
from tracker.target_rows import TargetRows
from tracker.triangulation import TriangulationParams, row_norm_code
from tracker.types import TargetArrays, TrackerOutput
from tracker.visibility import (
    EvidenceParams,
    SightMap,
    all_view_planes,
    count_sightings,
    overlapping_views,
    sight_map_grid,
    targets_in_view,
)

logger = logging.getLogger(__name__)

_DEFAULT_CONFIG = TrackerConfig()

IMPLAUSIBLE_SHARE = 0.25
"""Share of a target's observed joints (or bones) out of the birth limits that makes its body implausible."""

FRAME_PERIOD_INTERVALS = 9
"""How many of a camera's latest stamp intervals give its frame period (their median: a dropped frame or a
jittered stamp does not move it), which turns eq. (2)'s α2D from pixels per frame into pixels per second."""

MAX_SIGHT_MAP_CELLS = 20_000_000
"""Most cells of all cameras' sight maps together (two float64 counts each: 320 MB)."""


class _TargetRowStore(Rows):
    """The live targets' rows (`TargetRows`, with the lifecycle's ids, states and birth times), grown on demand
    and compacted on removal.

    Attributes:
        rows: the current views of the fields as one `TargetRows`, the way the kernels take them (made again
            whenever the views are).
    """

    def __init__(self, num_cameras: int, num_joints: int, history: int, num_bones: int):
        self.ids = np.zeros(0, dtype=np.int64)
        self.state = np.zeros(0, dtype=np.int8)
        self.born_s = np.zeros(0)
        # The fields of `TargetRows`, which documents them.
        for name, empty in zip(TargetRows._fields, TargetRows.empty(0, num_cameras, num_joints, history,
                                                                                num_bones, BONE_SAMPLES)):
            setattr(self, name, empty)
        self.implausible_s = np.zeros(0)  # since when the observed body is implausible, NaN when it is not
        self._views()

    _FIELDS = ("ids", "state", "born_s", *TargetRows._fields, "implausible_s")

    def _views(self) -> None:
        super()._views()
        self.rows = TargetRows._make(self.__dict__[name] for name in TargetRows._fields)


class Tracker:
    """Cross-view multi-person 3D pose tracker (Chen et al., CVPR 2020).

    Args:
        cameras: the calibrated cameras (unique names).
        config: parameters (TrackerConfig.preset("campus"|"shelf"|"store") for Table S2).
        skeleton: the joint layout of the frames (COCO17, CAMPUS14, ...).

    Attributes:
        last_output: the TrackerOutput of the latest `update`.
    """

    def __init__(self, cameras: Sequence[Camera], config: TrackerConfig = _DEFAULT_CONFIG,
                 skeleton: Skeleton = COCO17):
        self._index = camera_index(cameras, "Tracker")
        self.cameras = list(cameras)
        self.config = config
        self.skeleton = skeleton
        self._bones = np.ascontiguousarray(np.asarray(skeleton.bones, dtype=np.int64).reshape(-1, 2))
        C, J = len(self.cameras), skeleton.num_joints
        self._P = np.stack([c.P for c in self.cameras]) if C else np.zeros((0, 3, 4))
        # Per-camera constants of the compiled kernels: eq. (3) R^T K^-1 and centre, lens model.
        self._world_from_pixel = np.stack([world_from_pixel_matrix(cam) for cam in self.cameras]) if C else None
        self._centers = np.stack([c.center_world for c in self.cameras]) if C else np.zeros((0, 3))
        self._K = [np.ascontiguousarray(cam.K, dtype=np.float64) for cam in self.cameras]
        self._dist = [np.ascontiguousarray(cam.dist, dtype=np.float64) for cam in self.cameras]
        cfg = config
        self._init_min_joints = int(cfg.init_min_joints)
        self._affinity_params = aff.AffinityParams(
            w_2d=float(cfg.w_2d), alpha_2d_floor_px=float(cfg.alpha_2d_floor_px), w_3d=float(cfg.w_3d),
            alpha_3d_m=float(cfg.alpha_3d_m), lambda_a_per_s=float(cfg.lambda_a_per_s),
            max_predict_s=float(cfg.max_predict_s), normalize=bool(cfg.normalize_affinity))
        mode = cfg.triangulation
        self._reconstruction_row_norm = row_norm_code(cfg, reconstruction=True)
        # The body prior's bones (docs/tracker.md, "Body and joint priors"), none when it is off.
        self._prior_bones, mirror = prior_bones(skeleton, bool(cfg.head_bones))
        if not cfg.bone_prior_tolerance > 0:
            self._prior_bones, mirror = self._prior_bones[:0], mirror[:0]
        prior = Priors(
            gate_m=float(cfg.joint_gate_m), gate_reset_s=float(cfg.joint_gate_reset_s),
            tolerance=float(cfg.bone_prior_tolerance), min_views=int(cfg.bone_prior_min_views),
            min_samples=int(cfg.bone_prior_min_samples), sample_s=float(cfg.bone_prior_sample_s),
            symmetric=bool(cfg.bone_symmetry), bones=self._prior_bones, mirror=mirror,
            resolve=bool(cfg.bone_prior_resolve),
            quadratic=bool(cfg.velocity_quadratic), window_s=velocity_windows(skeleton, cfg))
        self._update_params = UpdateParams(
            max_observation_age_s=float(cfg.max_observation_age_s),
            triangulation=TriangulationParams(
                lambda_t_per_s=float(cfg.lambda_t_per_s) if mode.weighs_time else 0.0,
                use_velocity=mode is Triangulation.VELOCITY, min_views=int(cfg.min_views),
                reject_factor=float(cfg.reject_factor), reject_floor_px=float(cfg.reject_floor_px),
                row_norm=row_norm_code(cfg)),
            max_bone_m=float(cfg.max_bone_m),
            velocity_window_s=float(cfg.velocity_window_s), max_speed_m_per_s=float(cfg.max_speed_m_per_s),
            stale_after_s=float(cfg.stale_after_s), max_predict_s=float(cfg.max_predict_s), prior=prior)
        self._evidence_params = EvidenceParams(
            max_predict_s=float(cfg.max_predict_s), inside_m=float(cfg.ghost_inside_m),
            window_s=float(cfg.ghost_window_s), prior_count=float(cfg.ghost_map_prior_count))
        # View volumes (which targets a frame is scored against) and the camera pairs whose views share part
        # of the band of heights where joints can be (the only pairs initialisation links, so the only ones
        # whose fundamental matrix is needed).
        self._planes = all_view_planes(self.cameras)
        self._linked = overlapping_views(self.cameras, config.init_min_bottom_m, config.init_max_top_m,
                                         config.view_margin_m)
        self._F = np.zeros((C, C, 3, 3))  # F[a, b]: x_b^T F x_a = 0 (eq. S1)
        for a, b in zip(*np.nonzero(self._linked)):
            if a != b:
                self._F[a, b] = fundamental_matrix(self.cameras[a], self.cameras[b])
        # Each camera's sight map (docs/tracker.md, "No ghosts"): how often it matched confirmed targets per cell.
        grid, nx, ny = sight_map_grid(self.cameras, config.ghost_cell_m)
        if C * nx * ny > MAX_SIGHT_MAP_CELLS:
            raise ConfigError(f"TrackerConfig.ghost_cell_m: {config.ghost_cell_m} m makes {C} sight maps of "
                              f"{nx * ny:,} cells (over {MAX_SIGHT_MAP_CELLS:,} in all); raise it, or 0 for no map")
        self._sight_maps = [SightMap(grid, nx, ny, np.zeros(nx * ny + 1), np.zeros(nx * ny + 1)) for _ in range(C)]
        self._targets = _TargetRowStore(C, J, config.velocity_history, self._prior_bones.shape[0])
        self._next_id = 0
        self._camera_last_s = np.full(C, -np.inf)
        # Each camera's latest stamp intervals (a ring, NaN unfilled) and their median, its frame period (NaN
        # before its second frame).
        self._intervals_s = np.full((C, FRAME_PERIOD_INTERVALS), np.nan)
        self._num_intervals = np.zeros(C, dtype=np.int64)
        self._period_s = np.full(C, np.nan)
        self._newest_s = -np.inf
        # Unmatched detections of the latest frame of each camera (Algorithm 1's D_u).
        self._pool_px: list[np.ndarray] = [np.zeros((0, J, 2)) for _ in range(C)]
        self._pool_s = np.full(C, -np.inf)
        self._pool_size = np.zeros(C, dtype=np.int64)
        self._pool_frame_index: list[np.ndarray] = [np.zeros(0, dtype=np.int64) for _ in range(C)]
        self._limits = PlausibilityLimits(
            max_reprojection_px=config.init_max_reprojection_px, min_joints_3d=config.init_min_joints_3d,
            max_bone_m=config.init_max_bone_m, min_top_m=config.init_min_top_m, max_top_m=config.init_max_top_m,
            min_bottom_m=config.init_min_bottom_m)
        self._body_limits = BodyLimits(
            stale_after_s=float(config.stale_after_s), min_bottom_m=float(config.init_min_bottom_m),
            max_top_m=float(config.init_max_top_m), max_bone_m=float(config.init_max_bone_m),
            max_reprojection_px=float(config.init_max_reprojection_px), share=IMPLAUSIBLE_SHARE)
        self._mean_body = mean_body(skeleton)
        self._hips = self._hip_joints(skeleton)
        self.last_output = TrackerOutput(stamp_s=0.0, camera="", targets=[],
                                         detection_target_ids=np.zeros(0, dtype=np.int64))

    # ------------------------------------------------------------------ public API

    def update(self, frame: Frame) -> TargetArrays:
        """Processes one camera frame (Algorithm 1) and returns the confirmed targets at `frame.stamp_s`.

        Args:
            frame: detections of one camera, distorted pixels (D, J, 2), scores (D, J).

        Returns:
            Confirmed targets (a sequence of `Target`) with poses (J, 3) predicted to the frame's stamp;
            joints never triangulated are inferred from the target's body (`joint_state`).
        """
        D = frame.keypoints_px.shape[0]
        J = self.skeleton.num_joints
        if D and frame.keypoints_px.shape[1] != J:
            raise ValueError(f"Frame {frame.camera}@{frame.stamp_s}: {frame.keypoints_px.shape[1]} joints, "
                             f"the tracker's skeleton {self.skeleton.name} has {J}")
        t = float(frame.stamp_s)
        reason = self._reject_reason(frame, t)
        if reason is not None:
            logger.warning("dropping frame %s@%s: %s", frame.camera, frame.stamp_s, reason)
            out_t = t if np.isfinite(t) else max(self._newest_s, 0.0)
            return self._emit(out_t, frame.camera, np.full(D, -1, dtype=np.int64))
        c = self._index[frame.camera]
        if np.isfinite(self._camera_last_s[c]):
            self._note_interval(c, t - self._camera_last_s[c])
        self._camera_last_s[c] = t
        self._newest_s = max(self._newest_s, t)
        self._advance_lifecycle(t)
        if D == 0:
            self._record_evidence(c, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, J, 2)), t)
            self._set_pool(c, np.zeros((0, J, 2)), np.zeros(0, dtype=np.int64), t)
            return self._emit(t, frame.camera, np.zeros(0, dtype=np.int64))

        det_px, usable = self._clean(frame, c)  # (D, J, 2) undistorted, NaN for unusable joints; (D,) counts
        matched_rows, matched_cols = self._associate(c, det_px, t)
        if matched_rows.size:
            self._update_targets(c, matched_rows, matched_cols, det_px, t)
        self._record_evidence(c, matched_rows, matched_cols, det_px, t)
        # (D,) matched target ids, and the unmatched detections with enough joints to start a target
        assigned, unmatched = split_detections(usable, self._init_min_joints, matched_rows, matched_cols,
                                               self._targets.ids)
        self._set_pool(c, det_px[unmatched], unmatched, t)
        if unmatched.size:
            for new_id, frame_index in self._initialize(c, t):
                assigned[frame_index] = new_id
        return self._emit(t, frame.camera, assigned)

    def frame_period_s(self, camera: str) -> float:
        """The camera's frame period as its stamps show it: the median of its latest `FRAME_PERIOD_INTERVALS`
        intervals between processed frames, s; NaN before its second frame."""
        return float(self._period_s[self._index[camera]])

    # ------------------------------------------------------------------ steps

    def _note_interval(self, c: int, interval_s: float) -> None:
        k = self._num_intervals[c]
        self._intervals_s[c, k % FRAME_PERIOD_INTERVALS] = interval_s
        self._num_intervals[c] = k + 1
        # (statistics' median of the few floats: np.median's own value, at a twentieth of its cost per frame)
        self._period_s[c] = statistics.median(self._intervals_s[c, :min(k + 1, FRAME_PERIOD_INTERVALS)].tolist())

    def _reject_reason(self, frame: Frame, t: float) -> str | None:
        if frame.camera not in self._index:
            return f"unknown camera (known: {', '.join(self._index)})"
        if not np.isfinite(t):
            return "non-finite stamp"
        c = self._index[frame.camera]
        if t <= self._camera_last_s[c]:
            return f"stamp not after this camera's previous frame ({self._camera_last_s[c]})"
        if t < self._newest_s - self.config.max_lateness_s:
            return f"more than max_lateness_s={self.config.max_lateness_s} s older than stamp {self._newest_s}"
        return None

    def _clean(self, frame: Frame, c: int) -> tuple[np.ndarray, np.ndarray]:
        """(D, J, 2) undistorted pixels, NaN where the joint is missing, non-finite or below threshold (scores
        NaN read as 0, clipped to [0, 1]), and the (D,) number of usable joints of each detection."""
        kp, scores = frame.keypoints_px, frame.scores
        out = np.empty(kp.shape)
        usable = undistort_detections(kp if kp.flags.c_contiguous else np.ascontiguousarray(kp),
                                      scores if scores.flags.c_contiguous else np.ascontiguousarray(scores),
                                      float(self.config.score_threshold), self._K[c], self._dist[c], out)
        return out, usable

    def _advance_lifecycle(self, t: float) -> None:
        tg = self._targets
        if not len(tg):
            return
        cfg = self.config
        ghost = lifecycle.ghosts(tg.expected, tg.sighted, tg.state, tg.implausible_s, t, cfg)
        if ghost.any():
            logger.debug("removing ghost targets %s", tg.ids[ghost].tolist())
        tg.state = lifecycle.on_time(tg.state, tg.last_update_s, t, cfg, ghost)
        removed = tg.state == lifecycle.REMOVED
        if removed.any():
            tg.keep(~removed)

    def _associate(self, c: int, det_px: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Eq. (1)-(5) affinity of every (target, detection) pair, then the Hungarian algorithm."""
        tg, cfg = self._targets, self.config
        if not len(tg):
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        # Only the targets this camera can see (tracker.visibility): the others have no positive affinity.
        rows = np.empty(len(tg), dtype=np.int64)
        rows = rows[:targets_in_view(self._planes[c], c, tg.pos, tg.vel, tg.joint_s, tg.obs_s, tg.cam_s, t,
                                     float(cfg.max_predict_s), float(cfg.view_margin_m),
                                     float(cfg.max_observation_age_s), rows)]
        if not rows.size:
            return rows, np.zeros(0, dtype=np.int64)
        # Eq. (4)'s time penalty counts from the joint's last observation t', also for a joint carried with
        # the body since (its position is a guess, so it keeps losing weight as in the paper).
        # Eq. (2)'s α2D is pixels per frame of this camera (Table S2): per second, divided by its frame period,
        # and at least alpha_2d_floor_px_per_s (beyond the paper; 0 in the -paper presets). (The period is NaN
        # before the camera's second frame, when no target can hold a point of this camera for eq. 2.)
        alpha_2d_px_per_s = max(cfg.alpha_2d_px_per_frame / self._period_s[c], cfg.alpha_2d_floor_px_per_s)
        matrix = np.empty((rows.size, det_px.shape[0]))
        aff.affinity_matrix(tg.rows, c, det_px, self._world_from_pixel[c], self._centers[c], t, alpha_2d_px_per_s,
                            self._affinity_params, rows, matrix)
        matched, cols = associate(matrix)  # eq. (1), (T, D)
        return rows[matched], cols

    def _update_targets(self, c: int, rows: np.ndarray, cols: np.ndarray, det_px: np.ndarray, t: float) -> None:
        """Incremental 3D reconstruction (eq. 6-11) of the matched targets, then velocity and lifecycle.

        `kernels.update_matched` does it in place: the detection's joints become the camera's latest points;
        each joint it holds is triangulated from the latest point of every camera not older than
        `max_observation_age_s`; an estimate that would make a bone longer than `max_bone_m` is not taken (a
        gross 2D error seen in two views, beyond the paper); the paper's estimates feed the least-squares
        velocity of eq. (5); a joint unseen for `stale_after_s` moves with the body (beyond the paper).

        Args:
            rows: (M,) matched targets; cols: (M,) their detections in det_px (D, J, 2).
        """
        tg = self._targets
        update_matched(rows, cols, det_px, c, t, tg.rows, self._P, self._bones, self._update_params)
        tg.state[rows] = lifecycle.on_match(tg.state[rows], tg.born_s[rows], tg.num_updates[rows], t, self.config,
                                            self._has_body(rows))

    def _record_evidence(self, c: int, rows: np.ndarray, cols: np.ndarray, det_px: np.ndarray, t: float) -> None:
        """What camera c's frame says about each target (docs/tracker.md, "No ghosts").

        1. Sightings: every target whose predicted hip centre lies `ghost_inside_m` inside the camera's view
           volume should have been seen, as often as the camera's sight map says it sees confirmed targets
           there; its decayed counts of expected and matched sightings (time constant `ghost_window_s`) are
           updated, and the confirmed targets teach the map.
        2. Plausibility: each matched target's observed body (joints triangulated within `stale_after_s`) is
           implausible when more than `IMPLAUSIBLE_SHARE` of its observed joints lie outside the heights
           [init_min_bottom_m, init_max_top_m] or of its observed bones are longer than init_max_bone_m, or its
           median reprojection error in this frame exceeds init_max_reprojection_px (shares, not single joints:
           one joint badly triangulated for a moment is the tracker's own business); `implausible_s` holds
           since when it is, NaN while it is not.

        Args:
            rows, cols: (M,) the matched targets and their detections in det_px (D, J, 2).
        """
        tg = self._targets
        if not len(tg) or self._hips.size == 0:
            return
        matched = np.zeros(len(tg), dtype=np.bool_)
        matched[rows] = True
        count_sightings(self._planes[c], self._hips, tg.rows, t, matched, tg.state == lifecycle.CONFIRMED,
                        self._sight_maps[c], self._evidence_params)
        if rows.size:
            bad = np.empty(rows.size, dtype=np.bool_)
            implausible_bodies(rows, cols, det_px, self._P[c], tg.pos, tg.seen_s, t, self._bones, self._body_limits,
                               bad)
            start = bad & np.isnan(tg.implausible_s[rows])
            tg.implausible_s[rows[start]] = t
            tg.implausible_s[rows[~bad]] = np.nan

    @staticmethod
    def _hip_joints(skeleton: Skeleton) -> np.ndarray:
        """The root joints a target needs before confirmation: the hips, or none in a layout without them."""
        try:
            return np.asarray(skeleton.hips, dtype=np.int64)
        except ValueError:
            return np.zeros(0, dtype=np.int64)

    def _has_body(self, rows: np.ndarray) -> np.ndarray:
        """(M,) whether each target has its root (both hips) and `init_min_joints_3d` joints triangulated: the
        body a confirmation needs (its other joints can then be inferred from it, tracker.body)."""
        return has_body(self._targets.pos, rows, self._hips, int(self.config.init_min_joints_3d))

    def _set_pool(self, c: int, px: np.ndarray, frame_index: np.ndarray, t: float) -> None:
        self._pool_px[c] = px
        self._pool_frame_index[c] = frame_index
        self._pool_s[c] = t
        self._pool_size[c] = px.shape[0]

    def _initialize(self, c: int, t: float) -> list[tuple[int, np.ndarray]]:
        """Supplement: epipolar affinity (S2), partitioning (S3-S5) and new targets, around each of this frame's
        unmatched detections.

        The graph is the one of Algorithm S1 restricted to where this frame adds to it: for each unmatched
        detection x of camera c, x and, from each other camera, the pooled detection with the largest positive
        affinity to x (eq. S2). A cluster holds one detection per camera, and only a detection with a positive
        affinity to x adds to (S3) by joining x's; of a camera's several such, the others are mostly people
        who happen to lie along x's epipolar line (in a crowd seen by hundreds of cameras, most of them), and
        of the cameras' best matches only those that agree on where x is stay (`consensus_views`, beyond the
        paper). The clusters without any of c's detections were the graph's when their own latest camera's frame came,
        and their detections are still pooled only because they were not a plausible new person then. So a
        frame costs its unmatched detections times the pool, and a partition of at most one node per camera
        for each, however many people the store holds. The cluster holding x becomes a target when it is
        plausible and has its root (both hips triangulated); its detections leave the pool.

        Returns:
            (new target id, indices of the current frame's detections in its cluster) per new target.
        """
        cfg = self.config
        # Only cameras whose views overlap c's: the others' detections have no positive affinity to c's (eq. S2).
        pooled = self._linked[c] & (self._pool_size > 0) & (np.abs(t - self._pool_s) <= cfg.init_window_s)
        pooled[c] = False
        cams = np.flatnonzero(pooled).tolist()
        new_px = self._pool_px[c]
        if not cams or not new_px.shape[0]:
            return []
        node_cam = np.concatenate([np.full(self._pool_px[k].shape[0], k) for k in cams])
        node_pos = np.concatenate([np.arange(self._pool_px[k].shape[0]) for k in cams])
        node_px = np.concatenate([self._pool_px[k] for k in cams])
        alpha_px, min_common = cfg.alpha_epipolar_px, cfg.init_min_common_joints
        to_pool = aff.epipolar_affinity_between(new_px, np.full(new_px.shape[0], c), node_px, node_cam, self._F,
                                                alpha_px, min_common, self._linked)  # eq. (S2), (D_c, n)
        taken = np.zeros(node_cam.size, dtype=bool)
        created: list[tuple[int, np.ndarray]] = []
        used: dict[int, list[int]] = {c: []}
        for x in range(new_px.shape[0]):
            near = np.flatnonzero((to_pool[x] > 0) & ~taken)
            # x's cluster holds one detection per camera at most: each camera's best match to x
            near = near[np.lexsort((-to_pool[x, near], node_cam[near]))]
            near = np.sort(near[np.unique(node_cam[near], return_index=True)[1]])
            if near.size:
                rays = ray_directions(None, new_px[x], self._world_from_pixel[c])
                candidate_rays = ray_directions(None, node_px[near], self._world_from_pixel[node_cam[near]][:, None])
                near = near[consensus_views(self._centers[c], rays, self._centers[node_cam[near]], candidate_rays,
                                            to_pool[x, near], cfg.init_min_common_joints, cfg.init_consensus_m)]
            if near.size + 1 < cfg.min_views:
                continue
            ks = np.concatenate([[c], node_cam[near]])
            pts = np.concatenate([new_px[x:x + 1], node_px[near]])  # (V, J, 2)
            A = aff.epipolar_affinity_matrix(pts, ks, self._F, alpha_px, min_common, self._linked)
            cluster = next(p for p in partition_graph(A, cfg.milp_max_nodes) if p[0] == 0)  # the one holding x
            if cluster.size < cfg.min_views:
                continue
            ks, pts = ks[cluster], pts[cluster]
            stamps = self._pool_s[ks]
            pose = reconstruct(self._P[ks], pts, stamps, t, cfg.lambda_t_per_s, cfg.min_views,
                               self._reconstruction_row_norm)
            why = check_plausible(pose, self._P[ks], pts, self.skeleton, self._limits)
            if why is None and not np.isfinite(pose[self._hips]).all():
                why = "a hip not triangulated"
            if why is None and self._duplicates_existing(pose, t):
                why = "duplicate of an existing target"
            if why is not None:
                logger.debug("initialisation: cluster of %d views rejected: %s", cluster.size, why)
                continue
            new_id = self._create_target(ks, pts, stamps, pose, t)
            members = near[cluster[1:] - 1]
            taken[members] = True
            used[c].append(x)
            for k, d in zip(node_cam[members], node_pos[members]):
                used.setdefault(int(k), []).append(int(d))
            created.append((new_id, self._pool_frame_index[c][x:x + 1]))
        for k, gone in used.items():
            keep = np.setdiff1d(np.arange(self._pool_px[k].shape[0]), gone)
            self._pool_px[k] = self._pool_px[k][keep]
            self._pool_frame_index[k] = self._pool_frame_index[k][keep]
            self._pool_size[k] = keep.size
        return created

    def _duplicates_existing(self, pose: np.ndarray, t: float) -> bool:
        tg, cfg = self._targets, self.config
        if not len(tg):
            return False
        predicted = aff.predict_positions(tg.pos, tg.vel, tg.joint_s, t, cfg.max_predict_s)
        dist = np.linalg.norm(predicted - pose, axis=-1)  # (T, J)
        with np.errstate(invalid="ignore"):
            counts = np.sum(np.isfinite(dist), axis=1)
            mean = np.nansum(dist, axis=1) / np.maximum(counts, 1)
        return bool(np.any((counts >= 3) & (mean < cfg.init_min_separation_m)))

    def _create_target(self, ks: np.ndarray, pts: np.ndarray, stamps: np.ndarray, pose: np.ndarray,
                       t: float) -> int:
        C, J, H = len(self.cameras), self.skeleton.num_joints, self.config.velocity_history
        B = self._prior_bones.shape[0]
        obs_px = np.full((1, C, J, 2), np.nan)
        obs_s = np.full((1, C, J), np.nan)
        obs_px[0, ks] = pts
        obs_s[0, ks] = np.where(np.isfinite(pts[..., 0]), stamps[:, None], np.nan)
        cam_s = np.full((1, C), np.nan)
        cam_s[0, ks] = stamps
        known = np.all(np.isfinite(pose), axis=-1)
        hist_pos = np.full((1, H, J, 3), np.nan)
        hist_s = np.full((1, H, J), np.nan)
        hist_pos[0, 0] = pose
        hist_s[0, 0] = np.where(known, t, np.nan)
        state, born_s, num_updates = lifecycle.TENTATIVE, t, ks.size
        lost = self._lost_nearby(pose, t)
        if lost is None:
            new_id = self._next_id
            self._next_id += 1
        else:
            # The person reappears near where a lost target was last seen: it takes that identity back.
            tg = self._targets
            new_id, state, born_s = int(tg.ids[lost]), int(tg.state[lost]), float(tg.born_s[lost])
            num_updates += int(tg.num_updates[lost])
            tg.keep(np.arange(len(tg)) != lost)
        self._targets.append(
            ids=np.array([new_id]), state=np.array([state], dtype=np.int8), born_s=np.array([born_s]),
            last_update_s=np.array([t]), num_updates=np.array([num_updates]), pos=pose[None],
            joint_s=np.where(known, t, -np.inf)[None], seen_s=np.where(known, t, -np.inf)[None],
            vel=np.zeros((1, J, 3)), obs_px=obs_px, obs_s=obs_s, cam_s=cam_s,
            expected=np.zeros(1), sighted=np.zeros(1), evidence_s=np.array([t]), implausible_s=np.array([np.nan]),
            hist_pos=hist_pos, hist_s=hist_s, hist_next=np.array([1]),
            bone_samples=np.full((1, BONE_SAMPLES, B), np.nan), bone_next=np.zeros(1, np.int64),
            bone_sampled_s=np.array([-np.inf]), bone_len=np.full((1, B), np.nan))
        tg = self._targets
        last = np.array([len(tg) - 1])
        tg.state[last] = lifecycle.on_match(tg.state[last], tg.born_s[last], tg.num_updates[last], t, self.config,
                                            self._has_body(last))
        return new_id

    def _lost_nearby(self, pose: np.ndarray, t: float) -> int | None:
        """Row of the LOST target whose last ground position is nearest to `pose` (J, 3) within reach, or None.

        Reach: `reid_speed_m_per_s` times the time since the target's last update, at least 0.5 m and at
        most `reid_max_m` (0 disables re-identification: the paper starts a new identity).
        """
        tg, cfg = self._targets, self.config
        if cfg.reid_max_m <= 0 or not len(tg):
            return None
        lost = np.flatnonzero(tg.state == lifecycle.LOST)
        if not lost.size:
            return None
        with np.errstate(invalid="ignore"):
            here = np.nanmean(pose[:, :2], axis=0)
            there = np.nanmean(tg.pos[lost, :, :2], axis=1)  # (L, 2)
        dist = np.linalg.norm(there - here, axis=-1)
        reach = np.clip(cfg.reid_speed_m_per_s * (t - tg.last_update_s[lost]), 0.5, cfg.reid_max_m)
        dist = np.where(np.isfinite(dist) & (dist <= reach), dist, np.inf)
        best = int(np.argmin(dist))
        return int(lost[best]) if np.isfinite(dist[best]) else None

    def _emit(self, t: float, camera: str, assigned: np.ndarray) -> TargetArrays:
        tg = self._targets
        # Eq. (5) to the stamp; joints never triangulated from the target's own body (tracker.body).
        params = self._update_params
        ids, poses, codes = output_poses(tg.state, lifecycle.CONFIRMED, tg.ids, tg.pos, tg.vel, tg.joint_s, tg.seen_s,
                                         t, params.max_predict_s, params.stale_after_s, self._mean_body, self._bones)
        targets = TargetArrays(ids, poses, codes, t, lifecycle.to_state(lifecycle.CONFIRMED))
        self.last_output = TrackerOutput(stamp_s=t, camera=camera, targets=targets, detection_target_ids=assigned)
        return targets
