"""Plug-in trackers: resolving `--method`, checking their outputs every frame, and the example run and scored."""

import json
import subprocess
import sys
import threading
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from core.types import COCO17
from crossview import pipeline, recording
from crossview.cli import EXIT_BAD_INPUT, main
from crossview.formats.datasets import load_cameras
from crossview.plugins import ENTRY_POINT_GROUP, PluginError, check_targets, resolve
from examples.greedy_triangulation import GreedyTriangulationTracker
from tracker.config import TrackerConfig
from tracker.protocol import PoseTracker
from tracker.tracker import Tracker
from tracker.types import Target, TargetState

EXAMPLE = "examples.greedy_triangulation:GreedyTriangulationTracker"
HERE = "tests.crossview.test_plugins"


class _Broken:
    """A tracker that works like the example until frame `BAD_FRAME`, then returns `bad()`."""

    BAD_FRAME = 5

    def __init__(self, cameras, config, skeleton):
        self.inner = GreedyTriangulationTracker(cameras, config, skeleton)
        self.count = 0

    def update(self, frame):
        targets = self.inner.update(frame)
        self.count += 1
        if self.count <= self.BAD_FRAME:
            return targets
        return self.bad(frame)


class NaNPose(_Broken):
    def bad(self, frame):
        pose = np.full((17, 3), 1.0)
        pose[3, 1] = np.nan
        return [Target(id=0, pose=pose, stamp_s=frame.stamp_s)]


class HugePose(_Broken):
    def bad(self, frame):  # (finite in float64, infinity in the tracks file's float32: exported as null)
        return [Target(id=0, pose=np.full((17, 3), 1e300), stamp_s=frame.stamp_s)]


class LeavesAThread(GreedyTriangulationTracker):
    """The example with a thread that is no daemon and never ends (it kept the command alive for ever)."""

    def __init__(self, cameras, config, skeleton):
        super().__init__(cameras, config, skeleton)
        threading.Thread(target=threading.Event().wait, name="plugin-forever").start()


class WrongJoints(_Broken):
    def bad(self, frame):
        return [Target(id=0, pose=np.zeros((14, 3)), stamp_s=frame.stamp_s)]


class StringIds(_Broken):
    def bad(self, frame):
        return [Target(id="person-1", pose=np.zeros((17, 3)), stamp_s=frame.stamp_s)]


class Raises(_Broken):
    def bad(self, frame):
        raise RuntimeError("the model file is missing")


class Exits(_Broken):
    def bad(self, frame):
        sys.exit(3)


class Interrupts(_Broken):
    def bad(self, frame):
        raise KeyboardInterrupt  # (its own, not the user's Ctrl-C)


class NoAssignments:
    """The example without its `last_output`: a tracker that does not say where each detection went."""

    def __init__(self, cameras, config, skeleton):
        self._inner = GreedyTriangulationTracker(cameras, config, skeleton)

    def update(self, frame):
        return self._inner.update(frame)


class NoUpdate:
    def __init__(self, cameras, config, skeleton):
        pass


def not_a_class(cameras, config, skeleton):
    return None


@pytest.fixture
def short_recording(store_recording):
    return store_recording


def test_builtin_names_and_their_module_paths_resolve_to_the_same_class():
    assert resolve("crossview").factory is resolve("tracker.tracker:Tracker").factory is Tracker
    assert resolve("crossview").builtin and not resolve("tracker.tracker:Tracker").builtin


def test_the_example_meets_the_protocol():
    cameras = load_cameras(Path(__file__).parents[1] / "data" / "campus")
    assert isinstance(GreedyTriangulationTracker(cameras, TrackerConfig.preset("store"), COCO17), PoseTracker)


@pytest.mark.parametrize("spec, message", [
    ("nosuchpackage.mod:Tracker", "no module named 'nosuchpackage'"),
    ("tracker.nosuchmodule:Tracker", "module tracker.nosuchmodule does not import (ModuleNotFoundError"),
    (f"{HERE}:Missing", f"module {HERE} has no attribute 'Missing'"),
    (f"{HERE}:not_a_class", "not_a_class is a function, not a class"),
    (f"{HERE}:NoUpdate", "class NoUpdate has no update(frame) method"),
    ("greedy", "not a known tracker (baseline, crossview"),
    (f"{HERE}:", "expected package.module:Class, with both parts"),
])
def test_a_bad_method_is_one_line_naming_it_and_what_is_missing(spec, message, short_recording, tmp_path, capsys):
    out = tmp_path / "t.mcap"
    status = main(["--no-progress", "track", str(short_recording), "-o", str(out), "--method", spec])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT
    assert len(err.splitlines()) == 1 and spec in err and message in err, err
    assert list(tmp_path.iterdir()) == []


