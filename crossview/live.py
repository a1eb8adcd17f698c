"""The live view: a Foxglove WebSocket server (foxglove-sdk, the `live` extra) that publishes a recording's own
channels, schemas and message bytes while `run --live` or `generate --live` writes them, or replays finished files
(`crossview serve`) with Foxglove's play, pause, seek and speed controls.

What a client receives is what the file holds: the writers hand every message they write to a `Paced` stream
(`crossview.recording.LiveSink`), which publishes it paced to simulated time by `speed` (1 = real time, `math.inf`
= as fast as the run goes). The SDK queues each client's messages on its own threads and drops a slow client's
oldest once its queue (`BACKLOG` messages) is full, so a slow or vanished client never slows or stops the run.
This module knows nothing of MCAP: `crossview.recording` reads and writes the files.
"""

from __future__ import annotations

import argparse
import heapq
import math
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from core.errors import CrossviewError

if TYPE_CHECKING:  # (the CLI imports this module to build its parser: nothing heavy here)
    from crossview.recording import ChannelInfo

EXTRA = "pip install 'crossview-testbed[live]'"
DEFAULT_PORT = 8765  # Foxglove's default for a WebSocket connection
HOST = "127.0.0.1"
BACKLOG = 1024  # messages a client's queue holds before the SDK drops its oldest (the SDK's default)
SUBSCRIBE_GRACE_S = 0.2  # a paced stream's first message waits this long for clients to subscribe to its channels
LINGER_S = 1.0  # after the last message of run/generate --live, how long the server stays up for clients to drain
_SLICE_S = 0.05  # longest single sleep of the replay loop, so that a pause, seek or Ctrl-C is seen at once


def parse_speed(text: str) -> float:
    """`--speed`: a positive factor of real time, or `max` (math.inf: as fast as it runs)."""
    if text.strip().lower() == "max":
        return math.inf
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is neither a number nor max") from None
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"{text} must be > 0 (or max)")
    return value


def _sdk():
    try:
        import foxglove
    except ImportError:
        raise CrossviewError(f"the live view needs foxglove-sdk, the live extra: {EXTRA}") from None
    return foxglove


class Server:
    """A Foxglove WebSocket server on `port` (0: any free port; `port` then says which) with its own SDK context,
    so that its channels are only the files'. Use as a context manager; it stops on exit.

    Args:
        player: the replay's state, which the clients' playback requests change (`serve`), or None.
        time_range: (start, end) log times in ns of what is replayed: the server then offers playback control.
    """

    def __init__(self, port: int, *, player: Player | None = None, time_range: tuple[int, int] | None = None):
        foxglove = _sdk()
        from foxglove.websocket import Capability

        self._context = foxglove.Context()
        self._channels: dict[tuple[str, str], object] = {}
        self._topics: set[str] = set()
        self._lock = threading.Lock()
        self._latched: dict[int, list[tuple[int, bytes]]] = {}  # channel id -> its messages at log time 0
        capabilities = [Capability.Time] + ([Capability.PlaybackControl] if time_range else [])
        try:
            self._server = foxglove.start_server(
                name="crossview", host=HOST, port=port, context=self._context, capabilities=capabilities,
                server_listener=_listener(self, player), playback_time_range=time_range, message_backlog_size=BACKLOG,
            )
        except RuntimeError as e:  # (the SDK's FoxgloveError: a port in use, a port not allowed)
            raise CrossviewError(f"--port {port}: {str(e).removeprefix('FoxgloveError: ')}") from None
        self.port = self._server.port

    @property
    def url(self) -> str:
        return f"ws://{HOST}:{self.port}"

    def channel(self, info: ChannelInfo):
        """The server's channel for a file's channel: its topic, encoding and schema; one per (topic, schema). A
        second schema on a topic already taken (a tracks file's header beside the recording's) goes to
        TOPIC/SCHEMA_NAME, as a topic is one channel in the SDK."""
        key = (info.topic, info.schema_name)
        if key not in self._channels:
            foxglove = _sdk()
            topic = info.topic if info.topic not in self._topics else f"{info.topic}/{info.schema_name}"
            self._topics.add(topic)
            self._channels[key] = foxglove.Channel(
                topic, message_encoding=info.message_encoding, context=self._context,
                schema=foxglove.Schema(name=info.schema_name, encoding=info.schema_encoding, data=info.schema_data),
            )
        return self._channels[key]

    def log(self, channel, log_time_ns: int, data: bytes) -> None:
        """Publishes a message to every client subscribed to `channel`. The messages at log time 0 (the header, the
        store, the calibrations and frames: what a file states once, at its start) are kept and sent again to
        each client that subscribes later (`subscribed`), so that a late client sees the store too."""
        with self._lock:
            if log_time_ns == 0:
                latched = self._latched.setdefault(channel.id(), [])
                if (0, data) not in latched:
                    latched.append((0, data))
            channel.log(data, log_time=log_time_ns)

    def subscribed(self, channel_id: int) -> None:
        """A client subscribed to the channel: its messages at log time 0 are sent again (to all its subscribers:
        the SDK sends to a server's clients alike)."""
        with self._lock:
            latched = self._latched.get(channel_id, ())
            channel = next((c for c in self._channels.values() if c.id() == channel_id), None)
            for t, data in latched:
                channel.log(data, log_time=t)

    def broadcast_time(self, t_ns: int) -> None:
        self._server.broadcast_time(int(t_ns))

    def broadcast_playback_state(self, state) -> None:
        self._server.broadcast_playback_state(state)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self._server.stop()


