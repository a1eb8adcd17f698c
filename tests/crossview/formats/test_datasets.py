"""The published dataset layout: cameras, frames, truth, results, conversion, and the tracker on real Campus data."""

import json
from pathlib import Path

import numpy as np
import pytest

from core.layouts import coco17_to_campus14
from core.types import CAMPUS14, Frame
from crossview import pipeline, recording
from crossview.cli import main
from crossview.formats.datasets import (
    DatasetError,
    convert,
    load_cameras,
    load_frames,
    load_truth_3d,
    skeleton_of,
    write_result_3d,
)
from crossview.scoring.campus import evaluate
from sim.scenario import from_source_text
from tests.reference.detector import detect_visible
from tracker.config import TrackerConfig
from tracker.geometry import project
from tracker.tracker import Tracker
from tracker.types import Target, TrackerOutput


def _tiny_dataset(root: Path) -> Path:
    """Two cameras 3 m apart looking along +y, 100x80 images, one annotated person in two frames."""
    root.mkdir()
    K = [[0.5, 0.0, 0.5], [0.0, 0.625, 0.5], [0.0, 0.0, 1.0]]  # f = 50 px, centre (50, 40)
    # Camera-to-world: camera x = world x, camera y = -world z, camera z = world y; centres in cm.
    R_wc = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]
    cams = {f"Camera{i}": {"K": K, "dist_coeffs": [0.1, 0, 0, 0],
                           "Tw": [R_wc[0] + [300.0 * i], R_wc[1] + [0.0], R_wc[2] + [100.0], [0, 0, 0, 1]]}
            for i in range(2)}
    (root / "calibration.json").write_text(json.dumps({"cameras": cams}))
    frames = {
        "Camera1/0.04.jpg": {"camera": "Camera1", "timestamp": 0.04, "poses": []},
        "Camera0/0.00.jpg": {"camera": "Camera0", "timestamp": 0.0,
                             "poses": [{"id": 7, "points_2d": [[50.0, 40.0]] * 14, "scores": [1.0] * 13 + [0.0]}]},
    }
    (root / "annotation_2d.json").write_text(json.dumps({"image_wh": [100, 80], "frames": frames}))
    truth = [{"timestamp": 0.0, "poses": [{"id": 7, "points_3d": [[0.0, 500.0, 100.0]] * 14}]},
             {"timestamp": 0.04, "poses": []}]
    (root / "annotation_3d.json").write_text(json.dumps(truth))
    return root


def test_cameras_are_in_metres_with_denormalised_intrinsics(tmp_path):
    cams = load_cameras(_tiny_dataset(tmp_path / "d"))
    assert [c.name for c in cams] == ["Camera0", "Camera1"]
    np.testing.assert_allclose(cams[1].center_world, [3.0, 0.0, 1.0])  # m
    np.testing.assert_allclose(cams[0].K, [[50, 0, 50], [0, 50, 40], [0, 0, 1]])
    assert (cams[0].width_px, cams[0].height_px) == (100, 80)
    assert not cams[0].dist.any()
    assert load_cameras(tmp_path / "d", use_distortion=True)[0].dist[0] == 0.1
    # A point 5 m straight ahead of camera 0 at its height lands on the principal point.
    np.testing.assert_allclose(project(cams[0].P, np.array([0.0, 5.0, 1.0])), [50.0, 40.0])


def test_frames_are_sorted_by_stamp_and_keep_their_camera(tmp_path):
    frames = load_frames(_tiny_dataset(tmp_path / "d"))
    assert [(f.camera, f.stamp_s, f.num_detections) for f in frames] == [("Camera0", 0.0, 1), ("Camera1", 0.04, 0)]
    assert frames[0].keypoints_px.shape == (1, 14, 2) and frames[1].keypoints_px.shape == (0, 14, 2)
    assert np.isnan(frames[0].keypoints_px[0, 13]).all()  # score 0: missing
    assert skeleton_of(frames) is CAMPUS14


def test_truth_is_in_metres_indexed_by_frame(tmp_path):
    truth = load_truth_3d(_tiny_dataset(tmp_path / "d"))
    assert len(truth) == 2
    t, ids, poses = truth[0]
    assert t == 0.0 and ids.tolist() == [7]
    np.testing.assert_allclose(poses[0, 0], [0.0, 5.0, 1.0])
    assert truth[1][2].shape == (0, 14, 3)


