"""The main job end to end on a short run: generate, track, score, through the command line."""

import json
import multiprocessing
import os
import signal
import subprocess
import sys
import time

import pytest

from core.records import watched_floor
from crossview import pipeline
from crossview.cli import EXIT_BAD_INPUT, main
from sim.cameras import camera_grid
from sim.scenario import from_source_text

SCORE_KEYS = [
    "scenario", "seed", "num_cameras", "num_people", "duration_s", "pcp", "mpjpe_mm", "pck_100mm", "mota",
    "idf1", "id_switches", "hota", "association_accuracy", "tracker_fps", "camera_frames_per_s",
]
FRACTIONS = ["pcp", "pck_100mm", "idf1", "hota", "association_accuracy"]


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    status = main(["--no-progress", "run", "--duration", "4", "--seed", "3", "-o", str(out)])
    assert status == 0
    return out


def test_run_writes_recording_tracks_and_a_complete_score(short_run):
    assert sorted(p.name for p in short_run.iterdir()) == [
        "store_layout1.mcap", "store_layout1.score.json", "store_layout1.tracks.mcap"
    ]
    score = json.loads((short_run / "store_layout1.score.json").read_text())
    assert list(score)[: len(SCORE_KEYS)] == SCORE_KEYS
    assert (score["scenario"], score["seed"], score["num_cameras"], score["duration_s"]) == ("store_layout1", 3, 12, 4)
    for key in FRACTIONS:
        assert 0.0 <= score[key] <= 1.0, key
    # Four people in an open store seen by twelve cameras: the tracker must find them.
    assert score["pcp"] > 0.8 and score["idf1"] > 0.8
    assert score["tracker_fps"] > 0
    assert score["truth_head"] == "evaluate"  # the stores score the true head as evaluate.py maps an estimate


def test_the_campus_rig_scenario_runs_end_to_end(tmp_path):
    """The shipped scenario on Campus's calibrated cameras (standing around the square, outside its kerb):
    generated, tracked with the campus preset and scored in a 3 s smoke run."""
    status = main(["--no-progress", "run", "campus", "--duration", "3", "--preset", "campus", "-o", str(tmp_path)])
    assert status == 0
    score = json.loads((tmp_path / "campus.score.json").read_text())
    assert (score["scenario"], score["num_cameras"], score["num_people"], score["duration_s"]) == ("campus", 3, 3, 3)
    assert score["truth_head"] == "annotated"  # the rig's scenario scores the head as Campus annotates it
    # Three people, each seen by at least two of the three cameras: the tracker must find them.
    assert score["pcp"] > 0.8 and score["idf1"] > 0.8


def test_the_2d_scores_of_a_second_process_are_those_of_one(short_run, monkeypatch):
    """`score` leaves the per-camera 2D scores to a forked process: the same JSON as in one process; a failure
    there is raised here, as what it was, and no process is left behind."""
    from crossview.scoring import orchestrate

    rec, tracks = short_run / "store_layout1.mcap", short_run / "store_layout1.tracks.mcap"
    _, alone = pipeline.score(rec, tracks, progress=False, worker_process=False)
    _, beside = pipeline.score(rec, tracks, progress=False, worker_process=True)
    assert beside == alone and len(alone["camera_2d"]) == 12
    assert multiprocessing.active_children() == []

    def broken(*args):
        raise ArithmeticError("2D scoring broke")

    monkeypatch.setattr(orchestrate, "projected_2d_scores", broken)  # (the worker's)
    with pytest.raises(ArithmeticError, match="2D scoring broke") as failure:
        pipeline.score(rec, tracks, progress=False, worker_process=True)
    assert any("raised in the 2D scoring worker process" in note for note in failure.value.__notes__)
    assert multiprocessing.active_children() == []


def test_tracks_are_refused_against_another_recording(short_run, tmp_path, capsys):
    other = tmp_path / "other.mcap"
    scenario = pipeline.load_scenario("store_layout1", duration_s=1.0, seed=4)
    pipeline.generate(scenario, other, progress=False)
    status = main(["score", str(other), str(short_run / "store_layout1.tracks.mcap")])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT
    assert "tracks were made from scenario 'store_layout1' seed 3" in err and len(err.splitlines()) == 1


def test_a_tracks_file_is_not_a_recording(short_run, tmp_path, capsys):
    status = main(["track", str(short_run / "store_layout1.tracks.mcap"), "-o", str(tmp_path / "t.mcap")])
    assert status == EXIT_BAD_INPUT
    assert not (tmp_path / "t.mcap").exists()
    assert "tracks file" in capsys.readouterr().err


