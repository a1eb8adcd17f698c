"""The recording and tracks file formats (MCAP): atomic writers, streamed readers, `info`.

This is the only module of the project that imports `mcap`. The format is described channel by
channel in docs/recording-format.md; in short:

- A *recording* holds a JSON header (scenario text, seed, software and format version, cameras, store
  boxes), the 100 Hz ground truth (`crossview.PoseTruth`) and one `crossview.CameraFrame` per delivered
  camera frame (detections, scores, per-detection truth, true poses at capture time), plus Foxglove
  channels for people to look at (store, frusta, calibrations, skeletons, 2D detections).
- A *tracks file* holds a JSON header (the recording's scenario digest and seed, the tracker method,
  preset and config), one `crossview.TrackerOutput` per processed frame, the tracker's skeletons as a
  Foxglove `SceneUpdate`, and a summary (tracker seconds, updates) written at the end.

Program data use compact protobuf schemas built at run time from a FileDescriptorProto (packed
doubles, so every float round-trips bit for bit). Log times are integer nanoseconds since the
scenario start, converted from float seconds only in `to_ns`. Messages are written in log-time order,
so file order is log-time order and reading streams one chunk at a time. The same inputs and software
give the same bytes: no wall-clock time is written, chunk size and compression are fixed.
"""

from __future__ import annotations

import bisect
import functools
import importlib.metadata
import json
import math
import os
import struct
import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from google.protobuf.message import DecodeError
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, DataEnd, Message, Metadata, Schema
from mcap.stream_reader import CRCValidationError, StreamReader
from mcap.writer import CompressionType, Writer

from core.errors import CrossviewError
from core.types import SKELETONS, Camera, Frame, Skeleton
from crossview import foxglove
from sim.poses import interpolate_poses
from sim.types import Box, BoxKind, CameraFrame, DetectionRows, DetectionTruth, PoseTruth
from tracker.types import Target, TargetState, TrackerOutput

FORMAT_VERSION = 2
OLDEST_RECORDING_VERSION = 2  # format 1 stored every frame's poses at capture; this reader derives them
MAGIC = b"\x89MCAP0\r\n"
CHUNK_SIZE = 1 << 20  # bytes of uncompressed messages per chunk: the unit of reading and of CRC checks
COMPRESSION = CompressionType.LZ4  # lz4 ships with the mcap package; zstandard would be one more dependency
TRUTH_SCENE_PERIOD_S = 0.05  # the 3D truth skeletons people look at are drawn at 20 Hz, the data stay 100 Hz
TRACK_SCENE_PERIOD_S = 0.05  # likewise for the tracker's skeletons in a tracks file

KIND_RECORDING = "recording"
KIND_TRACKS = "tracks"
METADATA_NAME = "crossview"
SUMMARY_METADATA_NAME = "crossview.summary"

TOPIC_HEADER = "/crossview/header"
TOPIC_TRUTH = "/truth/poses"
TOPIC_TRUTH_SCENE = "/truth/skeletons"
TOPIC_STORE = "/store/scene"
TOPIC_TF = "/tf"
TOPIC_OUTPUTS = "/tracker/outputs"
TOPIC_TRACK_SCENE = "/tracker/skeletons"


def camera_topic(camera_name: str, what: str) -> str:
    """Per-camera topics: `frame` (crossview.CameraFrame); `detections`, `calibration`, `image` (Foxglove)."""
    return f"/cameras/{camera_name}/{what}"


class RecordingError(CrossviewError):
    """A file that cannot be read as the recording or tracks file asked for; the message names the file."""


def software_version() -> str:
    """The installed crossview-testbed version, or "0+unknown" when running from a source tree."""
    try:
        return importlib.metadata.version("crossview-testbed")
    except importlib.metadata.PackageNotFoundError:
        return "0+unknown"


def to_ns(t_s: float) -> int:
    """Seconds since the scenario start to MCAP log-time nanoseconds: the one conversion in the project."""
    t_s = float(t_s)
    if not math.isfinite(t_s) or t_s < 0:
        raise ValueError(f"log time {t_s} s must be finite and >= 0 (seconds since the scenario start)")
    return round(t_s * 1e9)


# --------------------------------------------------------------------------------------------------
# Project schemas: protobuf built at run time from a FileDescriptorProto.

_F = descriptor_pb2.FieldDescriptorProto


def _project_file() -> descriptor_pb2.FileDescriptorProto:
    """crossview/recording.proto. Arrays are flattened row-major into packed repeated fields; the
    shape is given by the counts beside them (num_detections, num_joints)."""
    f = descriptor_pb2.FileDescriptorProto(name="crossview/recording.proto", package="crossview", syntax="proto3")

    def message(name: str, fields: list[tuple]) -> None:
        m = f.message_type.add(name=name)
        for number, (fname, ftype, repeated, *type_name) in enumerate(fields, start=1):
            fd = m.field.add(
                name=fname, number=number, type=ftype, label=_F.LABEL_REPEATED if repeated else _F.LABEL_OPTIONAL
            )
            if type_name:
                fd.type_name = type_name[0]

    message("PoseTruth", [
        ("t_s", _F.TYPE_DOUBLE, False),
        ("num_joints", _F.TYPE_UINT32, False),
        ("person_ids", _F.TYPE_SINT64, True),  # (P,)
        ("poses_m", _F.TYPE_DOUBLE, True),  # (P, J, 3) world frame, metres
    ])
    message("CameraFrame", [
        ("camera", _F.TYPE_STRING, False),
        ("stamp_s", _F.TYPE_DOUBLE, False),
        ("capture_s", _F.TYPE_DOUBLE, False),
        ("delivery_s", _F.TYPE_DOUBLE, False),
        ("num_detections", _F.TYPE_UINT32, False),
        ("num_joints", _F.TYPE_UINT32, False),
        ("keypoints_px", _F.TYPE_DOUBLE, True),  # (D, J, 2), NaN for a joint not detected
        ("scores", _F.TYPE_DOUBLE, True),  # (D, J)
        ("person_ids", _F.TYPE_SINT64, True),  # (D,), -1 for a false positive
        ("true_keypoints_px", _F.TYPE_DOUBLE, True),  # (D, J, 2)
        ("in_image", _F.TYPE_BOOL, True),  # (D, J)
        ("occluded", _F.TYPE_BOOL, True),  # (D, J)
        ("self_occluded", _F.TYPE_BOOL, True),  # (D, J)
        ("effects", _F.TYPE_UINT32, True),  # (D,) sim.types.DetectionEffect bit mask
    ])
    f.message_type[-1].reserved_range.add(start=15, end=16)  # format 1's poses_at_capture
    f.message_type[-1].reserved_name.append("poses_at_capture")
    message("Target", [
        ("id", _F.TYPE_INT64, False),
        ("stamp_s", _F.TYPE_DOUBLE, False),
        ("state", _F.TYPE_STRING, False),  # tracker.types.TargetState value
        ("pose_m", _F.TYPE_DOUBLE, True),  # (J, 3)
    ])
    message("TrackerOutput", [
        ("stamp_s", _F.TYPE_DOUBLE, False),
        ("camera", _F.TYPE_STRING, False),
        ("num_joints", _F.TYPE_UINT32, False),
        ("targets", _F.TYPE_MESSAGE, True, ".crossview.Target"),
        ("detection_target_ids", _F.TYPE_SINT64, True),  # (D,), -1 unassigned
    ])
    return f


