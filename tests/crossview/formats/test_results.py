"""Result files scored against a recording: JSON lines and the dataset layout's result_3d.json, and their checks."""

import json

import numpy as np
import pytest

from core.types import CAMPUS14, COCO17
from crossview import pipeline, recording
from crossview.cli import EXIT_BAD_INPUT, main
from crossview.formats.datasets import write_result_3d
from crossview.formats.results import ResultError, json_lines, read_results
from examples import track_dataset
from tracker.types import Target, TrackerOutput

SAME = ("pcp", "pck_100mm", "mota", "idf1", "id_switches", "hota", "num_people")


def _line(stamp=1.0, id=0, joints=None, **extra):
    joints = [[0.0, 0.0, 1.0]] * 17 if joints is None else joints
    return json.dumps({"stamp_s": stamp, "id": id, "joints": joints, **extra})


def test_json_lines_of_the_tracks_score_as_the_tracks_without_association(store_recording, store_tracks, tmp_path):
    jsonl = tmp_path / "r.jsonl"
    assert main(["--no-progress", "export", str(store_tracks), "--format", "jsonl", "-o", str(jsonl)]) == 0
    _, tracks = pipeline.score(store_recording, store_tracks, progress=False)
    _, lines = pipeline.score(store_recording, jsonl, progress=False)
    for key in (*SAME, "mpjpe_mm", "motp_m"):
        assert lines[key] == tracks[key], key
    assert lines["association_accuracy"] is None and lines["tracker_fps"] is None


def test_result_3d_of_the_tracks_scores_as_the_tracks_to_its_rounding(store_recording, store_tracks, tmp_path):
    result = tmp_path / "result_3d.json"
    write_result_3d(recording.open_tracks(store_tracks).outputs(), result)
    _, tracks = pipeline.score(store_recording, store_tracks, progress=False)
    _, layout = pipeline.score(store_recording, result, progress=False)
    for key in SAME:
        assert layout[key] == tracks[key], key
    assert layout["mpjpe_mm"] == pytest.approx(tracks["mpjpe_mm"], abs=0.01)  # written to 0.01 mm


def test_a_tracker_outside_the_project_scores_through_the_dataset_layout(store_recording, tmp_path):
    # The example tracker run by its own script over the exported folder, and by `crossview track`.
    folder, jsonl, tracks = tmp_path / "d", tmp_path / "r.jsonl", tmp_path / "t.mcap"
    assert main(["--no-progress", "export", str(store_recording), "--format", "dataset", "-o", str(folder)]) == 0
    track_dataset.main([str(folder), "-o", str(jsonl)])
    pipeline.track(store_recording, tracks, method="examples.greedy_triangulation:GreedyTriangulationTracker",
                   progress=False)
    _, outside = pipeline.score(store_recording, jsonl, progress=False)
    _, inside = pipeline.score(store_recording, tracks, progress=False)
    for key in SAME:
        assert outside[key] == inside[key], key
    # The calibration reaches the outside tracker as the layout's JSON (its own parametrisation): the same
    # poses to floating-point noise, nanometres (1.4e-6 mm of MPJPE on this recording).
    assert outside["mpjpe_mm"] == pytest.approx(inside["mpjpe_mm"], abs=1e-4)


def test_a_line_with_only_a_stamp_is_an_output_with_no_target(tmp_path):
    path = tmp_path / "r.jsonl"
    lines = [_line(1.0, 3), json.dumps({"stamp_s": 1.1}), "", _line(1.2, 3, [None] * 16 + [[1, 2, 3]])]
    path.write_text("\n".join(lines))
    outputs = read_results(path, COCO17, (0.0, 2.0))
    assert [(o.stamp_s, [t.id for t in o.targets]) for o in outputs] == [(1.0, [3]), (1.1, []), (1.2, [3])]
    assert np.isnan(outputs[2].targets[0].pose[:16]).all() and outputs[2].targets[0].pose[16].tolist() == [1, 2, 3]


def test_result_3d_poses_map_to_the_campus_joints_of_a_campus_recording(tmp_path):
    pose = np.arange(51, dtype=float).reshape(17, 3) / 10 + 1
    write_result_3d([TrackerOutput(0.5, "", [Target(id=2, pose=pose, stamp_s=0.5)], np.zeros(0, np.int64))],
                    tmp_path / "r.json")
    (output,) = read_results(tmp_path / "r.json", CAMPUS14, (0.0, 1.0))
    assert output.targets[0].pose.shape == (14, 3)


