"""The recording and tracks file formats: topics, schemas (protobuf built at run time, JSON headers),
versions and the JSON forms of cameras, boxes and skeletons. See docs/recording-format.md."""

from __future__ import annotations

import importlib.metadata
import json
import math
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.writer import CompressionType

import crossview.recording.foxglove as foxglove
from core.records import Box, BoxKind
from core.types import SKELETONS, Camera, Skeleton

FORMAT_VERSION = 2  # of recordings
TRACKS_FORMAT_VERSION = 4  # of tracks files; 3: targets carry joint_state; 4: poses as float32 (1 to 3 are read too)
OLDEST_RECORDING_VERSION = 2  # format 1 stored every frame's poses at capture; this reader derives them
MAGIC = b"\x89MCAP0\r\n"
CHUNK_SIZE = 1 << 20  # bytes of uncompressed messages per chunk: the unit of reading and of CRC checks
# mcap installs lz4 and zstandard both. LZ4 writes several times faster: on the hypermarket's tracks file (format
# 3, 1 MiB chunks) 690 MB/s against zstd's 310 MB/s at level 1 and 140 MB/s at level 3, which leave it only 1.3-1.4x
# smaller.
COMPRESSION = CompressionType.LZ4
TRUTH_SCENE_PERIOD_S = 0.05  # the 3D truth skeletons people look at are drawn at 20 Hz, the data stay 100 Hz
TRACK_SCENE_PERIOD_S = 0.05  # likewise for the tracker's skeletons in a tracks file

KIND_RECORDING = "recording"
KIND_TRACKS = "tracks"
METADATA_NAME = "crossview"
SUMMARY_METADATA_NAME = "crossview.summary"

class ChannelInfo(NamedTuple):
    """A channel as a file declares it: its topic, message encoding and schema (name, encoding, bytes)."""

    topic: str
    message_encoding: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes


class LiveSink(Protocol):
    """Where a writer also sends each message as it writes it (`crossview.live`): the same channels, times and
    bytes as the file's. `channel` is called once per channel, before its messages; what it returns is the
    handle `publish` is given."""

    def channel(self, info: ChannelInfo) -> object: ...

    def publish(self, handle: object, log_time_ns: int, data: bytes) -> None: ...


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
        ("effects", _F.TYPE_UINT32, True),  # (D,) core.records.DetectionEffect bit mask
    ])
    f.message_type[-1].reserved_range.add(start=15, end=16)  # format 1's poses_at_capture
    f.message_type[-1].reserved_name.append("poses_at_capture")
    message("Target", [
        ("id", _F.TYPE_INT64, False),
        ("stamp_s", _F.TYPE_DOUBLE, False),
        ("state", _F.TYPE_STRING, False),  # tracker.types.TargetState value
        ("pose_m", _F.TYPE_DOUBLE, True),  # (J, 3), formats 1 to 3
        ("joint_state", _F.TYPE_UINT32, True),  # (J,) tracker.types.JointState values; absent in format 2
        ("pose_m32", _F.TYPE_FLOAT, True),  # (J, 3) from format 4: 1.9 µm at 40 m from the origin, half the bytes
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
    format_version: int = TRACKS_FORMAT_VERSION

    def __post_init__(self):
        _check_skeleton_name(self.skeleton_name)


def compact_json(value) -> bytes:
    """Compact JSON with fixed key order; Python writes floats with repr, so they round-trip exactly."""
    return json.dumps(value, separators=(",", ":"), ensure_ascii=False, allow_nan=False).encode()


def camera_json(camera: Camera) -> dict:
    """A camera as the headers' JSON holds it (`camera_from_json` reads it back)."""
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


def camera_from_json(d: dict) -> Camera:
    """The camera of a header's `camera_json` entry; a missing key is a KeyError, a bad value a ValueError."""
    return Camera(
        name=d["name"], K=np.array(d["K"]), dist=np.array(d["dist"]), R_cam_from_world=np.array(d["R_cam_from_world"]),
        t_cam_from_world=np.array(d["t_cam_from_world"]), width_px=int(d["width_px"]), height_px=int(d["height_px"]),
    )


def box_json(box: Box) -> dict:
    """A store box as the recording header (and a dataset's scene.json) holds it (`box_from_json` reads it)."""
    return {
        "kind": box.kind.value,
        "center_m": [float(v) for v in box.center_m],
        "size_m": [float(v) for v in box.size_m],
        "yaw_rad": float(box.yaw_rad),
    }


def box_from_json(d: dict) -> Box:
    """The store box of a `box_json` entry; a missing key is a KeyError, a bad kind a ValueError."""
    return Box(BoxKind(d["kind"]), tuple(d["center_m"]), tuple(d["size_m"]), float(d["yaw_rad"]))


def skeleton_json(skeleton: Skeleton) -> dict:
    """A skeleton as the headers' JSON holds it: its name, joint names and bones."""
    return {"name": skeleton.name, "joints": list(skeleton.joints), "bones": [list(b) for b in skeleton.bones]}


# --------------------------------------------------------------------------------------------------
# Array <-> message conversion.