_POOL = descriptor_pool.DescriptorPool()
_POOL.Add(_project_file())
PoseTruthMsg = message_factory.GetMessageClass(_POOL.FindMessageTypeByName("crossview.PoseTruth"))
CameraFrameMsg = message_factory.GetMessageClass(_POOL.FindMessageTypeByName("crossview.CameraFrame"))
TrackerOutputMsg = message_factory.GetMessageClass(_POOL.FindMessageTypeByName("crossview.TrackerOutput"))

# JSON Schemas of the two header documents (MCAP schema encoding "jsonschema").
_CAMERA_JSON_SCHEMA = {
    "type": "object",
    "required": ["name", "frame_id", "K", "dist", "R_cam_from_world", "t_cam_from_world", "width_px", "height_px"],
    "properties": {
        "name": {"type": "string"},
        "frame_id": {"type": "string"},
        "K": {"type": "array", "description": "(3, 3) intrinsics, pixels"},
        "dist": {"type": "array", "description": "(5,) OpenCV k1 k2 p1 p2 k3"},
        "R_cam_from_world": {"type": "array", "description": "(3, 3)"},
        "t_cam_from_world": {"type": "array", "description": "(3,) metres"},
        "width_px": {"type": "integer"},
        "height_px": {"type": "integer"},
    },
}
_COMMON_HEADER_PROPERTIES = {
    "kind": {"enum": [KIND_RECORDING, KIND_TRACKS]},
    "format_version": {"type": "integer"},
    "software_version": {"type": "string"},
    "scenario_name": {"type": "string"},
    "scenario_digest": {"type": "string", "description": "sha256 of the scenario text"},
    "seed": {"type": "integer"},
    "skeleton": {"type": "object", "description": "name, joints, bones"},
    "cameras": {"type": "array", "items": _CAMERA_JSON_SCHEMA},
}
HEADER_JSON_SCHEMAS = {
    KIND_RECORDING: {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "crossview.RecordingHeader",
        "type": "object",
        "required": ["kind", "format_version", "scenario_name", "scenario_text", "scenario_digest", "seed",
                     "duration_s", "skeleton", "cameras", "boxes"],
        "properties": _COMMON_HEADER_PROPERTIES | {
            "scenario_text": {"type": "string", "description": "the scenario TOML as simulated"},
            "duration_s": {"type": "number"},
            "boxes": {"type": "array", "description": "kind, center_m, size_m, yaw_rad"},
        },
    },
    KIND_TRACKS: {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "crossview.TracksHeader",
        "type": "object",
        "required": ["kind", "format_version", "scenario_name", "scenario_digest", "seed", "method", "preset",
                     "config", "skeleton", "cameras"],
        "properties": _COMMON_HEADER_PROPERTIES | {
            "method": {"type": "string"},
            "preset": {"type": "string"},
            "config": {"type": "object"},
        },
    },
}


# --------------------------------------------------------------------------------------------------
# Headers.


def _check_skeleton_name(name: str) -> None:
    if name not in SKELETONS:
        raise ValueError(f"skeleton_name: {name!r} is not one of {sorted(SKELETONS)}")


@dataclass(frozen=True)
class RecordingHeader:
    """What a recording says about itself."""

    scenario_name: str
    scenario_text: str
    scenario_digest: str
    seed: int
    duration_s: float
    skeleton_name: str
    software_version: str = field(default_factory=software_version)
    format_version: int = FORMAT_VERSION

    def __post_init__(self):
        _check_skeleton_name(self.skeleton_name)


@dataclass(frozen=True)
class TracksHeader:
    """What a tracks file says about itself and the recording it was made from."""

    scenario_name: str
    scenario_digest: str
    seed: int
    method: str
    preset: str
    config: dict
    skeleton_name: str
    software_version: str = field(default_factory=software_version)
    format_version: int = FORMAT_VERSION

    def __post_init__(self):
        _check_skeleton_name(self.skeleton_name)


def _json(value) -> bytes:
    """Compact JSON with fixed key order; Python writes floats with repr, so they round-trip exactly."""
    return json.dumps(value, separators=(",", ":"), ensure_ascii=False, allow_nan=False).encode()


def _camera_json(camera: Camera) -> dict:
    return {
        "name": camera.name,
        "frame_id": foxglove.camera_frame_id(camera.name),
        "K": camera.K.tolist(),
        "dist": camera.dist.tolist(),
        "R_cam_from_world": camera.R_cam_from_world.tolist(),
        "t_cam_from_world": camera.t_cam_from_world.tolist(),
        "width_px": int(camera.width_px),
        "height_px": int(camera.height_px),
    }


def _camera_from_json(d: dict) -> Camera:
    return Camera(
        name=d["name"], K=np.array(d["K"]), dist=np.array(d["dist"]), R_cam_from_world=np.array(d["R_cam_from_world"]),
        t_cam_from_world=np.array(d["t_cam_from_world"]), width_px=int(d["width_px"]), height_px=int(d["height_px"]),
    )


def _box_json(box: Box) -> dict:
    return {
        "kind": box.kind.value,
        "center_m": [float(v) for v in box.center_m],
        "size_m": [float(v) for v in box.size_m],
        "yaw_rad": float(box.yaw_rad),
    }


def _box_from_json(d: dict) -> Box:
    return Box(BoxKind(d["kind"]), tuple(d["center_m"]), tuple(d["size_m"]), float(d["yaw_rad"]))


def _skeleton_json(skeleton: Skeleton) -> dict:
    return {"name": skeleton.name, "joints": list(skeleton.joints), "bones": [list(b) for b in skeleton.bones]}


# --------------------------------------------------------------------------------------------------
# Array <-> message conversion.


def _pose_truth_to_msg(truth: PoseTruth, msg) -> None:
    poses, ids = _checked_poses(truth)
    msg.t_s = float(truth.t_s)
    msg.num_joints = poses.shape[1]
    msg.person_ids.extend(ids.tolist())
    msg.poses_m.extend(poses.ravel().tolist())


def pose_truth_bytes(truth: PoseTruth) -> bytes:
    """`crossview.PoseTruth` wire bytes of `truth`, written by a compiled loop (the same bytes as protobuf's)."""
    from crossview import wire  # (numba: loaded for writing only)

    poses, ids = _checked_poses(truth)
    out = _scratch(wire.pose_truth_capacity(*poses.shape[:2]))
    return out[:wire.pose_truth(out, 0, float(truth.t_s), ids, poses)].tobytes()


def _checked_poses(truth: PoseTruth) -> tuple[np.ndarray, np.ndarray]:
    """poses (P, J, 3) float64 and person_ids (P,) int64 of `truth`, C-contiguous, shapes checked."""
    poses = np.ascontiguousarray(truth.poses, dtype=np.float64)
    ids = np.ascontiguousarray(truth.person_ids, dtype=np.int64)
    if poses.ndim != 3 or poses.shape[2] != 3 or ids.ndim != 1 or poses.shape[0] != ids.shape[0]:
        raise ValueError(f"PoseTruth@{truth.t_s}: poses expected (P, J, 3) with P={ids.shape[0]}, got {poses.shape}")
    return poses, ids


