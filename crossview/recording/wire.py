"""Protobuf wire bytes of the recording's per-frame messages, written by numba-compiled loops.

`crossview.recording.camera_frame_bytes` and `crossview.recording.foxglove.image_annotations_bytes` say what the
bytes are (and the tests check those against protobuf's own serialisation); the kernels here write the
same bytes field by field into one buffer, which is most of what writing a recording costs per frame.
Only the recording writer and the tracks reader (`tracker_output_arrays`, which reads a tracker output's
targets straight into arrays) import this module, so reading a recording never loads numba.

proto3 rules kept here as there: a scalar whose value is its default (a double with all bits zero, an
integer 0, an empty string) is left out; a packed repeated field is one length-delimited run and is left
out when empty; sint64 is zigzag encoded; a message field is written whenever it is set.
"""

from __future__ import annotations

import struct

import numpy as np

from core.jit import intrinsic, llvm_ir, types
from core.jit import jit as _jit

_VARINT, _FIXED64, _LEN = 0, 1, 2  # wire types
_POINT2_BYTES = 20  # one Point2 element: tag, length (18), then x and y as fixed64 fields 1 and 2
NEW_STYLE = -2  # what `image_annotations` returns when a person has no style row yet


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
    """A packed fixed-width field of `values` (any shape, C order): double for float64, float for float32."""
    flat = values.reshape(-1)
    if flat.size == 0:
        return pos
    raw = flat.view(np.uint8)
    pos = _put_key(out, pos, field, _LEN)
    pos = _put_varint(out, pos, raw.size)
    out[pos:pos + raw.size] = raw
    return pos + raw.size


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
def pose_truth(out, pos, t_s, person_ids, poses):
    """`crossview.PoseTruth`: t_s, num_joints, person_ids (P,), poses (P, J, 3). Returns the end position."""
    pos = _put_double_field(out, pos, 1, t_s)
    pos = _put_uint_field(out, pos, 2, poses.shape[1])
    pos = _put_varints(out, pos, 3, person_ids, True)
    return _put_fixed(out, pos, 4, poses)


@_jit
def camera_frame(out, camera, stamp_s, capture_s, delivery_s, keypoints, scores, person_ids, true_keypoints, in_image,
                 occluded, self_occluded, effects):
    """`crossview.CameraFrame` into `out` (uint8, at least `camera_frame_capacity`); returns its size.

    camera: the camera name's UTF-8 bytes; stamp_s, capture_s, delivery_s: its times; keypoints
    (D, J, 2), scores (D, J), person_ids (D,), true_keypoints (D, J, 2), in_image, occluded, self_occluded
    (D, J) bool, effects (D,) uint32 masks.
    Returns -1 (and writes nothing useful) when an effects mask is not a uint32.
    """
    for v in effects:
        if v < 0 or v >= 1 << 32:
            return -1
    pos = _put_string(out, 0, 1, camera)
    pos = _put_double_field(out, pos, 2, stamp_s)
    pos = _put_double_field(out, pos, 3, capture_s)
    pos = _put_double_field(out, pos, 4, delivery_s)
    pos = _put_uint_field(out, pos, 5, keypoints.shape[0])
    pos = _put_uint_field(out, pos, 6, keypoints.shape[1])
    pos = _put_fixed(out, pos, 7, keypoints)
    pos = _put_fixed(out, pos, 8, scores)
    pos = _put_varints(out, pos, 9, person_ids, True)
    pos = _put_fixed(out, pos, 10, true_keypoints)
    pos = _put_bools(out, pos, 11, in_image)
    pos = _put_bools(out, pos, 12, occluded)
    pos = _put_bools(out, pos, 13, self_occluded)
    return _put_varints(out, pos, 14, effects, False)


