"""Message bytes: the protobuf messages of truth ticks, camera frames and tracker outputs, encoded one at a
time or many frames in one compiled call (`crossview.recording.wire`), and decoded back."""

from __future__ import annotations

import functools
import itertools
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from core.records import CameraFrame, DetectionRows, DetectionTruth, PoseTruth
from core.types import Frame, Skeleton
from crossview.recording import foxglove
from crossview.recording.schemas import TrackerOutputMsg, to_ns
from tracker.types import JointState, Target, TargetArrays, TargetState, TrackerOutput


def pose_truth_bytes(truth: PoseTruth) -> bytes:
    """`crossview.PoseTruth` wire bytes of `truth`, written by a compiled loop (the same bytes as protobuf's)."""
    from crossview.recording import wire  # (numba: loaded for writing only)

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
    protobuf's serialisation of the message object, which the tests check)."""
    from crossview.recording import wire  # (numba: loaded for writing only)

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
    image: bytes | None = None  # a rendered JPEG picture of the frame (`crossview generate --images`), or None


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
    from crossview.recording import wire  # (numba: loaded for writing only)

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


def pose_truth_from_msg(msg) -> PoseTruth:
    """The truth tick of a decoded `PoseTruthMsg` (poses (P, J, 3) metres)."""
    ids = np.array(msg.person_ids, dtype=np.int64)
    poses = np.array(msg.poses_m, dtype=np.float64).reshape(len(ids), msg.num_joints, 3)
    return PoseTruth(t_s=msg.t_s, person_ids=ids, poses=poses)


def camera_frame_from_msg(msg, poses_at_capture: PoseTruth | None = None) -> CameraFrame:
    """The camera frame of a decoded `CameraFrameMsg`, with `poses_at_capture` (None: not asked for)."""
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


_STATE_NAMES = [state.value for state in TargetState]
_STATE_BYTES = np.frombuffer("".join(_STATE_NAMES).encode(), dtype=np.uint8)
_STATE_ENDS = np.cumsum([len(name.encode()) for name in _STATE_NAMES]).astype(np.int64)


def tracker_output_bytes(output: TrackerOutput, num_joints: int) -> bytes:
    """`crossview.TrackerOutput` wire bytes of one tracker output, written by a compiled loop (the same bytes as
    protobuf's serialisation of `_tracker_output_to_msg`, which the tests check). A negative target id (which
    this encoder does not write) goes through protobuf."""
    from crossview.recording import wire  # (numba: loaded for writing only)

    T, J = len(output.targets), num_joints
    arrays = _target_arrays(output.targets, J)
    if arrays is not None:  # the built-in tracker's: no per-target object
        ids, stamps, states, poses, codes, has_states = arrays
    else:
        ids, stamps, states, poses, codes, has_states = _stacked_targets(output, J)
        if (ids < 0).any():
            return _tracker_output_to_msg(output, num_joints).SerializeToString()
    camera = _utf8(output.camera)
    det_ids = np.ascontiguousarray(output.detection_target_ids, dtype=np.int64).ravel()
    out = _scratch(wire.tracker_output_capacity(T, J, det_ids.size, camera.size, _STATE_BYTES.size))
    size = wire.tracker_output(out, float(output.stamp_s), camera, ids, stamps, _STATE_BYTES, _STATE_ENDS, states,
                               poses, codes, has_states, det_ids)
    return out[:size].tobytes()


def _target_arrays(targets, num_joints: int) -> tuple | None:
    """The encoder's arrays straight from a `TargetArrays` whose arrays are well formed (else None: the
    generic path checks and names what is wrong)."""
    if not isinstance(targets, TargetArrays):
        return None
    T = len(targets)
    ids = np.ascontiguousarray(targets.ids, dtype=np.int64)
    poses = np.ascontiguousarray(targets.poses, dtype=np.float32)
    codes = np.asarray(targets.joint_states)
    if ids.shape != (T,) or poses.shape != (T, num_joints, 3) or codes.shape != (T, num_joints) or (
            T and (ids.min() < 0 or codes.min() < 0 or codes.max() >= len(JointState))):
        return None
    codes = np.ascontiguousarray(codes, dtype=np.uint8)
    stamps = np.full(T, float(targets.stamp_s))
    states = np.full(T, _STATE_NAMES.index(TargetState(targets.state).value), dtype=np.int64)
    return ids, stamps, states, poses, codes, np.ones(T, dtype=np.bool_)


