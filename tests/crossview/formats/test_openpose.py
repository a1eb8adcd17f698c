"""OpenPose JSON folders: the joint maps by name, stamps, errors, and a recording's round trip through them."""

import json
import shutil

import numpy as np
import pytest

from core.types import COCO17
from crossview import pipeline, recording
from crossview.cli import EXIT_BAD_INPUT, main
from crossview.formats.openpose import BODY_25_FROM_COCO17, COCO_18_FROM_COCO17, body_25, read_frames

# OpenPose's own joint names (doc/02_output.md of CMU-Perceptual-Computing-Lab/openpose).
BODY_25 = ("Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist", "MidHip", "RHip",
           "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle", "REye", "LEye", "REar", "LEar", "LBigToe", "LSmallToe",
           "LHeel", "RBigToe", "RSmallToe", "RHeel")
COCO_18 = ("Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist", "RHip", "RKnee",
           "RAnkle", "LHip", "LKnee", "LAnkle", "REye", "LEye", "REar", "LEar")


def _openpose_name(coco17_joint: str) -> str:
    side, _, part = coco17_joint.partition("_")
    return "Nose" if coco17_joint == "nose" else side[0].upper() + part.capitalize()


@pytest.mark.parametrize("names, table", [(BODY_25, BODY_25_FROM_COCO17), (COCO_18, COCO_18_FROM_COCO17)])
def test_each_coco17_joint_comes_from_the_openpose_joint_of_its_name(names, table):
    assert [names[i] for i in table] == [_openpose_name(j) for j in COCO17.joints]


def _write(folder, name, people):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_text(json.dumps({"version": 1.3, "people": people}))


def test_coco18_files_read_as_coco17_with_stamps_from_the_frame_rate(tmp_path):
    flat = np.zeros((18, 3))
    flat[COCO_18.index("LWrist")] = [10.0, 20.0, 0.9]
    flat[COCO_18.index("Nose")] = [5.0, 6.0, 0.5]
    _write(tmp_path / "camA", "video_000000000004_keypoints.json", [{"pose_keypoints_2d": flat.ravel().tolist()}])
    _write(tmp_path / "camA", "video_000000000002_keypoints.json", [])
    frames = read_frames(tmp_path, fps=25.0)
    assert [(key, f.stamp_s, delivery) for key, f, delivery in frames] == [
        ("camA/video_000000000002_keypoints.json", 0.08, 0.08), ("camA/video_000000000004_keypoints.json", 0.16, 0.16)]
    frame = frames[1][1]
    assert frame.keypoints_px.shape == (1, 17, 2) and frame.num_detections == 1
    assert frame.keypoints_px[0, COCO17.index("left_wrist")].tolist() == [10.0, 20.0]
    assert frame.scores[0, COCO17.index("nose")] == 0.5
    assert np.isnan(frame.keypoints_px[0, COCO17.index("right_wrist")]).all()


def test_body25_written_from_coco17_reads_back_the_same_joints(tmp_path):
    rng = np.random.default_rng(0)
    kp, scores = rng.uniform(0, 500, (17, 2)), rng.uniform(0.1, 1, 17)
    kp[3] = np.nan
    _write(tmp_path / "c", "c_000000000000_keypoints.json", [{"pose_keypoints_2d": body_25(kp, scores)}])
    (_, frame, _), = read_frames(tmp_path, fps=10.0)
    np.testing.assert_array_equal(frame.keypoints_px[0], kp)
    np.testing.assert_array_equal(frame.scores[0], np.where(np.isnan(kp[:, 0]), 0.0, scores))


@pytest.mark.parametrize("people, fps, message", [
    ([{"pose_keypoints_2d": [1.0] * 45}], 10.0, "person 0: 45 values in pose_keypoints_2d; expected BODY_25"),
    ([], None, "frame 0 has no stamp: list it in timestamps.json or give the frame rate (--fps)"),
])
def test_a_bad_openpose_folder_is_one_line_naming_the_file(store_recording, tmp_path, capsys, people, fps, message):
    folder = tmp_path / "op"
    assert main(["--no-progress", "export", str(store_recording), "--format", "openpose", "-o", str(folder)]) == 0
    (folder / "timestamps.json").unlink()
    for path in (folder / "cam00").iterdir():
        path.unlink()
    _write(folder / "cam00", "cam00_000000000000_keypoints.json", people)
    argv = ["--no-progress", "convert", str(folder), "-o", str(tmp_path / "r.mcap")]
    status = main(argv + (["--fps", str(fps)] if fps else []))
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT and len(err.splitlines()) == 1, err
    assert "cam00_000000000000_keypoints.json: " in err and message in err, err
    assert not (tmp_path / "r.mcap").exists()