@_jit
def tracker_output(out, stamp_s, camera, ids, stamps, state_names, state_ends, state_index, poses, joint_states,
                   has_states, detection_target_ids):
    """`crossview.TrackerOutput` into `out` (uint8, at least `tracker_output_capacity`); returns its size.

    camera: the camera name's UTF-8 bytes; ids (T,) int64 >= 0; stamps (T,); state_names: the UTF-8 bytes of
    the state names one after another, name i ending at state_ends[i]; state_index (T,) each target's name;
    poses (T, J, 3) float32 (`pose_m32`); joint_states (T, J) uint8 codes (< 128), written for the targets
    with has_states (T,); detection_target_ids (D,) int64.
    """
    T, J = poses.shape[0], poses.shape[1]
    pos = _put_double_field(out, 0, 1, stamp_s)
    pos = _put_string(out, pos, 2, camera)
    pos = _put_uint_field(out, pos, 3, J)
    for t in range(T):
        start = state_ends[state_index[t] - 1] if state_index[t] > 0 else 0
        name_size = state_ends[state_index[t]] - start
        size = 0
        if ids[t] != 0:
            size += 1 + _varint_size(ids[t])
        if not _is_zero_bits(stamps[t]):
            size += 9
        if name_size:
            size += 1 + _varint_size(name_size) + name_size
        if J:
            size += 1 + _varint_size(12 * J) + 12 * J
            if has_states[t]:
                size += 1 + _varint_size(J) + J
        pos = _put_key(out, pos, 4, _LEN)
        pos = _put_varint(out, pos, size)
        if ids[t] != 0:
            pos = _put_key(out, pos, 1, _VARINT)
            pos = _put_varint(out, pos, ids[t])
        pos = _put_double_field(out, pos, 2, stamps[t])
        pos = _put_string(out, pos, 3, state_names[start:start + name_size])
        if J and has_states[t]:
            pos = _put_key(out, pos, 5, _LEN)
            pos = _put_varint(out, pos, J)
            for j in range(J):
                out[pos + j] = joint_states[t, j]
            pos += J
        pos = _put_fixed(out, pos, 6, poses[t])
    return _put_varints(out, pos, 5, detection_target_ids, True)


def tracker_output_capacity(T: int, J: int, D: int, name_bytes: int, state_bytes: int) -> int:
    """An upper bound of the bytes of `tracker_output` (varints counted at their longest)."""
    return 64 + name_bytes + T * (48 + state_bytes + 13 * J) + 11 * D


def camera_frame_capacity(D: int, J: int, name_bytes: int) -> int:
    """An upper bound of the bytes of `camera_frame` (varints counted at their longest)."""
    return 128 + name_bytes + D * (43 * J + 20)


def pose_truth_capacity(P: int, J: int) -> int:
    """An upper bound of the bytes of `pose_truth`."""
    return 64 + P * (24 * J + 10)


