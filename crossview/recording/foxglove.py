"""Foxglove messages for people to look at: the store, camera frusta and calibrations, skeletons, 2D detections.

Every message function returns a message of one of the exact Foxglove protobuf schemas
(`foxglove_schemas_protobuf`), so a recording opens in Foxglove with the store in the 3D panel. The 2D
detections (`ImageAnnotations`) are written by the compiled frame encoder (`crossview.recording.wire`) from the
serialized styles made here (`detection_style_pieces`, kept per person in a `PieceTable`). This
module knows nothing of MCAP; `crossview.recording` writes what it builds. Times are integer
nanoseconds (the recording converts seconds in one place); poses are metres in the world frame (z up).
"""

from __future__ import annotations

import colorsys
import functools
import math
import struct
import zlib
from collections.abc import Callable, Iterable, Sequence

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.CubePrimitive_pb2 import CubePrimitive
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
from foxglove_schemas_protobuf.Point3_pb2 import Point3
from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
from foxglove_schemas_protobuf.SceneEntityDeletion_pb2 import SceneEntityDeletion
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.SpherePrimitive_pb2 import SpherePrimitive
from foxglove_schemas_protobuf.TextPrimitive_pb2 import TextPrimitive
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from google.protobuf import descriptor_pb2
from google.protobuf.descriptor import Descriptor
from google.protobuf.timestamp_pb2 import Timestamp

from core.records import Box, BoxKind
from core.types import Camera, Skeleton

WORLD_FRAME = "world"
FRUSTUM_DEPTH_M = 0.6  # how far the drawn frustum reaches along the optical axis
TRUTH_LINE_M = 0.02  # bone thickness of ground-truth skeletons
TRACK_LINE_M = 0.04  # bone thickness of tracker skeletons, thicker so that both stay visible
JOINT_SPHERE_M = 0.05
DETECTION_LINE_PX = 2.0

BOX_COLORS = {
    BoxKind.FLOOR: (0.55, 0.55, 0.55, 1.0),
    BoxKind.WALL: (0.80, 0.80, 0.78, 0.25),
    BoxKind.SHELF: (0.62, 0.45, 0.30, 0.85),
    BoxKind.CHECKOUT: (0.25, 0.45, 0.75, 0.85),
    BoxKind.ENTRANCE: (0.20, 0.75, 0.30, 0.40),
    BoxKind.EXIT: (0.85, 0.25, 0.25, 0.40),
}
CAMERA_COLOR = (1.0, 0.85, 0.1, 1.0)
BACKDROP_GREY = 40  # 8-bit grey of the blank image the 2D detections are drawn over
FALSE_POSITIVE_COLOR = (0.6, 0.6, 0.6, 1.0)


def camera_frame_id(camera_name: str) -> str:
    """The Foxglove frame id of a camera's optical frame (OpenCV axes: x right, y down, z forward)."""
    return f"camera_{camera_name}"


def timestamp(t_ns: int) -> Timestamp:
    """A protobuf Timestamp of `t_ns` nanoseconds since the scenario start."""
    seconds, nanos = divmod(int(t_ns), 1_000_000_000)
    return Timestamp(seconds=seconds, nanos=nanos)


def color(rgba: Sequence[float]) -> Color:
    r, g, b, a = rgba
    return Color(r=r, g=g, b=b, a=a)


def id_color(identity: int, *, saturation: float, value: float, alpha: float = 1.0, offset: float = 0.0) -> Color:
    """A stable colour per integer identity: hues spaced by the golden ratio so neighbours differ."""
    hue = (offset + 0.618033988749895 * int(identity)) % 1.0
    r, g, b = colorsys.hsv_to_rgb(hue, saturation, value)
    return Color(r=r, g=g, b=b, a=alpha)


def truth_color(person_id: int) -> Color:
    """Ground truth: pale, half transparent."""
    return id_color(person_id, saturation=0.35, value=1.0, alpha=0.6)


def track_color(target_id: int) -> Color:
    """Tracker output: saturated and opaque, on a shifted hue wheel so it does not mimic the truth."""
    return id_color(target_id, saturation=0.95, value=0.9, offset=0.31)


def _quaternion_from_matrix(R: np.ndarray) -> Quaternion:
    """Unit quaternion (x, y, z, w) of the (3, 3) rotation R."""
    m = np.asarray(R, dtype=np.float64)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        w, x, y, z = 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        w, x, y, z = (m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        w, x, y, z = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        w, x, y, z = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s
    return Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))