def test_missing_files_and_keys_are_named(tmp_path):
    with pytest.raises(DatasetError, match="calibration.json"):
        load_cameras(tmp_path)
    root = _tiny_dataset(tmp_path / "d")
    (root / "annotation_2d.json").write_text(json.dumps({"image_wh": [100, 80], "frames": {"x": {"camera": "C"}}}))
    with pytest.raises(DatasetError, match="annotation_2d.json.*'x'"):
        load_frames(root)


def test_result_file_round_trips_through_the_published_mapping(tmp_path):
    rng = np.random.default_rng(0)
    campus = rng.normal(size=(14, 3)) + np.array([0, 0, 1.0])
    coco = rng.normal(size=(17, 3))
    outputs = [
        TrackerOutput(0.04, "Camera0", [Target(1, coco, 0.04)], np.zeros(0, dtype=np.int64)),
        TrackerOutput(0.04, "Camera1", [Target(1, coco + 1.0, 0.04)], np.zeros(0, dtype=np.int64)),  # same stamp: kept
        TrackerOutput(0.0, "Camera0", [Target(2, campus, 0.0)], np.zeros(0, dtype=np.int64)),
    ]
    path = tmp_path / "r.json"
    assert write_result_3d(outputs, path) == 2
    data = json.loads(path.read_text())
    assert [e["timestamp"] for e in data] == [0.0, 0.04]
    np.testing.assert_allclose(np.array(data[1]["poses"][0]["points_3d"]), (coco + 1.0) * 100, atol=1e-3)  # cm
    # 14-joint poses come back through evaluate.py's COCO-17 mapping with their limbs unchanged.
    written = np.array(data[0]["poses"][0]["points_3d"], dtype=np.float64)  # null -> NaN
    back = coco17_to_campus14(written / 100)
    np.testing.assert_allclose(back[:12], campus[:12], atol=1e-5)  # m
    # The face joints Campus lacks are written as missing (null), never as a point at the origin.
    assert data[0]["poses"][0]["points_3d"][1] == [None, None, None]
    assert not np.any(np.all(written == 0.0, axis=-1))


def test_convert_writes_a_recording_the_tracker_can_read(tmp_path):
    from crossview import recording

    root = _tiny_dataset(tmp_path / "d")
    assert convert(root, tmp_path / "d.mcap", check_scenario=from_source_text) == 2
    rec = recording.open_recording(tmp_path / "d.mcap")
    assert rec.header.skeleton_name == "campus14"
    frames = list(rec.frames(with_poses=True))
    assert [(cf.frame.camera, cf.frame.stamp_s) for cf in frames] == [("Camera0", 0.0), ("Camera1", 0.04)]
    assert frames[0].truth.person_ids.tolist() == [7]
    np.testing.assert_allclose(frames[0].poses_at_capture.poses[0, 0], [0.0, 5.0, 1.0])
    assert len(list(rec.truth())) == 2


# ---------------------------------------------------------------- real Campus data


@pytest.fixture(scope="module")
def campus(campus_dir):
    """The Campus dataset's cameras and 2D frames: frames 300-750 from the fixture (two seconds of run-up
    before the first test frame), or the whole sequence with --campus-data."""
    return campus_dir, load_cameras(campus_dir), load_frames(campus_dir)


def test_campus_calibration_reproduces_the_2d_annotations(campus):
    root, cams, frames = campus
    by_name = {c.name: c for c in cams}
    truth = {round(t, 2): dict(zip(ids.tolist(), poses)) for t, ids, poses in load_truth_3d(root)}
    ann = json.loads((root / "annotation_2d.json").read_text())["frames"]
    errors = []
    for item in ann.values():
        people = truth.get(round(item["timestamp"], 2), {})
        for pose in item["poses"]:
            if pose["id"] in people:
                x = project(by_name[item["camera"]].P, people[pose["id"]])
                errors.append(np.linalg.norm(x - np.array(pose["points_2d"]), axis=-1))
    assert np.median(np.concatenate(errors)) < 1.0  # px (README: 0.3 px)


def _campus_pcp(root, cams, frames, tmp_path):
    tracker = Tracker(cams, TrackerConfig.preset("campus"), CAMPUS14)
    outputs = []
    for frame in frames:
        tracker.update(frame)
        outputs.append(tracker.last_output)
    write_result_3d(outputs, tmp_path / "result_3d.json")
    return evaluate(root, tmp_path / "result_3d.json")


def test_campus_pcp_from_ground_truth_2d_joints(campus, tmp_path):
    root, cams, frames = campus
    result = _campus_pcp(root, cams, frames, tmp_path)
    assert result["average"] >= 0.99


