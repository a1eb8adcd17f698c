"""Reading and writing the dataset layout published with Chen et al., CVPR 2020 (Campus, Shelf, Store).

A dataset directory holds `calibration.json` (per camera `K` normalised by the image size, `Tw` the
camera-to-world pose in centimetres, `dist_coeffs` k1 k2 p1 p2), the 2D input as `detection.json` (COCO-17
detections, `id` -1) or `annotation_2d.json` (ground-truth joints, e.g. the 14 Campus joints), and optionally
`annotation_3d.json` (truth, 14 joints, centimetres; the list index is the frame number). Results use the
`annotation_3d.json` shape with COCO-17 joints (longcw/crossview_3d_pose_tracking documents the layout).

Distortion: the 2D points of the published files already fit the undistorted pinhole model (Campus: median
0.3 px without distortion), so `load_cameras` gives zero distortion unless asked for the listed coefficients.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from core.errors import CrossviewError
from core.types import CAMPUS14, COCO17, Camera, Frame
from tracker.types import TrackerOutput

CM_TO_M = 0.01
_SOURCES = ("detection.json", "annotation_2d.json")


class DatasetError(CrossviewError):
    """A dataset directory does not follow the published layout; the message names the file and the key."""


def _load(path: Path):
    if not path.is_file():
        raise DatasetError(f"{path}: not found (expected the crossview dataset layout: calibration.json, "
                           "detection.json or annotation_2d.json, optional annotation_3d.json)")
    try:
        with path.open() as f:
            return json.load(f)
    except json.JSONDecodeError as exc:
        raise DatasetError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from exc


def _source_path(dataset_dir: Path, source: str) -> Path:
    if source == "auto":
        for name in _SOURCES:
            if (dataset_dir / name).is_file():
                return dataset_dir / name
        raise DatasetError(f"{dataset_dir}: neither detection.json nor annotation_2d.json found")
    names = {"detection": "detection.json", "annotation_2d": "annotation_2d.json", "annotation": "annotation_2d.json"}
    if source not in names:
        raise DatasetError(f"source {source!r}: expected auto, detection or annotation_2d")
    return dataset_dir / names[source]


def image_size(dataset_dir, source: str = "auto") -> tuple[int, int]:
    """(width, height) in pixels from the 2D file's `image_wh`."""
    path = _source_path(Path(dataset_dir), source)
    data = _load(path)
    try:
        w, h = (int(v) for v in data["image_wh"])
    except (KeyError, TypeError, ValueError) as exc:
        raise DatasetError(f"{path}: key 'image_wh' missing or not [width, height]") from exc
    return w, h


def load_cameras(dataset_dir, use_distortion: bool = False) -> list[Camera]:
    """The cameras of `calibration.json` in metres, sorted by name.

    K is de-normalised with the image size of the 2D file; `Tw` (camera-to-world, cm) is inverted into
    R_cam_from_world and t_cam_from_world (m).

    Args:
        dataset_dir: the dataset directory.
        use_distortion: keep the listed k1 k2 p1 p2 (the published 2D points are already undistorted).
    """
    dataset_dir = Path(dataset_dir)
    path = dataset_dir / "calibration.json"
    data = _load(path)
    width, height = image_size(dataset_dir)
    try:
        entries = data["cameras"]
    except (KeyError, TypeError) as exc:
        raise DatasetError(f"{path}: key 'cameras' missing") from exc
    cameras = []
    for name in sorted(entries):
        entry = entries[name]
        try:
            K = np.asarray(entry["K"], dtype=np.float64) * np.array([[width], [height], [1.0]])
            Tw = np.asarray(entry["Tw"], dtype=np.float64)
            dist = np.asarray(entry.get("dist_coeffs", []), dtype=np.float64) if use_distortion else np.zeros(5)
        except (KeyError, TypeError, ValueError) as exc:
            raise DatasetError(f"{path}: camera {name!r}: key {exc} missing or not numeric") from exc
        if K.shape != (3, 3) or Tw.shape != (4, 4):
            raise DatasetError(f"{path}: camera {name!r}: K must be 3x3 and Tw 4x4, got {K.shape} and {Tw.shape}")
        R_world_from_cam = Tw[:3, :3]
        center_m = Tw[:3, 3] * CM_TO_M
        R = R_world_from_cam.T
        # Tw's rotation is orthonormal only to the precision the file was written with.
        u, _, vt = np.linalg.svd(R)
        R = u @ vt
        try:
            cameras.append(Camera(name=str(name), K=K, dist=dist, R_cam_from_world=R, t_cam_from_world=-R @ center_m,
                                  width_px=width, height_px=height))
        except ValueError as exc:
            raise DatasetError(f"{path}: camera {name!r}: {exc}") from exc
    return cameras


def load_frames(dataset_dir, source: str = "auto") -> list[Frame]:
    """Every 2D frame of the dataset, sorted by timestamp (then camera name), each with its own camera and stamp.

    Args:
        dataset_dir: the dataset directory.
        source: "auto" (detection.json if present, else annotation_2d.json), "detection" or "annotation_2d".

    Returns:
        Frames with (D, J, 2) pixels and (D, J) scores; a joint with score 0 is NaN.
    """
    return [frame for frame, _ in _read_frames(Path(dataset_dir), source)]