def _point(p) -> Point3:
    return Point3(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def _box_entity(index: int, box: Box, t_ns: int) -> SceneEntity:
    half = 0.5 * box.yaw_rad
    cube = CubePrimitive(
        pose=Pose(
            position=Vector3(x=box.center_m[0], y=box.center_m[1], z=box.center_m[2]),
            orientation=Quaternion(x=0.0, y=0.0, z=math.sin(half), w=math.cos(half)),
        ),
        size=Vector3(x=box.size_m[0], y=box.size_m[1], z=box.size_m[2]),
        color=color(BOX_COLORS[box.kind]),
    )
    return SceneEntity(
        timestamp=timestamp(t_ns), frame_id=WORLD_FRAME, id=f"box/{index:03d}/{box.kind.value}", cubes=[cube]
    )


def _frustum_entity(camera: Camera, t_ns: int) -> SceneEntity:
    """Lines from the optical centre to the image corners at FRUSTUM_DEPTH_M, in the camera's own frame."""
    K_inv = np.linalg.inv(camera.K)
    w, h = camera.width_px, camera.height_px
    corners = [K_inv @ np.array([u, v, 1.0]) * FRUSTUM_DEPTH_M for u, v in ((0, 0), (w, 0), (w, h), (0, h))]
    origin = Point3(x=0.0, y=0.0, z=0.0)
    points = []
    for i, c in enumerate(corners):
        points += [origin, _point(c), _point(c), _point(corners[(i + 1) % 4])]
    line = LinePrimitive(
        type=LinePrimitive.LINE_LIST,
        pose=Pose(orientation=Quaternion(w=1.0)),
        thickness=2.0,
        scale_invariant=True,
        points=points,
        color=color(CAMERA_COLOR),
    )
    label = TextPrimitive(
        pose=Pose(orientation=Quaternion(w=1.0)),
        billboard=True,
        font_size=14.0,
        scale_invariant=True,
        color=color(CAMERA_COLOR),
        text=camera.name,
    )
    return SceneEntity(
        timestamp=timestamp(t_ns),
        frame_id=camera_frame_id(camera.name),
        id=f"camera/{camera.name}",
        lines=[line],
        texts=[label],
    )


def store_scene(boxes: Iterable[Box], cameras: Sequence[Camera], t_ns: int = 0) -> SceneUpdate:
    """The static store: one cube per box (floor, walls, shelves, ...) and one frustum per camera."""
    entities = [_box_entity(i, box, t_ns) for i, box in enumerate(boxes)]
    entities += [_frustum_entity(camera, t_ns) for camera in cameras]
    return SceneUpdate(entities=entities)


def frame_transforms(cameras: Sequence[Camera], t_ns: int = 0) -> FrameTransforms:
    """world -> camera optical frame for every camera: the camera centre and R_world_from_cam = Rᵀ."""
    transforms = []
    for camera in cameras:
        center = camera.center_world
        transforms.append(
            FrameTransform(
                timestamp=timestamp(t_ns),
                parent_frame_id=WORLD_FRAME,
                child_frame_id=camera_frame_id(camera.name),
                translation=Vector3(x=float(center[0]), y=float(center[1]), z=float(center[2])),
                rotation=_quaternion_from_matrix(camera.R_cam_from_world.T),
            )
        )
    return FrameTransforms(transforms=transforms)


def camera_calibration(camera: Camera, t_ns: int = 0) -> CameraCalibration:
    """The camera's intrinsics in ROS/Foxglove form: plumb_bob D = (k1, k2, p1, p2, k3), P = [K | 0]."""
    P = np.hstack([camera.K, np.zeros((3, 1))])
    return CameraCalibration(
        timestamp=timestamp(t_ns),
        frame_id=camera_frame_id(camera.name),
        width=int(camera.width_px),
        height=int(camera.height_px),
        distortion_model="plumb_bob",
        D=camera.dist.tolist(),
        K=camera.K.ravel().tolist(),
        R=np.eye(3).ravel().tolist(),
        P=P.ravel().tolist(),
    )


@functools.lru_cache(maxsize=16)
def _png_grey(width: int, height: int, value: int) -> bytes:
    """A uniform 8-bit greyscale PNG, built with zlib alone so the bytes depend on nothing else."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    rows = (b"\x00" + bytes([value]) * width) * height  # filter byte 0 (None) before each row
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(rows, 9))
        + chunk(b"IEND", b"")
    )


def camera_backdrop(camera: Camera, t_ns: int = 0) -> CompressedImage:
    """A blank image of the camera's size: recordings hold no pixels, but an Image panel needs an image
    (or at least its size) to draw the 2D detections and the projected 3D scene over."""
    return CompressedImage(
        timestamp=timestamp(t_ns),
        frame_id=camera_frame_id(camera.name),
        data=_png_grey(int(camera.width_px), int(camera.height_px), BACKDROP_GREY),
        format="png",
    )


def camera_image(camera: Camera, t_ns: int, jpeg: bytes) -> CompressedImage:
    """A rendered picture of what the camera sees (`crossview generate --images`), in its optical frame, stamped
    `t_ns` like the frame's detections so that an Image panel pairs the two."""
    return CompressedImage(timestamp=timestamp(t_ns), frame_id=camera_frame_id(camera.name), data=jpeg, format="jpeg")


def truth_entity_pieces(person_id: int) -> tuple[bytes, bytes, bytes, bytes, bytes]:
    """Constant wire pieces of a person's entity in the truth's skeleton scene (a `PieceTable`'s pieces, for the
    compiled `wire.skeleton_scene`): the id field, the bone line before and after its points, and what follows
    the pose in the label and in the top sphere, each what protobuf writes for those fields."""
    return _entity_pieces(f"person/{person_id}", truth_color(person_id), TRUTH_LINE_M, f"p{person_id}")


def track_entity_pieces(target_id: int) -> tuple[bytes, bytes, bytes, bytes, bytes]:
    """`truth_entity_pieces` of a target's entity in the tracker's skeleton scene."""
    return _entity_pieces(f"target/{target_id}", track_color(target_id), TRACK_LINE_M, f"T{target_id}")


def _entity_pieces(entity_id: str, rgba: Color, thickness_m: float, label: str) -> tuple[bytes, ...]:
    """The pieces of a skeleton entity around its points (`truth_entity_pieces`; the whole entity as protobuf
    builds it: tests/reference/foxglove.py)."""
    line_head = LinePrimitive(type=LinePrimitive.LINE_LIST, pose=Pose(orientation=Quaternion(w=1.0)),
                              thickness=thickness_m).SerializeToString()
    line_tail = LinePrimitive(color=rgba).SerializeToString()
    text_tail = TextPrimitive(billboard=True, font_size=12.0, scale_invariant=True, color=rgba,
                              text=label).SerializeToString()
    sphere_tail = SpherePrimitive(size=Vector3(x=JOINT_SPHERE_M * 2, y=JOINT_SPHERE_M * 2, z=JOINT_SPHERE_M * 2),
                                  color=rgba).SerializeToString()
    return SceneEntity(id=entity_id).SerializeToString(), line_head, line_tail, text_tail, sphere_tail


def scene_heads(t_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """The wire pieces of a skeleton scene stamped t_ns (for `wire.skeleton_scene`): each entity's timestamp
    and frame id fields, and the SceneUpdate's deletions field."""
    head = SceneEntity(timestamp=timestamp(t_ns), frame_id=WORLD_FRAME).SerializeToString()
    deletion = SceneUpdate(deletions=[SceneEntityDeletion(timestamp=timestamp(t_ns),
                                                          type=SceneEntityDeletion.ALL)]).SerializeToString()
    return np.frombuffer(head, dtype=np.uint8), np.frombuffer(deletion, dtype=np.uint8)


ORIENTATION_FIELD = np.frombuffer(Pose(orientation=Quaternion(w=1.0)).SerializeToString(), dtype=np.uint8)
"""The identity orientation field of a Pose, as protobuf writes it."""
LINE_POINTS_KEY = (LinePrimitive.DESCRIPTOR.fields_by_name["points"].number << 3) | 2
"""The one-byte tag of LinePrimitive.points."""


def detection_style_pieces(person_id: int) -> tuple[bytes, bytes, bytes, bytes]:
    """Serialized style of a detection's bones and joints in its 2D annotations (`wire.image_annotations`;
    person -1: a false positive), each split around the points field so that type, points, colours, thickness
    come in field-number order: bones before, bones after, joints before, joints after (a `PieceTable`'s
    pieces)."""
    rgba = detection_color(person_id)
    bones_type = PointsAnnotation(type=PointsAnnotation.LINE_LIST)
    bones_rest = PointsAnnotation(outline_color=rgba, thickness=DETECTION_LINE_PX)
    joints_type = PointsAnnotation(type=PointsAnnotation.POINTS)
    joints_rest = PointsAnnotation(outline_color=rgba, fill_color=rgba, thickness=2 * DETECTION_LINE_PX)
    return tuple(m.SerializeToString() for m in (bones_type, bones_rest, joints_type, joints_rest))


def detection_color(person_id: int) -> Color:
    """A detection's colour in the 2D view: its true person's, opaque (grey for a false positive, id < 0)."""
    rgba = truth_color(person_id) if person_id >= 0 else color(FALSE_POSITIVE_COLOR)
    rgba.a = 1.0
    return rgba


_POINTS_FIELD = PointsAnnotation.DESCRIPTOR.fields_by_name["points"].number
_ANNOTATIONS_FIELD = ImageAnnotations.DESCRIPTOR.fields_by_name["points"].number
_STAMP_FIELD = PointsAnnotation.DESCRIPTOR.fields_by_name["timestamp"].number


@functools.lru_cache(maxsize=64)
def _bone_table(bones: tuple) -> np.ndarray:
    return np.asarray(bones, dtype=np.intp).reshape(-1, 2)


_ANNOTATIONS_KEY = np.frombuffer(bytes([(_ANNOTATIONS_FIELD << 3) | 2]), dtype=np.uint8)
_POINTS_KEY = (_POINTS_FIELD << 3) | 2
if _POINTS_KEY >= 128 or _ANNOTATIONS_KEY[0] >= 128 or _STAMP_FIELD >= 16:
    raise RuntimeError("PointsAnnotation: the compiled encoder expects one-byte field tags")
ANNOTATION_FIELDS = (_STAMP_FIELD, _ANNOTATIONS_KEY, _POINTS_KEY)  # the fields of wire.AnnotationStyle


def bone_table(skeleton: Skeleton) -> np.ndarray:
    """(B, 2) joint pairs of the skeleton's bones, as the compiled encoder takes them."""
    return _bone_table(tuple(skeleton.bones))


class PieceTable:
    """Constant wire pieces per person id for a compiled encoder: the pieces of each id back to back in a row
    of one uint8 `table`, with their `sizes` (rows, pieces). An encoder owns one (`rows` adds the ids it has
    not met) and hands the encoder each detection's row."""

    def __init__(self, pieces: Callable[[int], tuple[bytes, ...]]):
        self._pieces = pieces  # person id -> its byte strings
        self._rows: dict[int, int] = {}
        self.table = np.zeros((0, 0), dtype=np.uint8)
        self.sizes = np.zeros((0, 0), dtype=np.int64)

    def rows(self, person_ids: np.ndarray) -> np.ndarray:
        """(n,) int64 the row of each of `person_ids` (n,), made for the ids met for the first time."""
        ids = np.asarray(person_ids, dtype=np.int64)
        unique, inverse = np.unique(ids, return_inverse=True)
        new = [pid for pid in unique.tolist() if pid not in self._rows]
        if new:
            blobs = [self._pieces(pid) for pid in new]
            width = max(self.table.shape[1], *(sum(len(p) for p in b) for b in blobs))
            grown = np.zeros((self.table.shape[0] + len(new), width), dtype=np.uint8)
            grown[:self.table.shape[0], :self.table.shape[1]] = self.table
            for k, (pid, blob) in enumerate(zip(new, blobs)):
                data = b"".join(blob)
                grown[self.table.shape[0] + k, :len(data)] = np.frombuffer(data, dtype=np.uint8)
                self._rows[pid] = self.table.shape[0] + k
            self.sizes = np.vstack([self.sizes.reshape(-1, len(blobs[0])),
                                    [[len(p) for p in b] for b in blobs]]).astype(np.int64)
            self.table = grown
        return np.array([self._rows[pid] for pid in unique.tolist()], dtype=np.int64)[inverse.reshape(-1)]


def file_descriptor_set(descriptor: Descriptor) -> bytes:
    """The serialized FileDescriptorSet of a message type and its imports, dependencies first.

    This is the MCAP `protobuf` schema encoding; the order is fixed (depth-first over imports) so the
    same software writes the same bytes.
    """
    fds = descriptor_pb2.FileDescriptorSet()
    seen: set[str] = set()

    def add(file_descriptor) -> None:
        if file_descriptor.name in seen:
            return
        seen.add(file_descriptor.name)
        for dependency in file_descriptor.dependencies:
            add(dependency)
        proto = descriptor_pb2.FileDescriptorProto()
        file_descriptor.CopyToProto(proto)
        fds.file.append(proto)

    add(descriptor.file)
    return fds.SerializeToString(deterministic=True)