def test_a_recording_through_openpose_folders_tracks_and_scores_the_same(store_recording, store_tracks, tmp_path):
    folder, back = tmp_path / "op", tmp_path / "back.mcap"
    assert main(["--no-progress", "export", str(store_recording), "--format", "openpose", "-o", str(folder)]) == 0
    assert len(list((folder / "cam00").glob("*_keypoints.json"))) > 0
    assert main(["--no-progress", "convert", str(folder), "-o", str(back)]) == 0
    original, converted = list(recording.open_recording(store_recording).frames()), list(
        recording.open_recording(back).frames())
    assert [(f.frame.camera, f.frame.stamp_s, f.truth.delivery_s) for f in converted] == [
        (f.frame.camera, f.frame.stamp_s, f.truth.delivery_s) for f in original]
    pipeline.track(back, tmp_path / "t.mcap", progress=False)
    _, before = pipeline.score(store_recording, store_tracks, progress=False)
    _, after = pipeline.score(back, tmp_path / "t.mcap", progress=False)
    for key in ("pcp", "pck_100mm", "mota", "idf1", "id_switches", "hota", "num_people"):
        assert after[key] == before[key], key
    assert after["mpjpe_mm"] == pytest.approx(before["mpjpe_mm"], abs=1e-9)
    assert after["association_accuracy"] is None  # OpenPose's output says nothing of who each detection is


@pytest.fixture(scope="module")
def exported(store_recording, tmp_path_factory):
    """`store_recording` exported as OpenPose folders (COCO-17 frames with 17-joint 3D truth and scene.json)."""
    folder = tmp_path_factory.mktemp("exported") / "op"
    assert main(["--no-progress", "export", str(store_recording), "--format", "openpose", "-o", str(folder)]) == 0
    return folder


def _first_keypoints(folder):
    return sorted((folder / "cam00").iterdir())[0]


def _set_people(people):
    def change(folder):
        _first_keypoints(folder).write_text(json.dumps({"version": 1.3, "people": people}))
    return change


def _set_json(name, change):
    def apply(folder):
        data = json.loads((folder / name).read_text())
        changed = change(data)
        (folder / name).write_text(json.dumps(data if changed is None else changed))
    return apply


def _rename_first(folder):
    _first_keypoints(folder).rename(folder / "cam00" / f"cam00_{'9' * 40}_keypoints.json")


# (id, change to the exported folder, the file the line names, what it must say; --fps where given)
DAMAGED = [
    ("timestamp-1e300", _set_json("timestamps.json", lambda d: d["cam00"]["stamp_s"].__setitem__(0, 1e300)),
     "timestamps.json", "camera 'cam00': stamp_s[0]: timestamp 1e+300 must be in [0, 4e+09] s", None),
    ("timestamps-a-list", _set_json("timestamps.json", lambda d: []), "timestamps.json",
     "must be an object of camera name -> {stamp_s, delivery_s}, got list", None),
    ("delivery-a-string", _set_json("timestamps.json", lambda d: d["cam01"].update(delivery_s="late")),
     "timestamps.json", "camera 'cam01': delivery_s must be an array of seconds", None),
    ("person-not-an-object", _set_people([1]), "_keypoints.json", "person 0 must be an object", None),
    ("keypoints-not-numbers", _set_people([{"pose_keypoints_2d": ["a"] * 75}]), "_keypoints.json",
     "person 0: pose_keypoints_2d must be a flat array of numbers", None),
    ("keypoints-huge", _set_people([{"pose_keypoints_2d": [1e300] * 75}]), "_keypoints.json",
     "must be finite and within 1e+06", None),
    ("frame-number-huge", _rename_first, "_keypoints.json", "frame number 9999999999", None),
    ("fps-tiny", lambda folder: (folder / "timestamps.json").unlink(), "_keypoints.json",
     "must be in [0, 4e+09] s", "1e-300"),
    ("camera-pose-all-zero", _set_json("calibration.json", lambda d: d["cameras"]["cam00"].update(
        Tw=[[0.0] * 4] * 4)), "calibration.json", "camera 'cam00': Tw: the rotation", None),
    ("camera-pose-mirrored", _set_json("calibration.json", lambda d: d["cameras"]["cam00"]["Tw"][0].__setitem__(
        slice(0, 3), [-x for x in d["cameras"]["cam00"]["Tw"][0][:3]])), "calibration.json", "det -1", None),
    ("truth-not-a-list", _set_json("annotation_3d.json", lambda d: {"poses": d}), "annotation_3d.json",
     "the file (a list of {timestamp, poses} entries) must be an array, got dict", None),
    ("scene-a-list", _set_json("scene.json", lambda d: [d]), "scene.json", "the file must be an object, got list",
     None),
    ("scene-huge-seed", _set_json("scene.json", lambda d: d.update(seed=2**70)), "scene.json",
     f"seed {2**70} must be an integer in [0, 2^63)", None),
    ("scene-text-no-scenario", _set_json("scene.json", lambda d: d.update(scenario_text="[crowd]\npeople = -3\n")),
     "scene.json", "scenario_text: [crowd] people: -3 must be in [0, 2000]", None),
]


@pytest.mark.parametrize("change, named, message, fps", [c[1:] for c in DAMAGED], ids=[c[0] for c in DAMAGED])
def test_a_damaged_openpose_or_dataset_file_is_one_line_naming_it(exported, tmp_path, capsys, change, named, message,
                                                                  fps):
    """Every file of an OpenPose folder (and the dataset layout's files beside it) is checked as it is read: a
    stamp of 1e300, a pose that is no rotation, a truth file or scene.json of the wrong shape are named, not
    dropped in silence or left to fail later with a traceback."""
    folder = tmp_path / "op"
    shutil.copytree(exported, folder)
    change(folder)
    out = tmp_path / "r.mcap"
    status = main(["--no-progress", "convert", str(folder), "-o", str(out)] + (["--fps", fps] if fps else []))
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT and len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert f"{named}: " in err and message in err, err
    assert not out.exists()