_SCRATCH = [np.empty(1 << 16, dtype=np.uint8)]


def _scratch(size: int) -> np.ndarray:
    """A reusable byte buffer of at least `size` bytes for the message encoders (the writer's thread only)."""
    if _SCRATCH[0].size < size:
        _SCRATCH[0] = np.empty(2 * size, dtype=np.uint8)
    return _SCRATCH[0]


def camera_frame_bytes(cf: CameraFrame) -> bytes:
    """`crossview.CameraFrame` wire bytes of one camera frame, written by a compiled loop (the same bytes as
    protobuf's serialisation of `_camera_frame_to_msg`, which the tests check)."""
    from crossview import wire  # (numba: loaded for writing only)

    frame, truth = cf.frame, cf.truth
    kp = np.ascontiguousarray(frame.keypoints_px, dtype=np.float64)
    if kp.ndim != 3 or kp.shape[2] != 2:
        raise ValueError(f"CameraFrame {frame.camera}@{frame.stamp_s}: keypoints_px expected (D, J, 2), got "
                         f"{kp.shape}")
    D, J = kp.shape[:2]
    arrays = [kp]
    for name, value, shape, dtype in (
            ("scores", frame.scores, (D, J), np.float64), ("truth.person_ids", truth.person_ids, (D,), np.int64),
            ("truth.keypoints_px", truth.keypoints_px, (D, J, 2), np.float64),
            ("truth.in_image", truth.in_image, (D, J), bool), ("truth.occluded", truth.occluded, (D, J), bool),
            ("truth.self_occluded", truth.self_occluded, (D, J), bool),
            ("truth.effects", truth.effects, (D,), np.int64)):
        array = np.ascontiguousarray(value, dtype=dtype)
        if array.shape != shape:
            raise ValueError(f"CameraFrame {frame.camera}@{frame.stamp_s}: {name} expected {shape}, got {array.shape}")
        arrays.append(array)
    name = _utf8(frame.camera)
    out = _scratch(wire.camera_frame_capacity(D, J, name.size))
    size = wire.camera_frame(out, name, float(frame.stamp_s), float(truth.capture_s), float(truth.delivery_s), *arrays)
    if size < 0:
        raise ValueError(f"CameraFrame {frame.camera}@{frame.stamp_s}: truth.effects must be uint32 bit masks")
    return out[:size].tobytes()


class EncodedFrame(NamedTuple):
    """A camera frame as the two messages a recording stores for it (`encode_frames`). A writer takes it
    in place of the CameraFrame: a producer can encode frames as they are made and write them later, in
    log-time order, without the CameraFrame objects in between."""
    camera: str
    log_time_ns: int  # its delivery time
    frame: bytes  # crossview.CameraFrame
    annotations: bytes  # foxglove.ImageAnnotations stamped log_time_ns


# Where each field of `DetectionRows` lives in a CameraFrame (its part and attribute), with the dtype and
# trailing shape (J: joints) the compiled encoder expects.
_ROWS = dict(zip(DetectionRows._fields, (
    ("truth", "person_ids", np.int64, 0), ("frame", "keypoints_px", np.float64, 2), ("frame", "scores", np.float64, 1),
    ("truth", "keypoints_px", np.float64, 2), ("truth", "in_image", bool, 1), ("truth", "occluded", bool, 1),
    ("truth", "self_occluded", bool, 1), ("truth", "effects", np.int64, 0)), strict=True))


def encode_frames(cameras: Sequence[str], times: np.ndarray, bounds: np.ndarray, rows: DetectionRows,
                  skeleton: Skeleton) -> list[EncodedFrame]:
    """The EncodedFrame of n camera frames given as rows, from one compiled call (the bytes of
    `camera_frame_bytes` and `foxglove.image_annotations_bytes` at the delivery time, which the tests check).

    Args:
        cameras: the n frames' camera names.
        times: (n, 3) each frame's stamp, capture and delivery seconds.
        bounds: (n + 1,) frame i owns rows bounds[i]:bounds[i + 1].
        rows: the frames' detections (the detector's `DetectionRows`).

    A frame the batch does not take (a bad effects mask, a +0.0 coordinate, which protobuf leaves out) is
    encoded by the one-frame functions, which also raise their errors.
    """
    from crossview import wire  # (numba: loaded for writing only)

    times = np.ascontiguousarray(times, dtype=np.float64).reshape(-1, 3)
    bounds = np.ascontiguousarray(bounds, dtype=np.int64)
    n = len(cameras)
    J = skeleton.num_joints
    D = int(bounds[-1]) if bounds.size else 0
    if times.shape[0] != n or bounds.shape != (n + 1,) or len(rows) != len(_ROWS):
        raise ValueError(f"encode_frames: {n} cameras, times {times.shape}, bounds {bounds.shape} and "
                         f"{len(rows)} row arrays; expected (n, 3) times, (n + 1,) bounds and {len(_ROWS)} arrays")
    columns = []
    for (owner, name, dtype, tail), array in zip(_ROWS.values(), rows):
        array = np.ascontiguousarray(array, dtype=dtype)
        expected = (D, J, 2)[:1 + tail]
        if array.shape != expected:
            raise ValueError(f"encode_frames: {owner}.{name} rows expected {expected}, got {array.shape}")
        columns.append(array)
    names = [_utf8(camera) for camera in cameras]
    name_ends = np.cumsum([0] + [a.size for a in names])
    t_ns = [to_ns(t) for t in times[:, 2].tolist()]
    styles = foxglove.detection_styles(columns[0])
    bones = foxglove.bone_table(skeleton)
    counts = np.diff(bounds).tolist()
    capacity = sum(wire.camera_frame_capacity(d, J, a.size) + wire.image_annotations_capacity(
        d, J, len(bones), styles.table.shape[1]) for d, a in zip(counts, names))
    out = _scratch(capacity)
    ends = np.empty(2 * n, dtype=np.int64)
    status = np.empty(n, dtype=np.int64)
    ids, kp, scores, *truth = columns
    wire.frames_and_annotations(out, ends, status, np.concatenate(names) if names else np.zeros(0, np.uint8),
                                name_ends, times, np.asarray(t_ns, dtype=np.int64), bounds, kp, scores, ids, *truth,
                                bones, styles.lut, styles.table, styles.sizes, *foxglove.ANNOTATION_FIELDS)
    ends, status, bounds = ends.tolist(), status.tolist(), bounds.tolist()
    data = out[:ends[-1] if n else 0].tobytes()
    result, start = [], 0
    for i, camera in enumerate(cameras):
        if status[i]:  # the one-frame encoders' bytes (or their error)
            cf = CameraFrame.from_rows(camera, *times[i].tolist(), DetectionRows(*columns), bounds[i], bounds[i + 1])
            result.append(EncodedFrame(camera, t_ns[i], camera_frame_bytes(cf),
                                       foxglove.image_annotations_bytes(cf, skeleton, t_ns[i])))
        else:
            result.append(EncodedFrame(camera, t_ns[i], data[start:ends[2 * i]], data[ends[2 * i]:ends[2 * i + 1]]))
        start = ends[2 * i + 1]
    return result


