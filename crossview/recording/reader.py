"""Streamed readers of recordings and tracks files: one chunk at a time, CRCs checked, truncated files
read up to their last complete chunk on request."""

from __future__ import annotations

import bisect
import json
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import numpy as np
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from google.protobuf.message import DecodeError
from mcap.exceptions import EndOfFile, McapError
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Message, Metadata, Schema
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk

from core.errors import RecordingError
from core.poses import interpolate_poses
from core.records import CameraFrame, PoseTruth
from core.types import SKELETONS
from crossview.recording.messages import camera_frame_from_msg, pose_truth_from_msg, tracker_output_from_bytes
from crossview.recording.schemas import (
    FORMAT_VERSION,
    KIND_RECORDING,
    KIND_TRACKS,
    MAGIC,
    METADATA_NAME,
    OLDEST_RECORDING_VERSION,
    SUMMARY_METADATA_NAME,
    TOPIC_HEADER,
    TRACKS_FORMAT_VERSION,
    CameraFrameMsg,
    ChannelInfo,
    PoseTruthMsg,
    RecordingHeader,
    TracksHeader,
    box_from_json,
    camera_from_json,
    camera_topic,
    software_version,
)
from tracker.types import TrackerOutput

READ_ERRORS = (McapError, CRCValidationError, UnicodeDecodeError, OSError)
"""What reading a damaged MCAP file raises: the mcap library's documented exceptions (`McapError` and its classes
in `mcap.exceptions`, `mcap.stream_reader.CRCValidationError`), the UnicodeDecodeError of a damaged text field
of a record outside the chunks (which no CRC covers: mcap decodes each as UTF-8 as it reads it) and the
operating system's read errors (a seek to where a corrupt offset points). The readers turn these into a
`RecordingError`; any other exception is a bug and keeps its traceback."""


class FileWithinSize:
    """A binary file whose reads never ask for more than the file holds: a corrupt length field inside a
    record (which mcap's record size limit does not cover) then fails as a short read, instead of allocating
    what the field says (a terabyte). A read that comes back short, and a seek outside the file (a corrupt
    offset), raise mcap's `EndOfFile` there, as mcap does for a read at the end (mcap reads exactly the bytes
    a record needs: less means the file ended inside it). Tells pass through."""

    def __init__(self, f, size: int):
        self._f = f
        self._size = size

    def read(self, n: int = -1) -> bytes:
        left = max(0, self._size - self._f.tell())
        if n is None or n < 0:
            return self._f.read(left)
        data = self._f.read(min(n, left))
        if len(data) < n:
            raise EndOfFile()
        return data

    def seek(self, offset: int, whence: int = 0) -> int:
        target = offset + (0 if whence == 0 else self._f.tell() if whence == 1 else self._size)
        if not 0 <= target <= self._size:
            raise EndOfFile()
        return self._f.seek(target)

    def tell(self) -> int:
        return self._f.tell()

    def seekable(self) -> bool:
        return True

    def readable(self) -> bool:
        return True


class McapStream:
    """Streams one file's records in file order, turning the mcap library's errors (`READ_ERRORS`) into a
    RecordingError."""

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
                f"incomplete); `crossview info --allow-truncated {self.path}` describes its readable prefix"
            )

    def records(self) -> Iterator:
        """Schema, Channel, Message, Metadata records of the data section, in file order."""
        with open(self.path, "rb") as f:
            reader = StreamReader(FileWithinSize(f, self.size), emit_chunks=True, validate_crcs=True,
                                  record_size_limit=max(self.size, 1))
            iterator = iter(reader.records)
            while True:
                try:
                    record = next(iterator)
                    records = chunk_records(record) if isinstance(record, Chunk) else (record,)
                except StopIteration:
                    return
                except READ_ERRORS as e:
                    if self.allow_truncated:
                        return
                    raise RecordingError(f"{self.path}: corrupt MCAP data ({describe_read_error(e)}); `crossview info "
                                         f"{self.path}` names the bad chunk") from None
                if isinstance(record, DataEnd):
                    return
                yield from records


class ChunkDecompressionError(McapError):
    """A chunk whose compressed bytes do not decompress (raised by `chunk_records`, where the decompressor
    fails; an `McapError`, as the mcap library's own errors for a damaged file)."""


DECOMPRESSION_ERRORS = (RuntimeError,)
"""What the decompressor raises for damaged compressed bytes: the chunks are LZ4 frames (`schemas.COMPRESSION`),
and `lz4.frame.decompress` fails with a RuntimeError. Caught only around one chunk's decompression."""