def _typical_detector(frames, cams, seed):
    """The simulator's `typical` detector errors (noise, misses, gross errors, swaps) on the true 2D joints."""
    from core.records import Capture, PoseTruth
    from sim.sensing.detector import Detector
    from sim.sensing.profiles import DetectorConfig

    detector = Detector(DetectorConfig(), list(cams), np.random.default_rng(seed), skeleton=CAMPUS14)
    index = {c.name: i for i, c in enumerate(cams)}
    noisy = []
    for frame in frames:
        cam = cams[index[frame.camera]]
        px = frame.keypoints_px
        D, J = px.shape[:2]
        inside = np.isfinite(px[..., 0]) & (px[..., 0] >= 0) & (px[..., 0] < cam.width_px)
        inside &= (px[..., 1] >= 0) & (px[..., 1] < cam.height_px)
        clear = np.zeros((D, J), dtype=bool)
        poses = PoseTruth(frame.stamp_s, np.arange(D), np.zeros((D, J, 3)))
        request = Capture(index[frame.camera], poses, frame.stamp_s, frame.stamp_s, frame.stamp_s)
        out = detect_visible(detector, [request], [(px, inside, clear, clear)])[0]
        noisy.append(Frame(frame.camera, frame.stamp_s, out.frame.keypoints_px, out.frame.scores))
    return noisy


def test_campus_pcp_with_typical_detector_noise(campus, tmp_path):
    root, cams, frames = campus
    result = _campus_pcp(root, cams, _typical_detector(frames, cams, seed=0), tmp_path)
    # The paper's tracker scored 0.966 on Campus with a real detector. `typical`'s 2D errors alone (without the
    # detector's own joints, which need 3D poses) on the annotated joints: fitted to a table of OpenPose on Shelf
    # measured by another script (gross errors 0.73 %), they scored 0.959 on the fixture's short cut; refitted
    # to OpenPose as detector-stats measures it (gross errors 2.27 %, lasting about 0.8 s) they score 0.884:
    # a lasting gross error in one of Campus's three views costs the limb. Not more than about 8 points below
    # the paper's real-detector figure (docs/sensor-model.md, "Calibration of typical").
    assert result["average"] >= 0.87


# ---------------------------------------------------------------------------------------------- export
def _frames_equal(a, b) -> bool:
    """Same camera, stamp, times, scores and usable joints (a joint with score 0 or NaN is missing in both)."""
    usable_a = np.isfinite(a.frame.keypoints_px).all(-1) & (a.frame.scores > 0)
    usable_b = np.isfinite(b.frame.keypoints_px).all(-1) & (b.frame.scores > 0)
    return (a.frame.camera == b.frame.camera and a.frame.stamp_s == b.frame.stamp_s
            and (a.truth.capture_s, a.truth.delivery_s) == (b.truth.capture_s, b.truth.delivery_s)
            and np.array_equal(usable_a, usable_b)
            and np.array_equal(a.frame.keypoints_px[usable_a], b.frame.keypoints_px[usable_b])
            and np.array_equal(a.frame.scores[usable_a], b.frame.scores[usable_b])
            and np.array_equal(a.truth.person_ids, b.truth.person_ids))


@pytest.fixture(scope="module")
def round_trip(store_recording, tmp_path_factory):
    """The store recording exported to the dataset layout and converted back."""
    root = tmp_path_factory.mktemp("round_trip")
    assert main(["--no-progress", "export", str(store_recording), "--format", "dataset", "-o", str(root / "d")]) == 0
    assert main(["--no-progress", "convert", str(root / "d"), "-o", str(root / "back.mcap")]) == 0
    return root / "d", root / "back.mcap"


def test_the_export_holds_the_published_files_with_frames_in_delivery_order(store_recording, round_trip):
    folder, _ = round_trip
    assert sorted(p.name for p in folder.iterdir()) == [
        "annotation_2d.json", "annotation_3d.json", "calibration.json", "detection.json", "scene.json"]
    detection = json.loads((folder / "detection.json").read_text())
    delivered = [f["delivery_s"] for f in detection["frames"].values()]
    original = list(recording.open_recording(store_recording).frames())
    assert delivered == [cf.truth.delivery_s for cf in original]
    assert [f.stamp_s for f in load_frames(folder)] == [cf.frame.stamp_s for cf in original]
    # The stamps are not in delivery order: the layout's own order (by timestamp) would change the input.
    assert delivered == sorted(delivered) and [cf.frame.stamp_s for cf in original] != sorted(
        cf.frame.stamp_s for cf in original)