def encode_camera_frames(frames: Sequence[CameraFrame], skeleton: Skeleton) -> list[EncodedFrame]:
    """`encode_frames` of CameraFrame objects: their arrays are put together as rows. Frames with unusual
    arrays (not of the shapes and kinds the detector makes) go through the one-frame functions."""

    def one_by_one():
        result = []
        for cf in frames:
            t_ns = to_ns(cf.truth.delivery_s)
            result.append(EncodedFrame(cf.frame.camera, t_ns, camera_frame_bytes(cf),
                                       foxglove.image_annotations_bytes(cf, skeleton, t_ns)))
        return result

    if len(frames) < 2:
        return one_by_one()
    J = skeleton.num_joints
    try:
        counts = [cf.frame.keypoints_px.shape[0] for cf in frames]
        rows = []
        for owner, name, dtype, tail in _ROWS.values():
            parts = [getattr(getattr(cf, owner), name) for cf in frames]
            shape = (J, 2)[:tail]
            if any(p.shape != (d, *shape) for p, d in zip(parts, counts)):
                return one_by_one()
            rows.append(np.concatenate(parts, dtype=dtype))
    except (AttributeError, IndexError, TypeError, ValueError):  # not arrays of the expected kinds
        return one_by_one()
    times = [(cf.frame.stamp_s, cf.truth.capture_s, cf.truth.delivery_s) for cf in frames]
    return encode_frames([cf.frame.camera for cf in frames], np.array(times, dtype=np.float64),
                         np.cumsum([0] + counts), DetectionRows(*rows), skeleton)


def warm_up(skeleton: Skeleton) -> None:
    """Loads the writer's compiled encoders (the first use of each costs tens of milliseconds) by encoding
    a made-up instant: call it where the time is free, e.g. while a simulation worker starts."""
    J = skeleton.num_joints
    ids = np.array([3], dtype=np.int64)
    truth = PoseTruth(0.5, ids, np.ones((1, J, 3)))
    seen = np.ones((1, J), dtype=bool)
    frame = CameraFrame(Frame("warm", 0.5, np.ones((1, J, 2)), np.ones((1, J))),
                        DetectionTruth(0.5, 0.5, ids, np.ones((1, J, 2)), seen, ~seen, ~seen,
                                       np.zeros(1, dtype=np.int64)), None)
    pose_truth_bytes(truth)
    foxglove.truth_skeletons_bytes(truth, skeleton, 1)
    encode_camera_frames([frame, frame], skeleton)


@functools.lru_cache(maxsize=1024)
def _utf8(text: str) -> np.ndarray:
    return np.frombuffer(text.encode(), dtype=np.uint8)


def _pose_truth_from_msg(msg) -> PoseTruth:
    ids = np.array(msg.person_ids, dtype=np.int64)
    poses = np.array(msg.poses_m, dtype=np.float64).reshape(len(ids), msg.num_joints, 3)
    return PoseTruth(t_s=msg.t_s, person_ids=ids, poses=poses)


def _camera_frame_to_msg(cf: CameraFrame):
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


def _camera_frame_from_msg(msg, poses_at_capture: PoseTruth | None = None) -> CameraFrame:
    D, J = msg.num_detections, msg.num_joints
    frame = Frame(
        camera=msg.camera,
        stamp_s=msg.stamp_s,
        keypoints_px=np.array(msg.keypoints_px, dtype=np.float64).reshape(D, J, 2),
        scores=np.array(msg.scores, dtype=np.float64).reshape(D, J),
    )
    truth = DetectionTruth(
        capture_s=msg.capture_s,
        delivery_s=msg.delivery_s,
        person_ids=np.array(msg.person_ids, dtype=np.int64),
        keypoints_px=np.array(msg.true_keypoints_px, dtype=np.float64).reshape(D, J, 2),
        in_image=np.array(msg.in_image, dtype=bool).reshape(D, J),
        occluded=np.array(msg.occluded, dtype=bool).reshape(D, J),
        self_occluded=np.array(msg.self_occluded, dtype=bool).reshape(D, J),
        effects=np.array(msg.effects, dtype=np.int64),
    )
    return CameraFrame(frame=frame, truth=truth, poses_at_capture=poses_at_capture)


def _tracker_output_to_msg(output: TrackerOutput, num_joints: int):
    msg = TrackerOutputMsg(stamp_s=float(output.stamp_s), camera=output.camera, num_joints=num_joints)
    for target in output.targets:
        pose = np.asarray(target.pose, dtype=np.float64)
        if pose.shape != (num_joints, 3):
            raise ValueError(f"TrackerOutput@{output.stamp_s}: target {target.id} pose expected ({num_joints}, 3), "
                             f"got {pose.shape}")
        t = msg.targets.add(id=int(target.id), stamp_s=float(target.stamp_s), state=TargetState(target.state).value)
        t.pose_m.extend(pose.ravel().tolist())
    msg.detection_target_ids.extend(np.asarray(output.detection_target_ids, dtype=np.int64).ravel().tolist())
    return msg


def _tracker_output_from_msg(msg) -> TrackerOutput:
    J = msg.num_joints
    targets = [
        Target(id=t.id, pose=np.array(t.pose_m, dtype=np.float64).reshape(J, 3), stamp_s=t.stamp_s,
               state=TargetState(t.state))
        for t in msg.targets
    ]
    return TrackerOutput(
        stamp_s=msg.stamp_s, camera=msg.camera, targets=targets,
        detection_target_ids=np.array(msg.detection_target_ids, dtype=np.int64),
    )


# --------------------------------------------------------------------------------------------------
# Writing.


class _AtomicMcapWriter:
    """An MCAP writer onto a temporary file in the target folder, renamed onto `path` on clean exit."""

    def __init__(self, path, kind: str, header_doc: dict, metadata: dict[str, str], chunk_size: int):
        self.path = Path(path)
        self._tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        try:
            self._file = open(self._tmp, "wb")  # closed in close() or abort()
        except OSError as e:
            raise RecordingError(f"{self.path}: cannot write here: {e.strerror or e}") from None
        self._done = False
        try:
            self._writer = Writer(
                self._file, chunk_size=chunk_size, compression=COMPRESSION, enable_data_crcs=True,
            )
            self._writer.start(profile="", library=f"crossview-testbed {header_doc['software_version']}")
            # The flat metadata record lands before the first chunk, so kind and version are read first.
            self._writer.add_metadata(METADATA_NAME, metadata)
            self._schemas: dict[str, int] = {}
            header_channel = self.channel(TOPIC_HEADER, "json", f"crossview.{kind.capitalize()}Header",
                                          "jsonschema", _json(HEADER_JSON_SCHEMAS[kind]))
            self.add(header_channel, 0, _json(header_doc))
        except BaseException:
            self.abort()
            raise

    def schema(self, name: str, encoding: str, data: bytes) -> int:
        if name not in self._schemas:
            self._schemas[name] = self._writer.register_schema(name=name, encoding=encoding, data=data)
        return self._schemas[name]

    def channel(self, topic: str, message_encoding: str, schema_name: str, schema_encoding: str,
                schema_data: bytes) -> int:
        schema_id = self.schema(schema_name, schema_encoding, schema_data)
        return self._writer.register_channel(topic=topic, message_encoding=message_encoding, schema_id=schema_id)

    def protobuf_channel(self, topic: str, message_class) -> int:
        descriptor = message_class.DESCRIPTOR
        return self.channel(topic, "protobuf", descriptor.full_name, "protobuf",
                            foxglove.file_descriptor_set(descriptor))

    def end_chunk(self) -> None:
        """Closes the chunk in progress, so that what came before survives a truncation after it."""
        self._writer.flush()

    def add(self, channel_id: int, log_time_ns: int, data: bytes) -> None:
        self._writer.add_message(channel_id=channel_id, log_time=log_time_ns, data=data, publish_time=log_time_ns)

    def add_many(self, messages: Sequence[tuple[int, int, bytes]]) -> None:
        """`add` of each (channel id, log time ns, data) in turn."""
        add = self._writer.add_message
        for channel_id, t, data in messages:
            add(channel_id, t, data, t)

    def close(self, summary_metadata: dict[str, str]) -> None:
        """Finishes the file, fsyncs it and renames it onto the final path."""
        if self._done:
            return
        try:
            self._writer.add_metadata(SUMMARY_METADATA_NAME, summary_metadata)
            self._writer.finish()
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
            os.replace(self._tmp, self.path)
            self._done = True
        except BaseException:
            self.abort()
            raise
        try:
            dir_fd = os.open(self.path.parent, os.O_RDONLY)
        except OSError:
            return
        try:
            os.fsync(dir_fd)
        except OSError:
            pass
        finally:
            os.close(dir_fd)

    def abort(self) -> None:
        """Drops the temporary file; nothing appears under the final name."""
        if self._done:
            return
        self._done = True
        self._file.close()
        try:
            os.unlink(self._tmp)
        except FileNotFoundError:
            pass


