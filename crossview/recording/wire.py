"""Protobuf wire bytes of a recording's camera frames with their 2D annotations (`frames_and_annotations`, one
numba-compiled loop over many frames: `crossview.recording.Encoder.frames`) and of the truth's skeleton scene
(`skeleton_scene`, at 20 Hz: `Encoder.truth_scene`, and the tracker's: `Encoder.tracker_scene`), the
recording's two compiled encoders: protobuf's own serialisation of the same messages, one Python object per
point, made `crossview generate` 1.29 to 1.47 times slower for the frames and up to 1.43 times for the truth's
scenes, `crossview track` 1.38 times for the tracker's (docs/recording-format.md).
The tests decode these bytes with protobuf and compare them with its serialisation of the same messages.
Only the writer imports this module, so reading a recording never loads numba.

proto3 rules kept here as protobuf keeps them: a scalar whose value is its default (a double with all bits zero, an
integer 0, an empty string) is left out; a packed repeated field is one length-delimited run and is left
out when empty; sint64 is zigzag encoded; a message field is written whenever it is set.
"""

from __future__ import annotations

import struct
from typing import NamedTuple

import numpy as np

from core.jit import intrinsic, llvm_ir, types
from core.jit import jit as _jit

_VARINT, _FIXED64, _LEN = 0, 1, 2  # wire types


class FrameRows(NamedTuple):
    """A block's detections as rows, the frames' rows back to back (what a CameraFrame holds of each).

    Attributes:
        keypoints: (D, J, 2) detected pixels; scores: (D, J) joint scores; person_ids: (D,) int64 true person
            (-1: a false positive); true_keypoints: (D, J, 2) the person's true pixels.
        in_image, occluded, self_occluded: (D, J) bool; effects: (D,) uint32 `DetectionEffect` masks.
    """

    keypoints: np.ndarray
    scores: np.ndarray
    person_ids: np.ndarray
    true_keypoints: np.ndarray
    in_image: np.ndarray
    occluded: np.ndarray
    self_occluded: np.ndarray
    effects: np.ndarray


class AnnotationStyle(NamedTuple):
    """What `image_annotations` writes around each detection's points.

    Attributes:
        bones: (B, 2) int64 joint pairs of the skeleton's bones.
        styles: (S, L) uint8 rows holding bones-before, bones-after, joints-before and joints-after back to back
            (`foxglove.detection_style_pieces`); style_sizes: (S, 4) int64 their sizes.
        stamp_field_number: the Timestamp's field number in PointsAnnotation; key: (k,) uint8 the varint tag of
            ImageAnnotations.points; points_key: that of PointsAnnotation.points (one byte).
    """

    bones: np.ndarray
    styles: np.ndarray
    style_sizes: np.ndarray
    stamp_field_number: int
    key: np.ndarray
    points_key: int
_POINT2_BYTES = 20  # the most one Point2 element takes: tag, length (18), then x and y as fixed64 fields


@_jit
def _varint_size(value):
    n = 1
    while value >= 128:
        value >>= 7
        n += 1
    return n


@_jit
def _put_varint(out, pos, value):
    while value >= 128:
        out[pos] = (value & 0x7F) | 0x80
        value >>= 7
        pos += 1
    out[pos] = value
    return pos + 1


@_jit
def _put_key(out, pos, field, wire_type):
    return _put_varint(out, pos, (field << 3) | wire_type)


def _plain_bits(value):
    return struct.unpack("<q", struct.pack("<d", value))[0]


@intrinsic(plain=_plain_bits)
def _bits(typingctx, value):
    """The 64 bits of a number as a float64, as an int64 (a register move: viewing a one-element array, as
    this did before, allocated the array: 40 ns a value)."""
    if not isinstance(value, (types.Float, types.Integer)):
        return None
    signature = types.int64(value)

    def codegen(context, builder, sig, args):
        double = context.cast(builder, args[0], sig.args[0], types.float64)
        return builder.bitcast(double, llvm_ir.IntType(64))

    return signature, codegen