def test_convert_of_the_export_gives_back_the_recording(store_recording, round_trip):
    _, back = round_trip
    a, b = recording.open_recording(store_recording), recording.open_recording(back)
    assert (b.header.scenario_name, b.header.seed, b.header.duration_s) == ("store_layout1", 0, 6.0)
    assert b.boxes == a.boxes
    for ca, cb in zip(a.cameras, b.cameras, strict=True):
        assert ca.name == cb.name and np.array_equal(ca.dist, cb.dist)
        for x, y in ((ca.K, cb.K), (ca.R_cam_from_world, cb.R_cam_from_world)):
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-12)
        np.testing.assert_allclose(ca.t_cam_from_world, cb.t_cam_from_world, rtol=0, atol=1e-12)  # m
    frames_a, frames_b = list(a.frames()), list(b.frames())
    assert len(frames_a) == len(frames_b) and all(_frames_equal(x, y) for x, y in zip(frames_a, frames_b))
    truth_a, truth_b = list(a.truth()), list(b.truth())
    assert [t.t_s for t in truth_a] == [t.t_s for t in truth_b]
    for x, y in zip(truth_a, truth_b):
        assert np.array_equal(x.person_ids, y.person_ids)
        np.testing.assert_allclose(x.poses, y.poses, rtol=0, atol=1e-12)  # m


def _numbers(value, prefix=""):
    """{dotted key: number} of every number in a score JSON (nested dicts and lists flattened)."""
    if isinstance(value, dict):
        return {k: v for key, item in value.items() for k, v in _numbers(item, f"{prefix}{key}.").items()}
    if isinstance(value, list):
        return {k: v for i, item in enumerate(value) for k, v in _numbers(item, f"{prefix}{i}.").items()}
    return {prefix[:-1]: value} if isinstance(value, (int, float)) and not isinstance(value, bool) else {}


# Every shipped scenario, short: (name, seconds, people or None for the scenario's own). The hypermarket keeps
# its 240 cameras but 20 of its 200 people, which alone take 20 s to set up.
ROUND_TRIPS = [("campus", 1.0, None), ("store_layout1", 1.0, None), ("store_layout2", 1.0, None),
               ("panoptic_dome", 0.5, None), ("supermarket", 0.5, None), ("hypermarket", 0.5, 20)]


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize(("name", "duration_s", "people"), ROUND_TRIPS, ids=[r[0] for r in ROUND_TRIPS])
def test_export_convert_track_score_gives_the_scores_of_the_original(name, duration_s, people, seed, tmp_path):
    # A recording of the scenario, its export in the dataset layout, and that converted back (export writes the
    # cameras' own stamps, some below 0; convert must take every one).
    original, back = tmp_path / "a.mcap", tmp_path / "b.mcap"
    pipeline.generate(pipeline.load_scenario(name, duration_s=duration_s, seed=seed, people=people), original,
                      progress=False)
    assert main(["--no-progress", "export", str(original), "--format", "dataset", "-o", str(tmp_path / "d")]) == 0
    assert main(["--no-progress", "convert", str(tmp_path / "d"), "-o", str(back)]) == 0
    # Both tracked and scored the same way give the same scores; the calibration (cm, K normalised by the image
    # size) and the 3D truth (cm) cross JSON as decimals, so the numbers agree to rounding.
    scores = []
    for rec in (original, back):
        pipeline.track(rec, rec.with_suffix(".tracks.mcap"), progress=False)
        scores.append(_numbers(pipeline.score(rec, rec.with_suffix(".tracks.mcap"), progress=False)[1]))
    timing = ("tracker_fps", "camera_frames_per_s")
    a, b = ({k: v for k, v in s.items() if not k.startswith(timing)} for s in scores)
    assert a.keys() == b.keys() and a["eval_instants"] > 0
    for key in a:
        assert b[key] == pytest.approx(a[key], rel=1e-9, abs=1e-9), key


def test_export_refuses_a_folder_that_holds_files_and_leaves_nothing(store_recording, tmp_path, capsys):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "mine.txt").write_text("keep")
    status = main(["export", str(store_recording), "--format", "dataset", "-o", str(tmp_path / "d")])
    err = capsys.readouterr().err.strip()
    assert status == 2 and "d: exists and is not an empty folder" in err and len(err.splitlines()) == 1
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["d", "mine.txt"]