def _read_frames(dataset_dir: Path, source: str) -> list[tuple[Frame, np.ndarray]]:
    """Frames sorted by (timestamp, camera), each with the (D,) `id` of its poses (-1 for detections)."""
    path = _source_path(dataset_dir, source)
    data = _load(path)
    try:
        items = data["frames"]
    except (KeyError, TypeError) as exc:
        raise DatasetError(f"{path}: key 'frames' missing") from exc
    num_joints = None
    parsed = []
    for key, item in items.items():
        try:
            camera, stamp = str(item["camera"]), float(item["timestamp"])
            points = [np.asarray(p["points_2d"], dtype=np.float64) for p in item["poses"]]
            scores = [np.asarray(p.get("scores", np.ones(len(p["points_2d"]))), dtype=np.float64)
                      for p in item["poses"]]
            ids = np.asarray([int(p.get("id", -1)) for p in item["poses"]], dtype=np.int64)
        except (KeyError, TypeError, ValueError) as exc:
            raise DatasetError(f"{path}: frame {key!r}: key {exc} missing or malformed "
                               "(expected camera, timestamp, poses[points_2d, scores])") from exc
        for p, sc in zip(points, scores):
            if p.ndim != 2 or p.shape[1] != 2 or sc.shape != p.shape[:1]:
                raise DatasetError(f"{path}: frame {key!r}: points_2d {p.shape} / scores {sc.shape} do not match")
            if num_joints is None:
                num_joints = p.shape[0]
            elif p.shape[0] != num_joints:
                raise DatasetError(f"{path}: frame {key!r}: {p.shape[0]} joints, earlier frames have {num_joints}")
        parsed.append((stamp, camera, points, scores, ids))
    num_joints = num_joints or COCO17.num_joints
    out = []
    for stamp, camera, points, scores, ids in sorted(parsed, key=lambda x: (x[0], x[1])):
        kp = np.stack(points) if points else np.zeros((0, num_joints, 2))
        sc = np.stack(scores) if scores else np.zeros((0, num_joints))
        kp = np.where((sc > 0)[..., None], kp, np.nan)
        out.append((Frame(camera=camera, stamp_s=stamp, keypoints_px=kp, scores=sc), ids))
    return out


def skeleton_of(frames: list[Frame]):
    """The skeleton the frames' joint count implies (14: CAMPUS14, 17: COCO17)."""
    for frame in frames:
        if frame.num_detections:
            J = frame.keypoints_px.shape[1]
            for skeleton in (COCO17, CAMPUS14):
                if skeleton.num_joints == J:
                    return skeleton
            raise DatasetError(f"frames have {J} joints: neither COCO-17 nor the 14 Campus joints")
    return COCO17


def load_truth_3d(dataset_dir) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """`annotation_3d.json` as a list, index = frame number: (t_s, ids (P,), poses (P, 14, 3) metres)."""
    path = Path(dataset_dir) / "annotation_3d.json"
    data = _load(path)
    if not isinstance(data, list):
        raise DatasetError(f"{path}: expected a list of {{timestamp, poses}} entries")
    out = []
    for i, entry in enumerate(data):
        try:
            t = float(entry["timestamp"])
            ids = np.asarray([int(p["id"]) for p in entry["poses"]], dtype=np.int64)
            poses = np.asarray([p["points_3d"] for p in entry["poses"]], dtype=np.float64).reshape(-1, 14, 3)
        except (KeyError, TypeError, ValueError) as exc:
            raise DatasetError(f"{path}: entry {i}: key {exc} missing or points_3d not 14x3") from exc
        out.append((t, ids, poses * CM_TO_M))
    return out


def campus14_to_coco17(poses: np.ndarray) -> np.ndarray:
    """Writes 14-joint Campus poses (..., 14, 3) as COCO-17 (..., 17, 3) so that the published evaluate.py
    mapping (crossview.scoring.pose.coco17_to_campus14) gives the same limbs back and a head on the
    mid-shoulder-to-head line: the nose is placed where that mapping puts the top of the head's direction.
    Face joints other than the nose are NaN."""
    from crossview.scoring.pose import _BOTTOM_HEAD_FACTORS, _COCO_TO_CAMPUS12, _TOP_HEAD_FACTORS

    poses = np.asarray(poses, dtype=np.float64)
    out = np.full(poses.shape[:-2] + (17, 3), np.nan)
    out[..., _COCO_TO_CAMPUS12, :] = poses[..., :12, :]
    mid_shoulder = (poses[..., 8, :] + poses[..., 9, :]) / 2
    # evaluate.py: top = mid + (nose - mid) * f_top, bottom = mid + (nose - mid) * f_bottom, per axis.
    # Least squares for the nose offset d from both head joints, per axis: d = Σ f h / Σ f².
    top, bottom = poses[..., 13, :] - mid_shoulder, poses[..., 12, :] - mid_shoulder
    d = (top * _TOP_HEAD_FACTORS + bottom * _BOTTOM_HEAD_FACTORS) / (_TOP_HEAD_FACTORS ** 2 + _BOTTOM_HEAD_FACTORS ** 2)
    out[..., 0, :] = mid_shoulder + d
    return out


