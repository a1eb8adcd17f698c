"""An independent Foxglove WebSocket client for the live view's tests: the `websockets` package speaking the
protocol itself (subprotocol foxglove.sdk.v1, else foxglove.websocket.v1), none of the project's code and none of
foxglove-sdk's. It subscribes to every channel the server advertises, decodes every message with the schema
advertised for its channel (protobuf FileDescriptorSet, or JSON for a jsonschema channel), and keeps (log time,
bytes) per (topic, schema name)."""

from __future__ import annotations

import asyncio
import base64
import json
import re
import struct
import time
from collections import defaultdict

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
OP_MESSAGE_DATA = 1  # server binary opcodes of the protocol
OP_TIME = 2
OP_PLAYBACK_CONTROL = 3  # client binary opcode


def _decoder(channel: dict):
    """A function bytes -> decoded message for an advertised channel, from its schema alone."""
    if channel["encoding"] == "json":
        return lambda data: json.loads(data)
    assert channel["encoding"] == "protobuf", channel
    files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for f in files.file:
        pool.Add(f)
    message_class = message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))
    return message_class.FromString


def play_request(speed: float = 1.0, seek_ns: int | None = None, request_id: str = "test") -> bytes:
    """A playback control request: opcode, command (0 play), speed (f32), had seek, seek time (u64), request id."""
    rid = request_id.encode()
    return struct.pack("<BBfBQI", OP_PLAYBACK_CONTROL, 0, speed, seek_ns is not None, seek_ns or 0, len(rid)) + rid


async def _collect(url: str, expected: int | None, quiet_s: float, timeout_s: float, play: bool,
                   read_delay_s: float, play_speed: float, seek_ns: int | None, arrivals: list | None) -> dict:
    received: dict[tuple[str, str], list[tuple[int, bytes]]] = defaultdict(list)
    channels: dict[int, dict] = {}
    decoders: dict[int, object] = {}
    count = 0
    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosed

    async with connect(url, subprotocols=SUBPROTOCOLS, max_size=None) as ws:
        assert ws.subprotocol in SUBPROTOCOLS
        deadline = time.monotonic() + timeout_s
        played = False
        while time.monotonic() < deadline and (expected is None or count < expected):
            try:
                message = await asyncio.wait_for(ws.recv(), quiet_s if count else timeout_s)
            except (TimeoutError, ConnectionClosed):  # (the server stopped: the run ended)
                break
            if isinstance(message, str):
                doc = json.loads(message)
                unknown = re.fullmatch(r"Unknown channel ID: (\d+)", doc.get("message", "")) if doc["op"] == "status" \
                    else None
                if unknown and int(unknown[1]) in channels:  # (foxglove-sdk 0.30 can refuse a subscription to a
                    await asyncio.sleep(0.05)  # channel it has just advertised; asking again gets it)
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                        {"id": int(unknown[1]), "channelId": int(unknown[1])}]}))
                if doc["op"] == "advertise":
                    new = [c for c in doc["channels"] if c["id"] not in channels]
                    for channel in new:
                        channels[channel["id"]] = channel
                        decoders[channel["id"]] = _decoder(channel)
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                        {"id": c["id"], "channelId": c["id"]} for c in new]}))
                    if play and not played:
                        await ws.send(play_request(play_speed, seek_ns))
                        played = True
                continue
            if message[0] != OP_MESSAGE_DATA:
                continue
            subscription, log_time = struct.unpack_from("<IQ", message, 1)
            data = bytes(message[13:])
            decoders[subscription](data)  # (raises on bytes the advertised schema does not describe)
            channel = channels[subscription]
            received[(channel["topic"], channel["schemaName"])].append((log_time, data))
            if arrivals is not None:
                arrivals.append((channel["topic"], channel["schemaName"]))
            count += 1
            if read_delay_s:
                await asyncio.sleep(read_delay_s)
    return dict(received)


def collect(url: str, *, expected: int | None = None, quiet_s: float = 3.0, timeout_s: float = 60.0,
            play: bool = False, play_speed: float = 1.0, seek_ns: int | None = None, read_delay_s: float = 0.0,
            arrivals: list | None = None) -> dict:
    """Connects to `url` and returns {(topic, schema name): [(log time ns, bytes), ...]} of what it received, until
    `expected` messages came, none came for `quiet_s` after the first, or `timeout_s`. With `play`, asks a replay
    server to play at `play_speed` once subscribed, from `seek_ns` when given; `read_delay_s` after each message makes
    a slow client. `arrivals`, when given, gets the (topic, schema name) of each message in the order they came."""
    return asyncio.run(_collect(url, expected, quiet_s, timeout_s, play, read_delay_s, play_speed, seek_ns, arrivals))
