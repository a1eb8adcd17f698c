"""Atomic writers of recordings and tracks files, through mcap's public `Writer`: a temporary file in the
target folder, fsynced and renamed onto the final name only when complete."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from mcap.writer import Writer

import crossview.recording.foxglove as foxglove
from core.records import Box, CameraFrame, DetectionRows, PoseTruth
from core.stream import Block, LogTimeOrder, frame_times
from core.types import SKELETONS, Camera
from crossview.outputs import AtomicOutput
from crossview.recording.messages import EncodedFrame, Encoder
from crossview.recording.schemas import (
    CHUNK_SIZE,
    COMPRESSION,
    HEADER_JSON_SCHEMAS,
    KIND_RECORDING,
    KIND_TRACKS,
    METADATA_NAME,
    SUMMARY_METADATA_NAME,
    TOPIC_HEADER,
    TOPIC_OUTPUTS,
    TOPIC_STORE,
    TOPIC_TF,
    TOPIC_TRACK_SCENE,
    TOPIC_TRUTH,
    TOPIC_TRUTH_SCENE,
    TRACK_SCENE_PERIOD_S,
    TRUTH_SCENE_PERIOD_S,
    CameraFrameMsg,
    ChannelInfo,
    LiveSink,
    PoseTruthMsg,
    RecordingHeader,
    TrackerOutputMsg,
    TracksHeader,
    box_json,
    camera_json,
    camera_topic,
    compact_json,
    skeleton_json,
    to_ns,
)
from tracker.types import TargetArrays, TrackerOutput


class _AtomicMcapWriter:
    """An MCAP writer onto an `AtomicOutput`: the file appears under `path` only when `close` completes.
    With `live`, every message written is also published there (`LiveSink`); the file's bytes are the same."""

    def __init__(self, path, kind: str, header_doc: dict, metadata: dict[str, str], chunk_size: int,
                 inputs: tuple = (), live: LiveSink | None = None):
        self._file = AtomicOutput(path, inputs)
        self.path = self._file.path
        self._live = live
        self._live_channels: dict[int, object] = {}
        try:
            self._writer = Writer(
                self._file, chunk_size=chunk_size, compression=COMPRESSION, enable_data_crcs=True,
            )
            self._writer.start(profile="", library=f"crossview-testbed {header_doc['software_version']}")
            # The flat metadata record lands before the first chunk, so kind and version are read first.
            self._writer.add_metadata(METADATA_NAME, metadata)
            self._schemas: dict[str, int] = {}
            header_channel = self.channel(TOPIC_HEADER, "json", f"crossview.{kind.capitalize()}Header",
                                          "jsonschema", compact_json(HEADER_JSON_SCHEMAS[kind]))
            self.add(header_channel, 0, compact_json(header_doc))
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
        channel_id = self._writer.register_channel(topic=topic, message_encoding=message_encoding, schema_id=schema_id)
        if self._live is not None:
            self._live_channels[channel_id] = self._live.channel(
                ChannelInfo(topic, message_encoding, schema_name, schema_encoding, schema_data))
        return channel_id

    def protobuf_channel(self, topic: str, message_class) -> int:
        descriptor = message_class.DESCRIPTOR
        return self.channel(topic, "protobuf", descriptor.full_name, "protobuf",
                            foxglove.file_descriptor_set(descriptor))

    def end_chunk(self) -> None:
        """Closes the chunk in progress, so that what came before survives a truncation after it."""
        self._writer.flush()

    def add(self, channel_id: int, log_time_ns: int, data: bytes) -> None:
        self._writer.add_message(channel_id=channel_id, log_time=log_time_ns, data=data, publish_time=log_time_ns)
        if self._live is not None:
            self._live.publish(self._live_channels[channel_id], log_time_ns, data)

    def add_many(self, messages: Sequence[tuple[int, int, bytes]]) -> None:
        """`add` of each (channel id, log time ns, data) in turn."""
        add = self._writer.add_message
        for channel_id, t, data in messages:
            add(channel_id, t, data, t)
        if self._live is not None:
            for channel_id, t, data in messages:
                self._live.publish(self._live_channels[channel_id], t, data)

    def close(self, summary_metadata: dict[str, str]) -> None:
        """Finishes the file, fsyncs it and renames it onto the final path."""
        try:
            self._writer.add_metadata(SUMMARY_METADATA_NAME, summary_metadata)
            self._writer.finish()
        except BaseException:
            self.abort()
            raise
        self._file.commit()

    def abort(self) -> None:
        """Drops the temporary file; nothing appears under the final name."""
        self._file.abort()


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
    """Writes a recording atomically, in log-time order (truth at t_s, frames at delivery_s), which makes the
    file streamable in that order: either a simulation's blocks, which the writer puts in that order itself
    (`write_block`), or events that come in that order (`write`, `write_many`).

    Use as a context manager: the file appears under `path` only when the block exits cleanly; on an
    exception (KeyboardInterrupt included) the temporary file is removed.

    With `frames_to` (an argument or set later), each camera frame's `crossview.CameraFrame` message (the bytes
    the file holds) is also given to it as soon as that frame's messages are written (and published to `live`),
    in the file's order: how `run --live` tracks the frames while they are made (`crossview.pipeline.Tracking`).
    """

    def __init__(self, path, header: RecordingHeader, cameras: Sequence[Camera], boxes: Sequence[Box], *,
                 chunk_size: int = CHUNK_SIZE, inputs: tuple = (), live: LiveSink | None = None,
                 frames_to: Callable[[bytes], None] | None = None):
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
            "skeleton": skeleton_json(self.skeleton),
            "scenario_text": header.scenario_text,
            "cameras": [camera_json(c) for c in self.cameras],
            "boxes": [box_json(b) for b in self.boxes],
        }
        self.encoder = Encoder(self.skeleton)
        self.encoder.warm_up()  # (before the file opens: `Encoder.warm_up`)
        self._out = _AtomicMcapWriter(path, KIND_RECORDING, doc, _flat_metadata(KIND_RECORDING, header), chunk_size,
                                     inputs, live)
        try:
            out = self._out
            self._tf = out.protobuf_channel(TOPIC_TF, foxglove.FrameTransforms)
            self._store = out.protobuf_channel(TOPIC_STORE, foxglove.SceneUpdate)
            self._truth = out.protobuf_channel(TOPIC_TRUTH, PoseTruthMsg)
            self._truth_scene = out.protobuf_channel(TOPIC_TRUTH_SCENE, foxglove.SceneUpdate)
            self._frame_ch, self._annotation_ch, self._image_ch = {}, {}, {}
            for camera in self.cameras:
                calibration = out.protobuf_channel(camera_topic(camera.name, "calibration"),
                                                   foxglove.CameraCalibration)
                self._frame_ch[camera.name] = out.protobuf_channel(camera_topic(camera.name, "frame"), CameraFrameMsg)
                self._annotation_ch[camera.name] = out.protobuf_channel(
                    camera_topic(camera.name, "detections"), foxglove.ImageAnnotations)
                image = out.protobuf_channel(camera_topic(camera.name, "image"), foxglove.CompressedImage)
                self._image_ch[camera.name] = image
                out.add(calibration, 0, foxglove.camera_calibration(camera, 0).SerializeToString())
                out.add(image, 0, foxglove.camera_backdrop(camera, 0).SerializeToString())
            out.add(self._tf, 0, foxglove.frame_transforms(self.cameras, 0).SerializeToString())
            out.add(self._store, 0, foxglove.store_scene(self.boxes, self.cameras, 0).SerializeToString())
            out.end_chunk()  # the header and the static scene get a chunk of their own
        except BaseException:
            self._out.abort()
            raise
        self._last_ns = 0
        self._next_scene_ns = 0
        self._people: set[int] = set()
        self._counts = {"truth": 0, "frames": 0, "images": 0}
        self._camera_of = {c.name: c for c in self.cameras}
        self._order = LogTimeOrder()  # the blocks' truth ticks and encoded frames not yet due
        self.frames_to = frames_to

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
        in one compiled call (`Encoder.camera_frames`): what a producer of many events at a time should use."""
        encoded = iter(self.encoder.camera_frames([e for e in events if isinstance(e, CameraFrame)]))
        messages = []
        written: list[tuple[int, bytes]] = []  # (messages up to and with a frame's, its CameraFrame bytes)
        for event in events:
            if isinstance(event, CameraFrame):
                event = next(encoded)
            if isinstance(event, EncodedFrame):
                frame_channel = self._frame_ch.get(event.camera)
                if frame_channel is None:
                    raise ValueError(f"CameraFrame: camera {event.camera!r} is not one of the recording's cameras")
                t = self._log_time(event.log_time_ns, f"CameraFrame {event.camera}")
                messages.append((frame_channel, t, event.frame_bytes))
                messages.append((self._annotation_ch[event.camera], t, event.annotations))
                if event.image is not None:
                    picture = foxglove.camera_image(self._camera_of[event.camera], t, event.image)
                    messages.append((self._image_ch[event.camera], t, picture.SerializeToString()))
                    self._counts["images"] += 1
                self._counts["frames"] += 1
                written.append((len(messages), event.frame_bytes))
            elif isinstance(event, PoseTruth):
                t = self._log_time(to_ns(event.t_s), "PoseTruth")
                messages.append((self._truth, t, self.encoder.pose_truth(event)))
                if t >= self._next_scene_ns:
                    messages.append((self._truth_scene, t, self.encoder.truth_scene(event, t)))
                    self._next_scene_ns = t + to_ns(TRUTH_SCENE_PERIOD_S)
                self._people.update(np.asarray(event.person_ids).tolist())
                self._counts["truth"] += 1
            else:
                raise TypeError(f"RecordingWriter.write: expected PoseTruth, CameraFrame or EncodedFrame, got "
                                f"{type(event).__name__}")
        if self.frames_to is None:
            self._out.add_many(messages)
            return
        start = 0
        for end, frame in written:  # (each frame goes on once its own messages are out, before the next's)
            self._out.add_many(messages[start:end])
            self.frames_to(frame)
            start = end
        self._out.add_many(messages[start:])

    def write_block(self, block: Block, images: Sequence[bytes | None] | None = None) -> int:
        """Takes a simulation's next block (`sim.simulate.Simulation.blocks`): encodes its frames straight from
        the detector's rows (`Encoder.frames`, no CameraFrame objects in between) and writes whatever of the
        recording is now due, in log-time order (`core.stream.LogTimeOrder`); the rest waits for the next
        blocks, or `close`. Returns the number of the block's frames.

        Args:
            block: the block after the previous one written; its detections drawn.
            images: per capture request of the block, its rendered JPEG picture or None (`--images`).
        """
        requests = block.requests
        frames: list = []
        if requests:  # (a block can hold no capture at all: a short last block, a slow or dropping clock)
            frames = self.encode_frames([r.camera for r in requests], frame_times(requests), block.bounds, block.rows)
        if images is not None:
            frames = [f if p is None else f._replace(image=p) for f, p in zip(frames, images, strict=True)]
        self.write_many(self._order.add(block, frames))
        return len(frames)

    def encode_frames(self, cameras: Sequence[int], times: np.ndarray, bounds: np.ndarray,
                      rows: DetectionRows) -> list[EncodedFrame]:
        """`Encoder.frames` of frames from this recording's cameras, given by index; `times` (n, 3) in the columns
        of `core.stream.frame_times`."""
        return self.encoder.frames([self.cameras[i].name for i in cameras], times, bounds, rows)

    def close(self) -> None:
        try:
            self.write_many(self._order.rest())  # (the blocks' frames delivered after the last tick)
        except BaseException:
            self.abort()
            raise
        summary = {
            "num_people": len(self._people),
            "num_truth": self._counts["truth"],
            "num_frames": self._counts["frames"],
            "end_s": self._last_ns / 1e9,
        }
        if self._counts["images"]:  # (only then: a recording without pictures keeps its bytes)
            summary["num_images"] = self._counts["images"]
        self._out.close({"json": compact_json(summary).decode()})



class TracksWriter(_WriterContext):
    """Writes a tracks file atomically: one TrackerOutput per processed frame, in processing order.

    The log time of an output is its stamp (clamped at 0: a camera clock may stamp a frame slightly
    before the scenario start; the exact stamp is in the message). Call `finish(summary)` before the
    block ends to record tracker timings.
    """

    def __init__(self, path, header: TracksHeader, cameras: Sequence[Camera], *, chunk_size: int = CHUNK_SIZE,
                 inputs: tuple = (), live: LiveSink | None = None):
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
            "skeleton": skeleton_json(self.skeleton),
            "cameras": [camera_json(c) for c in self.cameras],
        }
        try:
            compact_json(header.config)
        except (TypeError, ValueError) as e:
            raise ValueError(f"TracksHeader.config: must be JSON-serialisable without NaN: {e}") from None
        self.encoder = Encoder(self.skeleton)
        self.encoder.warm_up()  # (before the file opens: `Encoder.warm_up`)
        self._out = _AtomicMcapWriter(path, KIND_TRACKS, doc, _flat_metadata(KIND_TRACKS, header), chunk_size, inputs,
                                      live)
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
        self._out.add(self._outputs, t_ns, self.encoder.tracker_output(output))
        if t_ns >= self._next_scene_ns:
            self._out.add(self._scene, t_ns, self.encoder.tracker_scene(output, t_ns))
            self._next_scene_ns = t_ns + to_ns(TRACK_SCENE_PERIOD_S)
        targets = output.targets
        self._targets.update(targets.ids.tolist() if isinstance(targets, TargetArrays) else
                             (int(t.id) for t in targets))
        self._count += 1

    def finish(self, summary: dict) -> None:
        """Records the run's summary (e.g. tracker_s, updates, num_cameras); written when the file closes."""
        try:
            compact_json(summary)
        except (TypeError, ValueError) as e:
            raise ValueError(f"tracks summary: must be JSON-serialisable without NaN: {e}") from None
        self._summary = dict(summary)

    def close(self) -> None:
        summary = {"num_outputs": self._count, "num_targets": len(self._targets)} | self._summary
        self._out.close({"json": compact_json(summary).decode()})



# --------------------------------------------------------------------------------------------------
# Reading.