@_jit
def image_annotations(out, keypoints, bones, person_ids, style_lut, styles, style_sizes, t_ns, stamp_field_number,
                      key, points_key):
    """`foxglove.ImageAnnotations` of one frame's detections into `out`; returns the number of bytes.

    Per detection (in order) a LINE_LIST PointsAnnotation of its bones whose two ends are known, then a
    POINTS one of its known joints, each left out when empty; each is the stamp field, its style's part
    before the points, the points, its style's part after them.

    keypoints (D, J, 2), NaN where unknown; bones (B, 2) joint pairs; person_ids (D,) the person behind each
    detection (-1, or a row beyond them: a false positive), whose style is row style_lut[id + 1] of
    styles (S, L) uint8 rows holding bones-before, bones-after, joints-before and
    joints-after back to back, with their sizes in style_sizes (S, 4); t_ns: the stamp (a Timestamp in
    PointsAnnotation field `stamp_field_number`); key: the varint tag of ImageAnnotations.points; points_key:
    that of PointsAnnotation.points
    (one byte). Returns -1 when a coordinate is exactly +0.0 (then protobuf's own serialisation is needed)
    and NEW_STYLE when someone has no style row yet.
    """
    D, J = keypoints.shape[0], keypoints.shape[1]
    style_rows = np.empty(D, dtype=np.int64)
    for d in range(D):
        pid = max(person_ids[d], -1) if d < person_ids.size else -1
        style_rows[d] = style_lut[pid + 1] if pid + 1 < style_lut.size else -1
        if style_rows[d] < 0:
            return NEW_STYLE
    raw = keypoints.reshape(-1).view(np.uint8)
    for v in keypoints.reshape(-1).view(np.int64):
        if v == 0:
            return -1  # a coordinate of exactly +0.0, which protobuf leaves out: the caller's slow path
    # The timestamp field: seconds and nanos as varints, each left out when 0.
    seconds, nanos = t_ns // 1_000_000_000, t_ns % 1_000_000_000
    stamp_field = np.empty(32, dtype=np.uint8)
    n = 0
    if seconds:
        n = _put_uint_field(stamp_field, 2, 1, seconds)
    if nanos:
        n = _put_uint_field(stamp_field, n if n else 2, 2, nanos)
    n = max(n, 2)
    stamp_field[0] = (stamp_field_number << 3) | _LEN
    stamp_field[1] = n - 2
    stamp_field = stamp_field[:n]
    known = np.empty(J, dtype=np.bool_)
    pos = 0
    for d in range(D):
        for j in range(J):
            known[j] = np.isfinite(keypoints[d, j, 0]) and np.isfinite(keypoints[d, j, 1])
        n_bones = 0
        for b in range(bones.shape[0]):
            if known[bones[b, 0]] and known[bones[b, 1]]:
                n_bones += 1
        n_joints = 0
        for j in range(J):
            if known[j]:
                n_joints += 1
        row = style_rows[d]
        for part in range(2):  # 0: bones, 1: joints
            count = 2 * n_bones if part == 0 else n_joints
            if count == 0:
                continue
            before, after = style_sizes[row, 2 * part], style_sizes[row, 2 * part + 1]
            start = style_sizes[row, 0] + style_sizes[row, 1] if part == 1 else 0
            out[pos:pos + key.size] = key
            pos += key.size
            pos = _put_varint(out, pos, stamp_field.size + before + after + _POINT2_BYTES * count)
            out[pos:pos + stamp_field.size] = stamp_field
            pos += stamp_field.size
            out[pos:pos + before] = styles[row, start:start + before]
            pos += before
            if part == 0:
                for b in range(bones.shape[0]):
                    if known[bones[b, 0]] and known[bones[b, 1]]:
                        pos = _put_point2(out, pos, points_key, raw, 16 * (d * J + bones[b, 0]))
                        pos = _put_point2(out, pos, points_key, raw, 16 * (d * J + bones[b, 1]))
            else:
                for j in range(J):
                    if known[j]:
                        pos = _put_point2(out, pos, points_key, raw, 16 * (d * J + j))
            out[pos:pos + after] = styles[row, start + before:start + before + after]
            pos += after
    return pos


@_jit
def _put_point2(out, pos, points_key, raw, start):
    """A Point2 element whose x and y are the 16 bytes of `raw` from `start`."""
    out[pos] = points_key
    out[pos + 1] = 18
    out[pos + 2] = 0x09
    out[pos + 11] = 0x11
    for b in range(8):  # (byte loops: far cheaper than slicing for eight bytes)
        out[pos + 3 + b] = raw[start + b]
        out[pos + 12 + b] = raw[start + 8 + b]
    return pos + _POINT2_BYTES


def image_annotations_capacity(D: int, J: int, B: int, style_bytes: int) -> int:
    """An upper bound of the bytes of `image_annotations`."""
    return D * (2 * 48 + style_bytes + (2 * B + J) * _POINT2_BYTES)


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
    return (0 if _is_zero_bits(x) else 9) + (0 if _is_zero_bits(y) else 9) + (0 if _is_zero_bits(z) else 9)