@pytest.mark.parametrize("text, message", [
    (_line(id="a"), "line 1: id 'a' of type str; ids must be integers"),
    (_line(id=1.5), "line 1: id 1.5 of type float"),
    (_line(id=None), "line 1: id None of type NoneType"),
    (_line(stamp=99.0), "line 1: stamp 99.0 s is outside the recording (0.000 to 6.000 s, give or take 1.0 s)"),
    (_line(stamp="now"), "line 1: stamp 'now' is not a finite number"),
    (_line(joints=[[0, 0, 1]] * 14), "line 1: 14 joints, the recording's coco17 has 17"),
    (_line(joints=[[0, 0]] * 17), "line 1: joints have shape (17, 2), expected (17, 3)"),
    (_line(joints=[[0, 0, None]] * 17), "line 1: a joint is infinite or NaN in some coordinates only"),
    (_line() + "\n" + _line(), "line 2: id 0 appears twice at stamp 1.0 s"),
    (_line() + "\n{not json", "line 2: not valid JSON"),
    ('{"id": 1}', "line 1: expected {\"stamp_s\": seconds"),
    ('{"stamp_s": 1.0, "id": 1}', "line 1: key 'joints' missing"),
    ('[{"timestamp": 1.0, "poses": [{"id": "x", "points_3d": []}]}]', "entry 0 pose 0: id 'x' of type str"),
    ('[{"timestamp": 1.0, "poses": [{"id": 1, "points_3d": [[1, 1, 1]]}]}]', "entry 0 pose 0: 1 joints"),
    ('[{"timestamp": -9.0, "poses": []}]', "entry 0: stamp -9.0 s is outside the recording"),
    ('[{"poses": []}]', "entry 0: expected {\"timestamp\": seconds"),
    ("[]", "holds no output"),
    ("id,stamp\n", "neither a tracks file (.mcap), result_3d.json (a JSON list) nor JSON lines"),
])
def test_a_bad_result_file_is_one_line_naming_the_file_and_the_entry(store_recording, tmp_path, capsys, text, message):
    path = tmp_path / "result.jsonl"
    path.write_text(text)
    status = main(["--no-progress", "score", str(store_recording), str(path)])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT and len(err.splitlines()) == 1, err
    assert f"{path}: " in err and message in err, err


def test_written_json_lines_read_back_to_the_same_outputs(tmp_path):
    pose = np.full((17, 3), 0.5)
    pose[2] = np.nan
    outputs = [TrackerOutput(0.1, "c", [], np.zeros(0, np.int64)),
               TrackerOutput(0.2, "c", [Target(4, pose, 0.2), Target(9, pose + 1, 0.2)], np.zeros(0, np.int64))]
    text = json_lines(outputs)
    assert len(text.splitlines()) == 3
    (tmp_path / "r.jsonl").write_text(text)
    back = read_results(tmp_path / "r.jsonl", COCO17, (0.0, 1.0))
    assert [(o.stamp_s, [t.id for t in o.targets]) for o in back] == [(0.1, []), (0.2, [4, 9])]
    np.testing.assert_array_equal(back[1].targets[1].pose, pose + 1)
    with pytest.raises(ResultError):
        read_results(tmp_path / "r.jsonl", CAMPUS14, (0.0, 1.0))


def test_a_result_file_that_is_not_utf8_or_holds_nan_is_one_line(tmp_path):
    (tmp_path / "r.json").write_bytes(b"\xff\xfe[")
    with pytest.raises(ResultError, match=r"r\.json: not UTF-8 text \(byte 0\)"):
        read_results(tmp_path / "r.json", COCO17, (0.0, 1.0))
    (tmp_path / "r.jsonl").write_text('{"stamp_s": 0.5, "id": 1, "joints": [[NaN, NaN, NaN]]}\n')
    with pytest.raises(ResultError, match=r"r\.jsonl: line 1: NaN is not a JSON number"):
        read_results(tmp_path / "r.jsonl", COCO17, (0.0, 1.0))