def chunk_records(chunk: Chunk) -> list:
    """The records of one chunk, decompressed and CRC-checked (`mcap.stream_reader.breakup_chunk`).

    Raises:
        ChunkDecompressionError: the compressed bytes do not decompress.
        CRCValidationError: the decompressed bytes are not those written.
    """
    try:  # (only mcap's code runs in here: a RuntimeError is the decompressor's)
        return breakup_chunk(chunk, validate_crc=True)
    except DECOMPRESSION_ERRORS as e:
        raise ChunkDecompressionError(f"the {chunk.compression} chunk does not decompress ({e})") from None


def describe_read_error(e: BaseException) -> str:
    """What one of `READ_ERRORS` says about the file, in a few words."""
    if isinstance(e, CRCValidationError):
        return "CRC mismatch"
    if isinstance(e, EndOfFile):
        return "unexpected end of file"
    return f"{type(e).__name__}: {e}" if str(e) else type(e).__name__


class Container:
    """The common part of a recording and a tracks file: the header document and the channel table."""

    kind: str

    def __init__(self, path, allow_truncated: bool):
        self._stream = McapStream(path, allow_truncated)
        self.path = self._stream.path
        self.truncated = not self._stream.complete
        self.doc = self._read_header()
        try:
            self.skeleton = SKELETONS[self.doc["skeleton"]["name"]]
            self.cameras = [camera_from_json(c) for c in self.doc["cameras"]]
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
        newest = FORMAT_VERSION if kind == KIND_RECORDING else TRACKS_FORMAT_VERSION
        if version > newest:
            raise RecordingError(
                f"{self.path}: format version {version} is newer than this software reads ({newest}); "
                f"upgrade crossview-testbed (this is {software_version()})"
            )

    def _read_header(self) -> dict:
        channels: dict[int, Channel] = {}
        for record in self._stream.records():
            if isinstance(record, Metadata) and record.name == METADATA_NAME:
                self._check(record.metadata.get("kind", "?"), self._version(record.metadata.get("format_version", 0)))
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message) and channels.get(record.channel_id, None) is not None \
                    and channels[record.channel_id].topic == TOPIC_HEADER:
                doc = json_object(record.data, f"{self.path}: unreadable crossview header")
                if "kind" not in doc or "format_version" not in doc:
                    raise RecordingError(f"{self.path}: unreadable crossview header (it names no kind and "
                                         "format_version)")
                self._check(doc["kind"], self._version(doc["format_version"]))
                return doc
        raise RecordingError(f"{self.path}: no {TOPIC_HEADER} message; not a crossview {self.kind} file")

    def _version(self, value) -> int:
        """A header's format_version (an integer, or its decimal text in the metadata record)."""
        try:
            return int(value)
        except (TypeError, ValueError):
            raise RecordingError(f"{self.path}: unreadable crossview header (format_version {value!r} is not an "
                                 "integer)") from None

    def channel_infos(self) -> list[ChannelInfo]:
        """Every channel of the file, from its summary section (one seek)."""
        try:
            with open(self.path, "rb") as f:
                summary = make_reader(FileWithinSize(f, self._stream.size)).get_summary()
        except READ_ERRORS as e:
            raise RecordingError(f"{self.path}: unreadable summary section ({describe_read_error(e)})") from None
        if summary is None:
            raise RecordingError(f"{self.path}: no summary section (a complete crossview file has one)")
        try:
            return [ChannelInfo(c.topic, c.message_encoding, summary.schemas[c.schema_id].name,
                                summary.schemas[c.schema_id].encoding, summary.schemas[c.schema_id].data)
                    for c in summary.channels.values()]
        except KeyError as e:
            raise RecordingError(f"{self.path}: a channel names schema {e}, which the summary does not hold") from None

    def raw(self) -> Iterator[tuple[ChannelInfo, int, bytes]]:
        """Every message of the file as written: (its channel, log time ns, bytes), in file order (log-time
        order), CRC-checked; what `crossview serve` publishes."""
        schemas: dict[int, Schema] = {}
        channels: dict[int, ChannelInfo] = {}
        for record in self._stream.records():
            if isinstance(record, Message):
                info = channels.get(record.channel_id)
                if info is None:
                    raise RecordingError(f"{self.path}: a message on channel {record.channel_id}, which the file does "
                                         "not declare before it")
                yield info, record.log_time, record.data
            elif isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                schema = schemas.get(record.schema_id)
                if schema is None:
                    raise RecordingError(f"{self.path}: channel {record.topic} names schema {record.schema_id}, "
                                         "which the file does not declare before it")
                channels[record.id] = ChannelInfo(record.topic, record.message_encoding, schema.name,
                                                  schema.encoding, schema.data)

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