class Paced:
    """A writer's live stream (`crossview.recording.LiveSink`): publishes each message on `server` once its log time
    is due, `speed` times real time (math.inf: at once) from the first after log time 0, which waits
    `SUBSCRIBE_GRACE_S`. The wait is the writer's, so the run goes at that pace; the clients' queues are the SDK's,
    so they never hold the run up."""

    def __init__(self, server: Server, speed: float):
        self._server = server
        self._speed = speed
        self._anchor: tuple[float, int] | None = None  # (wall clock, log time ns) of the first message
        self._last_time_ns = -1

    def channel(self, info: ChannelInfo):
        return self._server.channel(info)

    def publish(self, handle, log_time_ns: int, data: bytes) -> None:
        if log_time_ns > 0:  # (log time 0: the file's start, resent to late clients: `Server.log`)
            if self._anchor is None:  # (the writer has made its channels: clients subscribe on seeing them)
                time.sleep(SUBSCRIBE_GRACE_S)
                self._anchor = (time.perf_counter(), log_time_ns)
            if math.isfinite(self._speed):
                wait = self._anchor[0] + (log_time_ns - self._anchor[1]) / 1e9 / self._speed - time.perf_counter()
                if wait > 0.001:
                    time.sleep(wait)
        self._server.log(handle, log_time_ns, data)
        if log_time_ns > self._last_time_ns:
            self._server.broadcast_time(log_time_ns)
            self._last_time_ns = log_time_ns


def live_stream(port: int | None, speed: float, announce: Callable[[str], None]):
    """The server of `run --live` and `generate --live` on `port` (None: no live view, a null context), announced
    through `announce` once it listens; it lingers `LINGER_S` after a clean end for the clients to drain."""
    import contextlib

    if port is None:
        return contextlib.nullcontext(None)

    @contextlib.contextmanager
    def serving():
        with Server(port) as server:
            announce(f"live: {server.url} (Foxglove: Open connection > Foxglove WebSocket); "
                     f"{'as fast as it runs' if math.isinf(speed) else f'{speed:g}x real time'}")
            yield lambda: Paced(server, speed)
            time.sleep(LINGER_S)

    return serving()


# --------------------------------------------------------------------------------------------------
# Replay (`crossview serve`).


class Player:
    """The replay's state, shared between the SDK's thread (a client's play, pause, seek, speed:
    `on_playback_control_request`) and the replay loop (`replay`). Starts paused at the start, so that a client
    that connects sees everything from the first message once it presses play."""

    def __init__(self, start_ns: int, speed: float):
        self._lock = threading.Lock()
        self.changed = threading.Event()
        self.playing = False
        self.ended = False
        self.speed = speed
        self.position_ns = start_ns
        self.seek_ns: int | None = None

    def on_playback_control_request(self, request):
        from foxglove.websocket import PlaybackCommand

        with self._lock:
            self.playing = request.playback_command == PlaybackCommand.Play
            if request.playback_speed > 0:
                self.speed = float(request.playback_speed)
            if request.seek_time is not None:
                self.seek_ns = int(request.seek_time)
                self.position_ns = self.seek_ns
                self.ended = False
            self.changed.set()
            return self.state(request.request_id, did_seek=request.seek_time is not None)

    def state(self, request_id: str | None = None, did_seek: bool = False):
        from foxglove.websocket import PlaybackState, PlaybackStatus

        status = PlaybackStatus.Ended if self.ended else PlaybackStatus.Playing if self.playing else \
            PlaybackStatus.Paused
        return PlaybackState(status=status, current_time=self.position_ns, playback_speed=self.speed,
                             did_seek=did_seek, request_id=request_id)

    def take(self) -> tuple[bool, float, int | None]:
        """(playing, speed, a seek asked for since the last take or None)."""
        with self._lock:
            self.changed.clear()
            seek, self.seek_ns = self.seek_ns, None
            return self.playing, self.speed, seek

    def end(self, t_ns: int) -> None:
        with self._lock:
            self.ended, self.playing, self.position_ns = True, False, t_ns