def write_result_3d(outputs: Iterable[TrackerOutput], path) -> int:
    """Writes tracker outputs in the result_3d.json layout (COCO-17, centimetres; a joint the tracker does not
    know is written as missing, [null, null, null], never as a point at the origin).

    Outputs sharing a stamp (several cameras of one synchronised instant) keep the last, the most informed.
    Poses with 14 joints (CAMPUS14) are written as COCO-17 with `campus14_to_coco17`.

    Returns:
        The number of entries written.
    """
    by_stamp: dict[float, TrackerOutput] = {}
    for out in outputs:
        by_stamp[float(out.stamp_s)] = out
    entries = []
    for stamp in sorted(by_stamp):
        poses = []
        for target in by_stamp[stamp].targets:
            pose = np.asarray(target.pose, dtype=np.float64)
            if pose.shape == (14, 3):
                pose = campus14_to_coco17(pose)
            if pose.shape != (17, 3):
                raise ValueError(f"write_result_3d: target {target.id} at {stamp} s has pose {pose.shape}; "
                                 "expected (17, 3) COCO-17 or (14, 3) Campus joints")
            cm = np.round(pose / CM_TO_M, 3).tolist()
            missing = ~np.all(np.isfinite(pose), axis=-1)
            points = [[None, None, None] if gone else xyz for xyz, gone in zip(cm, missing.tolist())]
            poses.append({"id": int(target.id), "points_3d": points})
        entries.append({"timestamp": stamp if math.isfinite(stamp) else 0.0, "poses": poses})
    with open(path, "w") as f:
        json.dump(entries, f)
    return len(entries)


def convert(dataset_dir, out_mcap, source: str = "auto") -> int:
    """Writes a dataset of the published layout as a recording (crossview.recording), frames in timestamp order.

    Each frame keeps its own camera and stamp (capture = delivery = stamp). With annotation_2d.json the
    per-detection truth holds the annotated ids and joints; with detection.json the ids are -1. The 3D truth
    of annotation_3d.json (14 joints, metres) is written when the 2D joints use the same layout (CAMPUS14).

    Returns:
        The number of camera frames written.
    """
    import hashlib

    from crossview.recording import RecordingHeader, RecordingWriter
    from sim.types import CameraFrame, DetectionTruth, PoseTruth

    dataset_dir = Path(dataset_dir)
    cameras = load_cameras(dataset_dir)
    known = {c.name for c in cameras}
    frames = _read_frames(dataset_dir, source)
    for frame, _ in frames:
        if frame.camera not in known:
            raise DatasetError(f"{_source_path(dataset_dir, source)}: camera {frame.camera!r} is not in "
                               f"calibration.json ({', '.join(sorted(known))})")
    skeleton = skeleton_of([f for f, _ in frames])
    truth = load_truth_3d(dataset_dir) if (dataset_dir / "annotation_3d.json").is_file() else []
    if truth and skeleton.num_joints != 14:
        truth = []  # the 14-joint truth cannot be stored with COCO-17 frames in one recording
    truth.sort(key=lambda entry: entry[0])
    digest = hashlib.sha256()
    for name in ("calibration.json", _source_path(dataset_dir, source).name, "annotation_3d.json"):
        if (dataset_dir / name).is_file():
            digest.update((dataset_dir / name).read_bytes())
    end_s = max([f.stamp_s for f, _ in frames] + [e[0] for e in truth] + [0.0])
    header = RecordingHeader(scenario_name=dataset_dir.resolve().name, scenario_text="",
                             scenario_digest=digest.hexdigest(), seed=0, duration_s=float(end_s),
                             skeleton_name=skeleton.name)
    J = skeleton.num_joints
    events = [(t, 0, i) for i, (t, _, _) in enumerate(truth)] + [(f.stamp_s, 1, i) for i, (f, _) in enumerate(frames)]
    events.sort()
    with RecordingWriter(out_mcap, header, cameras, ()) as writer:
        for t, kind, i in events:
            if kind == 0:
                writer.write(PoseTruth(float(t), truth[i][1], truth[i][2]))
                continue
            frame, ids = frames[i]
            D = frame.num_detections
            annotated = ids >= 0
            keypoints = np.where(annotated[:, None, None], frame.keypoints_px, np.nan)
            in_image = np.isfinite(keypoints[..., 0])
            none = np.zeros((D, J), dtype=bool)
            det_truth = DetectionTruth(capture_s=frame.stamp_s, delivery_s=frame.stamp_s, person_ids=ids,
                                       keypoints_px=keypoints, in_image=in_image, occluded=none,
                                       self_occluded=none, effects=np.zeros(D, dtype=np.int64))
            # (The poses at capture are not stored: a reader derives them from the truth written here.)
            writer.write(CameraFrame(frame=frame, truth=det_truth, poses_at_capture=None))
    return len(frames)
