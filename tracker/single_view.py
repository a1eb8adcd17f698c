"""A single-view 2D multi-person tracker per camera (SORT, Bewley et al. 2016): the paper's Table 5 baseline.

Each camera is tracked on its own, with nothing from the other cameras and no calibration: the 2D
counterpart that the cross-view tracker is compared with in the paper's Table 5 ("a simple single-view
tracking baseline [Bewley2016_sort]").

Per camera, as in SORT:

- a detection is the bounding box of its reported joints (`core.boxes.keypoint_boxes`);
- each track holds a constant-velocity Kalman filter on its box, state x = (cx, cy, w, h, vcx, vcy, vw, vh)
  in pixels and pixels per second. Time is the frames' stamps in seconds, not a frame count, because the
  cameras are unsynchronised and drop frames: the filter predicts over the real interval dt;
- tracks (rows) and detections (columns) are matched by the Hungarian method on 1 - IoU of the predicted
  box and the detection's box (`scipy.optimize.linear_sum_assignment`); a pair below `min_iou` is no match;
- an unmatched detection starts a tentative track; a track is confirmed after `min_hits` matched frames and
  removed when it has not been matched for more than `max_age_s` seconds;
- a detection's id is its track's id once the track is confirmed (the detection that confirms it
  included), else -1.

The Kalman filter is the textbook one (filterpy's `predict`/`update`), written out here so that the
package stays numpy and scipy only:

    predict:  x <- F x,             P <- F P F^T + Q
    update:   y = z - H x,          S = H P H^T + R,     K = P H^T S^-1,
              x <- x + K y,         P <- (I - K H) P

with F = [[I, dt I], [0, I]] (constant velocity), H = [I, 0] (the box is measured), Q the discretised
white-noise acceleration of spectral density q^2 per coordinate, Q = q^2 [[dt^3/3, dt^2/2], [dt^2/2, dt]],
and R = diag(sigma^2). Like DeepSORT, sigma and q scale with the box height, so that one setting fits a
person near the camera and one far from it.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from core.boxes import box_iou, keypoint_boxes
from core.types import Camera, Frame, camera_index

logger = logging.getLogger(__name__)

_DIM = 4  # measured box coordinates: cx, cy, w, h
_MIN_SIZE_PX = 1.0  # a box side below this is held at it (a degenerate box still has a scale)


@dataclass(frozen=True)
class SingleViewConfig:
    """Parameters of `SingleViewTracker`.

    Attributes:
        min_iou: least IoU of a track's predicted box and a detection's box for them to match, in [0, 1]
            (SORT: 0.3).
        min_hits: matched frames a track needs to be confirmed, including the one that started it (SORT: 3).
        max_age_s: a track not matched for longer than this is removed, seconds (SORT: 1 frame; here a
            few frames of a 10 fps camera, so that a short miss does not end a track).
        score_threshold: joints scored below this are left out of a detection's box, [0, 1].
        measurement_std_frac: standard deviation of a measured box coordinate, as a fraction of the box
            height (DeepSORT: 1/20).
        accel_std_frac_per_s2: standard deviation of the white-noise acceleration of each box coordinate,
            box heights per second squared.
        init_velocity_std_frac_per_s: standard deviation of a new track's velocity, box heights per second.
    """

    min_iou: float = 0.3
    min_hits: int = 3
    max_age_s: float = 0.5
    score_threshold: float = 0.0
    measurement_std_frac: float = 0.05
    accel_std_frac_per_s2: float = 2.0
    init_velocity_std_frac_per_s: float = 1.0

    def __post_init__(self):
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
        box_px: (4,) filtered box (x0, y0, x1, y1) at `stamp_s`, pixels.
        stamp_s: the time the box refers to.
    """

    id: int
    camera: str
    box_px: np.ndarray
    stamp_s: float


@dataclass(frozen=True, eq=False)
class SingleViewOutput:
    """What the single-view tracker reported after one frame (the 2D counterpart of `TrackerOutput`).

    Attributes:
        stamp_s: stamp of the frame that was processed.
        camera: name of that frame's camera.
        tracks: the camera's confirmed tracks matched in this frame, boxes at `stamp_s`.
        detection_track_ids: (D,) int64 id of the confirmed track each detection of the frame went to, -1
            for a detection left unassigned or held by a track not yet confirmed (as `detection_target_ids`).
    """

    stamp_s: float
    camera: str
    tracks: list[Track2D]
    detection_track_ids: np.ndarray


