"""Per-camera 2D tracking scores (the paper's Table 5): MOTA and IDF1 of 2D tracks in each camera, by py-motmetrics.

Every source of 2D tracks comes down to, per camera frame, true people and track ids with a distance
between each pair (NaN: no match); py-motmetrics does the CLEAR-MOT bookkeeping and the IDF1 assignment
per camera (`Camera2DAccumulator`). Two protocols feed it:

- *projected* (`projected_2d_scores`, the paper's own protocol on Shelf, MOTChallenge's matching): for
  each tracker output of a camera, the targets' 3D poses and the true poses at the output's stamp are
  projected into the camera and boxed (`crossview.scoring.association.pose_boxes`); the truth is
  everybody whose box is at least half inside the image, occluded or not. A track box matches a true
  box when their IoU is at least `IOU_THRESHOLD`, at distance 1 - IoU.
- *per detection* (`detection_2d_scores`): for each camera frame, the truth is the people the detector
  reported (the frame's per-detection truth, person id >= 0) with their true joints; the tracks are the
  frame's detections that a tracker gave an id (>= 0) with their reported joints. The distance of a
  track to a person is the mean distance of the track's reported joints to the person's true ones,
  divided by the diagonal of the box of the person's true joints inside the image; a match needs at most
  `JOINT_MATCH_FRACTION`. Any tracker that says which track each detection went to can be scored this
  way, 2D (`tracker.single_view`) or 3D (`TrackerOutput.detection_target_ids`), on the same detections
  and the same truth; the detector's own localisation (a fragment, a missed joint) costs nothing. People
  the detector missed are in neither side.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

import motmetrics as mm
import numpy as np

from core.boxes import box_iou, keypoint_boxes
from core.errors import CrossviewError
from core.records import CameraFrame
from core.types import Camera, Frame
from crossview.scoring.association import (
    may_project,
    project_points,
    projected_boxes,
    projection_volume,
    stamp_key,
)
from crossview.scoring.identity import identity_scores
from tracker.types import TrackerOutput, target_arrays

logger = logging.getLogger(__name__)

IOU_THRESHOLD = 0.5
"""Smallest IoU of a projected track box and a true box that counts as a match (MOTChallenge)."""
JOINT_MATCH_FRACTION = 0.5
"""Largest mean joint distance of a detection to a true person, as a fraction of the diagonal of the
person's true box, that counts as a match. On store_layout1 and store_layout2 (seed 0) 99.3 % of the true
detections lie within it of their own person, and under 1 % of the pairs of a detection and another person
in the same frame lie within it."""


@dataclass
class Camera2DScores:
    """MOTChallenge-style scores of one camera's 2D tracks (the paper's Table 5).

    Attributes:
        mota: 1 - (FN + FP + IDS) / num_truth; None with no true box.
        idf1: identity F1; None when undefined.
        false_positives, false_negatives, id_switches: counts over the camera's frames.
        num_truth: true boxes scored.
        num_frames: camera frames scored.
    """

    mota: float | None
    idf1: float | None
    false_positives: int
    false_negatives: int
    id_switches: int
    num_truth: int
    num_frames: int


class Camera2DAccumulator:
    """One py-motmetrics accumulator per camera, fed frame by frame.

    Args:
        cameras: the camera names, in the order the result lists them.
    """

    def __init__(self, cameras: Sequence[str]):
        self._accs = {name: mm.MOTAccumulator(auto_id=True) for name in cameras}
        self._frames: Counter = Counter()

    def update(self, camera: str, truth_ids, track_ids, distances: np.ndarray) -> None:
        """Adds one frame of one camera.

        Args:
            camera: the camera's name (one given to the constructor).
            truth_ids: (G,) distinct person ids.
            track_ids: (H,) distinct track ids.
            distances: (G, H) distance of each pair, NaN where they cannot match.
        """
        acc = self._accs.get(camera)
        if acc is None:
            raise ValueError(f"2D scores: a frame of camera {camera!r}, not among {sorted(self._accs)}")
        acc.update([int(i) for i in truth_ids], [int(i) for i in track_ids], distances)
        self._frames[camera] += 1

    def result(self) -> dict[str, Camera2DScores]:
        """Camera name -> scores, for every camera given to the constructor."""
        out = {}
        for name, acc in self._accs.items():
            s = identity_scores(acc)
            out[name] = Camera2DScores(s.mota, s.idf1, s.false_positives, s.false_negatives, s.id_switches,
                                       s.num_truth, self._frames[name])
        return out


def iou_distances(truth_boxes: np.ndarray, track_boxes: np.ndarray, threshold: float = IOU_THRESHOLD) -> np.ndarray:
    """(G, H) 1 - IoU of (x0, y0, x1, y1) boxes, NaN where the IoU is under `threshold` (MOTChallenge)."""
    iou = box_iou(truth_boxes, track_boxes)
    return np.where(iou >= threshold, 1.0 - iou, np.nan)


def joint_distances(truth_px: np.ndarray, truth_valid: np.ndarray, track_px: np.ndarray,
                    threshold: float = JOINT_MATCH_FRACTION) -> np.ndarray:
    """(G, H) mean joint distance of each track to each person, in units of the person's true box diagonal.

    Args:
        truth_px: (G, J, 2) true joints, pixels (NaN: unknown).
        truth_valid: (G, J) bool, the joints that make the person's box (those inside the image).
        track_px: (H, J, 2) reported joints, pixels (NaN: not reported).
        threshold: larger distances are NaN (no match).

    Returns:
        (G, H) distances; NaN beyond `threshold`, with no joint known on both sides, or for a person
        without a box.
    """
    boxes = keypoint_boxes(truth_px, truth_valid)
    diagonal = np.hypot(boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1])  # (G,), NaN: no box
    err = np.linalg.norm(truth_px[:, None] - track_px[None, :], axis=-1)  # (G, H, J), NaN where unknown
    known = np.isfinite(err)
    count = known.sum(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.where(known, err, 0.0).sum(axis=-1) / count / diagonal[:, None]
    d[~(d <= threshold)] = np.nan
    return d


class Projected2DAccumulator:
    """The *projected* protocol fed one tracker output at a time (see the module docstring).

    Each camera's outputs wait in a block of at most `BLOCK_POINTS` joints and are projected together in
    one `project_points` call (the same per-point arithmetic as one call per pose); the block then goes
    into the camera's py-motmetrics accumulator in the order the outputs came. Memory: one block per camera.

    Args:
        cameras: the calibrated cameras.
        truth_at: t -> (ids (P,), poses (P, J, 3)) true poses at time t.
    """

    BLOCK_POINTS = 16384
    """Joints (truth and targets) of one camera's outputs projected in one call."""

    def __init__(self, cameras: Sequence[Camera], truth_at: Callable[[float], tuple[np.ndarray, np.ndarray]]):
        self._cameras = {c.name: c for c in cameras}
        self._volumes = {c.name: projection_volume(c) for c in cameras}
        self._truth_at = truth_at
        self._acc = Camera2DAccumulator(list(self._cameras))
        self._blocks: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]] = {
            name: [] for name in self._cameras}
        self._points: Counter = Counter()

    def add(self, output: TrackerOutput) -> None:
        """Adds a tracker output, scored in the camera that produced it."""
        if output.camera not in self._cameras:
            raise ValueError(f"2D scores: tracker output from camera {output.camera!r}, not among "
                             f"{sorted(self._cameras)}")
        ids, poses = self._truth_at(output.stamp_s)
        ids, poses = np.asarray(ids), np.asarray(poses, dtype=np.float64)
        h_ids, h_poses = target_arrays(output.targets, poses.shape[1])
        # Only the poses with a joint the camera could project can have a box in it (`may_project`).
        volume = self._volumes[output.camera]
        near, h_near = may_project(volume, poses), may_project(volume, h_poses)
        ids, poses, h_ids, h_poses = ids[near], poses[near], h_ids[h_near], h_poses[h_near]
        self._blocks[output.camera].append((ids, poses, h_ids, h_poses))
        self._points[output.camera] += poses[..., 0].size + h_poses[..., 0].size
        if self._points[output.camera] >= self.BLOCK_POINTS:
            self._flush(output.camera)

    def _flush(self, name: str) -> None:
        camera, block = self._cameras[name], self._blocks[name]
        self._blocks[name], self._points[name] = [], 0
        if not block:
            return
        sides = [poses for item in block for poses in (item[1], item[3])]  # truth, targets, truth, ...
        counts = [len(p) for p in sides]
        px = project_points(camera, np.concatenate([p.reshape(-1, 3) for p in sides]))
        shapes = {p.shape[1:] for p in sides if len(p)}
        if len(shapes) <= 1:  # one joint layout: box every pose of the block at once (row by row the same)
            j = shapes.pop()[0] if shapes else 1
            all_boxes, all_vis = projected_boxes(camera, px.reshape(-1, j, 2))
            ends = np.cumsum(counts)[:-1]
            boxes = list(zip(np.split(all_boxes, ends), np.split(all_vis, ends), strict=True))
        else:
            ends = np.cumsum([p[..., 0].size for p in sides])[:-1]
            boxes = [projected_boxes(camera, chunk.reshape(*p.shape[:2], 2))
                     for p, chunk in zip(sides, np.split(px, ends), strict=True)]
        for (ids, _, h_ids, _), (t_boxes, t_vis), (h_boxes, h_vis) in zip(block, boxes[::2], boxes[1::2],
                                                                          strict=True):
            self._acc.update(name, ids[t_vis], h_ids[h_vis], iou_distances(t_boxes[t_vis], h_boxes[h_vis]))

    def result(self) -> dict[str, Camera2DScores]:
        """Camera name -> scores, for every camera given."""
        for name in self._cameras:
            self._flush(name)
        return self._acc.result()


