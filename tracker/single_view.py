"""A single-view 2D multi-person pose tracker per camera (SORT, Bewley et al. 2016): the paper's Table 5 baseline.

Each camera is tracked on its own, with nothing from the other cameras and no calibration: the 2D
counterpart that the cross-view tracker is compared with in the paper's Table 5 ("a simple single-view
tracking baseline [Bewley2016_sort]").

Per camera, as in SORT, with the pose's joints in place of SORT's box:

- each track holds a constant-velocity Kalman filter per joint, state (u, v, du/dt, dv/dt) in pixels and
  pixels per second. Time is the frames' stamps in seconds, not a frame count, because the cameras are
  unsynchronised and drop frames: the filter predicts over the real interval dt. A joint the detection
  did not report is only predicted;
- tracks (rows) and detections (columns) are matched by the Hungarian method
  (`scipy.optimize.linear_sum_assignment`) on a 2D affinity (`Affinity2D`): KEYPOINTS, the mean distance
  of the detection's joints to the track's predicted ones over the joints both know, in units of the
  diagonal of the track's predicted box (an OKS-like distance), a pair above `max_joint_distance` being no
  match; or IOU, SORT's 1 - IoU of the predicted and the detected box (`core.boxes`), a pair below
  `min_iou` being no match;
- an unmatched detection starts a tentative track; a track is confirmed after `min_hits` matched frames and
  removed when it has not been matched for more than `max_age_s` seconds;
- a detection's id is its track's id once the track is confirmed (the detection that confirms it
  included), else -1.

Why joints and not SORT's box: a pose detector's box is the box of the joints it reported, and it jumps
whenever joints drop out under occlusion. On store_layout1 (seed 0) one detection in five has an IoU
below SORT's 0.3 with the same person's detection in the previous frame of the same camera.

The Kalman filter is the textbook one (filterpy's `predict`/`update`), written out here so that the
package stays numpy and scipy only. Per joint and image axis, with state x = (position, velocity):

    predict:  x <- F x,             P <- F P F^T + Q
    update:   y = z - H x,          S = H P H^T + R,     K = P H^T S^-1,
              x <- x + K y,         P <- (I - K H) P

with F = [[1, dt], [0, 1]] (constant velocity), H = [1, 0] (the position is measured), Q the discretised
white-noise acceleration of spectral density q^2, Q = q^2 [[dt^3/3, dt^2/2], [dt^2/2, dt]], and R = sigma^2.
Both image axes share P (same F, Q, H and R), so P is (J, 2, 2) per track. Like DeepSORT, sigma and q
scale with the person's size in the image (the diagonal of the track's box), so that one setting fits a
person near the camera and one far from it.
"""

from __future__ import annotations

import enum
import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from core.boxes import box_iou, keypoint_boxes
from core.types import Camera, Frame, camera_index
from tracker.rows import Rows

logger = logging.getLogger(__name__)

_MIN_SCALE_PX = 1.0  # a box diagonal below this is held at it (a degenerate box still has a scale)
_NO_MATCH_COST = 1e6  # Hungarian cost of a pair the gate refuses


class Affinity2D(enum.Enum):
    """How a track and a detection of one camera are compared.

    KEYPOINTS: mean distance of the joints both know, over the diagonal of the track's predicted box.
    IOU: SORT's 1 - IoU of the track's predicted box and the detection's box.
    """

    KEYPOINTS = "keypoints"
    IOU = "iou"