@_jit
def _put_f8(out, pos, value):
    """Eight little-endian bytes of a float64."""
    bits = _bits(value)
    for i in range(8):
        out[pos + i] = (bits >> (8 * i)) & 0xFF
    return pos + 8


@_jit
def _is_zero_bits(value):
    return _bits(value) == 0


@_jit
def _put_double_field(out, pos, field, value):
    if _is_zero_bits(value):
        return pos
    pos = _put_key(out, pos, field, _FIXED64)
    return _put_f8(out, pos, value)


@_jit
def _put_uint_field(out, pos, field, value):
    if value == 0:
        return pos
    pos = _put_key(out, pos, field, _VARINT)
    return _put_varint(out, pos, value)


@_jit
def _put_fixed(out, pos, field, values):
    """A packed fixed-width field of `values` (any shape, C order): double for float64, float for float32; on
    the wire, the length-delimited bytes `_put_string` writes."""
    return _put_string(out, pos, field, values.reshape(-1).view(np.uint8))


@_jit
def _put_string(out, pos, field, data):
    """A string (or bytes) field of the UTF-8 bytes `data`, left out when empty."""
    if data.size == 0:
        return pos
    pos = _put_key(out, pos, field, _LEN)
    pos = _put_varint(out, pos, data.size)
    out[pos:pos + data.size] = data
    return pos + data.size


@_jit
def _put_bools(out, pos, field, values):
    flat = values.reshape(-1)
    if flat.size == 0:
        return pos
    pos = _put_key(out, pos, field, _LEN)
    pos = _put_varint(out, pos, flat.size)
    for i in range(flat.size):
        out[pos + i] = 1 if flat[i] else 0
    return pos + flat.size


@_jit
def _zigzag(value):
    return 2 * value if value >= 0 else -2 * value - 1


@_jit
def _put_varints(out, pos, field, values, zigzag):
    """A packed varint field: sint64 (zigzag) or unsigned values."""
    if values.size == 0:
        return pos
    size = 0
    for v in values:
        size += _varint_size(_zigzag(v) if zigzag else v)
    pos = _put_key(out, pos, field, _LEN)
    pos = _put_varint(out, pos, size)
    for v in values:
        pos = _put_varint(out, pos, _zigzag(v) if zigzag else v)
    return pos


@_jit
def camera_frame(out, camera, stamp_s, capture_s, delivery_s, rows, a, b):
    """`crossview.CameraFrame` of the detections rows[a:b] (`FrameRows`) into `out` (uint8, at least
    `camera_frame_capacity`); returns its size. camera: the camera name's UTF-8 bytes; stamp_s, capture_s,
    delivery_s: its times (the caller checks the effects' masks)."""
    keypoints = rows.keypoints[a:b]
    pos = _put_string(out, 0, 1, camera)
    pos = _put_double_field(out, pos, 2, stamp_s)
    pos = _put_double_field(out, pos, 3, capture_s)
    pos = _put_double_field(out, pos, 4, delivery_s)
    pos = _put_uint_field(out, pos, 5, keypoints.shape[0])
    pos = _put_uint_field(out, pos, 6, keypoints.shape[1])
    pos = _put_fixed(out, pos, 7, keypoints)
    pos = _put_fixed(out, pos, 8, rows.scores[a:b])
    pos = _put_varints(out, pos, 9, rows.person_ids[a:b], True)
    pos = _put_fixed(out, pos, 10, rows.true_keypoints[a:b])
    pos = _put_bools(out, pos, 11, rows.in_image[a:b])
    pos = _put_bools(out, pos, 12, rows.occluded[a:b])
    pos = _put_bools(out, pos, 13, rows.self_occluded[a:b])
    return _put_varints(out, pos, 14, rows.effects[a:b], False)


def camera_frame_capacity(D: int, J: int, name_bytes: int) -> int:
    """An upper bound of the bytes of `camera_frame` (varints counted at their longest)."""
    return 128 + name_bytes + D * (43 * J + 20)