def test_a_package_in_the_current_folder_is_found_as_python_m_would(tmp_path, monkeypatch):
    package = tmp_path / "mytrackers"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "simple.py").write_text("from examples.greedy_triangulation import GreedyTriangulationTracker as T\n")
    monkeypatch.chdir(tmp_path)
    try:
        assert resolve("mytrackers.simple:T").factory is GreedyTriangulationTracker
    finally:
        for name in ("mytrackers", "mytrackers.simple"):
            sys.modules.pop(name, None)


def test_an_installed_package_registers_a_name_under_the_entry_point_group(tmp_path, monkeypatch):
    # A distribution as pip leaves it: its metadata folder with entry_points.txt beside its module.
    info = tmp_path / "greedy_plugin-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: greedy-plugin\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(f"[{ENTRY_POINT_GROUP}]\ngreedy = {EXAMPLE}\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    method = resolve("greedy")
    assert (method.factory, method.target, method.builtin) == (GreedyTriangulationTracker, EXAMPLE, False)


def _t(id, pose=None, **optional):
    """A target with only what the contract asks for (plus optional fields)."""
    return SimpleNamespace(id=id, pose=np.zeros((17, 3)) if pose is None else pose, **optional)


@pytest.mark.parametrize("targets, message", [
    ({"id": 0}, "update returned a dict, expected a list of targets"),
    ([object()], "target 0 is a object without `id` and `pose`"),
    ([_t(1.0)], "target 0 has id 1.0 of type float; ids must be ints"),
    ([_t(True)], "target 0 has id True of type bool"),
    ([_t(2**70)], f"target 0 has id {2**70}; ids must fit int64"),
    ([_t(np.int32(4)), _t(4)], "target 1 (id 4): the id is reported twice"),
    ([_t(0, np.zeros((17, 2)))], "pose has shape (17, 2), expected (17, 3) for the coco17 skeleton"),
    ([_t(0, "head")], "pose is not numeric (str)"),
    ([_t(0, np.full((17, 3), np.inf))], "pose holds infinite values"),
    ([_t(0, np.full((17, 3), np.nan))], "pose is NaN in every joint"),
    ([_t(0, np.where(np.arange(3) == 2, np.nan, np.zeros((17, 3))))], "joint nose is NaN in some coordinates only"),
    ([_t(0, stamp_s=float("nan"))], "stamp_s nan is not a finite number"),
    ([_t(0, state="confirmed")], "state 'confirmed' is not a tracker.types.TargetState"),
])
def test_each_malformed_target_is_named_with_what_is_wrong(targets, message):
    with pytest.raises(PluginError) as info:
        check_targets(targets, 1.5, COCO17, "here")
    assert str(info.value).startswith("here: ") and message in str(info.value), str(info.value)


def test_a_target_with_only_id_and_pose_takes_the_frames_stamp_and_is_confirmed():
    (target,) = check_targets([_t(np.int64(7))], 1.5, COCO17, "here")
    assert (target.id, type(target.id), target.stamp_s, target.state) == (7, int, 1.5, TargetState.CONFIRMED)


def test_a_missing_joint_nan_in_all_three_coordinates_is_allowed():
    pose = np.zeros((17, 3))
    pose[4] = np.nan
    (target,) = check_targets([Target(id=7, pose=pose, stamp_s=2.0)], 2.0, COCO17, "here")
    assert target.stamp_s == 2.0 and np.isnan(target.pose[4]).all() and np.isfinite(target.pose[5]).all()


@pytest.mark.parametrize("plugin, message", [
    ("NaNPose", "target 0 (id 0): joint left_ear is NaN in some coordinates only"),
    ("WrongJoints", "target 0 (id 0): pose has shape (14, 3), expected (17, 3)"),
    ("HugePose", "target 0 (id 0): pose holds 1e+300 m; joints must be within 1e+06 m"),
    ("StringIds", "target 0 has id 'person-1' of type str; ids must be ints"),
    ("Raises", "update raised RuntimeError: the model file is missing"),
    ("Exits", "update raised SystemExit: 3"),
    ("Interrupts", "update raised KeyboardInterrupt"),
], ids=["NaNPose", "WrongJoints", "HugePose", "StringIds", "Raises", "Exits", "Interrupts"])
def test_a_plugin_going_wrong_stops_the_run_naming_the_frame_and_leaves_nothing(
        plugin, message, short_recording, tmp_path, capsys):
    out = tmp_path / "t.mcap"
    status = main(["--no-progress", "track", str(short_recording), "-o", str(out), "--method", f"{HERE}:{plugin}"])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT
    assert len(err.splitlines()) == 1 and f"frame {_Broken.BAD_FRAME} (camera " in err and message in err, err
    assert list(tmp_path.iterdir()) == []