def test_info_describes_the_recording(short_run, capsys):
    assert main(["info", str(short_run / "store_layout1.mcap")]) == 0
    text = capsys.readouterr().out
    assert "store_layout1" in text and "12" in text


@pytest.mark.parametrize("count, expected", [(12, (3, 4)), (28, (4, 7)), (7, (1, 7)), (1, (1, 1))])
def test_camera_grid_fits_the_floor(count, expected):
    assert camera_grid(count, width_m=8.0, depth_m=6.0) == expected


def test_camera_grid_keeps_to_the_largest_grid_a_scenario_takes():
    # 10,000 on a long floor fitted best as 80 x 125, which the scenario then refused blaming its own file.
    assert camera_grid(10_000, width_m=100.0, depth_m=64.0) == (100, 100)
    assert camera_grid(200, width_m=1000.0, depth_m=1.0) == (2, 100)  # (unbounded: 1 x 200)


def test_the_watched_floor_is_the_floor_box_footprint_walls_included():
    import numpy as np

    from core.records import Box, BoxKind
    from sim.scenario import load
    from sim.store import StoreGeometry

    store = StoreGeometry(load("store_layout1").store)
    x0, y0, x1, y1 = watched_floor(store.boxes)
    assert (x0, y0) == pytest.approx((-0.1, -0.1)) and (x1, y1) == pytest.approx((4.7, 3.9))  # 4.6 x 3.8 m, 0.1 m walls
    turned = Box(BoxKind.FLOOR, (1.0, 2.0, 0.0), (4.0, 2.0, 0.1), np.pi / 2)
    assert watched_floor([turned]) == pytest.approx((0.0, 0.0, 2.0, 4.0))
    assert watched_floor([Box(BoxKind.SHELF, (0, 0, 0), (1, 1, 1))]) is None


def test_generate_gives_the_bytes_of_a_plain_one_process_write(tmp_path):
    """`generate` runs the geometry in a worker process, draws and encodes in batches and loads kernels
    while the worker starts; none of it may change a byte: twice the same file, and the file that one
    process writes event by event from a simulation that keeps the captures' poses."""
    from crossview import recording
    from sim.simulate import Simulation

    scenario = pipeline.load_scenario("store_layout2", duration_s=0.8, seed=5)
    a = pipeline.generate(scenario, tmp_path / "a.mcap", progress=False)
    pipeline.generate(scenario, tmp_path / "b.mcap", progress=False)
    assert a.num_frames > 100 and 0 < a.startup_s < a.wall_s
    sim = Simulation(scenario, scenario.seed, worker_process=False)
    header = recording.RecordingHeader(scenario.name, scenario.source_text, scenario.digest, scenario.seed,
                                       scenario.duration_s, sim.skeleton.name)
    with recording.RecordingWriter(tmp_path / "plain.mcap", header, sim.cameras, sim.boxes) as writer:
        for event in sim.events():
            writer.write(event)
    assert (tmp_path / "a.mcap").read_bytes() == (tmp_path / "b.mcap").read_bytes()
    assert (tmp_path / "a.mcap").read_bytes() == (tmp_path / "plain.mcap").read_bytes()


@pytest.mark.parametrize("where", ["opening", "writing"])
def test_generate_interrupted_leaves_no_file_and_no_worker(tmp_path, monkeypatch, where):
    """Ctrl-C while the writer is opened (beside the starting worker) or in the middle of writing: nothing
    under the final name or left as a temporary file, and the worker process is gone."""
    import multiprocessing

    from crossview import recording

    calls = []

    def interrupt(*args, **kwargs):
        calls.append(1)
        if where == "opening" or len(calls) == 3:
            raise KeyboardInterrupt

    if where == "opening":  # (warm_up runs once the worker has started, before the first event)
        monkeypatch.setattr(recording.Encoder, "warm_up", interrupt)
    else:
        monkeypatch.setattr(recording.RecordingWriter, "write_many", interrupt)
    scenario = pipeline.load_scenario("store_layout2", duration_s=3.0, seed=5)
    with pytest.raises(KeyboardInterrupt):
        pipeline.generate(scenario, tmp_path / "g.mcap", progress=False)
    assert calls and list(tmp_path.iterdir()) == []
    assert multiprocessing.active_children() == []


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_a_terminating_signal_ends_generate_cleanly(tmp_path, signum):
    """SIGTERM or SIGHUP in the middle of a real `crossview generate`: exit status 128 + the signal, one
    line saying so, no file under the final name or left as a temporary, and no worker process left."""
    out = tmp_path / "g.mcap"
    # (-X faulthandler: a crash, once seen here as exit -11 with an empty stderr, then says where it was)
    command = [sys.executable, "-X", "faulthandler", "-c", "from crossview.cli import run; run()", "--no-progress",
               "generate", "store_layout2", "-o", str(out), "--duration", "600"]
    process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 120
    while not any(tmp_path.iterdir()) and time.monotonic() < deadline:  # the temporary file: it is writing
        time.sleep(0.05)
    time.sleep(0.5)
    process.send_signal(signum)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 128 + signum, err
    name = signal.Signals(signum).name
    assert err.strip().splitlines()[-1] == f"crossview: ended by {name}; no partial output was kept"
    assert list(tmp_path.iterdir()) == []
    # Nothing of the process group is left (the simulation worker included).
    time.sleep(0.2)
    with pytest.raises(ProcessLookupError):
        os.killpg(process.pid, 0)


