"""`crossview info`: what a recording or tracks file holds, from its summary section, after every chunk's
CRC is checked."""

from __future__ import annotations

from pathlib import Path

from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message
from mcap.stream_reader import StreamReader

from core.errors import RecordingError
from crossview.recording.reader import (
    READ_ERRORS,
    Container,
    FileWithinSize,
    McapStream,
    Recording,
    Tracks,
    chunk_records,
    describe_read_error,
    read_kind,
    read_summary,
)
from crossview.recording.schemas import (
    KIND_RECORDING,
    TOPIC_OUTPUTS,
    TOPIC_TRUTH,
    PoseTruthMsg,
    TrackerOutputMsg,
)


def check_chunks(path) -> int:
    """Reads every record of a complete file, decompressing each chunk and checking its CRC (and the data
    section's), without decoding the messages.

    Returns:
        The number of chunks.

    Raises:
        RecordingError: naming the bad chunk (its number, byte range and message times) or the byte
            offset of the bad record.
    """
    path = Path(path)
    chunks = 0
    with open(path, "rb") as f:
        size = path.stat().st_size
        reader = StreamReader(FileWithinSize(f, size), emit_chunks=True, validate_crcs=True,
                              record_size_limit=max(size, 1))
        records = iter(reader.records)
        start = f.tell()  # where the next record begins (the reader reads exactly what it needs)
        while True:
            try:
                record = next(records)
            except StopIteration:
                return chunks
            except READ_ERRORS as e:
                raise RecordingError(f"{path}: corrupt MCAP data in the record at byte {start:,} (after chunk "
                                     f"{chunks}; {describe_read_error(e)})") from None
            end = f.tell()
            if isinstance(record, Chunk):
                try:
                    chunk_records(record)
                except READ_ERRORS as e:
                    first_s, last_s = record.message_start_time / 1e9, record.message_end_time / 1e9
                    raise RecordingError(f"{path}: chunk {chunks} (bytes {start:,}..{end:,}, messages {first_s:.3f}"
                                         f"..{last_s:.3f} s) is corrupt ({describe_read_error(e)})") from None
                chunks += 1
            start = end


def info(path, allow_truncated: bool = False, check: bool = True) -> dict:
    """What `crossview info` prints: kind, duration, cameras, people, messages per channel, size, chunks.

    A complete file is first read through, every chunk's CRC checked (`check_chunks`; skipped with
    `check` False), then described from its summary section; a truncated one (with `allow_truncated`)
    by streaming its readable prefix.
    """
    stream = McapStream(path, allow_truncated)
    kind = read_kind(path, allow_truncated)
    opener = Recording if kind == KIND_RECORDING else Tracks
    container: Container = opener(path, allow_truncated)
    doc = container.doc
    counts: dict[str, int] = {}
    start_ns = end_ns = None
    summary: dict = {}
    chunks = None  # checked chunks (None: not checked)
    if stream.complete:
        if check:
            chunks = check_chunks(stream.path)
        try:
            with open(stream.path, "rb") as f:
                mcap_summary = make_reader(FileWithinSize(f, stream.size)).get_summary()
        except READ_ERRORS as e:
            raise RecordingError(f"{stream.path}: unreadable summary section ({describe_read_error(e)})") from None
        if mcap_summary is None or mcap_summary.statistics is None:
            raise RecordingError(f"{stream.path}: MCAP file without a summary section")
        stats = mcap_summary.statistics
        for channel_id, channel in sorted(mcap_summary.channels.items()):
            counts[channel.topic] = stats.channel_message_counts.get(channel_id, 0)
        start_ns, end_ns = stats.message_start_time, stats.message_end_time
        summary = read_summary(stream.path)
        people = summary.get("num_people" if kind == KIND_RECORDING else "num_targets")
    else:
        topics: dict[int, str] = {}
        ids: set[int] = set()
        for record in stream.records():
            if isinstance(record, Channel):
                topics[record.id] = record.topic
                counts.setdefault(record.topic, 0)
            elif isinstance(record, Message):
                topic = topics.get(record.channel_id, f"#{record.channel_id}")
                counts[topic] = counts.get(topic, 0) + 1
                start_ns = record.log_time if start_ns is None else min(start_ns, record.log_time)
                end_ns = record.log_time if end_ns is None else max(end_ns, record.log_time)
                if topic == TOPIC_TRUTH:
                    ids.update(PoseTruthMsg.FromString(record.data).person_ids)
                elif topic == TOPIC_OUTPUTS:
                    ids.update(t.id for t in TrackerOutputMsg.FromString(record.data).targets)
        people = len(ids)
    result = {
        "path": str(stream.path),
        "kind": kind,
        "format_version": doc["format_version"],
        "software_version": doc["software_version"],
        "scenario_name": doc["scenario_name"],
        "scenario_digest": doc["scenario_digest"],
        "seed": doc["seed"],
        "skeleton": doc["skeleton"]["name"],
        "size_bytes": stream.size,
        "truncated": not stream.complete,
        "chunks_checked": chunks,
        "start_s": (start_ns or 0) / 1e9,
        "end_s": (end_ns or 0) / 1e9,
        "duration_s": ((end_ns or 0) - (start_ns or 0)) / 1e9,
        "cameras": [c["name"] for c in doc["cameras"]],
        "people" if kind == KIND_RECORDING else "targets": people,
        "messages": counts,
    }
    if kind == KIND_RECORDING:
        frames = sum(n for topic, n in counts.items() if topic.startswith("/cameras/") and topic.endswith("/frame"))
        result["camera_frames"] = frames
        result["bytes_per_camera_frame"] = stream.size / frames if frames else None
        result["scenario_duration_s"] = doc["duration_s"]
        result["boxes"] = len(doc["boxes"])
    else:
        result["method"] = doc["method"]
        result["preset"] = doc["preset"]
        result["summary"] = summary
    return result