def _stacked_targets(output: TrackerOutput, num_joints: int) -> tuple:
    """The encoder's arrays from any sequence of `Target`, each checked (a ValueError names the first bad one)."""
    T, J = len(output.targets), num_joints
    try:  # the targets' arrays stacked at once; a wrong shape is found and named below
        poses = np.ascontiguousarray(np.stack([t.pose for t in output.targets]) if T else np.zeros((0, J, 3)),
                                     dtype=np.float32)
    except ValueError:
        poses = None
    if poses is None or poses.shape != (T, J, 3):
        for target in output.targets:
            _checked_pose(output, target, J)
    has_states = np.array([t.joint_state is not None for t in output.targets], dtype=np.bool_)
    codes = np.zeros((T, J), dtype=np.uint8)
    if has_states.any():
        try:
            given = np.stack([t.joint_state for t in output.targets if t.joint_state is not None])
        except ValueError:
            given = None
        if given is None or given.shape != (int(has_states.sum()), J) or given.size and (
                given.min() < 0 or given.max() >= len(JointState)):
            for target in output.targets:
                if target.joint_state is not None:
                    _checked_joint_state(output, target, J)
        codes[has_states] = given
    ids = np.array([int(t.id) for t in output.targets], dtype=np.int64)
    stamps = np.array([float(t.stamp_s) for t in output.targets], dtype=np.float64)
    states = np.array([_STATE_NAMES.index(TargetState(t.state).value) for t in output.targets], dtype=np.int64)
    return ids, stamps, states, poses, codes, has_states


def _checked_pose(output: TrackerOutput, target: Target, num_joints: int) -> np.ndarray:
    pose = np.asarray(target.pose, dtype=np.float64)
    if pose.shape != (num_joints, 3):
        raise ValueError(f"TrackerOutput@{output.stamp_s}: target {target.id} pose expected ({num_joints}, 3), "
                         f"got {pose.shape}")
    return pose


def _checked_joint_state(output: TrackerOutput, target: Target, num_joints: int) -> np.ndarray:
    codes = np.asarray(target.joint_state)
    valid = {state.value for state in JointState}
    if codes.shape != (num_joints,) or not np.isin(codes, list(valid)).all():
        raise ValueError(f"TrackerOutput@{output.stamp_s}: target {target.id} joint_state expected ({num_joints},) "
                         f"codes in {sorted(valid)}, got {codes!r}")
    return codes


def _tracker_output_to_msg(output: TrackerOutput, num_joints: int):
    msg = TrackerOutputMsg(stamp_s=float(output.stamp_s), camera=output.camera, num_joints=num_joints)
    for target in output.targets:
        pose = _checked_pose(output, target, num_joints)
        t = msg.targets.add(id=int(target.id), stamp_s=float(target.stamp_s), state=TargetState(target.state).value)
        t.pose_m32.extend(pose.ravel().tolist())
        if target.joint_state is not None:
            t.joint_state.extend(_checked_joint_state(output, target, num_joints).tolist())
    msg.detection_target_ids.extend(np.asarray(output.detection_target_ids, dtype=np.int64).ravel().tolist())
    return msg


_TARGET_STATES = {s.value: s for s in TargetState}


