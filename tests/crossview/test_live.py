"""The live view (`crossview serve`, `run/generate --live`) seen by an independent client (`live_client`): what it
receives equals the file's messages, read by the mcap library alone, channel by channel (count and bytes)."""

import collections
import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from crossview.cli import EXIT_BAD_INPUT, main
from crossview.live import parse_speed
from tests.crossview.live_client import collect

pytest.importorskip("foxglove", reason="the live extra (pip install '.[live]')")
pytest.importorskip("websockets", reason="the test client's websockets")
REPO = Path(__file__).resolve().parents[2]


def file_messages(*paths) -> dict:
    """{(topic, schema name): [(log time ns, bytes), ...]} of the files, in file order, by the mcap library."""
    out = collections.defaultdict(list)
    for path in paths:
        with open(path, "rb") as f:
            for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
                out[(channel.topic, schema.name)].append((message.log_time, message.data))
    return dict(out)


def start(*argv) -> tuple[subprocess.Popen, str]:
    """The command started with --port 0, and the URL it printed."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-m", "crossview.cli", "--no-progress", *argv, "--port", "0"], cwd=REPO,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    found = re.search(r"ws://\S+", line)
    if not found:
        proc.kill()
        raise AssertionError(f"no URL printed: {line!r} {proc.stderr.read()}")
    return proc, found.group(0).rstrip(";,)")


def total(messages: dict) -> int:
    return sum(len(v) for v in messages.values())


def once(received: dict) -> tuple[dict, int]:
    """The messages received with a repeat of a log-time-0 message left out, and how many were left out: a client
    that subscribes just as such a message goes out can get it live and again as a late subscriber
    (`crossview.live.Server.subscribed`)."""
    out, repeats = {}, 0
    for key, messages in received.items():
        kept = [m for i, m in enumerate(messages) if not (m[0] == 0 and m in messages[:i])]
        repeats += len(messages) - len(kept)
        out[key] = kept
    return out, repeats


def test_generate_live_publishes_the_file_s_messages(store_recording, tmp_path):
    out = tmp_path / "live.mcap"
    proc, url = start("generate", "store_layout1", "--duration", "6", "--seed", "0", "-o", str(out), "--live",
                      "--speed", "4")
    received = collect(url, quiet_s=5.0, timeout_s=120.0)
    assert proc.wait(120) == 0, proc.stderr.read()
    assert out.read_bytes() == store_recording.read_bytes()  # (the live view leaves the file's bytes as they were)
    expected = file_messages(out)
    received, repeats = once(received)
    print(f"generate --live --speed 4: {total(received)} of {total(expected)} messages received ({repeats} repeated)")
    assert received == expected


def summary_apart_from_timing(path) -> tuple[bytes, dict]:
    """A tracks file's bytes before its summary metadata record (every message, chunk and header), and the summary
    without `tracker_s`, the tracker's wall-clock seconds: the one thing that differs between two runs."""
    data = path.read_bytes()
    cut = data.index(b"crossview.summary") - 13  # (the record's opcode, length and name length: MCAP's Metadata)
    with open(path, "rb") as f:
        summary = json.loads(next(m for m in make_reader(f).iter_metadata() if m.name == "crossview.summary")
                             .metadata["json"])
    assert summary.pop("tracker_s") > 0
    return data[:cut], summary


def test_run_live_tracks_as_it_goes(store_recording, store_tracks, tmp_path):
    """`run --live --speed max` tracks each frame as it is made: the client gets the tracker's outputs interleaved
    with the recording's messages, each decoded with its advertised schema, and what it gets is the files' messages
    less the SDK's drops; the files are those of `generate` then `track` (the session's fixtures)."""
    # In this process (its kernels loaded: seconds less than a command started afresh), on a port found free.
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    arrivals: list = []
    got: dict = {}

    def client():
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline:  # (until the run's server listens)
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1.0).close()
                break
            except OSError:
                time.sleep(0.02)
        got["received"] = collect(f"ws://127.0.0.1:{port}", quiet_s=10.0, timeout_s=120.0, arrivals=arrivals)

    thread = threading.Thread(target=client)
    thread.start()
    status = main(["--no-progress", "run", "store_layout1", "--duration", "6", "--seed", "0", "-o", str(tmp_path),
                   "--live", "--speed", "max", "--port", str(port)])
    thread.join(60)
    assert status == 0
    received = got["received"]
    rec, tracks = tmp_path / "store_layout1.mcap", tmp_path / "store_layout1.tracks.mcap"
    assert rec.read_bytes() == store_recording.read_bytes()
    assert summary_apart_from_timing(tracks) == summary_apart_from_timing(store_tracks)
    header = ("/crossview/header", "crossview.TracksHeader")
    received[header] = received.pop(("/crossview/header/crossview.TracksHeader", "crossview.TracksHeader"))
    expected = file_messages(rec, tracks)
    received, repeats = once(received)
    for key, messages in received.items():
        it = iter(expected[key])
        assert all(m in it for m in messages), key  # (a subsequence: dropped, never altered or reordered)
    tracks_topics = {"/tracker/outputs", "/tracker/skeletons"}
    first_track = next(i for i, (topic, _) in enumerate(arrivals) if topic in tracks_topics)
    last_frame = max(i for i, (topic, _) in enumerate(arrivals) if topic.endswith("/frame"))
    assert first_track < last_frame  # (tracked while the frames come, not after them)
    outputs = [i for i, (topic, _) in enumerate(arrivals) if topic == "/tracker/outputs"]
    frames = [i for i, (topic, _) in enumerate(arrivals) if topic.endswith("/frame")]
    dropped = total(expected) - total(received)
    print(f"run --live --speed max: {total(received)} of {total(expected)} messages received, {dropped} dropped "
          f"({repeats} repeated); the median output came after {sum(f < outputs[len(outputs) // 2] for f in frames)} "
          f"of {len(frames)} frames")