def format_info(d: dict) -> str:
    """`info` as the lines `crossview info` prints."""
    lines = [
        f"{d['path']}: crossview {d['kind']}, format version {d['format_version']}, "
        f"written by crossview-testbed {d['software_version']}" + ("  [TRUNCATED: readable prefix only]"
                                                                    if d["truncated"] else ""),
        f"  scenario   {d['scenario_name']}  seed {d['seed']}  digest {d['scenario_digest'][:12]}",
        f"  size       {d['size_bytes']:,} bytes"
        + (f" ({d['bytes_per_camera_frame']:,.0f} per camera-frame)" if d.get("bytes_per_camera_frame") else ""),
        f"  time       {d['start_s']:.3f} .. {d['end_s']:.3f} s  (duration {d['duration_s']:.3f} s)",
        f"  cameras    {len(d['cameras'])}: {', '.join(d['cameras'])}",
    ]
    if d["kind"] == KIND_RECORDING:
        lines.append(f"  people     {d['people']}, camera-frames {d['camera_frames']:,}")
        lines.append(f"  boxes      {d['boxes']}")
    else:
        lines.append(f"  tracker    {d['method']} (preset {d['preset']}), {d['targets']} target ids")
        if d.get("summary"):
            lines.append("  summary    " + ", ".join(f"{k}={v}" for k, v in d["summary"].items()))
    lines.append(f"  skeleton   {d['skeleton']}")
    if d.get("chunks_checked") is not None:
        lines.append(f"  integrity  {d['chunks_checked']} chunks read, every CRC matches")
    lines.append(f"  messages   {sum(d['messages'].values()):,} on {len(d['messages'])} channels")
    # Per-camera channels are summed over the cameras: /cameras/*/frame and so on.
    grouped: dict[str, list[int]] = {}
    for topic, n in d["messages"].items():
        parts = topic.split("/")
        key = f"/cameras/*/{parts[3]}" if len(parts) == 4 and parts[1] == "cameras" else topic
        grouped.setdefault(key, []).append(n)
    width = max((len(t) for t in grouped), default=0)
    for topic, ns in grouped.items():
        per = f"  ({len(ns)} channels)" if "*" in topic else ""
        lines.append(f"    {topic:<{width}}  {sum(ns):>9,}{per}")
    return "\n".join(lines)