@_jit
def _put_pose(out, pos, x, y, z, orientation):
    """A foxglove.Pose: position (x, y, z), then the (constant) orientation field's bytes."""
    pos = _put_ld_head(out, pos, 1, _vector3_size(x, y, z))
    pos = _put_double_field(out, pos, 1, x)
    pos = _put_double_field(out, pos, 2, y)
    pos = _put_double_field(out, pos, 3, z)
    return _put_bytes(out, pos, orientation)


@_jit
def skeletons(out, poses, person_ids, piece_lut, pieces, piece_sizes, bones, head, deletion, orientation,
              points_key):
    """`foxglove.truth_skeletons` or `foxglove.tracker_skeletons` (a SceneUpdate) into `out`; returns the
    number of bytes.

    poses (P, J, 3), person_ids (P,) (person or target ids); per id, row piece_lut[id + 1] of pieces (uint8
    rows) holds its id field, the bone line before and after its points, and what follows the pose in its
    label and in its top sphere (sizes in piece_sizes (rows, 5)); bones (B, 2); head: the entities'
    timestamp and frame id fields; deletion: the deletions field; orientation: the identity orientation
    field of a Pose; points_key: the one-byte tag of LinePrimitive.points. Per id (in order) an entity:
    head, id, a sphere and a label (at the highest known joint, the label 0.25 m above) when a joint is
    known, and the line of the bones whose two ends are known. Returns -1 when a coordinate is exactly +0.0
    (then protobuf's own serialisation is needed) and NEW_STYLE when an id has no row of pieces yet.
    """
    P, J = poses.shape[0], poses.shape[1]
    for v in poses.reshape(-1).view(np.int64):
        if v == 0:
            return -1
    rows = np.empty(P, dtype=np.int64)
    for i in range(P):
        pid = max(person_ids[i], -1)
        rows[i] = piece_lut[pid + 1] if pid + 1 < piece_lut.size else -1
        if rows[i] < 0:
            return NEW_STYLE
    raw = poses.reshape(-1).view(np.uint8)
    known = np.empty(J, dtype=np.bool_)
    pos = _put_bytes(out, 0, deletion)
    for i in range(P):
        row = rows[i]
        sizes = piece_sizes[row]
        starts = np.zeros(6, dtype=np.int64)
        for k in range(5):
            starts[k + 1] = starts[k] + sizes[k]
        top, top_z = -1, -np.inf
        for j in range(J):
            known[j] = np.isfinite(poses[i, j, 0]) and np.isfinite(poses[i, j, 1]) and np.isfinite(poses[i, j, 2])
            if known[j] and (top < 0 or poses[i, j, 2] > top_z):
                top, top_z = j, poses[i, j, 2]
        ends = 0
        for b in range(bones.shape[0]):
            if known[bones[b, 0]] and known[bones[b, 1]]:
                ends += 2
        line = sizes[1] + 29 * ends + sizes[2]
        entity = head.size + sizes[0] + _ld_size(line)
        if top >= 0:
            x, y, z = poses[i, top, 0], poses[i, top, 1], poses[i, top, 2]
            sphere_pose = _ld_size(_vector3_size(x, y, z)) + orientation.size
            text_pose = _ld_size(_vector3_size(x, y, z + 0.25)) + orientation.size
            sphere = _ld_size(sphere_pose) + sizes[4]
            text = _ld_size(text_pose) + sizes[3]
            entity += _ld_size(sphere) + _ld_size(text)
        pos = _put_ld_head(out, pos, 2, entity)
        pos = _put_bytes(out, pos, head)
        pos = _put_bytes(out, pos, pieces[row, starts[0]:starts[1]])
        if top >= 0:
            pos = _put_ld_head(out, pos, 9, sphere)
            pos = _put_ld_head(out, pos, 1, sphere_pose)
            pos = _put_pose(out, pos, x, y, z, orientation)
            pos = _put_bytes(out, pos, pieces[row, starts[4]:starts[5]])
        pos = _put_ld_head(out, pos, 11, line)
        pos = _put_bytes(out, pos, pieces[row, starts[1]:starts[2]])
        for b in range(bones.shape[0]):
            if known[bones[b, 0]] and known[bones[b, 1]]:
                for end in range(2):
                    start = 24 * (i * J + bones[b, end])
                    out[pos] = points_key
                    out[pos + 1] = 27
                    for c in range(3):
                        out[pos + 2 + 9 * c] = ((c + 1) << 3) | _FIXED64
                        for k in range(8):
                            out[pos + 3 + 9 * c + k] = raw[start + 8 * c + k]
                    pos += 29
        pos = _put_bytes(out, pos, pieces[row, starts[2]:starts[3]])
        if top >= 0:
            pos = _put_ld_head(out, pos, 13, text)
            pos = _put_ld_head(out, pos, 1, text_pose)
            pos = _put_pose(out, pos, x, y, z + 0.25, orientation)
            pos = _put_bytes(out, pos, pieces[row, starts[3]:starts[4]])
    return pos