@dataclass(frozen=True)
class SingleViewConfig:
    """Parameters of `SingleViewTracker`.

    Attributes:
        affinity: KEYPOINTS or IOU (see `Affinity2D`).
        max_joint_distance: KEYPOINTS gate: largest mean joint distance of a match, in diagonals of the
            track's predicted box, > 0.
        min_iou: IOU gate: least IoU of a match, in (0, 1] (SORT: 0.3).
        min_hits: matched frames a track needs to be confirmed, including the one that started it (SORT: 3).
        max_age_s: a track not matched for longer than this is removed, seconds (SORT: one frame; here ten
            frames of a 10 fps camera, so that a person hidden for a moment keeps the track).
        score_threshold: joints scored below this are ignored, [0, 1].
        measurement_std_frac: standard deviation of a measured joint coordinate, in box diagonals.
        accel_std_frac_per_s2: standard deviation of the white-noise acceleration of a joint coordinate,
            box diagonals per second squared.
        init_velocity_std_frac_per_s: standard deviation of a new joint's velocity, box diagonals per second.
    """

    affinity: Affinity2D = Affinity2D.KEYPOINTS
    max_joint_distance: float = 0.3
    min_iou: float = 0.3
    min_hits: int = 3
    max_age_s: float = 1.0
    score_threshold: float = 0.0
    measurement_std_frac: float = 0.05
    accel_std_frac_per_s2: float = 1.0
    init_velocity_std_frac_per_s: float = 0.5

    def __post_init__(self):
        if not isinstance(self.affinity, Affinity2D):
            raise ValueError(f"SingleViewConfig.affinity={self.affinity!r}: must be one of "
                             f"{[a.name for a in Affinity2D]}")
        if not self.max_joint_distance > 0:
            raise ValueError(f"SingleViewConfig.max_joint_distance={self.max_joint_distance}: must be > 0")
        if not 0.0 < self.min_iou <= 1.0:
            raise ValueError(f"SingleViewConfig.min_iou={self.min_iou}: must be in (0, 1]")
        if not (isinstance(self.min_hits, int) and self.min_hits >= 1):
            raise ValueError(f"SingleViewConfig.min_hits={self.min_hits}: must be an integer >= 1")
        if not self.max_age_s >= 0:
            raise ValueError(f"SingleViewConfig.max_age_s={self.max_age_s}: must be >= 0 seconds")
        if not 0.0 <= self.score_threshold <= 1.0:
            raise ValueError(f"SingleViewConfig.score_threshold={self.score_threshold}: must be in [0, 1]")
        for name in ("measurement_std_frac", "accel_std_frac_per_s2", "init_velocity_std_frac_per_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"SingleViewConfig.{name}={getattr(self, name)}: must be > 0")


_DEFAULT_CONFIG = SingleViewConfig()


@dataclass(frozen=True, eq=False)
class Track2D:
    """One confirmed track of one camera as the single-view tracker reports it.

    Attributes:
        id: identity, never reused within a run (unique over all cameras).
        camera: the camera it lives in.
        keypoints_px: (J, 2) filtered joints at `stamp_s`, pixels; NaN for a joint never seen.
        box_px: (4,) the box (x0, y0, x1, y1) of those joints, pixels.
        stamp_s: the time they refer to.
    """

    id: int
    camera: str
    keypoints_px: np.ndarray
    box_px: np.ndarray
    stamp_s: float


@dataclass(frozen=True, eq=False)
class SingleViewOutput:
    """What the single-view tracker reported after one frame (the 2D counterpart of `TrackerOutput`).

    Attributes:
        stamp_s: stamp of the frame that was processed.
        camera: name of that frame's camera.
        tracks: the camera's confirmed tracks matched in this frame.
        detection_track_ids: (D,) int64 id of the confirmed track each detection of the frame went to, -1
            for a detection left unassigned or held by a track not yet confirmed (as `detection_target_ids`).
    """

    stamp_s: float
    camera: str
    tracks: list[Track2D]
    detection_track_ids: np.ndarray


def kf_predict(pos: np.ndarray, vel: np.ndarray, P: np.ndarray, dt_s: float, accel_std: float):
    """Constant-velocity prediction of N points over dt seconds: x <- F x, P <- F P F^T + Q.

    Args:
        pos: (N, 2) positions, pixels.
        vel: (N, 2) velocities, pixels per second.
        P: (N, 2, 2) covariance of (position, velocity) along one image axis (both axes share it).
        dt_s: interval, seconds (>= 0).
        accel_std: q, standard deviation of the white-noise acceleration, pixels per second squared.

    Returns:
        (pos, vel, P) predicted.
    """
    F = np.array([[1.0, dt_s], [0.0, 1.0]])
    Q = accel_std**2 * np.array([[dt_s**3 / 3, dt_s**2 / 2], [dt_s**2 / 2, dt_s]])
    return pos + dt_s * vel, vel, F @ P @ F.T + Q


def kf_update(pos: np.ndarray, vel: np.ndarray, P: np.ndarray, z: np.ndarray, measurement_std: float):
    """Kalman update of N points with measured positions z (N, 2), each coordinate of std `measurement_std` px.

    With H = [1, 0]: S = P00 + sigma^2, K = P[:, 0] / S, x <- x + K (z - pos), P <- P - K P[0, :].

    Returns:
        (pos, vel, P) updated; shapes as `kf_predict`'s.
    """
    S = P[:, 0, 0] + measurement_std**2  # (N,)
    K = P[:, :, 0] / S[:, None]  # (N, 2): gains of position and velocity
    y = z - pos  # (N, 2) innovation, both axes
    return pos + K[:, :1] * y, vel + K[:, 1:] * y, P - K[:, :, None] * P[:, None, 0, :]


def keypoint_distances(predicted_px: np.ndarray, scales_px: np.ndarray, detected_px: np.ndarray) -> np.ndarray:
    """(T, D) mean distance of each detection's joints to each track's predicted joints, in track scales.

    Args:
        predicted_px: (T, J, 2) predicted joints, pixels (NaN: never seen).
        scales_px: (T,) each track's size, pixels (the diagonal of its box).
        detected_px: (D, J, 2) detected joints, pixels (NaN: not reported).

    Returns:
        (T, D) distances; NaN where the two share no joint.
    """
    err = np.linalg.norm(predicted_px[:, None] - detected_px[None, :], axis=-1)  # (T, D, J)
    known = np.isfinite(err)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(known, err, 0.0).sum(axis=-1) / known.sum(axis=-1) / scales_px[:, None]


def match(cost: np.ndarray, allowed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hungarian matching of tracks (rows) and detections (columns) on `cost`, pairs outside `allowed` refused.

    Args:
        cost: (T, D) cost, lower is better (NaN allowed where not allowed).
        allowed: (T, D) bool, the pairs the gate lets through.

    Returns:
        (rows, cols): int64 arrays of the matched track and detection indices, rows ascending.
    """
    if not allowed.any():
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    rows, cols = linear_sum_assignment(np.where(allowed, cost, _NO_MATCH_COST))
    keep = allowed[rows, cols]
    return rows[keep].astype(np.int64), cols[keep].astype(np.int64)


class _CameraTracks(Rows):
    """The tracks of one camera as a struct of arrays (N tracks, J joints)."""

    def __init__(self, num_joints: int):
        J = num_joints
        self.ids = np.zeros(0, dtype=np.int64)
        self.pos = np.zeros((0, J, 2))  # NaN: a joint never seen
        self.vel = np.zeros((0, J, 2))
        self.P = np.zeros((0, J, 2, 2))
        self.hits = np.zeros(0, dtype=np.int64)
        self.last_s = np.zeros(0)  # time of the last match
        self.time_s = np.zeros(0)  # time the state refers to

    _FIELDS = ("ids", "pos", "vel", "P", "hits", "last_s", "time_s")


def _scales(boxes: np.ndarray) -> np.ndarray:
    """(N,) diagonal of each box, at least `_MIN_SCALE_PX`."""
    return np.maximum(np.hypot(boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1]), _MIN_SCALE_PX)


class SingleViewTracker:
    """SORT per camera on the 2D poses, see the module docstring.

    Takes the same frames as `tracker.Tracker` in the same order; only the frames' stamps and pixels
    are used, never the calibration. Its input policy is the cross-view tracker's: a frame from an unknown
    camera or with a non-finite stamp is dropped with a logged warning (all its detections -1); NaN or
    infinite coordinates make a joint missing.

    Args:
        cameras: the cameras whose frames will come (unique names).
        config: parameters.

    Attributes:
        last_output: the SingleViewOutput of the latest `update`.
    """

    def __init__(self, cameras: Sequence[Camera], config: SingleViewConfig = _DEFAULT_CONFIG):
        self._index = camera_index(cameras, "SingleViewTracker")
        self.config = config
        self._tracks: dict[str, _CameraTracks] = {}  # made at a camera's first frame (J from the frame)
        self._next_id = 0
        self.last_output = SingleViewOutput(0.0, "", [], np.zeros(0, dtype=np.int64))

    def update(self, frame: Frame) -> list[Track2D]:
        """Processes one camera frame and returns that camera's confirmed tracks matched in it.

        Args:
            frame: detections of one camera, pixels (D, J, 2), scores (D, J).

        Returns:
            the confirmed tracks matched in this frame, joints filtered to `frame.stamp_s`.
        """
        t = float(frame.stamp_s)
        D, J = frame.keypoints_px.shape[:2]
        tracks = self._tracks.get(frame.camera)
        reason = None
        if frame.camera not in self._index:
            reason = "an unknown camera"
        elif not np.isfinite(t):
            reason = "a stamp that is not finite"
        elif tracks is not None and D and tracks.pos.shape[1] != J:
            reason = f"{J} joints where the camera's earlier frames had {tracks.pos.shape[1]}"
        if reason is not None:
            # The cross-view tracker's input policy: bad input is dropped with a warning, never raised.
            logger.warning("single-view: dropping frame %s@%s: %s", frame.camera, frame.stamp_s, reason)
            self.last_output = SingleViewOutput(t, frame.camera, [], np.full(D, -1, dtype=np.int64))
            return []
        if tracks is None:
            if D == 0:  # nothing to track yet, and an empty frame may not say how many joints come
                self.last_output = SingleViewOutput(t, frame.camera, [], np.zeros(0, dtype=np.int64))
                return []
            tracks = self._tracks[frame.camera] = _CameraTracks(J)
        cfg = self.config
        tracks.keep(t - tracks.last_s <= cfg.max_age_s)  # death (a frame from the past keeps everything)

        # Predict every track to the frame's stamp (a stamp older than a track's state: no motion).
        scales = _scales(keypoint_boxes(tracks.pos))
        for i in range(len(tracks.ids)):
            dt = max(t - tracks.time_s[i], 0.0)
            tracks.pos[i], tracks.vel[i], tracks.P[i] = kf_predict(
                tracks.pos[i], tracks.vel[i], tracks.P[i], dt, cfg.accel_std_frac_per_s2 * scales[i])
        tracks.time_s[:] = np.maximum(tracks.time_s, t)

        det = np.array(frame.keypoints_px, dtype=np.float64)
        det[~np.isfinite(det).all(axis=-1) | ~(frame.scores >= cfg.score_threshold)] = np.nan
        det_boxes = keypoint_boxes(det)  # (D, 4), NaN: fewer than two joints
        rows, cols = self._associate(tracks, det, det_boxes)

        # Update the matched tracks' joints with their detection's (a joint seen for the first time starts
        # at the measurement with the track's mean velocity).
        det_scales = _scales(det_boxes)
        for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
            self._update_track(tracks, r, det[c], det_scales[c])
            tracks.hits[r] += 1
            tracks.last_s[r] = t

        # Birth: every unmatched detection that has a box starts a tentative track.
        track_of = np.full(D, -1, dtype=np.int64)  # detection -> track row
        track_of[cols] = rows
        new = np.flatnonzero((track_of < 0) & np.isfinite(det_boxes).all(axis=1))
        if new.size:
            track_of[new] = len(tracks.ids) + np.arange(new.size)
            self._start(tracks, det[new], det_scales[new], t)

        confirmed = tracks.hits >= cfg.min_hits
        ids = np.full(D, -1, dtype=np.int64)
        has = track_of >= 0
        ids[has] = np.where(confirmed[track_of[has]], tracks.ids[track_of[has]], -1)
        out = []
        for r in np.sort(track_of[has & (ids >= 0)]).tolist():
            kp = tracks.pos[r].copy()
            out.append(Track2D(int(tracks.ids[r]), frame.camera, kp, keypoint_boxes(kp[None])[0], t))
        self.last_output = SingleViewOutput(t, frame.camera, out, ids)
        return out

    def _associate(self, tracks: _CameraTracks, det: np.ndarray, det_boxes: np.ndarray):
        """(rows, cols) of the matched tracks and detections under the configured affinity."""
        cfg = self.config
        pred_boxes = keypoint_boxes(tracks.pos)
        if cfg.affinity is Affinity2D.IOU:
            iou = box_iou(pred_boxes, det_boxes)
            return match(1.0 - iou, iou >= cfg.min_iou)
        d = keypoint_distances(tracks.pos, _scales(pred_boxes), det)
        with np.errstate(invalid="ignore"):
            return match(d, d <= cfg.max_joint_distance)

    def _update_track(self, tracks: _CameraTracks, r: int, z: np.ndarray, scale: float) -> None:
        """Kalman update of track r's joints with one detection z (J, 2) of size `scale` px."""
        cfg = self.config
        seen = np.isfinite(z).all(axis=-1)
        known = np.isfinite(tracks.pos[r]).all(axis=-1)
        both, first = seen & known, seen & ~known
        std = cfg.measurement_std_frac * scale
        if both.any():
            pos, vel, P = kf_update(tracks.pos[r, both], tracks.vel[r, both], tracks.P[r, both], z[both], std)
            tracks.pos[r, both], tracks.vel[r, both], tracks.P[r, both] = pos, vel, P
        if first.any():
            mean_vel = tracks.vel[r, known].mean(axis=0) if known.any() else np.zeros(2)
            tracks.pos[r, first] = z[first]
            tracks.vel[r, first] = mean_vel
            tracks.P[r, first] = self._initial_covariance(scale)

    def _initial_covariance(self, scale: float) -> np.ndarray:
        """(2, 2) covariance of a joint first seen in a detection of size `scale` px: the measurement's
        spread, and an unknown velocity."""
        cfg = self.config
        return np.diag([(cfg.measurement_std_frac * scale) ** 2, (cfg.init_velocity_std_frac_per_s * scale) ** 2])

    def _start(self, tracks: _CameraTracks, det: np.ndarray, scales: np.ndarray, t: float) -> None:
        """Appends one tentative track per detection det (N, J, 2), at rest."""
        n, J = det.shape[:2]
        P = np.stack([self._initial_covariance(s) for s in scales])  # (N, 2, 2)
        tracks.append(
            ids=self._next_id + np.arange(n, dtype=np.int64), pos=det.copy(), vel=np.zeros((n, J, 2)),
            P=np.repeat(P[:, None], J, axis=1), hits=np.ones(n, dtype=np.int64), last_s=np.full(n, t),
            time_s=np.full(n, t),
        )
        self._next_id += n
