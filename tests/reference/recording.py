"""The recording's messages built field by field with protobuf's message objects: the reference whose
serialisation the writer's compiled encoders (`crossview.recording.messages`) must equal byte for byte."""

from __future__ import annotations

import numpy as np

from core.records import CameraFrame, PoseTruth
from crossview.recording.schemas import CameraFrameMsg


def pose_truth_to_msg(truth: PoseTruth, msg) -> None:
    poses, ids = np.asarray(truth.poses, dtype=np.float64), np.asarray(truth.person_ids, dtype=np.int64)
    msg.t_s = float(truth.t_s)
    msg.num_joints = poses.shape[1]
    msg.person_ids.extend(ids.tolist())
    msg.poses_m.extend(poses.ravel().tolist())


def camera_frame_to_msg(cf: CameraFrame):
    frame, truth = cf.frame, cf.truth
    D, J = frame.keypoints_px.shape[:2]
    msg = CameraFrameMsg(
        camera=frame.camera,
        stamp_s=float(frame.stamp_s),
        capture_s=float(truth.capture_s),
        delivery_s=float(truth.delivery_s),
        num_detections=D,
        num_joints=J,
    )
    msg.keypoints_px.extend(frame.keypoints_px.ravel().tolist())
    msg.scores.extend(frame.scores.ravel().tolist())

    def rows(name: str, value, shape: tuple, dtype) -> list:
        array = np.asarray(value, dtype=dtype)
        if array.shape != shape:
            raise ValueError(f"CameraFrame {frame.camera}@{frame.stamp_s}: truth.{name} expected {shape}, got "
                             f"{array.shape}")
        return array.ravel().tolist()

    msg.person_ids.extend(rows("person_ids", truth.person_ids, (D,), np.int64))
    msg.true_keypoints_px.extend(rows("keypoints_px", truth.keypoints_px, (D, J, 2), np.float64))
    msg.in_image.extend(rows("in_image", truth.in_image, (D, J), bool))
    msg.occluded.extend(rows("occluded", truth.occluded, (D, J), bool))
    msg.self_occluded.extend(rows("self_occluded", truth.self_occluded, (D, J), bool))
    msg.effects.extend(rows("effects", truth.effects, (D,), np.int64))
    return msg