@_jit
def frames_and_annotations(out, ends, status, names, name_ends, times, t_ns, det_ends, keypoints, scores, person_ids,
                           true_keypoints, in_image, occluded, self_occluded, effects, bones, style_lut, styles,
                           style_sizes, stamp_field_number, key, points_key):
    """`camera_frame` then `image_annotations` of n frames, back to back in `out`, in one call.

    The frames' rows are concatenated: frame i owns rows det_ends[i]:det_ends[i + 1] of keypoints, scores,
    person_ids, true_keypoints, in_image, occluded, self_occluded, effects, and bytes
    name_ends[i]:name_ends[i + 1] of names (its camera's UTF-8 name); times (n, 3): stamp, capture and
    delivery; t_ns (n,): the annotations' stamp. The other arguments are `image_annotations`'s.
    Writes ends (2 n,): where frame i's CameraFrame (2 i) and its annotations (2 i + 1) end, and status (n,):
    0, or what the single-frame encoders returned instead of a size (-1 for a bad effects mask in the
    CameraFrame, else the annotations' -1 or NEW_STYLE): the caller encodes those frames one by one.
    """
    pos = 0
    for i in range(t_ns.size):
        a, b = det_ends[i], det_ends[i + 1]
        status[i] = 0
        size = camera_frame(out[pos:], names[name_ends[i]:name_ends[i + 1]], times[i, 0], times[i, 1], times[i, 2],
                            keypoints[a:b], scores[a:b], person_ids[a:b], true_keypoints[a:b], in_image[a:b],
                            occluded[a:b], self_occluded[a:b], effects[a:b])
        if size < 0:
            status[i] = -1
            size = 0
        pos += size
        ends[2 * i] = pos
        if a < b and status[i] == 0:
            size = image_annotations(out[pos:], keypoints[a:b], bones, person_ids[a:b], style_lut, styles, style_sizes,
                                     t_ns[i], stamp_field_number, key, points_key)
            if size < 0:
                status[i] = size
                size = 0
            pos += size
        ends[2 * i + 1] = pos
    return pos


# --------------------------------------------------------------------------------------------------
# Reading: the one message read in bulk (a tracks file holds every target at every camera frame).

BAD_BYTES = 1
"""`tracker_output_arrays`'s status for bytes it does not read."""
TARGET_ID, TARGET_STATE, TARGET_STATE_END, TARGET_CODES, TARGET_CODES_END = range(5)
"""Columns of `tracker_output_arrays`'s target rows: the id, then byte offsets into the message (-1: absent)."""


def _plain_double(bits):
    return struct.unpack("<d", struct.pack("<q", bits))[0]