def tracker_output_from_bytes(data: bytes) -> TrackerOutput:
    """The `TrackerOutput` of `crossview.TrackerOutput` wire bytes, read into arrays by a compiled scan
    (`wire.tracker_output_arrays`): the targets are a `TargetArrays` when they share one stamp and state and
    all carry joint states (every output of the built-in tracker), else a list of `Target`. Bytes the scan
    does not read go through protobuf (`_tracker_output_from_msg`), which reads the same output from the
    same bytes and names what is wrong in a corrupt message (DecodeError or ValueError)."""
    from crossview.recording import wire

    buf = np.frombuffer(data, dtype=np.uint8)
    status, head, stamps, poses, rows, detection_ids = wire.tracker_output_arrays(buf)
    try:
        camera = data[head[1]:head[2]].decode()
    except UnicodeDecodeError:
        status = wire.BAD_BYTES
    if status:
        return _tracker_output_from_msg(TrackerOutputMsg.FromString(data))
    stamp_s, J, T = float(head[:1].view(np.float64)[0]), int(head[3]), len(rows)
    if not T:
        return TrackerOutput(stamp_s=stamp_s, camera=camera, targets=[], detection_target_ids=detection_ids)
    starts, ends = rows[:, wire.TARGET_STATE], rows[:, wire.TARGET_STATE_END]  # -1, -1: absent (b"")
    size = int(ends[0] - starts[0])
    one_name = bool((ends - starts == size).all()) and (
        size == 0 or bool((buf[starts[:, None] + np.arange(size)] == buf[starts[0]:ends[0]]).all()))
    names = [data[starts[0]:ends[0]]] * T if one_name else [data[a:b] for a, b in zip(starts.tolist(), ends.tolist())]
    states = {name: _TARGET_STATES.get(name.decode()) or TargetState(name.decode()) for name in set(names)}
    known = (rows[:, wire.TARGET_CODES_END] - rows[:, wire.TARGET_CODES] == J) & (J > 0)
    if len(states) == 1 and known.all() and (stamps == stamps[0]).all():
        codes = buf[rows[:, wire.TARGET_CODES, None] + np.arange(J)]
        return TrackerOutput(stamp_s=stamp_s, camera=camera, detection_target_ids=detection_ids,
                             targets=TargetArrays(rows[:, wire.TARGET_ID].copy(), poses, codes, float(stamps[0]),
                                                  states.popitem()[1]))
    targets = [
        Target(id=target_id, pose=poses[i], stamp_s=float(stamps[i]), state=states[name],
               joint_state=buf[c:c + J].copy() if known[i] else None)
        for i, (target_id, name, c) in enumerate(zip(rows[:, wire.TARGET_ID].tolist(), names,
                                                     rows[:, wire.TARGET_CODES].tolist(), strict=True))
    ]
    return TrackerOutput(stamp_s=stamp_s, camera=camera, targets=targets, detection_target_ids=detection_ids)


def _tracker_output_from_msg(msg) -> TrackerOutput:
    J = msg.num_joints
    # All targets' joints in one array (each target's pose is a row of it): one conversion per message.
    # A pose is in pose_m32 (format 4) or in pose_m (formats 1 to 3), never in both.
    if any(len(t.pose_m) + len(t.pose_m32) != J * 3 or (len(t.pose_m) and len(t.pose_m32)) for t in msg.targets):
        raise ValueError(f"a target pose of {msg.camera}@{msg.stamp_s} does not hold {J} joints x 3 in one field")
    poses = np.fromiter(itertools.chain.from_iterable(t.pose_m32 or t.pose_m for t in msg.targets), np.float64,
                        count=len(msg.targets) * J * 3).reshape(len(msg.targets), J, 3)
    known = [len(t.joint_state) == J and J > 0 for t in msg.targets]
    states = iter(np.fromiter(itertools.chain.from_iterable(t.joint_state for t, k in zip(msg.targets, known) if k),
                              np.uint8, count=sum(known) * J).reshape(sum(known), J))
    targets = [
        Target(id=t.id, pose=pose, stamp_s=t.stamp_s, state=_TARGET_STATES.get(t.state) or TargetState(t.state),
               joint_state=next(states) if k else None)
        for t, pose, k in zip(msg.targets, poses, known, strict=True)
    ]
    return TrackerOutput(
        stamp_s=msg.stamp_s, camera=msg.camera, targets=targets,
        detection_target_ids=np.array(msg.detection_target_ids, dtype=np.int64),
    )


# --------------------------------------------------------------------------------------------------
# Writing.