def projected_2d_scores(
    outputs: Iterable[TrackerOutput],
    cameras: Sequence[Camera],
    truth_at: Callable[[float], tuple[np.ndarray, np.ndarray]],
) -> dict[str, Camera2DScores]:
    """Per-camera 2D scores of 3D tracks projected into each camera, the *projected* protocol above.

    Args:
        outputs: tracker outputs; each is scored in the camera that produced it.
        cameras: the calibrated cameras.
        truth_at: t -> (ids (P,), poses (P, J, 3)) true poses at time t.

    Returns:
        camera name -> scores, for every camera given.
    """
    acc = Projected2DAccumulator(cameras, truth_at)
    for out in outputs:
        acc.add(out)
    return acc.result()


def detection_truth(camera_frame: CameraFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The people behind a frame's detections, with their true joints.

    Args:
        camera_frame: a delivered frame with its per-detection truth.

    Returns:
        ids (G,) int64, distinct, in the order of their first detection (false positives left out); their
        true joints (G, J, 2), pixels, and (G, J) bool, the joints inside the image. Taken from each
        person's first detection: a duplicate or fragment of the same person has the same truth.
    """
    truth = camera_frame.truth
    persons = np.asarray(truth.person_ids, dtype=np.int64)
    ids, first = np.unique(persons, return_index=True)
    rows = np.sort(first[ids >= 0])
    return persons[rows], truth.keypoints_px[rows], truth.in_image[rows]


def detection_tracks(frame: Frame, detection_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The tracks a tracker reported in a frame, each with the joints of its detection.

    Args:
        frame: the camera frame.
        detection_ids: (D,) track id of each detection, -1 for none.

    Returns:
        ids (H,) int64, distinct, and (H, J, 2) reported joints, pixels. A track given two detections of
        one frame keeps the first (a tracker reports one place per track and frame).
    """
    ids = np.asarray(detection_ids, dtype=np.int64)
    unique, first = np.unique(ids, return_index=True)
    rows = np.sort(first[unique >= 0])
    return ids[rows], frame.keypoints_px[rows]


def detection_2d_scores(
    camera_frames: Iterable[CameraFrame],
    detection_ids: Mapping[tuple[str, int], np.ndarray],
    cameras: Sequence[str],
) -> dict[str, Camera2DScores]:
    """Per-camera 2D scores of per-detection track ids, the *per detection* protocol above.

    Args:
        camera_frames: delivered frames with their per-detection truth.
        detection_ids: `stamp_key(camera, stamp_s)` -> (D,) track id of each detection of that frame (-1:
            none), e.g. `{stamp_key(o.camera, o.stamp_s): o.detection_target_ids for o in outputs}`.
        cameras: camera names, in the order of the result.

    Returns:
        camera name -> scores, for every camera given. Frames with no entry in `detection_ids` (the
        tracker never processed them) are left out, and logged.

    Raises:
        CrossviewError: ids for a frame whose number of detections differs, or no frame with ids at all.
    """
    acc = Camera2DAccumulator(cameras)
    missing = scored = 0
    for cf in camera_frames:
        key = stamp_key(cf.frame.camera, cf.frame.stamp_s)
        ids = detection_ids.get(key)
        if ids is None:
            missing += 1
            continue
        if len(ids) != cf.frame.num_detections:
            raise CrossviewError(
                f"2D scores: camera {key[0]} at {cf.frame.stamp_s} s has {cf.frame.num_detections} detections but "
                f"the tracks assign {len(ids)}; the tracks do not belong to this recording"
            )
        truth_ids, truth_px, truth_valid = detection_truth(cf)
        track_ids, track_px = detection_tracks(cf.frame, ids)
        acc.update(key[0], truth_ids, track_ids, joint_distances(truth_px, truth_valid, track_px))
        scored += 1
    if missing and not scored:
        raise CrossviewError(f"2D scores: none of the recording's {missing} camera frames has track ids; the tracks "
                             "do not belong to this recording")
    if missing:
        logger.warning("2D scores: %d camera frames had no track ids and were left out", missing)
    return acc.result()