def _flat_metadata(kind: str, header) -> dict[str, str]:
    return {
        "kind": kind,
        "format_version": str(header.format_version),
        "software_version": header.software_version,
        "scenario_name": header.scenario_name,
        "scenario_digest": header.scenario_digest,
        "seed": str(header.seed),
        "skeleton": header.skeleton_name,
    }


class _WriterContext:
    """Context-manager behaviour shared by the writers: close on a clean exit, abort on any exception.

    Subclasses hold an `_AtomicMcapWriter` in `_out` and define `close()`.
    """

    _out: _AtomicMcapWriter

    def abort(self) -> None:
        """Drops the temporary file; nothing appears under the final name."""
        self._out.abort()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


class RecordingWriter(_WriterContext):
    """Writes a recording atomically. Events must come in log-time order (truth at t_s, frames at
    delivery_s), which makes the file streamable in that order.

    Use as a context manager: the file appears under `path` only when the block exits cleanly; on an
    exception (KeyboardInterrupt included) the temporary file is removed.
    """

    def __init__(self, path, header: RecordingHeader, cameras: Sequence[Camera], boxes: Sequence[Box], *,
                 chunk_size: int = CHUNK_SIZE):
        self.header = header
        self.cameras = list(cameras)
        self.boxes = tuple(boxes)
        self.skeleton = SKELETONS[header.skeleton_name]
        names = [c.name for c in self.cameras]
        if len(set(names)) != len(names):
            raise ValueError(f"cameras: names must be unique, got {names}")
        doc = {
            "kind": KIND_RECORDING,
            "format_version": header.format_version,
            "software_version": header.software_version,
            "scenario_name": header.scenario_name,
            "scenario_digest": header.scenario_digest,
            "seed": int(header.seed),
            "duration_s": float(header.duration_s),
            "skeleton": _skeleton_json(self.skeleton),
            "scenario_text": header.scenario_text,
            "cameras": [_camera_json(c) for c in self.cameras],
            "boxes": [_box_json(b) for b in self.boxes],
        }
        self._out = _AtomicMcapWriter(path, KIND_RECORDING, doc, _flat_metadata(KIND_RECORDING, header), chunk_size)
        try:
            out = self._out
            self._tf = out.protobuf_channel(TOPIC_TF, foxglove.FrameTransforms)
            self._store = out.protobuf_channel(TOPIC_STORE, foxglove.SceneUpdate)
            self._truth = out.protobuf_channel(TOPIC_TRUTH, PoseTruthMsg)
            self._truth_scene = out.protobuf_channel(TOPIC_TRUTH_SCENE, foxglove.SceneUpdate)
            self._frame_ch, self._annotation_ch = {}, {}
            for camera in self.cameras:
                calibration = out.protobuf_channel(camera_topic(camera.name, "calibration"),
                                                   foxglove.CameraCalibration)
                self._frame_ch[camera.name] = out.protobuf_channel(camera_topic(camera.name, "frame"), CameraFrameMsg)
                self._annotation_ch[camera.name] = out.protobuf_channel(
                    camera_topic(camera.name, "detections"), foxglove.ImageAnnotations)
                backdrop = out.protobuf_channel(camera_topic(camera.name, "image"), foxglove.CompressedImage)
                out.add(calibration, 0, foxglove.camera_calibration(camera, 0).SerializeToString())
                out.add(backdrop, 0, foxglove.camera_backdrop(camera, 0).SerializeToString())
            out.add(self._tf, 0, foxglove.frame_transforms(self.cameras, 0).SerializeToString())
            out.add(self._store, 0, foxglove.store_scene(self.boxes, self.cameras, 0).SerializeToString())
            out.end_chunk()  # the header and the static scene get a chunk of their own
        except BaseException:
            self._out.abort()
            raise
        self._last_ns = 0
        self._next_scene_ns = 0
        self._people: set[int] = set()
        self._counts = {"truth": 0, "frames": 0}

    def _log_time(self, t_ns: int, what: str) -> int:
        if t_ns < self._last_ns:
            raise ValueError(f"{what}: log time {t_ns / 1e9} s is before the previous event ({self._last_ns / 1e9} s); "
                             "events must be written in log-time order")
        self._last_ns = t_ns
        return t_ns

    def write(self, event: PoseTruth | CameraFrame | EncodedFrame) -> None:
        """Appends one event: a PoseTruth (log time t_s) or a CameraFrame (log time truth.delivery_s),
        or a camera frame already encoded (`EncodedFrame`, log time log_time_ns)."""
        self.write_many([event])

    def write_many(self, events: Sequence[PoseTruth | CameraFrame | EncodedFrame]) -> None:
        """`write` of each event in turn (the same bytes), with all the CameraFrames among them encoded
        in one compiled call (`encode_camera_frames`): what a producer of many events at a time should use."""
        encoded = iter(encode_camera_frames([e for e in events if isinstance(e, CameraFrame)], self.skeleton))
        messages = []
        for event in events:
            if isinstance(event, CameraFrame):
                event = next(encoded)
            if isinstance(event, EncodedFrame):
                frame_channel = self._frame_ch.get(event.camera)
                if frame_channel is None:
                    raise ValueError(f"CameraFrame: camera {event.camera!r} is not one of the recording's cameras")
                t = self._log_time(event.log_time_ns, f"CameraFrame {event.camera}")
                messages.append((frame_channel, t, event.frame))
                messages.append((self._annotation_ch[event.camera], t, event.annotations))
                self._counts["frames"] += 1
            elif isinstance(event, PoseTruth):
                t = self._log_time(to_ns(event.t_s), "PoseTruth")
                messages.append((self._truth, t, pose_truth_bytes(event)))
                if t >= self._next_scene_ns:
                    messages.append((self._truth_scene, t, foxglove.truth_skeletons_bytes(event, self.skeleton, t)))
                    self._next_scene_ns = t + to_ns(TRUTH_SCENE_PERIOD_S)
                self._people.update(np.asarray(event.person_ids).tolist())
                self._counts["truth"] += 1
            else:
                raise TypeError(f"RecordingWriter.write: expected PoseTruth, CameraFrame or EncodedFrame, got "
                                f"{type(event).__name__}")
        self._out.add_many(messages)

    def encode_frames(self, cameras: Sequence[int], times: np.ndarray, bounds: np.ndarray,
                      rows: DetectionRows) -> list[EncodedFrame]:
        """`encode_frames` (the module's) of frames from this recording's cameras, given by index."""
        names = [self.cameras[i].name for i in cameras]
        return encode_frames(names, times, bounds, rows, self.skeleton)

    def close(self) -> None:
        summary = {
            "num_people": len(self._people),
            "num_truth": self._counts["truth"],
            "num_frames": self._counts["frames"],
            "end_s": self._last_ns / 1e9,
        }
        self._out.close({"json": _json(summary).decode()})