def test_run_live_with_a_tracker_going_wrong_leaves_nothing(tmp_path, capsys):
    """A plug-in that raises on frame 5, tracked as the frames are made: one line naming the frame, status 2, and
    neither the recording nor the tracks file (nor a temporary) left."""
    status = main(["--no-progress", "run", "store_layout1", "--duration", "1", "--seed", "0", "-o", str(tmp_path),
                   "--method", "tests.crossview.test_plugins:Raises", "--live", "--speed", "max", "--port", "0"])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT
    assert len(err.splitlines()) == 1 and "frame 5 (camera " in err and "the model file is missing" in err, err
    assert list(tmp_path.iterdir()) == []


def test_serve_replays_recording_and_tracks(store_recording, store_tracks):
    proc, url = start("serve", str(store_recording), str(store_tracks))
    try:
        expected = file_messages(store_recording, store_tracks)
        received = collect(url, expected=total(expected), play=True, play_speed=8.0, timeout_s=120.0)
    finally:
        proc.terminate()
        proc.wait(30)
    # The tracks file's header shares its topic with the recording's: served as TOPIC/SCHEMA (crossview.live.Server).
    header = ("/crossview/header", "crossview.TracksHeader")
    received[header] = received.pop(("/crossview/header/crossview.TracksHeader", "crossview.TracksHeader"))
    print(f"serve at 8x: {total(received)} of {total(expected)} messages received")
    assert received == expected


def test_serve_seeks(store_recording):
    """A play request with a seek to 4 s: the messages at log time 0 (the store, calibrations, header), then those from
    4 s on; Ctrl-C ends the server with status 0."""
    proc, url = start("serve", str(store_recording))
    seek_ns = 4_000_000_000
    try:
        expected = {key: [m for m in messages if m[0] == 0 or m[0] >= seek_ns]
                    for key, messages in file_messages(store_recording).items()}
        expected = {key: messages for key, messages in expected.items() if messages}
        received = collect(url, expected=total(expected), play=True, play_speed=8.0, seek_ns=seek_ns,
                           timeout_s=120.0)
    finally:
        proc.send_signal(signal.SIGINT)
        status = proc.wait(30)
    assert received == expected
    assert status == 0 and proc.stdout.read().strip() == "serve: stopped"


def test_generate_live_at_max_speed_is_not_held_up_by_a_slow_client(tmp_path):
    """A client that reads one message per 5 ms: the run goes on at its own speed, the SDK drops the
    client's oldest messages, and what arrives is the file's, in its order."""
    out = tmp_path / "max.mcap"
    proc, url = start("generate", "store_layout1", "--duration", "3", "--seed", "0", "-o", str(out), "--live",
                      "--speed", "max")
    received = collect(url, quiet_s=5.0, timeout_s=120.0, read_delay_s=0.005)
    assert proc.wait(120) == 0, proc.stderr.read()
    expected = file_messages(out)
    received, _ = once(received)
    for key, messages in received.items():
        it = iter(expected[key])
        assert all(m in it for m in messages), key  # (a subsequence: dropped, never altered or reordered)
    dropped = total(expected) - total(received)
    print(f"generate --live --speed max, a client reading 1 message/5 ms: {dropped} of {total(expected)} dropped")


def test_a_vanished_client_does_not_stop_the_run(tmp_path):
    """A client that takes a few messages and goes: the run goes on to its end and writes its file."""
    out = tmp_path / "gone.mcap"
    proc, url = start("generate", "store_layout1", "--duration", "2", "--seed", "0", "-o", str(out), "--live",
                      "--speed", "4")
    received = collect(url, expected=50, timeout_s=60.0)
    assert total(received) == 50
    assert proc.wait(120) == 0, proc.stderr.read()
    assert total(file_messages(out)) > 50


def test_port_in_use_is_one_line(tmp_path, capsys):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        status = main(["generate", "store_layout1", "-o", str(tmp_path / "unused.mcap"), "--live", "--port", str(port)])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT and len(err.splitlines()) == 1
    assert f"--port {port}" in err and "in use" in err
    assert not (tmp_path / "unused.mcap").exists()


def test_serve_refuses_a_truncated_recording(store_recording, tmp_path, capsys):
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(store_recording.read_bytes()[: store_recording.stat().st_size // 2])
    status = main(["serve", str(cut), "--port", "0"])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT and len(err.splitlines()) == 1
    assert "cut.mcap: truncated MCAP file" in err


def test_missing_extra_names_it(store_recording, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "foxglove", None)  # (import foxglove then raises ImportError)
    status = main(["serve", str(store_recording), "--port", "0"])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT and len(err.splitlines()) == 1
    assert "foxglove-sdk" in err and "[live]" in err


@pytest.mark.parametrize("text, value", [("1", 1.0), ("2.5", 2.5), ("max", float("inf")), ("MAX", float("inf"))])
def test_speed(text, value):
    assert parse_speed(text) == value


@pytest.mark.parametrize("text", ["0", "-1", "fast", "inf", "nan"], ids=["zero", "negative", "word", "inf", "nan"])
def test_bad_speed_is_refused(text, tmp_path, capsys):
    assert main(["generate", "store_layout1", "-o", str(tmp_path / "x.mcap"), "--speed", text]) == EXIT_BAD_INPUT
    assert "--speed" in capsys.readouterr().err