def _listener(server: Server, player: Player | None):
    from foxglove.websocket import ServerListener

    class Listener(ServerListener):
        def on_subscribe(self, client, channel):  # (resent from a thread of its own: the SDK's callback returns at
            threading.Thread(target=server.subscribed, args=(channel.id,), daemon=True).start()  # once, no lock held)

        def on_playback_control_request(self, playback_control_request):
            return None if player is None else player.on_playback_control_request(playback_control_request)

    return Listener()


def serve(files: list, port: int, speed: float, start_ns: int, end_ns: int, announce: Callable[[str], None],
          *, play: bool = False) -> None:
    """Replays opened files (a recording, its tracks file) merged in log-time order on a server on `port`, until
    Ctrl-C: paused at the start until a client plays it (or at once with `play`), then paced `speed` times real
    time, following the clients' pause, seek and speed. A seek republishes the messages at the start time (the
    static scene, calibrations, headers) and goes on from the first message at or after the seek time."""
    player = Player(start_ns, speed)
    player.playing = play
    with Server(port, player=player, time_range=(start_ns, end_ns)) as server:
        for f in files:  # (every channel advertised before the first message)
            for info in f.channel_infos():
                server.channel(info)
        announce(f"serving {', '.join(str(f.path) for f in files)} on {server.url} (Foxglove: Open connection > "
                 f"Foxglove WebSocket; {'playing' if play else 'paused until a client plays'}; Ctrl-C ends)")
        _replay(files, server, player, start_ns)


def _merged(files: list, start_ns: int, from_ns: int) -> Iterator[tuple[ChannelInfo, int, bytes]]:
    """The files' messages merged by log time (a file's own order kept, the first file first at a tie): those at
    `start_ns`, then those at or after `from_ns`."""
    def keyed(index: int, f):
        for info, t, data in f.raw():
            if t <= start_ns or t >= from_ns:
                yield (t, index), (info, t, data)

    for _, message in heapq.merge(*(keyed(i, f) for i, f in enumerate(files)), key=lambda item: item[0]):
        yield message


def _replay(files: list, server: Server, player: Player, start_ns: int) -> None:
    messages = _merged(files, start_ns, start_ns)
    anchor: tuple[float, int, float] | None = None  # (wall clock, log time, speed) the pace is measured from
    pending = None
    while True:
        playing, speed, seek = player.take()
        if seek is not None:
            messages, pending, anchor = _merged(files, start_ns, seek), None, None
        if not playing:
            anchor = None
            player.changed.wait(_SLICE_S)
            continue
        if pending is None:
            pending = next(messages, None)
            if pending is None:
                player.end(player.position_ns)
                server.broadcast_playback_state(player.state())
                continue
        info, t, data = pending
        now = time.perf_counter()
        if anchor is None or anchor[2] != speed:
            anchor = (now, t, speed)
        wait = anchor[0] + (t - anchor[1]) / 1e9 / speed - now
        if wait > 0.001:
            player.changed.wait(min(wait, _SLICE_S))
            continue
        server.log(server.channel(info), t, data)
        player.position_ns = t
        server.broadcast_time(t)
        pending = None


def open_files(recording_path: Path, tracks_path: Path | None) -> tuple[list, int, int]:
    """The files `serve` replays, opened and checked (a tracks file must be of the recording), and the time range
    of the replay: 0 to the recording's last log time."""
    from crossview import pipeline, recording
    from crossview.recording.reader import read_summary

    rec = recording.open_recording(recording_path)
    files = [rec]
    if tracks_path is not None:
        tracks = recording.open_tracks(tracks_path)
        pipeline.check_tracks_match(rec, tracks)
        files.append(tracks)
    end_s = max(rec.header.duration_s, float(read_summary(rec.path).get("end_s", 0.0)))
    return files, 0, recording.to_ns(end_s)
