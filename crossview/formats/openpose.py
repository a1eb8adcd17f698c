"""OpenPose's JSON output as COCO-17 camera frames: one folder per camera of `*_keypoints.json` (BODY_25 or COCO-18).

A folder in this form sits where the dataset layout's detection.json would (`crossview.formats.datasets.convert`):

    DIR/calibration.json                        the dataset layout's cameras; a camera's folder has its name
    DIR/CAMERA/NAME_000000000012_keypoints.json   OpenPose's output for frame 12 of that camera
    DIR/timestamps.json                         optional: {CAMERA: {"stamp_s": [...], "delivery_s": [...]}}

OpenPose writes `{"people": [{"pose_keypoints_2d": [x0, y0, c0, x1, ...]}]}` per image, a joint it did not find
as 0, 0, 0. The frame number is the digits before `_keypoints.json`; a frame's stamp is `timestamps.json`'s entry
for it, else the frame number divided by the frame rate given. Frames are delivered in order of
`delivery_s` where given, else of stamp.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from core.errors import CrossviewError
from core.types import COCO17, Frame
from crossview.formats.json_input import read_json, stamp_s

# OpenPose's index of each COCO-17 joint (nose, eyes, ears, shoulders, elbows, wrists, hips, knees, ankles).
BODY_25_FROM_COCO17 = (0, 16, 15, 18, 17, 5, 2, 6, 3, 7, 4, 12, 9, 13, 10, 14, 11)
COCO_18_FROM_COCO17 = (0, 15, 14, 17, 16, 5, 2, 6, 3, 7, 4, 11, 8, 12, 9, 13, 10)
LAYOUTS = {25: BODY_25_FROM_COCO17, 18: COCO_18_FROM_COCO17}
BODY_25_NECK, BODY_25_MID_HIP = 1, 8
TIMESTAMPS_FILE = "timestamps.json"
MAX_FRAME_NUMBER = 10 ** 12
"""Frame numbers are below this (OpenPose writes 12 digits)."""
MAX_PIXEL = 1e6
"""Largest magnitude of an OpenPose value (pixels; confidences are in [0, 1]), as for the tracker's pixels."""
_FRAME_NUMBER = re.compile(r"(\d+)_keypoints\.json$")


class OpenPoseError(CrossviewError):
    """An OpenPose folder that cannot be read; the message names the file and what is wrong."""


def camera_folders(dataset_dir) -> list[Path]:
    """The sub-folders of `dataset_dir` that hold `*_keypoints.json` files, sorted by name."""
    return sorted(p for p in Path(dataset_dir).iterdir() if p.is_dir() and any(p.glob("*_keypoints.json")))


def read_frames(dataset_dir, fps: float | None) -> list[tuple[str, Frame, float]]:
    """Every camera's frames as (key, COCO-17 frame, delivery time) in delivery order.

    Args:
        dataset_dir: the folder with one sub-folder of `*_keypoints.json` per camera.
        fps: frames per second, for the stamps of cameras that `timestamps.json` does not list.

    Raises:
        OpenPoseError: no camera folder, an unreadable file, a joint count other than 25 or 18, or a frame
            with no stamp.
    """
    dataset_dir = Path(dataset_dir)
    folders = camera_folders(dataset_dir)
    if not folders:
        raise OpenPoseError(f"{dataset_dir}: no sub-folder holds *_keypoints.json files (expected one folder of "
                            "OpenPose output per camera)")

    times = read_timestamps(dataset_dir / TIMESTAMPS_FILE) if (dataset_dir / TIMESTAMPS_FILE).exists() else {}
    frames = []
    for folder in folders:
        camera = folder.name
        listed = times.get(camera, {})
        stamps, deliveries = listed.get("stamp_s"), listed.get("delivery_s")
        for path in sorted(folder.glob("*_keypoints.json")):
            match = _FRAME_NUMBER.search(path.name)
            if match is None:
                raise OpenPoseError(f"{path}: no frame number before _keypoints.json")
            number = int(match.group(1))
            if number >= MAX_FRAME_NUMBER:
                raise OpenPoseError(f"{path}: frame number {number} must be below {MAX_FRAME_NUMBER:,}")
            if stamps is not None and number < len(stamps):
                stamp = stamps[number]
            elif fps:
                stamp = stamp_s(number / fps, path, f"frame {number} at --fps {fps:g}")
            else:
                raise OpenPoseError(f"{path}: frame {number} has no stamp: list it in {TIMESTAMPS_FILE} or give "
                                    "the frame rate (--fps)")
            delivery = deliveries[number] if deliveries is not None and number < len(deliveries) else stamp
            frames.append((delivery, stamp, f"{camera}/{path.name}", _frame(path, camera, stamp)))
    frames.sort(key=lambda f: (f[0], f[1], f[2]))
    return [(key, frame, delivery) for delivery, _, key, frame in frames]