class TracksWriter(_WriterContext):
    """Writes a tracks file atomically: one TrackerOutput per processed frame, in processing order.

    The log time of an output is its stamp (clamped at 0: a camera clock may stamp a frame slightly
    before the scenario start; the exact stamp is in the message). Call `finish(summary)` before the
    block ends to record tracker timings.
    """

    def __init__(self, path, header: TracksHeader, cameras: Sequence[Camera], *, chunk_size: int = CHUNK_SIZE):
        self.header = header
        self.cameras = list(cameras)
        self.skeleton = SKELETONS[header.skeleton_name]
        doc = {
            "kind": KIND_TRACKS,
            "format_version": header.format_version,
            "software_version": header.software_version,
            "scenario_name": header.scenario_name,
            "scenario_digest": header.scenario_digest,
            "seed": int(header.seed),
            "method": header.method,
            "preset": header.preset,
            "config": header.config,
            "skeleton": _skeleton_json(self.skeleton),
            "cameras": [_camera_json(c) for c in self.cameras],
        }
        try:
            _json(header.config)
        except (TypeError, ValueError) as e:
            raise ValueError(f"TracksHeader.config: must be JSON-serialisable without NaN: {e}") from None
        self._out = _AtomicMcapWriter(path, KIND_TRACKS, doc, _flat_metadata(KIND_TRACKS, header), chunk_size)
        try:
            self._outputs = self._out.protobuf_channel(TOPIC_OUTPUTS, TrackerOutputMsg)
            self._scene = self._out.protobuf_channel(TOPIC_TRACK_SCENE, foxglove.SceneUpdate)
            self._out.end_chunk()
        except BaseException:
            self._out.abort()
            raise
        self._summary: dict = {}
        self._next_scene_ns = 0
        self._targets: set[int] = set()
        self._count = 0

    def write(self, output: TrackerOutput) -> None:
        """Appends the tracker's output after one frame."""
        t_ns = to_ns(max(0.0, float(output.stamp_s)))
        msg = _tracker_output_to_msg(output, self.skeleton.num_joints)
        self._out.add(self._outputs, t_ns, msg.SerializeToString())
        if t_ns >= self._next_scene_ns:
            scene = foxglove.tracker_skeletons(output, self.skeleton, t_ns)
            self._out.add(self._scene, t_ns, scene.SerializeToString())
            self._next_scene_ns = t_ns + to_ns(TRACK_SCENE_PERIOD_S)
        self._targets.update(int(t.id) for t in output.targets)
        self._count += 1

    def finish(self, summary: dict) -> None:
        """Records the run's summary (e.g. tracker_s, updates, num_cameras); written when the file closes."""
        try:
            _json(summary)
        except (TypeError, ValueError) as e:
            raise ValueError(f"tracks summary: must be JSON-serialisable without NaN: {e}") from None
        self._summary = dict(summary)

    def close(self) -> None:
        summary = {"num_outputs": self._count, "num_targets": len(self._targets)} | self._summary
        self._out.close({"json": _json(summary).decode()})



# --------------------------------------------------------------------------------------------------
# Reading.

_READ_ERRORS = (McapError, CRCValidationError, struct.error, EOFError, UnicodeDecodeError, RuntimeError,
                DecodeError, KeyError, ValueError, zlib.error)


class _McapStream:
    """Streams one file's records in file order, turning every failure into a RecordingError."""

    def __init__(self, path, allow_truncated: bool):
        self.path = Path(path)
        self.allow_truncated = allow_truncated
        try:
            size = self.path.stat().st_size
            with open(self.path, "rb") as f:
                head = f.read(len(MAGIC))
                if size >= 2 * len(MAGIC):
                    f.seek(size - len(MAGIC))
                tail = f.read(len(MAGIC))
        except OSError as e:
            raise RecordingError(f"{self.path}: cannot read: {e.strerror or e}") from None
        self.size = size
        if head != MAGIC:
            raise RecordingError(f"{self.path}: not an MCAP file (it does not start with the MCAP magic bytes)")
        self.complete = tail == MAGIC and size > 2 * len(MAGIC)
        if not self.complete and not allow_truncated:
            raise RecordingError(
                f"{self.path}: truncated MCAP file (no end magic; the writer was interrupted or the copy is "
                "incomplete); use --allow-truncated to read the readable prefix"
            )

    def records(self) -> Iterator:
        """Schema, Channel, Message, Metadata records of the data section, in file order."""
        with open(self.path, "rb") as f:
            reader = StreamReader(f, validate_crcs=True, record_size_limit=max(self.size, 1))
            iterator = iter(reader.records)
            while True:
                try:
                    record = next(iterator)
                except StopIteration:
                    return
                except _READ_ERRORS as e:
                    if self.allow_truncated:
                        return
                    raise RecordingError(f"{self.path}: corrupt MCAP data ({_describe(e)}); "
                                         "use --allow-truncated to read the readable prefix") from None
                if isinstance(record, DataEnd):
                    return
                yield record


def _describe(e: BaseException) -> str:
    if isinstance(e, CRCValidationError):
        return "CRC mismatch"
    if isinstance(e, McapError) and type(e).__name__ == "EndOfFile":
        return "unexpected end of file"
    return f"{type(e).__name__}: {e}" if str(e) else type(e).__name__


