"""The recording and tracks file formats (MCAP): atomic writers, streamed readers, `info`.

This package is the only part of the project that imports `mcap`. The format is described channel by
channel in docs/recording-format.md; in short:

- A *recording* holds a JSON header (scenario text, seed, software and format version, cameras, store
  boxes), the 100 Hz ground truth (`crossview.PoseTruth`) and one `crossview.CameraFrame` per delivered
  camera frame (detections, scores, per-detection truth), plus Foxglove channels for people to look at
  (store, frusta, calibrations, skeletons, 2D detections).
- A *tracks file* holds a JSON header (the recording's scenario digest and seed, the tracker method,
  preset and config), one `crossview.TrackerOutput` per processed frame, the tracker's skeletons as a
  Foxglove `SceneUpdate`, and a summary (tracker seconds, updates) written at the end.

Program data use compact protobuf schemas built at run time from a FileDescriptorProto (packed doubles, so
every float round-trips bit for bit). Log times are integer nanoseconds since the scenario start,
converted from float seconds only in `to_ns`. Messages are written in log-time order, so file order is
log-time order and reading streams one chunk at a time. The same inputs and software give the same bytes:
no wall-clock time is written, chunk size and compression are fixed.

Modules: `schemas` (topics, schemas, headers, versions), `messages` (message bytes), `writer`, `reader`,
`info`. The names below are the package's interface.
"""

from core.errors import RecordingError
from crossview.recording.info import format_info, info
from crossview.recording.messages import EncodedFrame, Encoder, camera_frame_from_bytes
from crossview.recording.reader import CameraImage, Recording, Tracks, open_recording, open_tracks
from crossview.recording.schemas import (  # a store box's JSON form, as the header's
    CHUNK_SIZE,
    FORMAT_VERSION,
    TOPIC_HEADER,
    TOPIC_OUTPUTS,
    TOPIC_STORE,
    TOPIC_TRACK_SCENE,
    TOPIC_TRUTH,
    TOPIC_TRUTH_SCENE,
    TRACKS_FORMAT_VERSION,
    ChannelInfo,
    LiveSink,
    PoseTruthMsg,
    RecordingHeader,
    TracksHeader,
    box_from_json,
    box_json,
    camera_from_json,
    camera_json,
    camera_topic,
    software_version,
    to_ns,
)
from crossview.recording.writer import RecordingWriter, TracksWriter

__all__ = [
    "CHUNK_SIZE", "FORMAT_VERSION", "TRACKS_FORMAT_VERSION", "TOPIC_HEADER", "TOPIC_OUTPUTS", "TOPIC_STORE",
    "TOPIC_TRACK_SCENE", "TOPIC_TRUTH", "CameraImage", "ChannelInfo", "LiveSink",
    "TOPIC_TRUTH_SCENE", "EncodedFrame", "Encoder", "PoseTruthMsg", "Recording", "RecordingError", "RecordingHeader",
    "RecordingWriter", "Tracks", "TracksHeader", "TracksWriter", "box_from_json", "box_json",
    "camera_frame_from_bytes", "camera_from_json", "camera_json", "camera_topic",
    "format_info", "info", "open_recording", "open_tracks", "software_version", "to_ns",
]
