"""Recordings shared by the glue's tests: made once per session, since a simulation takes seconds."""

import pytest

from crossview import pipeline


@pytest.fixture(scope="session")
def store_recording(tmp_path_factory):
    """store_layout1 (12 cameras, 4 people), seed 0, 6 s: a short but complete recording."""
    path = tmp_path_factory.mktemp("store") / "store_layout1.mcap"
    pipeline.generate(pipeline.load_scenario("store_layout1", duration_s=6.0, seed=0), path, progress=False)
    return path


@pytest.fixture(scope="session")
def store_tracks(store_recording, tmp_path_factory):
    """The built-in tracker's tracks of `store_recording` (store preset)."""
    path = tmp_path_factory.mktemp("store_tracks") / "store_layout1.tracks.mcap"
    pipeline.track(store_recording, path, progress=False)
    return path