class _Container:
    """The common part of a recording and a tracks file: the header document and the channel table."""

    kind: str

    def __init__(self, path, allow_truncated: bool):
        self._stream = _McapStream(path, allow_truncated)
        self.path = self._stream.path
        self.truncated = not self._stream.complete
        self.doc = self._read_header()
        try:
            self.skeleton = SKELETONS[self.doc["skeleton"]["name"]]
            self.cameras = [_camera_from_json(c) for c in self.doc["cameras"]]
        except (KeyError, TypeError, ValueError) as e:
            raise RecordingError(f"{self.path}: unreadable header ({e})") from None

    def _check(self, kind: str, version: int) -> None:
        if kind != self.kind:
            wanted = "a recording (made by `crossview generate`)" if self.kind == KIND_RECORDING else \
                "a tracks file (made by `crossview track`)"
            raise RecordingError(f"{self.path}: this is a {kind} file, but {wanted} is expected here")
        if kind == KIND_RECORDING and version < OLDEST_RECORDING_VERSION:
            raise RecordingError(
                f"{self.path}: format version {version} is older than this software reads (recordings: "
                f"{OLDEST_RECORDING_VERSION} to {FORMAT_VERSION}); generate it again with `crossview generate`"
            )
        if version > FORMAT_VERSION:
            raise RecordingError(
                f"{self.path}: format version {version} is newer than this software reads ({FORMAT_VERSION}); "
                f"upgrade crossview-testbed (this is {software_version()})"
            )

    def _read_header(self) -> dict:
        channels: dict[int, Channel] = {}
        try:
            for record in self._stream.records():
                if isinstance(record, Metadata) and record.name == METADATA_NAME:
                    self._check(record.metadata.get("kind", "?"), int(record.metadata.get("format_version", "0")))
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message) and channels.get(record.channel_id, None) is not None \
                        and channels[record.channel_id].topic == TOPIC_HEADER:
                    doc = json.loads(record.data)
                    self._check(doc["kind"], int(doc["format_version"]))
                    return doc
        except RecordingError:
            raise
        except (ValueError, KeyError, TypeError) as e:
            raise RecordingError(f"{self.path}: unreadable crossview header ({e})") from None
        raise RecordingError(f"{self.path}: no {TOPIC_HEADER} message; not a crossview {self.kind} file")

    def _messages(self, schema_names: set[str]) -> Iterator[tuple[str, Message]]:
        """(schema name, message) for the messages whose channel has one of `schema_names`, in file order."""
        schemas: dict[int, str] = {}
        wanted: dict[int, str] = {}
        for record in self._stream.records():
            if isinstance(record, Message):
                name = wanted.get(record.channel_id)
                if name is not None:
                    yield name, record
            elif isinstance(record, Schema):
                schemas[record.id] = record.name
            elif isinstance(record, Channel):
                name = schemas.get(record.schema_id)
                if name in schema_names:
                    wanted[record.id] = name

    def _decode(self, decode, data: bytes):
        try:
            return decode(data)
        except (DecodeError, ValueError) as e:
            if self._stream.allow_truncated:
                return None
            raise RecordingError(f"{self.path}: corrupt message ({e})") from None


class Recording(_Container):
    """A recording opened for reading. `header`, `cameras` and `boxes` are read on open; the events
    stream from disk one chunk at a time every time an iterator is asked for."""

    kind = KIND_RECORDING

    def __init__(self, path, allow_truncated: bool = False):
        super().__init__(path, allow_truncated)
        d = self.doc
        try:
            self.header = RecordingHeader(
                scenario_name=d["scenario_name"], scenario_text=d["scenario_text"],
                scenario_digest=d["scenario_digest"], seed=int(d["seed"]), duration_s=float(d["duration_s"]),
                skeleton_name=d["skeleton"]["name"], software_version=d["software_version"],
                format_version=int(d["format_version"]),
            )
            self.boxes = tuple(_box_from_json(b) for b in d["boxes"])
        except (KeyError, TypeError, ValueError) as e:
            raise RecordingError(f"{self.path}: unreadable recording header ({e})") from None

    def _events(self, names: set[str], with_poses: bool = False) -> Iterator[PoseTruth | CameraFrame]:
        window = _TruthWindow(self.truth, self.skeleton.num_joints) if with_poses else None
        for name, record in self._messages(names):
            if name == "crossview.PoseTruth":
                event = self._decode(lambda b: _pose_truth_from_msg(PoseTruthMsg.FromString(b)), record.data)
            else:
                event = self._decode(lambda b: CameraFrameMsg.FromString(b), record.data)
                if event is not None:
                    event = _camera_frame_from_msg(event, window.at(event.capture_s) if window else None)
            if event is None:
                return
            yield event

    def events(self, with_poses: bool = False) -> Iterator[PoseTruth | CameraFrame]:
        """Truth and camera frames in log-time order (the order they were written).

        Args:
            with_poses: give each frame its `poses_at_capture`, derived from the truth ticks (read in a
                second pass over the file); else None.
        """
        return self._events({"crossview.PoseTruth", "crossview.CameraFrame"}, with_poses)

    def frames(self, with_poses: bool = False) -> Iterator[CameraFrame]:
        """Camera frames in delivery order (`with_poses` as in `events`)."""
        return self._events({"crossview.CameraFrame"}, with_poses)

    def truth(self) -> Iterator[PoseTruth]:
        """The 100 Hz ground truth in time order."""
        return self._events({"crossview.PoseTruth"})


class _TruthWindow:
    """Everybody's true pose at any capture time of a recording, derived from its truth ticks by
    `sim.poses.interpolate_poses`: the rule and the arithmetic the simulator used for the frames'
    `poses_at_capture`, so the same bits.

    The ticks stream from a second pass over the file. Captures come nearly in time order (frames are in
    delivery order), so only the ticks of the last `KEEP_S` seconds are kept; a capture older than that
    reads the ticks again from the start.
    """

    KEEP_S = 10.0

    def __init__(self, open_ticks, num_joints: int):
        self._open = open_ticks
        self._empty = np.zeros((0, num_joints, 3))
        self._start()

    def _start(self) -> None:
        self._ticks = self._open()
        self._times: list[float] = []
        self._poses: list[PoseTruth] = []
        self._trimmed = False
        self._ended = False

    def at(self, t_s: float) -> PoseTruth:
        if self._trimmed and t_s <= self._times[0]:
            self._start()
        while not self._ended and (not self._times or self._times[-1] < t_s):
            tick = next(self._ticks, None)
            if tick is None:
                self._ended = True
            else:
                self._times.append(tick.t_s)
                self._poses.append(tick)
        i = bisect.bisect_left(self._times, t_s)
        before = self._poses[i - 1] if i > 0 else None
        after = self._poses[i] if i < len(self._poses) else None
        if before is None and after is None:  # a recording without truth
            return PoseTruth(float(t_s), np.zeros(0, dtype=np.int64), self._empty)
        poses = interpolate_poses(before, after, t_s)
        old = bisect.bisect_left(self._times, t_s - self.KEEP_S) - 1
        if old > 0:
            del self._times[:old], self._poses[:old]
            self._trimmed = True
        return poses


class Tracks(_Container):
    """A tracks file opened for reading; `outputs()` streams the tracker outputs in processing order."""

    kind = KIND_TRACKS

    def __init__(self, path, allow_truncated: bool = False):
        super().__init__(path, allow_truncated)
        d = self.doc
        try:
            self.header = TracksHeader(
                scenario_name=d["scenario_name"], scenario_digest=d["scenario_digest"], seed=int(d["seed"]),
                method=d["method"], preset=d["preset"], config=d["config"], skeleton_name=d["skeleton"]["name"],
                software_version=d["software_version"], format_version=int(d["format_version"]),
            )
        except (KeyError, TypeError, ValueError) as e:
            raise RecordingError(f"{self.path}: unreadable tracks header ({e})") from None
        self.summary: dict = _read_summary(self.path) if not self.truncated else {}

    def outputs(self) -> Iterator[TrackerOutput]:
        for _, record in self._messages({"crossview.TrackerOutput"}):
            output = self._decode(lambda b: _tracker_output_from_msg(TrackerOutputMsg.FromString(b)), record.data)
            if output is None:
                return
            yield output