def box_to_z(boxes: np.ndarray) -> np.ndarray:
    """(N, 4) boxes (x0, y0, x1, y1) -> (N, 4) measurements (cx, cy, w, h), pixels."""
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    return np.hstack([(boxes[:, :2] + boxes[:, 2:]) / 2, boxes[:, 2:] - boxes[:, :2]])


def z_to_box(z: np.ndarray) -> np.ndarray:
    """(N, 4) (cx, cy, w, h) -> (N, 4) boxes (x0, y0, x1, y1), pixels; sides below 1 px held at 1 px."""
    z = np.asarray(z, dtype=np.float64).reshape(-1, 4)
    half = np.maximum(z[:, 2:], _MIN_SIZE_PX) / 2
    return np.hstack([z[:, :2] - half, z[:, :2] + half])


def transition(dt_s: float) -> np.ndarray:
    """(8, 8) constant-velocity transition F over dt seconds: position += velocity * dt."""
    F = np.eye(2 * _DIM)
    F[:_DIM, _DIM:] = dt_s * np.eye(_DIM)
    return F


def process_noise(dt_s: float, accel_std: float) -> np.ndarray:
    """(8, 8) discretised white-noise acceleration Q over dt seconds (filterpy's Q_continuous_white_noise).

    Args:
        dt_s: interval, seconds.
        accel_std: q, standard deviation of the acceleration, pixels per second squared.
    """
    block = np.array([[dt_s**3 / 3, dt_s**2 / 2], [dt_s**2 / 2, dt_s]]) * accel_std**2
    return np.kron(block, np.eye(_DIM))


def kf_predict(x: np.ndarray, P: np.ndarray, dt_s: float, accel_std: float) -> tuple[np.ndarray, np.ndarray]:
    """Kalman prediction: x <- F x, P <- F P F^T + Q. x (8,), P (8, 8)."""
    F = transition(dt_s)
    return F @ x, F @ P @ F.T + process_noise(dt_s, accel_std)


def kf_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, measurement_std: float) -> tuple[np.ndarray, np.ndarray]:
    """Kalman update with a measured box z (4,) = (cx, cy, w, h), each coordinate of std `measurement_std` px.

    y = z - H x, S = H P H^T + R, K = P H^T S^-1, x <- x + K y, P <- (I - K H) P, with H = [I, 0].
    """
    H = np.hstack([np.eye(_DIM), np.zeros((_DIM, _DIM))])
    y = z - H @ x
    S = H @ P @ H.T + measurement_std**2 * np.eye(_DIM)
    K = np.linalg.solve(S, H @ P).T  # P H^T S^-1 (S and P symmetric)
    return x + K @ y, (np.eye(2 * _DIM) - K @ H) @ P


def match_boxes(predicted: np.ndarray, detected: np.ndarray, min_iou: float) -> tuple[np.ndarray, np.ndarray]:
    """Hungarian matching of predicted track boxes (rows) and detection boxes (columns) on 1 - IoU.

    Args:
        predicted: (T, 4) boxes.
        detected: (D, 4) boxes (NaN: cannot match).
        min_iou: least IoU of a kept pair.

    Returns:
        (rows, cols): int64 arrays of the matched track and detection indices, rows ascending.
    """
    iou = box_iou(predicted, detected)  # (T, D)
    if iou.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    rows, cols = linear_sum_assignment(1.0 - iou)
    keep = iou[rows, cols] >= min_iou
    return rows[keep].astype(np.int64), cols[keep].astype(np.int64)


class _CameraTracks:
    """The tracks of one camera as a struct of arrays (N tracks)."""

    def __init__(self):
        self.ids = np.zeros(0, dtype=np.int64)
        self.x = np.zeros((0, 2 * _DIM))
        self.P = np.zeros((0, 2 * _DIM, 2 * _DIM))
        self.hits = np.zeros(0, dtype=np.int64)
        self.last_s = np.zeros(0)  # time of the last match
        self.time_s = np.zeros(0)  # time the state refers to

    def keep(self, mask: np.ndarray) -> None:
        for name in ("ids", "x", "P", "hits", "last_s", "time_s"):
            setattr(self, name, getattr(self, name)[mask])