def test_a_plugins_thread_left_running_does_not_keep_the_command_alive(short_recording, tmp_path):
    out = tmp_path / "t.mcap"
    done = subprocess.run([sys.executable, "-c", "from crossview.cli import run; run()", "--no-progress", "track",
                           str(short_recording), "-o", str(out), "--method", f"{HERE}:LeavesAThread"],
                          cwd=Path(__file__).parents[2], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip().endswith("'plugin-forever' still running when the command ended (a plug-in's, not a "
                                        "daemon); ending without them"), done.stderr
    assert recording.open_tracks(out).header.method == f"{HERE}:LeavesAThread"


def test_verbose_shows_the_plugins_own_traceback(short_recording, tmp_path):
    with pytest.raises(PluginError) as info:
        main(["-v", "--no-progress", "track", str(short_recording), "-o", str(tmp_path / "t.mcap"),
              "--method", f"{HERE}:Raises"])
    assert isinstance(info.value.__cause__, RuntimeError)
    assert list(tmp_path.iterdir()) == []


def test_the_example_tracks_and_scores_through_the_command_line(short_recording, tmp_path, capsys):
    tracks, score_json = tmp_path / "t.mcap", tmp_path / "s.json"
    assert main(["--no-progress", "track", str(short_recording), "-o", str(tracks), "--method", EXAMPLE]) == 0
    assert main(["--no-progress", "score", str(short_recording), str(tracks), "-o", str(score_json)]) == 0
    assert recording.open_tracks(tracks).header.method == EXAMPLE
    score = json.loads(score_json.read_text())
    # Four people in an open store, twelve cameras: plain triangulation of stale views still finds them all.
    assert score["pcp"] > 0.8 and score["idf1"] > 0.8 and score["mpjpe_mm"] < 120, score
    assert 0.5 < score["association_accuracy"] <= 1.0


def test_a_plugin_without_last_output_is_scored_without_association_accuracy(short_recording, tmp_path):
    tracks = tmp_path / "t.mcap"
    pipeline.track(short_recording, tracks, method=f"{HERE}:NoAssignments", progress=False)
    _, with_last = pipeline.score(short_recording, _example_tracks(short_recording, tmp_path), progress=False)
    _, without = pipeline.score(short_recording, tracks, progress=False)
    assert without["association_accuracy"] is None and with_last["association_accuracy"] is not None
    # Same targets either way: every other figure agrees.
    for key in ("pcp", "mpjpe_mm", "mota", "idf1", "hota"):
        assert without[key] == with_last[key], key


def _example_tracks(rec, tmp_path):
    path = tmp_path / "example.mcap"
    pipeline.track(rec, path, method=EXAMPLE, progress=False)
    return path


def test_the_minimal_plugin_of_the_docs_runs_as_written(short_recording, tmp_path, monkeypatch):
    # The docs' block, saved as the docs say, run from that folder as the docs say.
    docs = (Path(__file__).resolve().parents[2] / "docs" / "plugins.md").read_text(encoding="utf-8")
    section = docs.split("## A minimal plug-in", 1)[1]
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    (tmp_path / "hip_plane.py").write_text(code)
    monkeypatch.chdir(tmp_path)
    monkeypatch.delitem(sys.modules, "hip_plane", raising=False)
    tracks, score_json = tmp_path / "t.mcap", tmp_path / "s.json"
    assert main(["--no-progress", "track", str(short_recording), "-o", str(tracks),
                 "--method", "hip_plane:HipPlaneTracker"]) == 0
    assert main(["--no-progress", "score", str(short_recording), str(tracks), "-o", str(score_json)]) == 0
    score = json.loads(score_json.read_text())
    # Hips only: found on the ground plane by the identity metrics (most of what it reports is somebody), not a
    # pose. It returns everyone it tracks after each frame, so it misses few people at a scoring tick (docs/plugins.md:
    # identity recall 70 % here; the version that returned only the current camera's people recalled 42 %).
    assert score["idr"] > 0.6 and score["idp"] > 0.5 and score["idf1"] > 0.5, score
    assert score["pcp"] < 0.5, score
