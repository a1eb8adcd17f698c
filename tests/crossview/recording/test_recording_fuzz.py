"""Property: any damage to a recording (cut, bytes changed, removed or inserted, the end magic kept or not)
is read as the exact events or refused with a RecordingError naming the file; `info` likewise, and with
`allow_truncated` every event it gives back is one that was written."""

import functools
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import event, given
from hypothesis import strategies as st

from crossview import recording
from crossview.recording import RecordingError
from tests.crossview.recording.test_recording import make_cameras, make_events, write_recording
from tests.fuzz import FUZZ


@functools.cache
def _small() -> tuple[bytes, int]:
    """A small recording (3 cameras, 2 people, 0.6 s; 2 kB chunks, so many of them) and its event count."""
    rng = np.random.default_rng(7)
    cameras = make_cameras(3, rng)
    events = make_events(cameras, 2, 0.6, rng)
    with tempfile.TemporaryDirectory() as folder:
        path = write_recording(Path(folder) / "r.mcap", cameras, events, chunk_size=2048)
        return path.read_bytes(), len(events)


@st.composite
def damaged(draw) -> bytes:
    data, _ = _small()
    out = bytearray(data)
    for _ in range(draw(st.integers(1, 3))):
        if not out:
            break
        at = draw(st.integers(0, len(out) - 1))
        kind = draw(st.sampled_from(["flip", "cut", "cut-keep-magic", "remove", "insert", "tail"]))
        if kind == "flip":
            out[at] ^= draw(st.integers(1, 255))
        elif kind == "cut":
            out = out[:at]
        elif kind == "cut-keep-magic":
            out = out[:at] + data[-8:]
        elif kind == "remove":
            del out[at:at + draw(st.integers(1, 64))]
        elif kind == "insert":
            out[at:at] = draw(st.binary(min_size=1, max_size=16))
        else:  # the summary and footer at the end
            out[len(out) - 1 - draw(st.integers(0, min(300, len(out) - 1)))] ^= draw(st.integers(1, 255))
    return bytes(out)


@FUZZ
@given(damaged(), st.booleans())
def test_fuzz_a_damaged_recording_reads_exactly_or_is_refused_naming_the_file(data, allow_truncated):
    original, count = _small()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "r.mcap"
        path.write_bytes(data)
        try:
            recording.info(path, allow_truncated=allow_truncated)
        except RecordingError as e:
            assert str(e).startswith(f"{path}: ") and "\n" not in str(e), e
        try:
            rec = recording.open_recording(path, allow_truncated=allow_truncated)
            read = sum(1 for _ in rec.events())
        except RecordingError as e:
            assert str(e).startswith(f"{path}: ") and "\n" not in str(e), e
            event("refused")
            return
    event("read")
    # What is read is at most what was written (a readable prefix, or all of it).
    assert read <= count or data == original