# Durations that end at awkward instants: before most cameras' first capture, one truth tick into a block
# of ticks, and in the middle of a block and of a frame period.
AWKWARD_DURATIONS_S = (0.05, 0.31, 1.37)
SEEDS = range(50)


def _one_per_capture_schedule() -> list[str]:
    """The shipped scenarios, one per distinct [cameras] and [clock] (which alone make the schedule of captures):
    of those that share them, the one with the smallest floor."""
    loaded = [pipeline.scenario_mod.load(p) for p in pipeline.scenario_mod.shipped()]
    first = {}
    for scenario in sorted(loaded, key=lambda s: (s.store.width_m * s.store.depth_m, s.name)):
        first.setdefault((scenario.cameras, scenario.clock), scenario.name)
    return sorted(first.values())


@pytest.mark.parametrize("name", _one_per_capture_schedule())
def test_every_shipped_scenario_generates_at_every_seed_and_awkward_duration(name, tmp_path):
    """Generation never fails on the schedule of captures: however the clocks' phases, jitter and drops fall
    against the blocks of truth ticks (a block with no capture at all included), each of 50 seeds x 3
    durations gives a complete recording. Two people keep it short: the clocks do not depend on the crowd, nor on
    the store, so of shipped scenarios with the same cameras and clocks (convenience has store_layout1's) one runs."""
    from crossview import recording

    out = tmp_path / "r.mcap"
    # Each camera's clock is drawn on its own: the megastore's 1,000 cameras try 5,000 clocks in 5 seeds, more than
    # a 28-camera store in 50 (and 50 seeds of it would take minutes of the suite).
    rig = pipeline.load_scenario(name).cameras
    seeds = SEEDS if rig.rows * rig.cols <= 300 else SEEDS[:5]
    for seed in seeds:
        for duration in AWKWARD_DURATIONS_S:
            scenario = pipeline.load_scenario(name, seed=seed, duration_s=duration, people=2)
            result = pipeline.generate(scenario, out, progress=False)
            rec = recording.open_recording(out)
            assert sum(1 for _ in rec.frames()) == result.num_frames, (name, seed, duration)
            assert max(truth.t_s for truth in rec.truth()) >= duration, (name, seed, duration)


def test_the_truth_head_is_the_one_the_recorded_scenario_names(store_recording, tmp_path):
    """`crossview score` reads the head convention from the scenario the recording keeps; a recording converted
    from a dataset keeps none, and its 14-joint truth already holds the annotated head joints."""
    from pathlib import Path

    from crossview import recording
    from crossview.formats import datasets
    from sim.humanoid import ANNOTATED_HEAD

    def head_of(scenario_name, **overrides):
        path = tmp_path / f"{scenario_name}-{len(overrides)}.mcap"
        pipeline.generate(pipeline.load_scenario(scenario_name, duration_s=0.2, overrides=overrides), path,
                          progress=False)
        return pipeline.truth_head(recording.open_recording(path))

    # The campus rig's file says "annotated", an override on the command line says otherwise ...
    assert head_of("campus") is ANNOTATED_HEAD
    assert head_of("campus", **{"scoring.truth_head": "evaluate"}) is None
    # ... the stores keep the default, and a converted dataset is scored on its own annotations.
    assert pipeline.truth_head(recording.open_recording(store_recording)) is None
    converted = tmp_path / "campus_real.mcap"
    datasets.convert(Path(__file__).resolve().parents[1] / "data" / "campus", converted,
                     check_scenario=from_source_text)
    real = recording.open_recording(converted)
    assert real.skeleton.name == "campus14" and pipeline.truth_head(real) is None