@_jit
def _point2_size(x, y):
    """Bytes of one element of a repeated Point2 field: its tag and length, then x and y as fixed64 fields 1
    and 2, each left out when +0.0 (as protobuf leaves out a scalar at its default)."""
    return 2 + (0 if _is_zero_bits(x) else 9) + (0 if _is_zero_bits(y) else 9)


@_jit
def _put_point2(out, pos, points_key, x, y):
    """One element of a repeated Point2 field whose one-byte tag is `points_key`."""
    out[pos] = points_key
    out[pos + 1] = _point2_size(x, y) - 2
    pos = _put_double_field(out, pos + 2, 1, x)
    return _put_double_field(out, pos, 2, y)


@_jit
def image_annotations(out, keypoints, style_rows, style, t_ns):
    """`foxglove.ImageAnnotations` of one frame's detections into `out` (uint8, at least
    `image_annotations_capacity`); returns the number of bytes.

    Per detection (in order) a LINE_LIST PointsAnnotation of its bones whose two ends are known, then a
    POINTS one of its known joints, each left out when empty; each is the stamp field, its style's part
    before the points, the points, its style's part after them.

    keypoints (D, J, 2), NaN where unknown; style_rows (D,) each detection's row of the `AnnotationStyle`'s
    styles; t_ns: the stamp (a Timestamp in PointsAnnotation field `style.stamp_field_number`).
    """
    D, J = keypoints.shape[0], keypoints.shape[1]
    bones, styles, style_sizes, key, points_key = style.bones, style.styles, style.style_sizes, style.key, \
        style.points_key
    # The timestamp field: seconds and nanos as varints, each left out when 0.
    seconds, nanos = t_ns // 1_000_000_000, t_ns % 1_000_000_000
    stamp_field = np.empty(32, dtype=np.uint8)
    n = _put_uint_field(stamp_field, 2, 1, seconds)
    n = _put_uint_field(stamp_field, n, 2, nanos)
    stamp_field[0] = (style.stamp_field_number << 3) | _LEN
    stamp_field[1] = n - 2
    stamp_field = stamp_field[:n]
    known = np.empty(J, dtype=np.bool_)
    pos = 0
    for d in range(D):
        for j in range(J):
            known[j] = np.isfinite(keypoints[d, j, 0]) and np.isfinite(keypoints[d, j, 1])
        row = style_rows[d]
        for part in range(2):  # 0: bones, 1: joints
            count, points_size = 0, 0
            if part == 0:
                for b in range(bones.shape[0]):
                    if known[bones[b, 0]] and known[bones[b, 1]]:
                        for end in range(2):
                            points_size += _point2_size(keypoints[d, bones[b, end], 0], keypoints[d, bones[b, end], 1])
                        count += 2
            else:
                for j in range(J):
                    if known[j]:
                        points_size += _point2_size(keypoints[d, j, 0], keypoints[d, j, 1])
                        count += 1
            if count == 0:
                continue
            before, after = style_sizes[row, 2 * part], style_sizes[row, 2 * part + 1]
            start = style_sizes[row, 0] + style_sizes[row, 1] if part == 1 else 0
            out[pos:pos + key.size] = key
            pos += key.size
            pos = _put_varint(out, pos, stamp_field.size + before + after + points_size)
            out[pos:pos + stamp_field.size] = stamp_field
            pos += stamp_field.size
            out[pos:pos + before] = styles[row, start:start + before]
            pos += before
            if part == 0:
                for b in range(bones.shape[0]):
                    if known[bones[b, 0]] and known[bones[b, 1]]:
                        for end in range(2):
                            j = bones[b, end]
                            pos = _put_point2(out, pos, points_key, keypoints[d, j, 0], keypoints[d, j, 1])
            else:
                for j in range(J):
                    if known[j]:
                        pos = _put_point2(out, pos, points_key, keypoints[d, j, 0], keypoints[d, j, 1])
            out[pos:pos + after] = styles[row, start + before:start + before + after]
            pos += after
    return pos


