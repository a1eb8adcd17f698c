"""The published Campus PCP protocol: the paper's own result reproduced, export round trip, bad input."""

import json
from pathlib import Path

import numpy as np
import pytest

from core.layouts import coco17_to_campus14
from crossview.formats.datasets import DatasetError, write_result_3d
from crossview.scoring.campus import DatasetLayoutError, evaluate, format_evaluation
from tracker.types import Target, TrackerOutput

CAMPUS = Path(__file__).resolve().parents[2] / "data" / "campus"  # the fixture cut from the dataset


def test_paper_campus_result_reproduces_published_pcp(campus_dir):
    # Table 2 of Chen et al. (Campus, 96.6): the authors' own result file scored with the protocol, from the
    # fixture (the entries evaluate.py can pick for a test frame) and, when given, from the whole file.
    result = evaluate(campus_dir, campus_dir / "result_3d.json")
    assert result["num_frames"] == 222
    actors = [result["actors"][k] for k in sorted(result["actors"])]
    np.testing.assert_allclose(actors, [0.9714, 0.9413, 0.9862], atol=1e-4)
    assert result["average"] == pytest.approx(0.9663, abs=1e-4)
    # The per-group table of evaluate.py: lower arms are the only weak group.
    assert result["groups"]["torso"]["average"] == pytest.approx(1.0)
    assert result["groups"]["lower_arms"]["average"] == pytest.approx(0.8464, abs=1e-4)
    text = format_evaluation(result)
    assert "0.9714" in text and "0.9413" in text and "0.9862" in text and "0.9663" in text


def _write_dataset(root: Path, poses_by_frame: list[list[tuple[int, np.ndarray]]]) -> Path:
    """Writes an annotation_3d.json (14 joints, cm) at 25 fps into root."""
    root.mkdir(parents=True, exist_ok=True)
    anno = [
        {"timestamp": i * 0.04, "poses": [{"id": pid, "points_3d": p.tolist()} for pid, p in frame]}
        for i, frame in enumerate(poses_by_frame)
    ]
    (root / "annotation_3d.json").write_text(json.dumps(anno))
    return root


def test_exported_tracks_score_pcp_one_on_their_own_truth(tmp_path):
    # Two people as COCO-17 poses in metres; the truth is their 14-joint mapping in centimetres.
    rng = np.random.default_rng(7)
    base = {1: rng.normal(0, 0.3, (17, 3)) + [0, 0, 1], 2: rng.normal(0, 0.3, (17, 3)) + [3, 0, 1]}
    frames, outputs = [], []
    for i in range(10):
        shift = np.array([0.02 * i, 0.0, 0.0])
        frames.append([(pid, coco17_to_campus14((p + shift) * 100.0)) for pid, p in base.items()])
        targets = [Target(pid * 10, p + shift, i * 0.04) for pid, p in base.items()]
        outputs.append(TrackerOutput(i * 0.04, "Camera0", targets, np.zeros(0, dtype=np.int64)))
    root = _write_dataset(tmp_path / "synthetic", frames)
    # Export, then score with the protocol on every frame.
    assert write_result_3d(outputs, tmp_path / "result_3d.json") == 10
    result = evaluate(root, tmp_path / "result_3d.json", test_frames=range(10))
    assert result["actors"] == {1: pytest.approx(1.0), 2: pytest.approx(1.0)}


def test_export_writes_centimetres_and_nulls_for_unknown_joints(tmp_path):
    pose = np.full((17, 3), 1.5)
    pose[4] = np.nan
    out = TrackerOutput(0.5, "c", [Target(3, pose, 0.5)], np.zeros(0, dtype=np.int64))
    write_result_3d([out], tmp_path / "r.json")
    entry = json.loads((tmp_path / "r.json").read_text())[0]
    assert entry["timestamp"] == 0.5 and entry["poses"][0]["id"] == 3
    pts = np.asarray(entry["poses"][0]["points_3d"])
    assert pts[0].tolist() == [150.0, 150.0, 150.0] and pts[4].tolist() == [None, None, None]  # missing


def test_missing_result_file_is_a_one_line_layout_error(tmp_path):
    with pytest.raises(DatasetError, match="result file not found"):
        evaluate(CAMPUS, tmp_path / "nope.json")


def test_result_with_wrong_joint_count_is_rejected(tmp_path):
    (tmp_path / "r.json").write_text(json.dumps([{"timestamp": 0.0, "poses": [{"id": 1, "points_3d": [[0, 0, 0]]}]}]))
    with pytest.raises(DatasetLayoutError, match=r"expected \(17, 3\)"):
        evaluate(CAMPUS, tmp_path / "r.json")


def test_unknown_dataset_name_asks_for_test_frames(tmp_path):
    root = _write_dataset(tmp_path / "mystery", [[]])
    (tmp_path / "r.json").write_text("[]")
    with pytest.raises(DatasetLayoutError, match="name the folder after its dataset"):
        evaluate(root, tmp_path / "r.json")


def test_a_result_joint_is_three_numbers_or_three_nulls(tmp_path):
    points = [[0.0, 0.0, 0.0]] * 17
    missing = [*points[:3], [None, None, None], *points[4:]]  # as `crossview export` writes an unknown joint
    (tmp_path / "r.json").write_text(json.dumps([{"timestamp": 0.0, "poses": [{"id": 1, "points_3d": missing}]}]))
    evaluate(CAMPUS, tmp_path / "r.json")  # read: the missing joint is no correct part, not an error
    half = [*points[:3], [None, 0.0, 0.0], *points[4:]]
    (tmp_path / "r.json").write_text(json.dumps([{"timestamp": 0.0, "poses": [{"id": 1, "points_3d": half}]}]))
    with pytest.raises(DatasetLayoutError, match=r"entry 0 id 1: points_3d hold a joint that is neither three finite"):
        evaluate(CAMPUS, tmp_path / "r.json")