class CameraImage(NamedTuple):
    """A picture of a camera's `image` topic: its camera, log time (ns), format ("png", "jpeg") and bytes."""

    camera: str
    log_time_ns: int
    format: str
    data: bytes


class Recording(Container):
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
            self.boxes = tuple(box_from_json(b) for b in d["boxes"])
        except (KeyError, TypeError, ValueError) as e:
            raise RecordingError(f"{self.path}: unreadable recording header ({e})") from None

    def _events(self, names: set[str], with_poses: bool = False) -> Iterator[PoseTruth | CameraFrame]:
        window = _TruthWindow(self.truth, self.skeleton.num_joints) if with_poses else None
        for name, record in self._messages(names):
            if name == "crossview.PoseTruth":
                event = self._decode(lambda b: pose_truth_from_msg(PoseTruthMsg.FromString(b)), record.data)
            else:
                event = self._decode(lambda b: CameraFrameMsg.FromString(b), record.data)
                if event is not None:
                    event = camera_frame_from_msg(event, window.at(event.capture_s) if window else None)
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

    def images(self) -> Iterator[CameraImage]:
        """The pictures of the cameras' `image` topics in file order: each camera's grey backdrop at 0 and, in
        a recording made with `crossview generate --images`, the rendered JPEG pictures of its frames."""
        topics = {camera_topic(c.name, "image"): c.name for c in self.cameras}
        camera_of: dict[int, str] = {}
        for record in self._stream.records():
            if isinstance(record, Channel) and record.topic in topics:
                camera_of[record.id] = topics[record.topic]
            elif isinstance(record, Message) and record.channel_id in camera_of:
                image = self._decode(CompressedImage.FromString, record.data)
                if image is None:
                    return
                yield CameraImage(camera_of[record.channel_id], record.log_time, image.format, image.data)


class _TruthWindow:
    """Everybody's true pose at any capture time of a recording, derived from its truth ticks by
    `core.poses.interpolate_poses`: the rule and the arithmetic the simulator used for the frames'
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


class Tracks(Container):
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
        self.summary: dict = read_summary(self.path) if not self.truncated else {}

    def outputs(self) -> Iterator[TrackerOutput]:
        for _, record in self._messages({"crossview.TrackerOutput"}):
            output = self._decode(tracker_output_from_bytes, record.data)
            if output is None:
                return
            yield output


def json_object(data: bytes | str, where: str) -> dict:
    """The JSON object a header or summary stores; a RecordingError starting with `where` when it is none."""
    try:
        doc = json.loads(data)
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise RecordingError(f"{where} (not JSON: {e})") from None
    if not isinstance(doc, dict):
        raise RecordingError(f"{where} (a {type(doc).__name__}, not an object)")
    return doc


def read_summary(path: Path) -> dict:
    """The summary metadata written at close, found through the file's summary section (one seek)."""
    try:
        with open(path, "rb") as f:
            for metadata in make_reader(FileWithinSize(f, path.stat().st_size)).iter_metadata():
                if metadata.name == SUMMARY_METADATA_NAME:
                    return json_object(metadata.metadata.get("json", ""), f"{path}: unreadable summary section")
    except READ_ERRORS as e:
        raise RecordingError(f"{path}: unreadable summary section ({describe_read_error(e)})") from None
    return {}


def read_kind(path, allow_truncated: bool = False) -> str:
    """The kind of a crossview file (`KIND_RECORDING` or `KIND_TRACKS`) from its metadata record; RecordingError
    for an MCAP file that is neither (or a file that is not MCAP)."""
    stream = McapStream(path, allow_truncated)
    for record in stream.records():
        if isinstance(record, Metadata) and record.name == METADATA_NAME:
            kind = record.metadata.get("kind")
            if kind in (KIND_RECORDING, KIND_TRACKS):
                return kind
            break
    raise RecordingError(f"{stream.path}: an MCAP file, but not a crossview recording or tracks file")


def open_recording(path, allow_truncated: bool = False) -> Recording:
    """Opens a recording. Raises RecordingError for a file that is not MCAP, truncated (unless
    `allow_truncated`), corrupt, of a newer format version, or a tracks file."""
    return Recording(path, allow_truncated)


def open_tracks(path, allow_truncated: bool = False) -> Tracks:
    """Opens a tracks file; the same errors as `open_recording`, and a recording given here is one."""
    return Tracks(path, allow_truncated)


# --------------------------------------------------------------------------------------------------
# info.