def image_annotations_capacity(D: int, J: int, B: int, style_bytes: int) -> int:
    """An upper bound of the bytes of `image_annotations`."""
    return D * (2 * 48 + style_bytes + (2 * B + J) * _POINT2_BYTES)


@_jit
def frames_and_annotations(out, ends, names, name_ends, times, t_ns, det_ends, rows, style_rows, style):
    """`camera_frame` then `image_annotations` of n frames, back to back in `out`, in one call.

    Frame i owns rows det_ends[i]:det_ends[i + 1] of `rows` (`FrameRows`) and style_rows (its detections'
    rows of the `AnnotationStyle`'s styles), and bytes name_ends[i]:name_ends[i + 1] of names (its camera's
    UTF-8 name); times (n, 3): stamp, capture and delivery; t_ns (n,): the annotations' stamp.
    Writes ends (2 n,): where frame i's CameraFrame (2 i) and its annotations (2 i + 1) end.
    """
    pos = 0
    for i in range(t_ns.size):
        a, b = det_ends[i], det_ends[i + 1]
        pos += camera_frame(out[pos:], names[name_ends[i]:name_ends[i + 1]], times[i, 0], times[i, 1], times[i, 2],
                            rows, a, b)
        ends[2 * i] = pos
        pos += image_annotations(out[pos:], rows.keypoints[a:b], style_rows[a:b], style, t_ns[i])
        ends[2 * i + 1] = pos
    return pos


# --------------------------------------------------------------------------------------------------
# The truth's skeleton scene: a SceneUpdate at every truth tick (100 Hz), protobuf's bytes written by one loop.


class SceneStyle(NamedTuple):
    """The constant wire pieces `skeleton_scene` writes around each person's points.

    Attributes:
        pieces: (S, L) uint8 rows, one per person: the entity's id field, the bone line before and after its
            points, and what follows the pose in the label and in the top sphere, back to back
            (`foxglove.truth_entity_pieces`); piece_sizes: (S, 5) int64 their sizes.
        bones: (B, 2) int64 joint pairs of the skeleton's bones.
        head: (h,) uint8 each entity's timestamp and frame id fields; deletion: (d,) uint8 the SceneUpdate's
            deletions field; orientation: (o,) uint8 the identity orientation field of a Pose.
        points_key: the one-byte tag of LinePrimitive.points.
    """

    pieces: np.ndarray
    piece_sizes: np.ndarray
    bones: np.ndarray
    head: np.ndarray
    deletion: np.ndarray
    orientation: np.ndarray
    points_key: int


@_jit
def _ld_size(n):
    """Bytes of a length-delimited field with a one-byte tag and an n-byte payload."""
    return 1 + _varint_size(n) + n


@_jit
def _put_ld_head(out, pos, field, n):
    pos = _put_key(out, pos, field, _LEN)
    return _put_varint(out, pos, n)


@_jit
def _put_bytes(out, pos, data):
    out[pos:pos + data.size] = data
    return pos + data.size


@_jit
def _vector3_size(x, y, z):
    """Bytes of a Vector3 or Point3's fields (a coordinate whose bits are all zero is left out)."""
    return (0 if _is_zero_bits(x) else 9) + (0 if _is_zero_bits(y) else 9) + (0 if _is_zero_bits(z) else 9)


@_jit
def _put_vector3(out, pos, x, y, z):
    pos = _put_double_field(out, pos, 1, x)
    pos = _put_double_field(out, pos, 2, y)
    return _put_double_field(out, pos, 3, z)


@_jit
def _put_pose(out, pos, x, y, z, orientation):
    """A foxglove.Pose: position (x, y, z), then the (constant) orientation field's bytes."""
    pos = _put_ld_head(out, pos, 1, _vector3_size(x, y, z))
    pos = _put_vector3(out, pos, x, y, z)
    return _put_bytes(out, pos, orientation)


