"""Message bytes: one encoder per message type of the recording's time series (`Encoder`, one per writer) and
one decoder per message type (protobuf's parser, then arrays).

Every message is what protobuf serialises for it. Two kinds are written by compiled encoders
(`crossview.recording.wire`): the camera frames with their 2D annotations, and the skeleton scenes (the
truth's and the tracker's, each at 20 Hz at most); protobuf's own serialisation of them, one object per point,
made `crossview generate` 1.29 to 1.47 times slower for the frames and 1.08 (store_layout1) to 1.43 times
(store_layout2) for the truth's scenes, and `crossview track` 1.38 times for the tracker's (the figures and how
they were measured: docs/recording-format.md). The others are protobuf's `SerializeToString`."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

import crossview.recording.foxglove as foxglove
from core.records import CameraFrame, DetectionRows, DetectionTruth, PoseTruth
from core.types import Frame, Skeleton
from crossview.recording.schemas import CameraFrameMsg, PoseTruthMsg, TrackerOutputMsg, to_ns
from tracker.types import JointState, Target, TargetArrays, TargetState, TrackerOutput


class EncodedFrame(NamedTuple):
    """A camera frame as the two messages a recording stores for it (`Encoder.frames`). A writer takes it
    in place of the CameraFrame: a producer can encode frames as they are made and write them later, in
    log-time order, without the CameraFrame objects in between."""
    camera: str
    log_time_ns: int  # its delivery time
    frame_bytes: bytes  # the crossview.CameraFrame message
    annotations: bytes  # foxglove.ImageAnnotations stamped log_time_ns
    image: bytes | None = None  # a rendered JPEG picture of the frame (`crossview generate --images`), or None


# Where each field of `DetectionRows` lives in a CameraFrame (its part and attribute), with the dtype and
# trailing shape (J: joints) the compiled encoder expects.
_ROWS = dict(zip(DetectionRows._fields, (
    ("truth", "person_ids", np.int64, 0), ("frame", "keypoints_px", np.float64, 2), ("frame", "scores", np.float64, 1),
    ("truth", "keypoints_px", np.float64, 2), ("truth", "in_image", bool, 1), ("truth", "occluded", bool, 1),
    ("truth", "self_occluded", bool, 1), ("truth", "effects", np.int64, 0)), strict=True))
_UINT32_END = 1 << 32  # effects masks are uint32 fields


class Encoder:
    """The message encoders of one writer, one per message type: `pose_truth`, `truth_scene`, `frames`
    (crossview.CameraFrame with its foxglove.ImageAnnotations), `tracker_output` and `tracker_scene`.

    It owns what the compiled encoder writes with: one byte buffer, grown to the bound of each call before
    the call, and the wire pieces of each person's detection style, added before a call meets them.
    """

    def __init__(self, skeleton: Skeleton):
        self.skeleton = skeleton
        self._bones = foxglove.bone_table(skeleton)
        self._styles = foxglove.PieceTable(foxglove.detection_style_pieces)
        self._entities = foxglove.PieceTable(foxglove.truth_entity_pieces)
        self._tracks = foxglove.PieceTable(foxglove.track_entity_pieces)
        self._buffer = np.empty(1 << 16, dtype=np.uint8)

    def _buffer_of(self, size: int) -> np.ndarray:
        """The byte buffer, grown (to twice `size`) when it holds fewer than `size` bytes."""
        if self._buffer.size < size:
            self._buffer = np.empty(2 * size, dtype=np.uint8)
        return self._buffer

    def pose_truth(self, truth: PoseTruth) -> bytes:
        """`crossview.PoseTruth` of one truth tick."""
        poses = np.asarray(truth.poses, dtype=np.float64)
        ids = np.asarray(truth.person_ids, dtype=np.int64)
        if poses.ndim != 3 or poses.shape[2] != 3 or ids.ndim != 1 or poses.shape[0] != ids.shape[0]:
            raise ValueError(f"PoseTruth@{truth.t_s}: poses expected (P, J, 3) with P={ids.shape[0]}, got "
                             f"{poses.shape}")
        return PoseTruthMsg(t_s=float(truth.t_s), num_joints=poses.shape[1], person_ids=ids.tolist(),
                            poses_m=poses.ravel().tolist()).SerializeToString()

    def truth_scene(self, truth: PoseTruth, t_ns: int) -> bytes:
        """The truth's skeleton scene (a SceneUpdate) of one truth tick, stamped t_ns, as protobuf writes it
        (tests/reference/foxglove.py), by the compiled `wire.skeleton_scene` (the writer calls it at 20 Hz,
        `TRUTH_SCENE_PERIOD_S`: docs/benchmarks.md, "Kernel ledger", has what compiling it buys)."""
        poses = np.ascontiguousarray(truth.poses, dtype=np.float64)
        ids = np.asarray(truth.person_ids, dtype=np.int64)
        if poses.ndim != 3 or poses.shape[2] != 3 or poses.shape[0] != ids.shape[0]:
            raise ValueError(f"PoseTruth@{truth.t_s}: poses expected (P, J, 3) with P={ids.shape[0]}, got "
                             f"{poses.shape}")
        return self._scene(ids, poses, self._entities, t_ns)

    def _scene(self, ids: np.ndarray, poses: np.ndarray, pieces: foxglove.PieceTable, t_ns: int) -> bytes:
        """A skeleton scene of the entities `ids` (n,) with poses (n, J, 3), from their rows of `pieces`."""
        import crossview.recording.wire as wire  # (numba: loaded for writing only)

        rows = pieces.rows(ids)
        head, deletion = foxglove.scene_heads(t_ns)
        style = wire.SceneStyle(pieces.table, pieces.sizes, self._bones, head, deletion, foxglove.ORIENTATION_FIELD,
                                foxglove.LINE_POINTS_KEY)
        out = self._buffer_of(wire.skeleton_scene_capacity(len(ids), len(self._bones), pieces.table.shape[1],
                                                           head.size, deletion.size))
        return out[:wire.skeleton_scene(out, poses, rows, style)].tobytes()

    def tracker_scene(self, output: TrackerOutput, t_ns: int) -> bytes:
        """The tracker's skeleton scene (a SceneUpdate) of one tracker output, stamped t_ns, as protobuf writes it
        (tests/reference/foxglove.py), by the compiled `wire.skeleton_scene` (the tracks writer calls it at 20 Hz
        at most, `TRACK_SCENE_PERIOD_S`: docs/recording-format.md)."""
        targets = output.targets
        J = self.skeleton.num_joints
        if isinstance(targets, TargetArrays):
            ids, poses = np.asarray(targets.ids, dtype=np.int64), targets.poses
        else:
            ids = np.array([t.id for t in targets], dtype=np.int64)
            poses = np.array([np.asarray(t.pose, dtype=np.float64) for t in targets]).reshape(len(ids), J, 3)
        return self._scene(ids, np.ascontiguousarray(poses, dtype=np.float64).reshape(len(ids), J, 3), self._tracks,
                           t_ns)

    def frames(self, cameras: Sequence[str], times: np.ndarray, bounds: np.ndarray,
               rows: DetectionRows) -> list[EncodedFrame]:
        """The EncodedFrame of n camera frames given as rows, from one compiled call (`wire.frames_and_annotations`):
        the crossview.CameraFrame and the foxglove.ImageAnnotations (`wire.image_annotations`, stamped at the
        delivery time) that protobuf serialises for each, as the tests check.

        Args:
            cameras: the n frames' camera names.
            times: (n, 3) each frame's stamp, capture and delivery seconds.
            bounds: (n + 1,) frame i owns rows bounds[i]:bounds[i + 1].
            rows: the frames' detections (the detector's `DetectionRows`).
        """
        import crossview.recording.wire as wire  # (numba: loaded for writing only)

        times = np.ascontiguousarray(times, dtype=np.float64).reshape(-1, 3)
        bounds = np.ascontiguousarray(bounds, dtype=np.int64)
        n = len(cameras)
        J = self.skeleton.num_joints
        D = int(bounds[-1]) if bounds.size else 0
        if times.shape[0] != n or bounds.shape != (n + 1,) or len(rows) != len(_ROWS):
            raise ValueError(f"Encoder.frames: {n} cameras, times {times.shape}, bounds {bounds.shape} and "
                             f"{len(rows)} row arrays; expected (n, 3) times, (n + 1,) bounds and {len(_ROWS)} arrays")
        columns = []
        for (owner, name, dtype, tail), array in zip(_ROWS.values(), rows):
            array = np.ascontiguousarray(array, dtype=dtype)
            expected = (D, J, 2)[:1 + tail]
            if array.shape != expected:
                raise ValueError(f"Encoder.frames: {owner}.{name} rows expected {expected}, got {array.shape}")
            columns.append(array)
        ids, kp, scores, *truth = columns
        effects = columns[-1]
        bad = np.flatnonzero((effects < 0) | (effects >= _UINT32_END))
        if bad.size:
            i = int(np.searchsorted(bounds, bad[0], side="right")) - 1
            raise ValueError(f"CameraFrame {cameras[i]}@{times[i, 0]}: truth.effects must be uint32 bit masks, got "
                             f"{int(effects[bad[0]])}")
        names = [_utf8(camera) for camera in cameras]
        name_ends = np.cumsum([0] + [a.size for a in names])
        t_ns = [to_ns(t) for t in times[:, 2].tolist()]
        style_rows = self._styles.rows(np.maximum(ids, -1))  # (a negative id: a false positive's style)
        counts = np.diff(bounds).tolist()
        capacity = sum(wire.camera_frame_capacity(d, J, a.size) + wire.image_annotations_capacity(
            d, J, len(self._bones), self._styles.table.shape[1]) for d, a in zip(counts, names))
        out = self._buffer_of(capacity)
        ends = np.empty(2 * n, dtype=np.int64)
        style = wire.AnnotationStyle(self._bones, self._styles.table, self._styles.sizes, *foxglove.ANNOTATION_FIELDS)
        wire.frames_and_annotations(out, ends, np.concatenate(names) if names else np.zeros(0, np.uint8), name_ends,
                                    times, np.asarray(t_ns, dtype=np.int64), bounds,
                                    wire.FrameRows(kp, scores, ids, *truth), style_rows, style)
        ends = ends.tolist()
        data = out[:ends[-1] if n else 0].tobytes()
        result, start = [], 0
        for i, camera in enumerate(cameras):
            result.append(EncodedFrame(camera, t_ns[i], data[start:ends[2 * i]], data[ends[2 * i]:ends[2 * i + 1]]))
            start = ends[2 * i + 1]
        return result

    def camera_frames(self, frames: Sequence[CameraFrame]) -> list[EncodedFrame]:
        """`frames` of CameraFrame objects: their arrays are put together as rows; a frame whose arrays are
        not of the shapes the detector makes is named."""
        J = self.skeleton.num_joints
        rows = []
        for owner, name, dtype, tail in _ROWS.values():
            parts = []
            for cf in frames:
                D = np.shape(cf.frame.keypoints_px)[0] if np.ndim(cf.frame.keypoints_px) else 0
                part = np.asarray(getattr(getattr(cf, owner), name), dtype=dtype)
                if part.shape != (D, *(J, 2)[:tail]):
                    raise ValueError(f"CameraFrame {cf.frame.camera}@{cf.frame.stamp_s}: {owner}.{name} expected "
                                     f"{(D, *(J, 2)[:tail])}, got {part.shape}")
                parts.append(part)
            rows.append(np.concatenate(parts) if parts else np.zeros((0, *(J, 2)[:tail]), dtype=dtype))
        counts = [len(cf.frame.keypoints_px) for cf in frames]
        times = [(cf.frame.stamp_s, cf.truth.capture_s, cf.truth.delivery_s) for cf in frames]
        return self.frames([cf.frame.camera for cf in frames], np.array(times, dtype=np.float64).reshape(-1, 3),
                           np.cumsum([0] + counts), DetectionRows(*rows))

    def tracker_output(self, output: TrackerOutput) -> bytes:
        """`crossview.TrackerOutput` of one tracker output (poses as float32, `pose_m32`)."""
        J = self.skeleton.num_joints
        msg = TrackerOutputMsg(stamp_s=float(output.stamp_s), camera=output.camera, num_joints=J)
        targets = output.targets
        if isinstance(targets, TargetArrays):  # the built-in tracker's: no per-target object
            T = len(targets)
            poses = np.asarray(targets.poses, dtype=np.float64)
            codes = np.asarray(targets.joint_states)
            if poses.shape != (T, J, 3) or codes.shape != (T, J) or (
                    T and (codes.min() < 0 or codes.max() >= len(JointState))):
                raise ValueError(f"TrackerOutput@{output.stamp_s}: targets expected poses ({T}, {J}, 3) and "
                                 f"joint_states ({T}, {J}) codes in 0..{len(JointState) - 1}, got poses "
                                 f"{poses.shape} and joint_states {codes.shape}")
            state, stamp_s = TargetState(targets.state).value, float(targets.stamp_s)
            add = msg.targets.add
            for target_id, pose, code in zip(np.asarray(targets.ids, dtype=np.int64).tolist(),
                                             poses.reshape(T, 3 * J).tolist(), codes.tolist(), strict=True):
                add(id=target_id, stamp_s=stamp_s, state=state, pose_m32=pose, joint_state=code)
        else:
            for target in targets:
                pose = _checked_pose(output, target, J)
                t = msg.targets.add(id=int(target.id), stamp_s=float(target.stamp_s),
                                    state=TargetState(target.state).value, pose_m32=pose.ravel().tolist())
                if target.joint_state is not None:
                    t.joint_state.extend(_checked_joint_state(output, target, J).tolist())
        msg.detection_target_ids.extend(np.asarray(output.detection_target_ids, dtype=np.int64).ravel().tolist())
        return msg.SerializeToString()

    def warm_up(self) -> None:
        """Loads every compiled encoder (the camera frames' and the skeleton scenes'): their first use costs tens
        of milliseconds from numba's cache, and tens of seconds on a fresh install, where they compile. Each
        writer calls it before it opens its file: then no compile falls while a temporary output exists, where a
        signal must be held until the compiler returns (`crossview.cli`) and a fresh cache once left the
        temporary file behind."""
        J = self.skeleton.num_joints
        ids = np.array([3], dtype=np.int64)
        seen = np.ones((1, J), dtype=bool)
        frame = CameraFrame(Frame("warm", 0.5, np.ones((1, J, 2)), np.ones((1, J))),
                            DetectionTruth(0.5, 0.5, ids, np.ones((1, J, 2)), seen, ~seen, ~seen,
                                           np.zeros(1, dtype=np.int64)), None)
        self.camera_frames([frame, frame])
        self.truth_scene(PoseTruth(0.5, ids, np.ones((1, J, 3))), 500_000_000)  # (and so the tracker's scene)


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


def camera_frame_from_bytes(data: bytes) -> CameraFrame:
    """The camera frame of `crossview.CameraFrame` bytes, as `Recording.frames` reads it (no poses at capture)."""
    return camera_frame_from_msg(CameraFrameMsg.FromString(data))


_TARGET_STATES = {s.value: s for s in TargetState}


def tracker_output_from_bytes(data: bytes) -> TrackerOutput:
    """The `TrackerOutput` of `crossview.TrackerOutput` bytes (protobuf's parser): its targets are a
    `TargetArrays` when they share one stamp and state and all carry joint states (every output of the built-in
    tracker), else a list of `Target`. A corrupt message raises DecodeError or a ValueError that names it."""
    return _tracker_output_from_msg(TrackerOutputMsg.FromString(data))


def _tracker_output_from_msg(msg) -> TrackerOutput:
    J = msg.num_joints
    # One pass over the targets, their values gathered into lists, then one array per field.
    ids, stamps, names, values, codes, known = [], [], [], [], [], []
    for t in msg.targets:
        pose_m32, pose_m = t.pose_m32, t.pose_m  # a pose is in pose_m32 (format 4) or pose_m (1 to 3), never both
        if len(pose_m32) + len(pose_m) != 3 * J or (pose_m32 and pose_m):
            raise ValueError(f"a target pose of {msg.camera}@{msg.stamp_s} does not hold {J} joints x 3 in one field")
        values.extend(pose_m32 or pose_m)
        joint_state = t.joint_state
        known.append(J > 0 and len(joint_state) == J)
        if known[-1]:
            codes.extend(joint_state)
        ids.append(t.id)
        stamps.append(t.stamp_s)
        names.append(t.state)
    T = len(ids)
    poses = np.array(values, dtype=np.float64).reshape(T, J, 3)
    codes = np.array(codes, dtype=np.uint8).reshape(-1, J) if J else np.zeros((0, 0), dtype=np.uint8)
    states = {name: _TARGET_STATES.get(name) or TargetState(name) for name in set(names)}
    detection_ids = np.array(msg.detection_target_ids, dtype=np.int64)
    if T and all(known) and len(states) == 1 and all(stamp == stamps[0] for stamp in stamps):
        return TrackerOutput(stamp_s=msg.stamp_s, camera=msg.camera, detection_target_ids=detection_ids,
                             targets=TargetArrays(np.array(ids, dtype=np.int64), poses, codes, stamps[0],
                                                  states[names[0]]))
    rows = iter(codes)
    targets = [
        Target(id=target_id, pose=pose, stamp_s=stamp, state=states[name], joint_state=next(rows) if k else None)
        for target_id, pose, stamp, name, k in zip(ids, poses, stamps, names, known, strict=True)
    ]
    return TrackerOutput(stamp_s=msg.stamp_s, camera=msg.camera, targets=targets, detection_target_ids=detection_ids)
