"""Recording and tracks files: exact round trips, identical bytes, atomic writes, independent reading, bad files."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np
import pytest
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from core.errors import CrossviewError
from core.records import Box, BoxKind, CameraFrame, DetectionRows, DetectionTruth, PoseTruth
from core.types import COCO17, Camera, Frame
from crossview import recording
from crossview.recording import (
    FORMAT_VERSION,
    TRACKS_FORMAT_VERSION,
    RecordingError,
    RecordingHeader,
    RecordingWriter,
    TracksHeader,
    TracksWriter,
    open_recording,
    open_tracks,
    reader,
    schemas,
)
from tests.reference import recording as reference
from tests.reference.foxglove import tracker_skeletons, truth_skeletons
from tracker.types import JointState, Target, TargetArrays, TargetState, TrackerOutput

SCENARIO_TEXT = 'description = "synthetic"\n[crowd]\npeople = 3\n'


def make_cameras(num_cameras: int, rng: np.random.Generator, width_m: float = 8.0) -> list[Camera]:
    """Ceiling cameras looking straight down, spread along x, each with a random yaw."""
    cameras = []
    for c in range(num_cameras):
        yaw = rng.uniform(-np.pi, np.pi)
        Rz = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
        R = np.diag([1.0, -1.0, -1.0]) @ Rz  # optical axis along -z (down)
        center = np.array([width_m * (c + 0.5) / num_cameras, rng.uniform(1, 3), 3.0])
        K = np.array([[640.0 + rng.normal(), 0, 640.0], [0, 640.0, 360.0], [0, 0, 1]])
        cameras.append(Camera(f"cam{c:02d}", K, rng.normal(0, 0.01, 5), R, -R @ center, 1280, 720))
    return cameras


BOXES = (
    Box(BoxKind.FLOOR, (4.0, 2.0, -0.05), (8.0, 4.0, 0.1)),
    Box(BoxKind.SHELF, (2.0, 1.0, 0.9), (2.0, 0.5, 1.8), 0.3),
    Box(BoxKind.CHECKOUT, (6.5, 3.5, 0.5), (1.0, 0.6, 1.0)),
)


def synthetic_stream(cameras: list[Camera], num_people: int, duration_s: float, rng: np.random.Generator, *,
                     fps: float = 10.0, truth_hz: float = 100.0, num_joints: int = 17):
    """Events shaped like the simulator's, in log-time order and generated lazily (constant memory):
    truth at `truth_hz`, and per camera jittered, delayed frames of up to num_people + 1 detections
    with missing joints, false positives and signed zeros."""
    J = num_joints
    ids = np.arange(num_people, dtype=np.int64) + 1

    def poses_at(t_s: float) -> np.ndarray:
        base = np.stack([np.array([1.0 + i + 0.5 * t_s, 2.0, 0.0]) for i in range(num_people)]).reshape(-1, 1, 3)
        return base + rng.normal(0, 0.3, (num_people, J, 3)) + np.array([0, 0, 1.0])

    def camera_frame(camera: Camera, capture: float, delivery: float) -> CameraFrame:
        D = int(rng.integers(0, num_people + 2))
        kp = rng.uniform(0, 1280, (D, J, 2))
        missing = rng.random((D, J)) < 0.2
        kp[missing] = np.nan
        scores = np.where(missing, 0.0, rng.random((D, J)))
        pids = rng.choice(np.append(ids, -1), D).astype(np.int64)
        true_kp = kp + rng.normal(0, 2, kp.shape)
        true_kp[pids < 0] = np.nan
        if D:
            kp[0, 0] = -0.0  # signed zero must survive
        frame = Frame(camera=camera.name, stamp_s=capture + rng.normal(0, 0.001) - 0.0005, keypoints_px=kp,
                      scores=scores)
        truth = DetectionTruth(
            capture_s=capture, delivery_s=delivery, person_ids=pids, keypoints_px=true_kp,
            in_image=rng.random((D, J)) < 0.9, occluded=rng.random((D, J)) < 0.2,
            self_occluded=rng.random((D, J)) < 0.1, effects=rng.integers(0, 32, D).astype(np.int64),
        )
        return CameraFrame(frame, truth, PoseTruth(t_s=capture, person_ids=ids.copy(), poses=poses_at(capture)))

    # The timing of everything is drawn first (small); the contents are drawn as they are yielded.
    schedule = [(k / truth_hz, 0, None, k / truth_hz) for k in range(int(duration_s * truth_hz))]
    for index, camera in enumerate(cameras):
        captures = rng.uniform(0, 1 / fps) + np.arange(int(duration_s * fps)) / fps + rng.normal(0, 0.002)
        deliveries = captures + 0.03 + rng.uniform(0, 0.02, captures.shape)
        schedule += [(d, 1 + index, camera, c) for c, d in zip(captures.tolist(), deliveries.tolist()) if c >= 0]
    schedule.sort(key=lambda e: (recording.to_ns(e[0]), e[1]))
    for log_s, _, camera, t_s in schedule:
        if camera is None:
            yield PoseTruth(t_s=t_s, person_ids=ids.copy(), poses=poses_at(t_s))
        else:
            yield camera_frame(camera, t_s, log_s)


def make_events(cameras: list[Camera], num_people: int, duration_s: float, rng: np.random.Generator, **kwargs):
    return list(synthetic_stream(cameras, num_people, duration_s, rng, **kwargs))


def make_header(**overrides) -> RecordingHeader:
    fields = dict(scenario_name="synthetic", scenario_text=SCENARIO_TEXT, scenario_digest="ab" * 32, seed=7,
                  duration_s=1.0, skeleton_name="coco17", software_version="9.9.9", format_version=FORMAT_VERSION)
    return RecordingHeader(**(fields | overrides))


@pytest.fixture
def world():
    rng = np.random.default_rng(5)
    cameras = make_cameras(3, rng)
    events = make_events(cameras, 3, 1.0, rng)
    return cameras, events


def write_recording(path: Path, cameras, events, header=None, chunk_size: int = recording.CHUNK_SIZE) -> Path:
    with RecordingWriter(path, header or make_header(), cameras, BOXES, chunk_size=chunk_size) as writer:
        for event in events:
            writer.write(event)
    return path


def assert_same_arrays(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape
    # Bit-for-bit: compare the raw bytes (NaN and -0.0 included).
    assert a.tobytes() == b.tobytes()


def assert_same_pose_truth(a: PoseTruth, b: PoseTruth):
    assert a.t_s == b.t_s
    assert_same_arrays(np.asarray(a.person_ids, dtype=np.int64), b.person_ids)
    assert_same_arrays(np.asarray(a.poses, dtype=np.float64), b.poses)


def assert_same_event(a, b):
    assert type(a) is type(b)
    if isinstance(a, PoseTruth):
        assert_same_pose_truth(a, b)
        return
    assert a.frame.camera == b.frame.camera and a.frame.stamp_s == b.frame.stamp_s
    assert_same_arrays(a.frame.keypoints_px, b.frame.keypoints_px)
    assert_same_arrays(a.frame.scores, b.frame.scores)
    for name in ("person_ids", "keypoints_px", "in_image", "occluded", "self_occluded", "effects"):
        assert_same_arrays(getattr(a.truth, name), getattr(b.truth, name))
    assert a.truth.capture_s == b.truth.capture_s and a.truth.delivery_s == b.truth.delivery_s
    if b.poses_at_capture is not None:  # (derived from the truth ticks when the reader is asked for them)
        assert_same_pose_truth(a.poses_at_capture, b.poses_at_capture)


def test_recording_round_trip_is_bit_exact(tmp_path, world):
    cameras, events = world
    path = write_recording(tmp_path / "rec.mcap", cameras, events)
    rec = open_recording(path)
    # Header, cameras and boxes come back as written.
    assert rec.header == make_header()
    assert rec.boxes == BOXES
    assert [c.name for c in rec.cameras] == [c.name for c in cameras]
    for a, b in zip(cameras, rec.cameras):
        for name in ("K", "dist", "R_cam_from_world", "t_cam_from_world"):
            assert_same_arrays(getattr(a, name), getattr(b, name))
        assert (a.width_px, a.height_px) == (b.width_px, b.height_px)
    # Every event, in the written order, bit for bit.
    read = list(rec.events())
    assert len(read) == len(events)
    for a, b in zip(events, read):
        assert_same_event(a, b)
    assert all(e.poses_at_capture is None for e in read if isinstance(e, CameraFrame))  # not stored
    # The filtered streams are the two halves of it.
    assert len(list(rec.truth())) == sum(isinstance(e, PoseTruth) for e in events)
    frames = list(rec.frames())
    assert [f.truth.delivery_s for f in frames] == [e.truth.delivery_s for e in events if isinstance(e, CameraFrame)]


def test_same_inputs_give_identical_bytes(tmp_path, world):
    cameras, events = world
    a = write_recording(tmp_path / "a.mcap", cameras, events)
    b = write_recording(tmp_path / "b.mcap", cameras, events)
    assert a.read_bytes() == b.read_bytes()


def test_empty_detections_and_empty_store_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    cameras = make_cameras(1, rng)
    J = COCO17.num_joints
    frame = Frame("cam00", 0.1, np.zeros((0, J, 2)), np.zeros((0, J)))
    truth = DetectionTruth(0.1, 0.12, np.zeros(0, np.int64), np.zeros((0, J, 2)), np.zeros((0, J), bool),
                           np.zeros((0, J), bool), np.zeros((0, J), bool), np.zeros(0, np.int64))
    nobody = PoseTruth(0.1, np.zeros(0, np.int64), np.zeros((0, J, 3)))
    events = [PoseTruth(0.0, np.zeros(0, np.int64), np.zeros((0, J, 3))), CameraFrame(frame, truth, nobody)]
    path = tmp_path / "empty.mcap"
    with RecordingWriter(path, make_header(), cameras, ()) as writer:
        for e in events:
            writer.write(e)
    read = list(open_recording(path).events())
    for a, b in zip(events, read, strict=True):
        assert_same_event(a, b)


def test_events_out_of_log_time_order_are_refused(tmp_path, world):
    cameras, events = world
    with pytest.raises(ValueError, match="log-time order"), \
            RecordingWriter(tmp_path / "r.mcap", make_header(), cameras, BOXES) as writer:
        writer.write(events[5])
        writer.write(events[0])
    assert not (tmp_path / "r.mcap").exists()


def test_interrupted_write_leaves_no_file(tmp_path, world):
    cameras, events = world
    path = tmp_path / "rec.mcap"
    # A Ctrl-C in the middle of writing.
    with pytest.raises(KeyboardInterrupt), RecordingWriter(path, make_header(), cameras, BOXES) as writer:
        for i, event in enumerate(events):
            writer.write(event)
            if i == 50:
                raise KeyboardInterrupt
    # Nothing under the final name, and no temporary file left behind.
    assert list(tmp_path.iterdir()) == []


def test_interrupted_write_keeps_an_existing_file(tmp_path, world):
    cameras, events = world
    path = write_recording(tmp_path / "rec.mcap", cameras, events[:10])
    before = path.read_bytes()
    with pytest.raises(RuntimeError), RecordingWriter(path, make_header(), cameras, BOXES) as writer:
        writer.write(events[0])
        raise RuntimeError("crash")
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.mcap"]


def _protobuf_classes():
    from foxglove_schemas_protobuf import (
        CameraCalibration_pb2,
        FrameTransforms_pb2,
        ImageAnnotations_pb2,
        SceneUpdate_pb2,
    )
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

    return {
        "foxglove.CompressedImage": CompressedImage,
        "foxglove.SceneUpdate": SceneUpdate_pb2.SceneUpdate,
        "foxglove.FrameTransforms": FrameTransforms_pb2.FrameTransforms,
        "foxglove.CameraCalibration": CameraCalibration_pb2.CameraCalibration,
        "foxglove.ImageAnnotations": ImageAnnotations_pb2.ImageAnnotations,
    }


def read_independently(path: Path) -> dict[str, tuple[str, int]]:
    """Every message through the mcap package's own reader with CRC checks, decoded with its declared
    schema: Foxglove protobuf through foxglove_schemas_protobuf, the project's protobuf through
    mcap_protobuf's decoder (classes built from the schema stored in the file), JSON through json.loads.
    Returns topic -> (schema name, message count)."""
    foxglove_classes = _protobuf_classes()
    decoder_factory = DecoderFactory()
    seen: dict[str, tuple[str, int]] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.message_encoding == "protobuf":
                assert schema.encoding == "protobuf"
                decoded = decoder_factory.decoder_for("protobuf", schema)(message.data)
                assert decoded.DESCRIPTOR.full_name == schema.name
                if schema.name.startswith("foxglove."):
                    foxglove_classes[schema.name].FromString(message.data)
            else:
                assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
                json.loads(message.data)
                json.loads(schema.data)
            name, n = seen.get(channel.topic, (schema.name, 0))
            seen[channel.topic] = (name, n + 1)
    return seen


def test_independent_reader_decodes_every_message_with_its_schema(tmp_path, world):
    cameras, events = world
    path = write_recording(tmp_path / "rec.mcap", cameras, events)
    seen = read_independently(path)
    # The Foxglove channels carry exactly the Foxglove schema names.
    assert seen["/tf"][0] == "foxglove.FrameTransforms"
    assert seen["/store/scene"][0] == "foxglove.SceneUpdate"
    assert seen["/truth/skeletons"][0] == "foxglove.SceneUpdate"
    for camera in cameras:
        assert seen[f"/cameras/{camera.name}/calibration"] == ("foxglove.CameraCalibration", 1)
        assert seen[f"/cameras/{camera.name}/image"] == ("foxglove.CompressedImage", 1)
        assert seen[f"/cameras/{camera.name}/detections"][0] == "foxglove.ImageAnnotations"
        assert seen[f"/cameras/{camera.name}/frame"][0] == "crossview.CameraFrame"
    assert seen["/truth/poses"] == ("crossview.PoseTruth", sum(isinstance(e, PoseTruth) for e in events))
    assert seen["/crossview/header"] == ("crossview.RecordingHeader", 1)


def test_log_times_are_nanoseconds_of_truth_and_delivery_times(tmp_path, world):
    cameras, events = world
    path = write_recording(tmp_path / "rec.mcap", cameras, events)
    expected = [round(e.t_s * 1e9) if isinstance(e, PoseTruth) else round(e.truth.delivery_s * 1e9) for e in events]
    with open(path, "rb") as f:
        got = [m.log_time for _, c, m in make_reader(f).iter_messages(log_time_order=False)
               if c.topic == "/truth/poses" or c.topic.endswith("/frame")]
    assert got == expected
    assert got == sorted(got)


def make_tracks_header(**overrides) -> TracksHeader:
    fields = dict(scenario_name="synthetic", scenario_digest="ab" * 32, seed=7, method="crossview", preset="store",
                  config={"alpha_2d_px": 25.0, "lambda_t": 5.0, "mode": "paper", "nested": {"x": [1, 2.5]}},
                  skeleton_name="coco17", software_version="9.9.9", format_version=TRACKS_FORMAT_VERSION)
    return TracksHeader(**(fields | overrides))


def make_outputs(rng: np.random.Generator, n: int) -> list[TrackerOutput]:
    outputs = []
    for k in range(n):
        targets = []
        for tid in range(int(rng.integers(0, 4))):
            pose = rng.normal(0, 1, (17, 3))
            pose[rng.random(17) < 0.1] = np.nan
            codes = rng.integers(0, 3, 17).astype(np.uint8) if rng.random() < 0.7 else None  # None: format 2
            targets.append(Target(id=tid + 1, pose=pose, stamp_s=k * 0.05, state=TargetState.CONFIRMED,
                                  joint_state=codes))
        outputs.append(TrackerOutput(stamp_s=k * 0.05 - 0.001, camera=f"cam{k % 3:02d}", targets=targets,
                                     detection_target_ids=rng.integers(-1, 4, int(rng.integers(0, 5)))))
    return outputs


def test_tracks_round_trip_with_summary(tmp_path):
    rng = np.random.default_rng(3)
    cameras = make_cameras(3, rng)
    outputs = make_outputs(rng, 40)
    path = tmp_path / "tracks.mcap"
    with TracksWriter(path, make_tracks_header(), cameras) as writer:
        for output in outputs:
            writer.write(output)
        writer.finish({"tracker_s": 0.125, "updates": 40, "num_cameras": 3})
    tracks = open_tracks(path)
    assert tracks.header == make_tracks_header()
    assert tracks.summary["tracker_s"] == 0.125 and tracks.summary["updates"] == 40
    read = list(tracks.outputs())
    assert len(read) == len(outputs)
    for a, b in zip(outputs, read):
        assert a.stamp_s == b.stamp_s and a.camera == b.camera
        assert_same_arrays(np.asarray(a.detection_target_ids, dtype=np.int64), b.detection_target_ids)
        assert [t.id for t in a.targets] == [t.id for t in b.targets]
        for ta, tb in zip(a.targets, b.targets):
            assert ta.state is tb.state and ta.stamp_s == tb.stamp_s
            assert_same_arrays(ta.pose.astype(np.float32).astype(np.float64), tb.pose)  # format 4: float32
            assert (ta.joint_state is None and tb.joint_state is None) or np.array_equal(ta.joint_state,
                                                                                        tb.joint_state)
    # The tracker's skeletons are Foxglove SceneUpdates, readable independently.
    seen = read_independently(path)
    assert seen["/tracker/skeletons"][0] == "foxglove.SceneUpdate"
    assert seen["/tracker/outputs"] == ("crossview.TrackerOutput", 40)


# Bad files ------------------------------------------------------------------------------------------


def test_not_mcap_is_a_clear_error(tmp_path):
    path = tmp_path / "notes.mcap"
    path.write_text("hello, I am not a recording\n")
    with pytest.raises(RecordingError, match=r"notes\.mcap: not an MCAP file"):
        open_recording(path)
    with pytest.raises(RecordingError, match="not an MCAP file"):
        recording.info(path)


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(RecordingError, match="cannot read"):
        open_recording(tmp_path / "nope.mcap")


def test_truncated_file_is_an_error_unless_allowed(tmp_path, world):
    cameras, events = world
    # Small chunks, so that a cut file still holds whole chunks before the cut.
    path = write_recording(tmp_path / "rec.mcap", cameras, events, chunk_size=32 * 1024)
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.7)])
    with pytest.raises(RecordingError, match=r"cut\.mcap: truncated"):
        open_recording(cut)
    # allow_truncated recovers a prefix of the events, each one exact.
    prefix = list(open_recording(cut, allow_truncated=True).events())
    assert 0 < len(prefix) < len(events)
    for a, b in zip(events, prefix):
        assert_same_event(a, b)
    described = recording.info(cut, allow_truncated=True)
    assert described["truncated"] and described["kind"] == "recording"
    assert "TRUNCATED" in recording.format_info(described)


def test_corrupt_chunk_fails_the_crc_check(tmp_path, world):
    cameras, events = world
    path = write_recording(tmp_path / "rec.mcap", cameras, events)
    data = bytearray(path.read_bytes())
    # Flip bytes in the middle of the data section (inside a compressed chunk).
    middle = len(data) // 3
    data[middle: middle + 16] = bytes(b ^ 0xFF for b in data[middle: middle + 16])
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with pytest.raises(RecordingError, match=r"bad\.mcap: corrupt"):
        rec = open_recording(bad)
        list(rec.events())


@pytest.mark.parametrize("bug", [TypeError, ValueError, KeyError, RuntimeError])
def test_a_bug_inside_the_reader_is_not_reported_as_corrupt_data(tmp_path, world, monkeypatch, bug):
    """Only the mcap library's documented errors, and the damage the reader finds itself, become a
    RecordingError: any other exception out of the reading code is a bug and keeps its class (these four were
    once all reported as "corrupt MCAP data")."""
    cameras, events = world
    path = write_recording(tmp_path / "rec.mcap", cameras, events)
    assert len(list(open_recording(path).events())) == len(events)

    def broken(self, n=-1):
        raise bug("a bug in the reader")

    monkeypatch.setattr(reader.FileWithinSize, "read", broken)
    with pytest.raises(bug, match="a bug in the reader") as raised:
        open_recording(path)
    assert not isinstance(raised.value, RecordingError)


def test_a_corrupt_offset_or_a_short_record_is_corrupt_data_not_a_crash(tmp_path, world):
    """A damaged length or offset ends a read short (mcap's `EndOfFile`, raised where the file wrapper sees it)."""
    cameras, events = world
    path = write_recording(tmp_path / "rec.mcap", cameras, events)
    with open(path, "rb") as f:
        within = reader.FileWithinSize(f, path.stat().st_size)
        with pytest.raises(EndOfFile):
            within.seek(2 ** 70)
        within.seek(-4, 2)
        with pytest.raises(EndOfFile):
            within.read(8)
    assert reader.describe_read_error(EndOfFile()) == "unexpected end of file"


def test_newer_format_version_is_refused(tmp_path, world):
    cameras, events = world
    path = write_recording(tmp_path / "new.mcap", cameras, events[:5], make_header(format_version=FORMAT_VERSION + 1))
    with pytest.raises(RecordingError, match=rf"format version {FORMAT_VERSION + 1} is newer"):
        open_recording(path)


def test_a_format_1_recording_is_refused_with_what_to_do(tmp_path, world):
    cameras, events = world
    path = write_recording(tmp_path / "old.mcap", cameras, events[:5], make_header(format_version=1))
    with pytest.raises(RecordingError, match=r"old\.mcap: format version 1 is older than this software reads "
                                             r"\(recordings: 2 to .*crossview generate"):
        open_recording(path)


def test_poses_at_capture_far_behind_the_window_read_the_ticks_again():
    """Captures come nearly in time order; one older than the kept window restarts the tick stream and
    still gets the exact poses."""
    ticks = [PoseTruth(k / 100, np.array([3]), np.full((1, 17, 3), float(k))) for k in range(3001)]
    opened = []

    def open_ticks():
        opened.append(1)
        return iter(ticks)

    window = reader._TruthWindow(open_ticks, 17)
    assert window.at(25.005).poses[0, 0, 0] == pytest.approx(2500.5)
    assert window.at(0.0).poses[0, 0, 0] == 0.0  # 25 s back: read again
    assert len(opened) == 2
    assert window.at(30.0).poses[0, 0, 0] == 3000.0  # a tick's own time: that tick exactly
    assert window.at(31.0).poses[0, 0, 0] == 3000.0  # after the last tick: the last tick
    empty = reader._TruthWindow(lambda: iter(()), 17).at(1.0)
    assert empty.person_ids.size == 0 and empty.poses.shape == (0, 17, 3)


def test_wrong_kind_is_refused_both_ways(tmp_path, world):
    cameras, events = world
    rec_path = write_recording(tmp_path / "rec.mcap", cameras, events[:5])
    tracks_path = tmp_path / "tracks.mcap"
    with TracksWriter(tracks_path, make_tracks_header(), cameras) as writer:
        writer.finish({})
    with pytest.raises(RecordingError, match=r"tracks\.mcap: this is a tracks file, but a recording"):
        open_recording(tracks_path)
    with pytest.raises(RecordingError, match=r"rec\.mcap: this is a recording file, but a tracks file"):
        open_tracks(rec_path)


def test_info_describes_a_recording(tmp_path, world):
    cameras, events = world
    path = write_recording(tmp_path / "rec.mcap", cameras, events)
    d = recording.info(path)
    assert d["kind"] == "recording" and d["seed"] == 7 and d["scenario_name"] == "synthetic"
    assert d["format_version"] == FORMAT_VERSION
    assert d["cameras"] == [c.name for c in cameras]
    assert d["people"] == 3
    assert d["size_bytes"] == os.path.getsize(path)
    assert d["messages"]["/truth/poses"] == 100
    assert d["end_s"] == pytest.approx(max(e.truth.delivery_s for e in events if isinstance(e, CameraFrame)))
    text = recording.format_info(d)
    assert "synthetic" in text and "seed 7" in text and "/truth/poses" in text


def test_garbage_after_the_magic_and_empty_files_are_clear_errors(tmp_path, world):
    cameras, events = world
    data = write_recording(tmp_path / "rec.mcap", cameras, events).read_bytes()
    rng = np.random.default_rng(9)
    # The MCAP magic at both ends, random bytes between.
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(data[:8] + rng.integers(0, 256, 5000, dtype=np.uint8).tobytes() + data[-8:])
    with pytest.raises(RecordingError, match=r"garbage\.mcap: (corrupt|no /crossview/header)"):
        open_recording(garbage)
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(RecordingError, match=r"empty\.mcap: not an MCAP file"):
        open_recording(empty)
    # A plain MCAP file that this project did not write.
    from mcap.writer import Writer

    foreign = tmp_path / "foreign.mcap"
    with open(foreign, "wb") as f:
        writer = Writer(f)
        writer.start()
        writer.finish()
    with pytest.raises(RecordingError, match=r"foreign\.mcap: no /crossview/header message"):
        open_recording(foreign)
    with pytest.raises(RecordingError, match=r"foreign\.mcap: an MCAP file, but not a crossview"):
        recording.info(foreign)


def test_info_describes_a_tracks_file_and_its_summary(tmp_path):
    rng = np.random.default_rng(4)
    cameras = make_cameras(2, rng)
    path = tmp_path / "tracks.mcap"
    with TracksWriter(path, make_tracks_header(), cameras) as writer:
        for output in make_outputs(rng, 12):
            writer.write(output)
        writer.finish({"tracker_s": 0.5, "updates": 12})
    d = recording.info(path)
    assert d["kind"] == "tracks" and d["method"] == "crossview" and d["preset"] == "store"
    assert d["messages"]["/tracker/outputs"] == 12
    assert d["summary"]["updates"] == 12 and d["summary"]["num_outputs"] == 12
    assert "tracker_s=0.5" in recording.format_info(d)


def test_reading_memory_does_not_grow_with_the_recording(tmp_path):
    import tracemalloc

    def peak_bytes_reading(duration_s: float) -> tuple[int, int, int]:
        rng = np.random.default_rng(8)
        cameras = make_cameras(3, rng)
        path = tmp_path / f"rec{duration_s}.mcap"
        with RecordingWriter(path, make_header(), cameras, BOXES, chunk_size=64 * 1024) as writer:
            for event in synthetic_stream(cameras, 4, duration_s, rng):
                writer.write(event)
        rec = open_recording(path)
        tracemalloc.start()
        count = sum(1 for _ in rec.events())
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        return peak, path.stat().st_size, count

    short_peak, short_size, short_count = peak_bytes_reading(1.0)
    long_peak, long_size, long_count = peak_bytes_reading(6.0)
    # Six times the file, about the same memory: one chunk at a time.
    assert long_size > 5 * short_size and long_count > 5 * short_count
    assert long_peak < 1.5 * short_peak


def test_unwritable_destination_is_a_clear_error(tmp_path, world):
    cameras, _ = world
    (tmp_path / "file").write_text("not a folder")
    with pytest.raises(CrossviewError, match=r"/file: output folder cannot be created"):
        RecordingWriter(tmp_path / "file" / "rec.mcap", make_header(), cameras, BOXES)


def simulate_into(path: Path, duration_s: float) -> list:
    """A short real simulation of the default store, written as `crossview generate` does."""
    from sim import scenario as scenario_mod
    from sim.simulate import Simulation

    scenario = scenario_mod.load("store_layout1")
    sim = Simulation(scenario, scenario.seed)
    header = RecordingHeader(scenario.name, scenario.source_text, scenario.digest, scenario.seed, duration_s,
                             sim.skeleton.name)
    events = []
    with RecordingWriter(path, header, sim.cameras, sim.boxes) as writer:
        for event in sim.events(duration_s):
            writer.write(event)
            events.append(event)
    return events


def test_a_real_simulation_gives_identical_bytes_and_reads_back_exactly(tmp_path):
    # The same scenario and seed, simulated and written twice.
    events = simulate_into(tmp_path / "a.mcap", 0.5)
    simulate_into(tmp_path / "b.mcap", 0.5)
    assert (tmp_path / "a.mcap").read_bytes() == (tmp_path / "b.mcap").read_bytes()
    # What comes back is what the simulator produced, bit for bit, the poses at capture included: the
    # reader derives them from the stored truth ticks with the simulator's own rule and arithmetic.
    read = list(open_recording(tmp_path / "a.mcap").events(with_poses=True))
    assert len(read) == len(events) and any(isinstance(e, CameraFrame) for e in events)
    for a, b in zip(events, read):
        assert isinstance(b, PoseTruth) or b.poses_at_capture is not None
        assert_same_event(a, b)
    frames = list(open_recording(tmp_path / "a.mcap").frames(with_poses=True))
    for a, b in zip([e for e in events if isinstance(e, CameraFrame)], frames, strict=True):
        assert_same_event(a, b)
    # And the mcap package's own reader decodes every message with its declared schema.
    seen = read_independently(tmp_path / "a.mcap")
    assert seen["/truth/poses"][1] == sum(isinstance(e, PoseTruth) for e in events)


def test_truncated_tracks_file_gives_its_readable_prefix(tmp_path):
    rng = np.random.default_rng(6)
    cameras = make_cameras(2, rng)
    outputs = make_outputs(rng, 300)
    path = tmp_path / "tracks.mcap"
    with TracksWriter(path, make_tracks_header(), cameras, chunk_size=16 * 1024) as writer:
        for output in outputs:
            writer.write(output)
        writer.finish({"updates": 300})
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(RecordingError, match="truncated"):
        open_tracks(cut)
    tracks = open_tracks(cut, allow_truncated=True)
    assert tracks.summary == {}  # written at the end, so lost with it
    prefix = list(tracks.outputs())
    assert 0 < len(prefix) < len(outputs)
    assert [o.stamp_s for o in prefix] == [o.stamp_s for o in outputs[: len(prefix)]]


def test_encoded_messages_are_protobufs_own_serialisation(world):
    """The writer's encoders write what protobuf writes for the same message built field by field (zero
    doubles left out, -0.0 and NaN kept, packed fields, sint64 zigzag, large ids as multi-byte varints), and
    protobuf's parser reads every field back."""
    _, events = world
    encoder = recording.Encoder(COCO17)
    rng = np.random.default_rng(3)
    extra = []
    for event in events[:40]:
        if isinstance(event, PoseTruth):
            poses = event.poses.copy()
            if poses.size:
                poses[0, 0] = (0.0, -0.0, np.nan)
                poses[0, 5] = (0.0, -0.0, 1.5)  # a known joint (a bone's end) with a +0.0 and a -0.0 coordinate
            extra.append(PoseTruth(0.0, np.asarray(event.person_ids) * 100_003 - 7, poses))
    extra.append(PoseTruth(0.0, np.zeros(0, dtype=np.int64), np.zeros((0, 17, 3))))
    checked = 0
    for event in events + extra:
        if isinstance(event, PoseTruth):
            msg = recording.PoseTruthMsg()
            reference.pose_truth_to_msg(event, msg)
            data = encoder.pose_truth(event)
            assert data == msg.SerializeToString()
            back = recording.PoseTruthMsg.FromString(data)
            assert list(back.person_ids) == np.asarray(event.person_ids).tolist()
            assert np.array(back.poses_m).tobytes() == np.asarray(event.poses, dtype=np.float64).tobytes()
            # The truth's skeleton scene (compiled): Foxglove's SceneUpdate as protobuf writes it.
            scene = encoder.truth_scene(event, 1_234_567_891)
            assert scene == truth_skeletons(event, COCO17, 1_234_567_891).SerializeToString()
            assert len(SceneUpdate.FromString(scene).entities) == len(event.person_ids)
        else:
            effects = rng.integers(0, 1 << 31, len(event.truth.effects))
            bigger = CameraFrame(event.frame, dataclasses.replace(event.truth, effects=effects), event.poses_at_capture)
            for cf in (event, bigger):
                data = encoder.camera_frames([cf])[0].frame_bytes
                assert data == reference.camera_frame_to_msg(cf).SerializeToString()
                back = schemas.CameraFrameMsg.FromString(data)
                assert back.camera == cf.frame.camera and back.num_detections == cf.frame.num_detections
                assert np.array(back.keypoints_px).tobytes() == cf.frame.keypoints_px.tobytes()
                assert list(back.effects) == np.asarray(cf.truth.effects).tolist()
                assert list(back.in_image) == cf.truth.in_image.ravel().tolist()
        checked += 1
    assert checked > 50


def test_frames_written_many_at_a_time_give_the_same_file(tmp_path, world):
    """`write_many` encodes the frames between two truths in one compiled call; the file must be the one
    `write` makes event by event, also with the frames its batch hands back to the one-frame encoders (a
    +0.0 pixel, which protobuf leaves out; an unusual array) and empty frames."""
    cameras, events = world
    J = COCO17.num_joints
    odd = []
    for i, event in enumerate(events):
        if isinstance(event, CameraFrame) and event.frame.num_detections and len(odd) < 3:
            kp = event.frame.keypoints_px.copy()
            if not odd:
                kp[0, 0] = (0.0, 5.0)  # a +0.0 coordinate
            scores = event.frame.scores.astype(np.float32) if len(odd) == 1 else event.frame.scores
            frame = Frame(event.frame.camera, event.frame.stamp_s, kp, scores)
            event = CameraFrame(frame, event.truth, None)
            odd.append(i)
        elif isinstance(event, CameraFrame) and i % 7 == 0:  # nobody detected
            frame = Frame(event.frame.camera, event.frame.stamp_s, np.zeros((0, J, 2)), np.zeros((0, J)))
            truth = DetectionTruth(event.truth.capture_s, event.truth.delivery_s, np.zeros(0, np.int64),
                                   np.zeros((0, J, 2)), *(np.zeros((0, J), bool),) * 3, np.zeros(0, np.int64))
            event = CameraFrame(frame, truth, None)
        events[i] = event
    assert len(odd) == 3
    one = write_recording(tmp_path / "one.mcap", cameras, events).read_bytes()
    with RecordingWriter(tmp_path / "many.mcap", make_header(), cameras, BOXES) as writer:
        for start in range(0, len(events), 37):
            writer.write_many(events[start:start + 37])
    assert (tmp_path / "many.mcap").read_bytes() == one


def test_write_many_refuses_what_write_refuses(tmp_path, world):
    cameras, events = world
    frames = [e for e in events if isinstance(e, CameraFrame) and e.frame.num_detections][:4]
    bad = CameraFrame(frames[1].frame, dataclasses.replace(frames[1].truth, effects=np.full(
        frames[1].frame.num_detections, 1 << 40)), None)
    with RecordingWriter(tmp_path / "bad.mcap", make_header(), cameras, BOXES) as writer, \
            pytest.raises(ValueError, match="effects must be uint32 bit masks"):
        writer.write_many([frames[0], bad, frames[2]])
    with RecordingWriter(tmp_path / "late.mcap", make_header(), cameras, BOXES) as writer, \
            pytest.raises(ValueError, match="log-time order"):
        writer.write_many([frames[2], frames[0]])


def test_encoded_frames_are_written_as_the_frames_they_encode(tmp_path, world):
    """A writer handed `EncodedFrame`s (what `generate` hands it, encoded from the detector's rows) writes the
    file it writes from the CameraFrames; it refuses one of a camera the recording does not have, and rows
    of the wrong shape are refused by name."""
    cameras, events = world
    frames = [e for e in events if isinstance(e, CameraFrame)]
    encoded = dict(zip(map(id, frames), recording.Encoder(COCO17).camera_frames(frames)))
    mixed = [encoded[id(e)] if isinstance(e, CameraFrame) and i % 2 else e for i, e in enumerate(events)]
    assert any(isinstance(e, recording.EncodedFrame) for e in mixed)
    plain = write_recording(tmp_path / "plain.mcap", cameras, events).read_bytes()
    with RecordingWriter(tmp_path / "mixed.mcap", make_header(), cameras, BOXES) as writer:
        writer.write_many(mixed)
    assert (tmp_path / "mixed.mcap").read_bytes() == plain

    stranger = recording.EncodedFrame("nowhere", 0, b"", b"")
    with RecordingWriter(tmp_path / "bad.mcap", make_header(), cameras, BOXES) as writer, \
            pytest.raises(ValueError, match="'nowhere' is not one of the recording's cameras"):
        writer.write(stranger)
    f = frames[0]
    rows = DetectionRows(f.truth.person_ids, f.frame.keypoints_px, f.frame.scores[:, :3], f.truth.keypoints_px,
                         f.truth.in_image, f.truth.occluded, f.truth.self_occluded, f.truth.effects)
    times = np.array([[f.frame.stamp_s, f.truth.capture_s, f.truth.delivery_s]])
    with pytest.raises(ValueError, match=r"frame.scores rows expected \(\d+, 17\), got"):
        recording.Encoder(COCO17).frames([f.frame.camera], times, [0, f.frame.num_detections], rows)


def test_info_reads_every_chunk_and_names_the_corrupt_one(tmp_path, world):
    """A flipped byte inside one compressed chunk: the summary still reads as healthy, but `info` checks
    every chunk's CRC and names the bad chunk (number, byte range, message times); `--summary-only`
    keeps the cheap description."""
    from mcap.reader import make_reader

    cameras, events = world
    path = write_recording(tmp_path / "rec.mcap", cameras, events, chunk_size=32 * 1024)
    assert recording.info(path)["chunks_checked"] > 3
    with open(path, "rb") as f:
        indexes = make_reader(f).get_summary().chunk_indexes
    target = indexes[2]  # a chunk in the middle; its compressed data end the record
    data = bytearray(path.read_bytes())
    flip = target.chunk_start_offset + target.chunk_length - 100
    data[flip] ^= 0xFF
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    first, last = target.message_start_time / 1e9, target.message_end_time / 1e9
    end = target.chunk_start_offset + target.chunk_length
    with pytest.raises(RecordingError, match=rf"bad\.mcap: chunk 2 \(bytes {target.chunk_start_offset:,}\.\.{end:,}, "
                       rf"messages {first:.3f}\.\.{last:.3f} s\) is corrupt"):
        recording.info(bad)
    assert recording.info(bad, check=False)["chunks_checked"] is None  # (what the summary says)


def test_commands_on_a_cut_or_corrupt_file_give_one_line_with_a_hint_that_works(tmp_path, world, capsys):
    """A cut recording given to `track`: one line, exit 2, and the hint names a command that has the option
    (`info --allow-truncated`), which then works; `info` of a corrupt file fails, `--summary-only` does not."""
    from crossview.cli import EXIT_BAD_INPUT, main

    cameras, events = world
    path = write_recording(tmp_path / "rec.mcap", cameras, events, chunk_size=32 * 1024)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    assert main(["--no-progress", "track", str(cut), "-o", str(tmp_path / "t.mcap")]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.endswith(f"`crossview info --allow-truncated {cut}` describes its "
                                                       "readable prefix"), err
    assert main(["info", "--allow-truncated", str(cut)]) == 0
    assert "TRUNCATED" in capsys.readouterr().out
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    assert main(["info", str(bad)]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "bad.mcap: " in err and ("is corrupt" in err or "corrupt MCAP data" in err)
    assert main(["info", "--summary-only", str(bad)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.mcap", "cut.mcap", "rec.mcap"]


def test_a_corrupt_length_inside_a_chunk_is_refused_without_allocating_it(tmp_path, world):
    """A chunk whose compressed-size field says a terabyte (the record's own length, which mcap bounds,
    unchanged): refused as corrupt, by every reader, instead of a MemoryError."""
    import struct

    from mcap.reader import make_reader

    cameras, events = world
    path = write_recording(tmp_path / "rec.mcap", cameras, events, chunk_size=32 * 1024)
    with open(path, "rb") as f:
        chunk = make_reader(f).get_summary().chunk_indexes[1].chunk_start_offset
    data = bytearray(path.read_bytes())
    # opcode, record length, start and end time, uncompressed size and CRC, then the compression's name
    name_at = chunk + 1 + 8 + 8 + 8 + 8 + 4
    size_at = name_at + 4 + struct.unpack_from("<I", data, name_at)[0]
    struct.pack_into("<Q", data, size_at, 2**40)
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with pytest.raises(RecordingError, match=r"bad\.mcap: "):
        recording.info(bad)
    with pytest.raises(RecordingError, match=r"bad\.mcap: corrupt MCAP data"):
        list(open_recording(bad).events())


def test_tracker_outputs_decode_with_protobuf_to_their_fields():
    """The tracks file's encoder writes what protobuf's own parser reads back field by field: ids (large and
    negative ones too), stamps, states, poses as float32, joint states where given, the detections' ids."""
    from crossview.recording.schemas import TrackerOutputMsg

    rng = np.random.default_rng(11)
    outputs = make_outputs(rng, 30)
    outputs.append(TrackerOutput(stamp_s=0.0, camera="", targets=[
        Target(id=0, pose=np.zeros((17, 3)), stamp_s=0.0, state=TargetState.LOST,
               joint_state=np.zeros(17, dtype=np.uint8)),
        Target(id=2**40, pose=np.full((17, 3), np.nan), stamp_s=-1.5, state=TargetState.TENTATIVE)],
        detection_target_ids=np.array([-1, 0, 2**40])))
    outputs.append(TrackerOutput(stamp_s=1.0, camera="c", targets=[
        Target(id=-3, pose=np.ones((17, 3)), stamp_s=1.0)], detection_target_ids=np.zeros(0, dtype=np.int64)))
    encoder = recording.Encoder(COCO17)
    for output in outputs:
        msg = TrackerOutputMsg.FromString(encoder.tracker_output(output))
        assert (msg.stamp_s, msg.camera, msg.num_joints) == (output.stamp_s, output.camera, 17)
        assert list(msg.detection_target_ids) == np.asarray(output.detection_target_ids).tolist()
        assert len(msg.targets) == len(output.targets)
        for got, target in zip(msg.targets, output.targets):
            assert (got.id, got.stamp_s, got.state) == (target.id, target.stamp_s, TargetState(target.state).value)
            assert np.array(got.pose_m32, dtype=np.float32).tobytes() == \
                np.asarray(target.pose, dtype=np.float32).tobytes() and not got.pose_m
            expected = [] if target.joint_state is None else np.asarray(target.joint_state).tolist()
            assert list(got.joint_state) == expected
    bad = TrackerOutput(stamp_s=1.0, camera="c", targets=[
        Target(id=1, pose=np.ones((17, 3)), stamp_s=1.0, joint_state=np.full(17, 7))],
        detection_target_ids=np.zeros(0, dtype=np.int64))
    with pytest.raises(ValueError, match="joint_state"):
        encoder.tracker_output(bad)


def test_target_arrays_encode_as_their_targets_and_read_as_a_sequence():
    """The built-in tracker's `TargetArrays` are encoded without a per-target object: the same bytes as the
    list of the same targets; malformed arrays are named."""
    encoder = recording.Encoder(COCO17)
    rng = np.random.default_rng(5)
    for T in (0, 1, 7):
        arrays = TargetArrays(np.arange(T, dtype=np.int64) * 3 + 1, rng.normal(size=(T, 17, 3)),
                              rng.integers(0, len(JointState), (T, 17)).astype(np.uint8), 2.5)
        listed = list(arrays)
        assert len(listed) == T and [t.id for t in listed] == arrays.ids.tolist()
        if T:
            assert arrays[-1].id == listed[-1].id and [t.id for t in arrays[1:3]] == [4, 7][:T - 1]
            np.testing.assert_array_equal(arrays[0].pose, arrays.poses[0])
            assert arrays[0].state == TargetState.CONFIRMED and arrays[0].stamp_s == 2.5
        with pytest.raises(IndexError):
            arrays[T]
        as_arrays = TrackerOutput(2.5, "cam03", arrays, np.arange(T, dtype=np.int64))
        as_list = TrackerOutput(2.5, "cam03", listed, np.arange(T, dtype=np.int64))
        assert encoder.tracker_output(as_arrays) == encoder.tracker_output(as_list)
    bad = TargetArrays(np.array([1]), np.zeros((1, 17, 3)), np.full((1, 17), 7), 0.0)
    with pytest.raises(ValueError, match="joint_states"):
        encoder.tracker_output(TrackerOutput(0.0, "c", bad, np.zeros(0, dtype=np.int64)))


def _as_stored(output: TrackerOutput) -> TrackerOutput:
    """The output as a tracks file holds it: poses rounded to float32 (format 4)."""
    return dataclasses.replace(output, targets=[
        dataclasses.replace(t, pose=np.asarray(t.pose, dtype=np.float32).astype(np.float64)) for t in output.targets])


def _same_output(a: TrackerOutput, b: TrackerOutput) -> bool:
    return (a.stamp_s == b.stamp_s and a.camera == b.camera and len(a.targets) == len(b.targets)
            and np.array_equal(a.detection_target_ids, b.detection_target_ids)
            and all(x.id == y.id and x.stamp_s == y.stamp_s and x.state == y.state
                    and np.array_equal(x.pose, y.pose, equal_nan=True)
                    and (x.joint_state is None) == (y.joint_state is None)
                    and (x.joint_state is None or np.array_equal(x.joint_state, y.joint_state))
                    for x, y in zip(a.targets, b.targets, strict=True)))


def test_tracker_outputs_read_back_as_written():
    """`tracker_output_from_bytes` reads back what the encoder wrote: arrays for the built-in tracker's
    outputs, a list where the targets differ in stamp or state or lack joint states, poses of either format,
    and a ValueError or DecodeError for a corrupt message."""
    from google.protobuf.message import DecodeError

    from crossview.recording.messages import tracker_output_from_bytes
    from crossview.recording.schemas import TrackerOutputMsg

    encoder = recording.Encoder(COCO17)
    rng = np.random.default_rng(12)
    outputs = make_outputs(rng, 20)
    outputs += [
        TrackerOutput(3.0, "cam03", TargetArrays(np.array([4, 0, 2**40]), rng.normal(size=(3, 17, 3)),
                                                 rng.integers(0, 3, (3, 17)).astype(np.uint8), 3.0),
                      np.array([-1, 4, 2**40, -2**40])),
        TrackerOutput(0.0, "", [
            Target(id=0, pose=np.zeros((17, 3)), stamp_s=0.0, state=TargetState.LOST,
                   joint_state=np.zeros(17, dtype=np.uint8)),
            Target(id=7, pose=np.full((17, 3), np.nan), stamp_s=-1.5, state=TargetState.TENTATIVE)],
            np.zeros(0, dtype=np.int64)),
        TrackerOutput(1.0, "c", [Target(id=-3, pose=np.ones((17, 3)), stamp_s=1.0)], np.zeros(0, dtype=np.int64)),
        TrackerOutput(1.0, "kamera-ü", [], np.array([-1, -1])),
        TrackerOutput(2.0, "c", [Target(id=i, pose=np.ones((17, 3)), stamp_s=2.0, state=state,  # names of one length
                                        joint_state=np.zeros(17, dtype=np.uint8))
                                 for i, state in enumerate((TargetState.CONFIRMED, TargetState.TENTATIVE))],
                      np.zeros(0, dtype=np.int64)),
    ]
    kinds = set()
    for output in outputs:
        read = tracker_output_from_bytes(encoder.tracker_output(output))
        kinds.add(type(read.targets).__name__)
        assert _same_output(read, _as_stored(output))
    assert kinds == {"TargetArrays", "list"}
    f8 = np.float64(1.0).tobytes
    head = b"\x08\x01" + b"\x11" + f8() + b"\x1a\x09confirmed"
    # A format-3 pose (float64, pose_m) is read as written; so is a format-4 one (float32, pose_m32), also split
    # in two runs (valid protobuf).
    for key, dtype in ((b"\x22", np.float64), (b"\x32", np.float32)):
        size = np.dtype(dtype).itemsize
        target = (head + key + bytes([size]) + np.array([1.5], dtype).tobytes() + b"\x2a\x01\x00" + key
                  + bytes([2 * size]) + np.array([2.0, -3.25], dtype).tobytes())
        halves = b"\x09" + f8() + b"\x12\x01c" + b"\x18\x01" + b"\x22" + bytes([len(target)]) + target
        np.testing.assert_array_equal(tracker_output_from_bytes(halves).targets[0].pose, [[1.5, 2.0, -3.25]])
        assert tracker_output_from_bytes(halves).targets[0].pose.dtype == np.float64
    # A pose in both fields is refused, and named.
    both = TrackerOutputMsg(stamp_s=1.0, camera="c", num_joints=1)
    both.targets.add(id=1, pose_m=[1.0, 2.0, 3.0], pose_m32=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="does not hold 1 joints x 3 in one field"):
        tracker_output_from_bytes(both.SerializeToString())
    # A pose of the wrong size is named; every prefix of a message reads as protobuf reads it, or is refused.
    short = TrackerOutputMsg(stamp_s=1.0, camera="c", num_joints=17)
    short.targets.add(id=1, pose_m=[0.0] * 50)
    with pytest.raises(ValueError, match="does not hold 17 joints x 3"):
        tracker_output_from_bytes(short.SerializeToString())
    whole = encoder.tracker_output(outputs[-5])
    refused = 0
    for cut in range(len(whole)):
        try:
            tracker_output_from_bytes(whole[:cut])
        except (DecodeError, ValueError):
            refused += 1
    assert 0 < refused < len(whole)


def test_tracks_of_format_2_are_read_without_joint_states(tmp_path):
    rng = np.random.default_rng(4)
    outputs = [TrackerOutput(o.stamp_s, o.camera, [dataclasses.replace(t, joint_state=None) for t in o.targets],
                             o.detection_target_ids) for o in make_outputs(rng, 10)]
    path = tmp_path / "old.mcap"
    with TracksWriter(path, make_tracks_header(format_version=2), make_cameras(2, rng)) as writer:
        for output in outputs:
            writer.write(output)
        writer.finish({})
    tracks = open_tracks(path)
    assert tracks.header.format_version == 2
    read = [t for out in tracks.outputs() for t in out.targets]
    assert read and all(t.joint_state is None for t in read)


def test_the_tracker_scene_is_protobufs_own_serialisation():
    """The tracks file's skeleton scene (compiled) is Foxglove's SceneUpdate as protobuf writes it, for the
    built-in tracker's arrays and a plug-in's list of targets alike: +0.0 and -0.0 coordinates, unknown joints,
    a negative and a large id, no target."""
    encoder = recording.Encoder(COCO17)
    rng = np.random.default_rng(5)
    poses = rng.normal(size=(3, 17, 3))
    poses[0, 5] = (0.0, -0.0, 1.5)
    poses[1, :4] = np.nan
    poses[2] = np.nan
    ids = np.array([-3, 7, 2**40])
    arrays = TargetArrays(ids, poses, np.zeros((3, 17), np.uint8), 1.0)
    listed = [Target(int(i), pose, 1.0) for i, pose in zip(ids, poses)]
    for targets in (arrays, listed, []):
        output = TrackerOutput(1.0, "cam00", targets, np.zeros(0, np.int64))
        data = encoder.tracker_scene(output, 1_000_000_123)
        assert data == tracker_skeletons(output, COCO17, 1_000_000_123).SerializeToString()
        assert len(SceneUpdate.FromString(data).entities) == len(targets)