@_jit
def skeleton_scene(out, poses, rows, style):
    """A skeleton scene (a SceneUpdate; as protobuf builds it: tests/reference/foxglove.py) into `out`; returns
    the number of bytes.

    poses (P, J, 3) metres, NaN where unknown; rows (P,) each person's row of the `SceneStyle`'s pieces. Per
    person (in order) an entity: head, id, a sphere and a label (at the highest known joint, the label 0.25 m
    above) when a joint is known, and the line of the bones whose two ends are known. `out` holds at least
    `skeleton_scene_capacity` bytes.
    """
    P, J = poses.shape[0], poses.shape[1]
    bones = style.bones
    known = np.empty(J, dtype=np.bool_)
    starts = np.zeros(6, dtype=np.int64)
    pos = _put_bytes(out, 0, style.deletion)
    for i in range(P):
        row = rows[i]
        sizes = style.piece_sizes[row]
        for k in range(5):
            starts[k + 1] = starts[k] + sizes[k]
        top, top_z = -1, -np.inf
        for j in range(J):
            known[j] = np.isfinite(poses[i, j, 0]) and np.isfinite(poses[i, j, 1]) and np.isfinite(poses[i, j, 2])
            if known[j] and (top < 0 or poses[i, j, 2] > top_z):
                top, top_z = j, poses[i, j, 2]
        points = 0
        for b in range(bones.shape[0]):
            if known[bones[b, 0]] and known[bones[b, 1]]:
                for end in range(2):
                    j = bones[b, end]
                    points += 2 + _vector3_size(poses[i, j, 0], poses[i, j, 1], poses[i, j, 2])
        line = sizes[1] + points + sizes[2]
        entity = style.head.size + sizes[0] + _ld_size(line)
        x, y, z = 0.0, 0.0, 0.0
        sphere_pose, text_pose, sphere, text = 0, 0, 0, 0
        if top >= 0:
            x, y, z = poses[i, top, 0], poses[i, top, 1], poses[i, top, 2]
            sphere_pose = _ld_size(_vector3_size(x, y, z)) + style.orientation.size
            text_pose = _ld_size(_vector3_size(x, y, z + 0.25)) + style.orientation.size
            sphere = _ld_size(sphere_pose) + sizes[4]
            text = _ld_size(text_pose) + sizes[3]
            entity += _ld_size(sphere) + _ld_size(text)
        pos = _put_ld_head(out, pos, 2, entity)
        pos = _put_bytes(out, pos, style.head)
        pos = _put_bytes(out, pos, style.pieces[row, starts[0]:starts[1]])
        if top >= 0:
            pos = _put_ld_head(out, pos, 9, sphere)
            pos = _put_ld_head(out, pos, 1, sphere_pose)
            pos = _put_pose(out, pos, x, y, z, style.orientation)
            pos = _put_bytes(out, pos, style.pieces[row, starts[4]:starts[5]])
        pos = _put_ld_head(out, pos, 11, line)
        pos = _put_bytes(out, pos, style.pieces[row, starts[1]:starts[2]])
        for b in range(bones.shape[0]):
            if known[bones[b, 0]] and known[bones[b, 1]]:
                for end in range(2):
                    j = bones[b, end]
                    out[pos] = style.points_key
                    out[pos + 1] = _vector3_size(poses[i, j, 0], poses[i, j, 1], poses[i, j, 2])
                    pos = _put_vector3(out, pos + 2, poses[i, j, 0], poses[i, j, 1], poses[i, j, 2])
        pos = _put_bytes(out, pos, style.pieces[row, starts[2]:starts[3]])
        if top >= 0:
            pos = _put_ld_head(out, pos, 13, text)
            pos = _put_ld_head(out, pos, 1, text_pose)
            pos = _put_pose(out, pos, x, y, z + 0.25, style.orientation)
            pos = _put_bytes(out, pos, style.pieces[row, starts[3]:starts[4]])
    return pos


def skeleton_scene_capacity(P: int, B: int, style_bytes: int, head_bytes: int, deletion_bytes: int) -> int:
    """An upper bound of the bytes of `skeleton_scene` (P people, B bones, rows of `style_bytes` pieces)."""
    return deletion_bytes + P * (16 + head_bytes + style_bytes + 2 * B * 29 + 2 * 64)