class SingleViewTracker:
    """SORT per camera on the 2D detections, see the module docstring.

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
        self._tracks = [_CameraTracks() for _ in self._index]
        self._next_id = 0
        self.last_output = SingleViewOutput(0.0, "", [], np.zeros(0, dtype=np.int64))

    def update(self, frame: Frame) -> list[Track2D]:
        """Processes one camera frame and returns that camera's confirmed tracks matched in it.

        Args:
            frame: detections of one camera, pixels (D, J, 2), scores (D, J).

        Returns:
            the confirmed tracks matched in this frame, boxes filtered to `frame.stamp_s`.
        """
        t = float(frame.stamp_s)
        if frame.camera not in self._index or not np.isfinite(t):
            # The cross-view tracker's input policy: bad input is dropped with a warning, never raised.
            reason = "an unknown camera" if frame.camera not in self._index else "a stamp that is not finite"
            logger.warning("single-view: dropping frame %s@%s: %s", frame.camera, frame.stamp_s, reason)
            self.last_output = SingleViewOutput(t, frame.camera, [], np.full(frame.num_detections, -1, np.int64))
            return []
        cfg = self.config
        tracks = self._tracks[self._index[frame.camera]]
        tracks.keep(t - tracks.last_s <= cfg.max_age_s)  # death (a frame from the past keeps everything)

        # Predict every track to the frame's stamp (a stamp older than a track's state: no motion).
        for i in range(len(tracks.ids)):
            h = max(tracks.x[i, 3], _MIN_SIZE_PX)
            dt = max(t - tracks.time_s[i], 0.0)
            tracks.x[i], tracks.P[i] = kf_predict(tracks.x[i], tracks.P[i], dt, cfg.accel_std_frac_per_s2 * h)
        tracks.time_s[:] = np.maximum(tracks.time_s, t)

        valid = frame.scores >= cfg.score_threshold if cfg.score_threshold > 0 else None
        det_boxes = keypoint_boxes(frame.keypoints_px, valid)  # (D, 4), NaN: too few joints
        rows, cols = match_boxes(z_to_box(tracks.x[:, :_DIM]), det_boxes, cfg.min_iou)

        # Update the matched tracks with their detection's box.
        z = box_to_z(det_boxes)
        for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
            std = cfg.measurement_std_frac * max(z[c, 3], _MIN_SIZE_PX)
            tracks.x[r], tracks.P[r] = kf_update(tracks.x[r], tracks.P[r], z[c], std)
            tracks.hits[r] += 1
            tracks.last_s[r] = t

        # Birth: every unmatched detection that has a box starts a tentative track.
        D = frame.num_detections
        track_of = np.full(D, -1, dtype=np.int64)  # detection -> track row
        track_of[cols] = rows
        new = [d for d in range(D) if track_of[d] < 0 and np.isfinite(det_boxes[d]).all()]
        if new:
            track_of[new] = len(tracks.ids) + np.arange(len(new))
            self._start(tracks, z[new], t)

        confirmed = tracks.hits >= cfg.min_hits
        ids = np.full(D, -1, dtype=np.int64)
        has = track_of >= 0
        ids[has] = np.where(confirmed[track_of[has]], tracks.ids[track_of[has]], -1)
        matched_rows = np.sort(track_of[has & (ids >= 0)])
        out = [Track2D(int(tracks.ids[r]), frame.camera, z_to_box(tracks.x[r, :_DIM])[0], t) for r in matched_rows]
        self.last_output = SingleViewOutput(t, frame.camera, out, ids)
        return out

    def _start(self, tracks: _CameraTracks, z: np.ndarray, t: float) -> None:
        """Appends one tentative track per measured box z (N, 4): at rest, with the measurement's spread."""
        n = len(z)
        x = np.hstack([z, np.zeros((n, _DIM))])
        h = np.maximum(z[:, 3], _MIN_SIZE_PX)
        pos_var = (self.config.measurement_std_frac * h) ** 2
        vel_var = (self.config.init_velocity_std_frac_per_s * h) ** 2
        P = np.zeros((n, 2 * _DIM, 2 * _DIM))
        P[:, np.arange(_DIM), np.arange(_DIM)] = pos_var[:, None]
        P[:, np.arange(_DIM, 2 * _DIM), np.arange(_DIM, 2 * _DIM)] = vel_var[:, None]
        tracks.ids = np.concatenate([tracks.ids, self._next_id + np.arange(n, dtype=np.int64)])
        self._next_id += n
        tracks.x = np.vstack([tracks.x, x])
        tracks.P = np.concatenate([tracks.P, P])
        tracks.hits = np.concatenate([tracks.hits, np.ones(n, dtype=np.int64)])
        tracks.last_s = np.concatenate([tracks.last_s, np.full(n, t)])
        tracks.time_s = np.concatenate([tracks.time_s, np.full(n, t)])