@intrinsic(plain=_plain_double)
def _double(typingctx, bits):
    """The float64 whose 64 bits are the int64 `bits` (`_bits` the other way)."""
    if not isinstance(bits, types.Integer):
        return None

    def codegen(context, builder, sig, args):
        return builder.bitcast(context.cast(builder, args[0], sig.args[0], types.int64), llvm_ir.DoubleType())

    return types.float64(bits), codegen


def _plain_single(bits):
    return np.float32(struct.unpack("<f", struct.pack("<I", int(bits) & 0xFFFFFFFF))[0])


@intrinsic(plain=_plain_single)
def _single(typingctx, bits):
    """The float32 whose 32 bits are the low 32 bits of the integer `bits`."""
    if not isinstance(bits, types.Integer):
        return None

    def codegen(context, builder, sig, args):
        low = builder.trunc(context.cast(builder, args[0], sig.args[0], types.int64), llvm_ir.IntType(32))
        return builder.bitcast(low, llvm_ir.FloatType())

    return types.float32(bits), codegen


@_jit
def _get_bits(buf, pos, size):
    """The little-endian integer of the `size` (<= 8) bytes at pos, as an int64."""
    bits = np.int64(0)
    for i in range(size):
        bits |= np.int64(buf[pos + i]) << (8 * i)
    return bits


@_jit
def _get_f4(buf, pos):
    """The little-endian float32 at pos."""
    return _single(_get_bits(buf, pos, 4))


@_jit
def _get_f8(buf, pos):
    """The little-endian float64 at pos."""
    return _double(_get_bits(buf, pos, 8))


@_jit
def _get_varint(buf, pos, end):
    """(value as int64, next position) of the varint at pos; next position -1 when it runs past end or is
    longer than 10 bytes."""
    value = np.int64(0)
    for shift in range(0, 70, 7):
        if pos >= end:
            return value, -1
        byte = np.int64(buf[pos])
        pos += 1
        value |= (byte & 0x7F) << shift
        if byte < 128:
            return value, pos
    return value, -1


@_jit
def _run(buf, pos, end):
    """(start, end) of the length-delimited run whose length varint is at pos; (-1, -1) past end."""
    size, pos = _get_varint(buf, pos, end)
    if pos < 0 or size < 0 or pos + size > end:
        return -1, -1
    return pos, pos + size