def _read_summary(path: Path) -> dict:
    """The summary metadata written at close, found through the file's summary section (one seek)."""
    try:
        with open(path, "rb") as f:
            for metadata in make_reader(f).iter_metadata():
                if metadata.name == SUMMARY_METADATA_NAME:
                    return json.loads(metadata.metadata["json"])
    except _READ_ERRORS as e:
        raise RecordingError(f"{path}: unreadable summary section ({_describe(e)})") from None
    return {}


def open_recording(path, allow_truncated: bool = False) -> Recording:
    """Opens a recording. Raises RecordingError for a file that is not MCAP, truncated (unless
    `allow_truncated`), corrupt, of a newer format version, or a tracks file."""
    return Recording(path, allow_truncated)


def open_tracks(path, allow_truncated: bool = False) -> Tracks:
    """Opens a tracks file; the same errors as `open_recording`, and a recording given here is one."""
    return Tracks(path, allow_truncated)


# --------------------------------------------------------------------------------------------------
# info.


def info(path, allow_truncated: bool = False) -> dict:
    """What `crossview info` prints: kind, duration, cameras, people, messages per channel, size, ...

    A complete file is described from its summary section without reading the messages; a truncated
    one (with `allow_truncated`) by streaming its readable prefix.
    """
    stream = _McapStream(path, allow_truncated)
    kind = None
    for record in stream.records():
        if isinstance(record, Metadata) and record.name == METADATA_NAME:
            kind = record.metadata.get("kind")
            break
    if kind not in (KIND_RECORDING, KIND_TRACKS):
        raise RecordingError(f"{stream.path}: an MCAP file, but not a crossview recording or tracks file")
    opener = Recording if kind == KIND_RECORDING else Tracks
    container: _Container = opener(path, allow_truncated)
    doc = container.doc
    counts: dict[str, int] = {}
    start_ns = end_ns = None
    summary: dict = {}
    if stream.complete:
        with open(stream.path, "rb") as f:
            reader = make_reader(f)
            mcap_summary = reader.get_summary()
            if mcap_summary is None or mcap_summary.statistics is None:
                raise RecordingError(f"{stream.path}: MCAP file without a summary section")
            stats = mcap_summary.statistics
            for channel_id, channel in sorted(mcap_summary.channels.items()):
                counts[channel.topic] = stats.channel_message_counts.get(channel_id, 0)
            start_ns, end_ns = stats.message_start_time, stats.message_end_time
        summary = _read_summary(stream.path)
        people = summary.get("num_people" if kind == KIND_RECORDING else "num_targets")
    else:
        topics: dict[int, str] = {}
        ids: set[int] = set()
        for record in stream.records():
            if isinstance(record, Channel):
                topics[record.id] = record.topic
                counts.setdefault(record.topic, 0)
            elif isinstance(record, Message):
                topic = topics.get(record.channel_id, f"#{record.channel_id}")
                counts[topic] = counts.get(topic, 0) + 1
                start_ns = record.log_time if start_ns is None else min(start_ns, record.log_time)
                end_ns = record.log_time if end_ns is None else max(end_ns, record.log_time)
                if topic == TOPIC_TRUTH:
                    ids.update(PoseTruthMsg.FromString(record.data).person_ids)
                elif topic == TOPIC_OUTPUTS:
                    ids.update(t.id for t in TrackerOutputMsg.FromString(record.data).targets)
        people = len(ids)
    result = {
        "path": str(stream.path),
        "kind": kind,
        "format_version": doc["format_version"],
        "software_version": doc["software_version"],
        "scenario_name": doc["scenario_name"],
        "scenario_digest": doc["scenario_digest"],
        "seed": doc["seed"],
        "skeleton": doc["skeleton"]["name"],
        "size_bytes": stream.size,
        "truncated": not stream.complete,
        "start_s": (start_ns or 0) / 1e9,
        "end_s": (end_ns or 0) / 1e9,
        "duration_s": ((end_ns or 0) - (start_ns or 0)) / 1e9,
        "cameras": [c["name"] for c in doc["cameras"]],
        "people" if kind == KIND_RECORDING else "targets": people,
        "messages": counts,
    }
    if kind == KIND_RECORDING:
        frames = sum(n for topic, n in counts.items() if topic.startswith("/cameras/") and topic.endswith("/frame"))
        result["camera_frames"] = frames
        result["bytes_per_camera_frame"] = stream.size / frames if frames else None
        result["scenario_duration_s"] = doc["duration_s"]
        result["boxes"] = len(doc["boxes"])
    else:
        result["method"] = doc["method"]
        result["preset"] = doc["preset"]
        result["summary"] = summary
    return result


def format_info(d: dict) -> str:
    """`info` as the lines `crossview info` prints."""
    lines = [
        f"{d['path']}: crossview {d['kind']}, format version {d['format_version']}, "
        f"written by crossview-testbed {d['software_version']}" + ("  [TRUNCATED: readable prefix only]"
                                                                    if d["truncated"] else ""),
        f"  scenario   {d['scenario_name']}  seed {d['seed']}  digest {d['scenario_digest'][:12]}",
        f"  size       {d['size_bytes']:,} bytes"
        + (f" ({d['bytes_per_camera_frame']:,.0f} per camera-frame)" if d.get("bytes_per_camera_frame") else ""),
        f"  time       {d['start_s']:.3f} .. {d['end_s']:.3f} s  (duration {d['duration_s']:.3f} s)",
        f"  cameras    {len(d['cameras'])}: {', '.join(d['cameras'])}",
    ]
    if d["kind"] == KIND_RECORDING:
        lines.append(f"  people     {d['people']}, camera-frames {d['camera_frames']:,}")
        lines.append(f"  boxes      {d['boxes']}")
    else:
        lines.append(f"  tracker    {d['method']} (preset {d['preset']}), {d['targets']} target ids")
        if d.get("summary"):
            lines.append("  summary    " + ", ".join(f"{k}={v}" for k, v in d["summary"].items()))
    lines.append(f"  skeleton   {d['skeleton']}")
    lines.append(f"  messages   {sum(d['messages'].values()):,} on {len(d['messages'])} channels")
    # Per-camera channels are summed over the cameras: /cameras/*/frame and so on.
    grouped: dict[str, list[int]] = {}
    for topic, n in d["messages"].items():
        parts = topic.split("/")
        key = f"/cameras/*/{parts[3]}" if len(parts) == 4 and parts[1] == "cameras" else topic
        grouped.setdefault(key, []).append(n)
    width = max((len(t) for t in grouped), default=0)
    for topic, ns in grouped.items():
        per = f"  ({len(ns)} channels)" if "*" in topic else ""
        lines.append(f"    {topic:<{width}}  {sum(ns):>9,}{per}")
    return "\n".join(lines)


__all__ = [
    "FORMAT_VERSION", "Recording", "RecordingError", "RecordingHeader", "RecordingWriter", "Tracks",
    "TracksHeader", "TracksWriter", "format_info", "info", "open_recording", "open_tracks", "software_version",
    "to_ns",
]