def read_timestamps(path: Path) -> dict:
    """timestamps.json: {CAMERA: {"stamp_s": [...], "delivery_s": [...]}}, each list optional, each stamp a
    timestamp of the dataset layout (`crossview.formats.json_input.stamp_s`: finite, in [0, 4e9] s).

    Raises:
        OpenPoseError: naming the file, the camera and the key.
    """

    times = read_json(path)
    if not isinstance(times, dict):
        raise OpenPoseError(f"{path}: must be an object of camera name -> {{stamp_s, delivery_s}}, got "
                            f"{type(times).__name__}")
    for camera, listed in times.items():
        if not isinstance(listed, dict):
            raise OpenPoseError(f"{path}: camera {camera!r} must be an object with stamp_s and delivery_s arrays")
        for key in ("stamp_s", "delivery_s"):
            if key in listed:
                values = listed[key]
                if not isinstance(values, list):
                    raise OpenPoseError(f"{path}: camera {camera!r}: {key} must be an array of seconds")
                listed[key] = [stamp_s(v, path, f"camera {camera!r}: {key}[{i}]") for i, v in enumerate(values)]
    return times


def _frame(path: Path, camera: str, stamp_s: float) -> Frame:
    """One OpenPose file as a COCO-17 frame: (D, 17, 2) pixels, NaN where OpenPose gave 0, 0, 0.

    Raises:
        OpenPoseError: not OpenPose's output, a person that is not an object, or values that are not finite
            numbers (pixels within 1e6 of the image, confidences in [0, 1]); naming the file and the person.
    """
    data = read_json(path)
    people = data.get("people") if isinstance(data, dict) else None
    if not isinstance(people, list):
        raise OpenPoseError(f"{path}: key 'people' missing (expected OpenPose's JSON output)")
    keypoints, scores = [], []
    for k, person in enumerate(people):
        if not isinstance(person, dict):
            raise OpenPoseError(f"{path}: person {k} must be an object with pose_keypoints_2d, got "
                                f"{type(person).__name__}")
        values = person.get("pose_keypoints_2d", [])
        if not isinstance(values, list) or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
            raise OpenPoseError(f"{path}: person {k}: pose_keypoints_2d must be a flat array of numbers")
        flat = np.asarray(values, dtype=np.float64)
        if flat.size == 0:
            continue
        if not np.all(np.abs(flat) <= MAX_PIXEL):
            raise OpenPoseError(f"{path}: person {k}: pose_keypoints_2d holds {flat[np.abs(flat) > MAX_PIXEL][0]!r}; "
                                f"pixels and confidences must be finite and within {MAX_PIXEL:g}")
        if flat.size % 3 or flat.size // 3 not in LAYOUTS:
            raise OpenPoseError(f"{path}: person {k}: {flat.size} values in pose_keypoints_2d; expected BODY_25 "
                                "(75) or COCO-18 (54)")
        joints = flat.reshape(-1, 3)[list(LAYOUTS[flat.size // 3])]
        if not np.all((joints[:, 2] >= 0) & (joints[:, 2] <= 1)):
            raise OpenPoseError(f"{path}: person {k}: a confidence outside [0, 1]")
        found = joints[:, 2] > 0
        keypoints.append(np.where(found[:, None], joints[:, :2], np.nan))
        scores.append(np.where(found, joints[:, 2], 0.0))
    J = COCO17.num_joints
    return Frame(camera=camera, stamp_s=stamp_s,
                 keypoints_px=np.stack(keypoints) if keypoints else np.zeros((0, J, 2)),
                 scores=np.stack(scores) if scores else np.zeros((0, J)))


def body_25(keypoints_px: np.ndarray, scores: np.ndarray) -> list[float]:
    """One COCO-17 detection as OpenPose's flat BODY_25 `pose_keypoints_2d` (x, y, c per joint; 0, 0, 0 for a
    joint not found; the neck and mid-hip from both shoulders and both hips; the feet not found).

    Args:
        keypoints_px: (17, 2) pixels, NaN missing; scores: (17,) in [0, 1].
    """
    found = np.isfinite(keypoints_px).all(axis=-1) & (scores > 0)
    out = np.zeros((25, 3))
    out[list(BODY_25_FROM_COCO17)] = np.where(found[:, None], np.column_stack([keypoints_px, scores]), 0.0)
    for target, (a, b) in ((BODY_25_NECK, (5, 6)), (BODY_25_MID_HIP, (11, 12))):
        if found[a] and found[b]:
            out[target] = [*((keypoints_px[a] + keypoints_px[b]) / 2), min(scores[a], scores[b])]
    return out.ravel().tolist()