@_jit
def tracker_output_arrays(buf):
    """`crossview.TrackerOutput` wire bytes (uint8) read into arrays, as `tracker_output` writes them.

    Returns (status, head, stamps, poses, rows, detection_target_ids):
    - status: 0, or `BAD_BYTES` for anything this scan does not read (a field it does not know, a repeated
      field not packed or in two runs, a joint state code over one byte, a pose not of num_joints x 3
      doubles (`pose_m`, formats 1 to 3) or floats (`pose_m32`) or in both fields, bytes that end early):
      the caller reads the message with protobuf instead, which also names what is wrong.
    - head (4,) int64: the output's stamp bits (int64 of the float64), the camera name's start and end
      byte, num_joints J;
    - stamps (T,) and poses (T, J, 3) of the targets;
    - rows (T, 5) int64 (`TARGET_*` columns): the id, the byte offsets of the state name's start and end
      and of the joint states' run (-1 where absent);
    - detection_target_ids (D,) int64 (zigzag decoded).
    A field left out has proto3's default (0, 0.0, an empty string or run).
    """
    n = buf.size
    head = np.zeros(4, dtype=np.int64)
    # Pass 1: the top-level fields, counting the targets and the detection ids.
    num_targets, num_ids, status = 0, 0, 0
    pos = 0
    while pos < n and status == 0:
        key, pos = _get_varint(buf, pos, n)
        field, wire_type = key >> 3, key & 7
        if pos < 0:
            status = BAD_BYTES
        elif field == 1 and wire_type == _FIXED64 and pos + 8 <= n:
            head[0] = _bits(_get_f8(buf, pos))
            pos += 8
        elif field == 3 and wire_type == _VARINT:
            head[3], pos = _get_varint(buf, pos, n)
            status = BAD_BYTES if pos < 0 or head[3] < 0 else 0
        elif (field == 2 or field == 4 or field == 5) and wire_type == _LEN:
            start, stop = _run(buf, pos, n)
            if start < 0:
                status = BAD_BYTES
            elif field == 2:
                head[1], head[2] = start, stop
            elif field == 4:
                num_targets += 1
            else:
                for i in range(start, stop):
                    if buf[i] < 128:
                        num_ids += 1
            pos = stop
        else:
            status = BAD_BYTES
    J = head[3] if status == 0 else 0
    T = num_targets if status == 0 else 0
    stamps = np.zeros(T)
    poses = np.zeros((T, J, 3))
    rows = np.full((T, 5), -1, dtype=np.int64)
    ids = np.empty(num_ids if status == 0 else 0, dtype=np.int64)
    # Pass 2: each target's fields, and the detection ids.
    t, k, pos = 0, 0, 0
    while pos < n and status == 0:
        key, pos = _get_varint(buf, pos, n)
        field = key >> 3
        if field == 1:
            pos += 8
        elif field == 3:
            _, pos = _get_varint(buf, pos, n)
        else:
            start, stop = _run(buf, pos, n)
            pos = stop
            if field == 5:
                q = start
                while q < stop:
                    value, q = _get_varint(buf, q, stop)
                    if q < 0:
                        return BAD_BYTES, head, stamps, poses, rows, ids
                    ids[k] = ((value >> 1) & 0x7FFFFFFFFFFFFFFF) ^ -(value & 1)  # zigzag
                    k += 1
            elif field == 4:
                rows[t, TARGET_ID] = 0
                pose_values = 0
                q = start
                while q < stop:
                    key, q = _get_varint(buf, q, stop)
                    sub, sub_type = key >> 3, key & 7
                    if q < 0:
                        return BAD_BYTES, head, stamps, poses, rows, ids
                    elif sub == 1 and sub_type == _VARINT:
                        rows[t, TARGET_ID], q = _get_varint(buf, q, stop)
                    elif sub == 2 and sub_type == _FIXED64 and q + 8 <= stop:
                        stamps[t] = _get_f8(buf, q)
                        q += 8
                    elif (3 <= sub <= 6) and sub_type == _LEN:
                        a, b = _run(buf, q, stop)
                        if a < 0:
                            return BAD_BYTES, head, stamps, poses, rows, ids
                        if sub == 3:
                            rows[t, TARGET_STATE], rows[t, TARGET_STATE_END] = a, b
                        elif sub == 5:
                            if rows[t, TARGET_CODES] >= 0:  # a second run: protobuf joins them
                                return BAD_BYTES, head, stamps, poses, rows, ids
                            for i in range(a, b):
                                if buf[i] >= 128:
                                    return BAD_BYTES, head, stamps, poses, rows, ids
                            rows[t, TARGET_CODES], rows[t, TARGET_CODES_END] = a, b
                        elif pose_values:  # a second run of a pose (protobuf joins them), or both fields
                            return BAD_BYTES, head, stamps, poses, rows, ids
                        else:
                            width = 8 if sub == 4 else 4  # pose_m (formats 1-3) or pose_m32
                            pose_values = (b - a) // width
                            if b - a != 3 * width * J:
                                return BAD_BYTES, head, stamps, poses, rows, ids
                            for i in range(pose_values):
                                poses[t, i // 3, i % 3] = (_get_f8(buf, a + 8 * i) if width == 8 else
                                                           _get_f4(buf, a + 4 * i))
                        q = b
                    else:
                        return BAD_BYTES, head, stamps, poses, rows, ids
                if pose_values != 3 * J:
                    return BAD_BYTES, head, stamps, poses, rows, ids
                t += 1
    return status, head, stamps, poses, rows, ids
