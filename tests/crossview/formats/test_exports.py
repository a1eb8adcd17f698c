"""The motion and tracking exports, each read back by an independent reader: BVH by bvhio (forward kinematics),
TRC parsed as its text layout, C3D by ezc3d, MOT scored by TrackEval against `crossview score`, COCO by pycocotools."""

import dataclasses
import json

import numpy as np
import pytest

from core.types import COCO17
from crossview import pipeline
from crossview.cli import main
from crossview.formats.motion import (
    BVH_JOINT_NAMES,
    Y_UP,
    ExportError,
    bvh_person,
    read_motion,
    tracks_motion,
)
from crossview.recording import TracksWriter, open_recording, open_tracks
from tests.reference.exports import CHAIN, bvh_errors, disturbed_tracks
from tracker.types import Target, TargetState, TrackerOutput

_FLOAT32_CM = 1e-3  # bvhio computes in float32: 0.01 mm at a few metres


def _export(args, capsys):
    status = main(["--no-progress", "export", *map(str, args)])
    out, err = capsys.readouterr()
    assert status == 0, err
    return out


@pytest.mark.parametrize("which", ["truth", "tracks"])
def test_bvh_read_back_by_bvhio_is_the_source_within_the_bone_length_change(which, store_recording, store_tracks,
                                                                             tmp_path, capsys):
    src = store_recording if which == "truth" else store_tracks
    out = _export([src, "--format", "bvh", "-o", tmp_path / "bvh"], capsys)
    motion = read_motion(src)
    assert len(out.splitlines()) == len(motion.people) >= 3
    for person in sorted(motion.people):
        step = 3 if which == "truth" else 1  # (bvhio poses a frame in about 3 ms: every 3rd of the truth's 100 Hz)
        errors, bounds, bones = bvh_errors(motion, person, tmp_path / "bvh" / f"person_{person}.bvh", step)
        assert np.all(errors <= bounds + _FLOAT32_CM)
        constant = [j for j, name in enumerate(BVH_JOINT_NAMES)
                    if all(np.ptp(bones[b]) < 1e-6 for b in CHAIN[name])]
        assert 0 in constant and np.all(errors[:, constant] <= 0.1)  # 1 mm where the lengths are constant
        if which == "truth":
            assert np.all(errors <= 1.0)  # the truth's bones change by under 1 cm (the neck: the nose nods)


def test_bvh_rest_pose_is_y_up_with_the_documented_channels(store_recording, tmp_path, capsys):
    _export([store_recording, "--format", "bvh", "-o", tmp_path / "bvh"], capsys)
    text = (tmp_path / "bvh" / "person_0.bvh").read_text()
    assert "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation" in text
    assert text.count("CHANNELS 3 Zrotation Xrotation Yrotation") == len(BVH_JOINT_NAMES) - 1
    offsets = {}
    name = None
    for line in text.splitlines():
        words = line.split()
        if words[:1] in (["ROOT"], ["JOINT"]):
            name = words[1]
        elif words[:1] == ["OFFSET"] and name:
            offsets[name] = np.array(words[1:], dtype=float)
            name = None
    assert offsets["Head"][1] > 0 and offsets["Chest"][1] > 0  # up is +Y
    assert offsets["LeftLeg"][1] < 0 and offsets["LeftUpLeg"][0] > 0  # legs down, the left at +X


def test_bvh_of_a_person_never_seen_whole_is_one_line_naming_the_person(store_recording):
    motion = read_motion(store_recording)
    person = sorted(motion.people)[0]
    motion.people[person][:, COCO17.index("left_knee")] = np.nan
    with pytest.raises(ExportError, match=f"person {person}: never seen with all 13 joints.*never known: left_knee"):
        bvh_person(motion, person)


def test_trc_is_pose2sims_layout_and_parses_back_to_the_truth(store_recording, tmp_path, capsys):
    _export([store_recording, "--format", "trc", "-o", tmp_path / "trc"], capsys)
    motion = read_motion(store_recording)
    person = sorted(motion.people)[1]
    lines = (tmp_path / "trc" / f"person_{person}.trc").read_text().split("\n")
    assert lines[0].split("\t") == ["PathFileType", "4", "(X/Y/Z)", f"person_{person}.trc"]
    head = dict(zip(lines[1].split("\t"), lines[2].split("\t")))
    assert head["Units"] == "m" and float(head["DataRate"]) == pytest.approx(100.0)
    names = [n for n in lines[3].split("\t")[2:] if n]
    assert names[:3] == ["Nose", "LEye", "REye"] and names[-2:] == ["LAnkle", "RAnkle"] and len(names) == 17
    assert lines[4].split("\t")[2:5] == ["X1", "Y1", "Z1"]
    table = np.array([[float(c) if c else np.nan for c in line.split("\t")] for line in lines[5:] if line])
    assert int(head["NumFrames"]) == len(table) and np.array_equal(table[:, 0], np.arange(1, len(table) + 1))
    np.testing.assert_allclose(table[:, 1], motion.times_of(person), atol=1e-6)
    expected = (motion.people[person] @ Y_UP.T).reshape(len(table), -1)
    error = np.abs(table[:, 2:] - expected)
    assert np.nanmax(error) <= 1e-6 and np.array_equal(np.isnan(table[:, 2:]), np.isnan(expected))


def test_c3d_read_back_by_ezc3d_is_the_truth(store_recording, tmp_path, capsys):
    ezc3d = pytest.importorskip("ezc3d")
    _export([store_recording, "--format", "c3d", "-o", tmp_path / "c3d"], capsys)
    motion = read_motion(store_recording)
    for person in sorted(motion.people):
        c = ezc3d.c3d(str(tmp_path / "c3d" / f"person_{person}.c3d"))
        point = c["parameters"]["POINT"]
        assert point["LABELS"]["value"][:2] == ["Nose", "LEye"] and point["UNITS"]["value"] == ["mm"]
        assert point["RATE"]["value"][0] == pytest.approx(100.0)
        read = c["data"]["points"][:3].transpose(2, 1, 0)  # (frames, markers, xyz), mm
        expected = motion.people[person] * 1000.0
        assert read.shape == expected.shape
        assert np.max(np.abs(read - expected)) < 0.01  # float32 in the file: 0.01 mm at a few metres


def test_c3d_without_its_extra_says_which_to_install(store_recording, tmp_path, capsys, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_c3d(name, *args, **kwargs):
        if name == "c3d":
            raise ImportError("no c3d")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_c3d)
    status = main(["--no-progress", "export", str(store_recording), "--format", "c3d", "-o", str(tmp_path / "c")])
    err = capsys.readouterr().err
    assert status == 2 and len(err.splitlines()) == 1 and "crossview-testbed[c3d]" in err
    assert not (tmp_path / "c").exists()


@pytest.mark.parametrize("from_s", [0.0, 2.0], ids=["whole", "warm-up"])
def test_mot_export_scored_by_trackeval_equals_crossview_score(from_s, store_recording, store_tracks, tmp_path,
                                                               capsys):
    from examples.trackeval_mot import score as trackeval_score

    tracks = disturbed_tracks(store_tracks, tmp_path / "disturbed.mcap")
    out = _export([tracks, "--recording", store_recording, "--format", "mot", "--from", from_s, "-o",
                   tmp_path / "mot"], capsys)
    assert "sequence store_layout1-s0" in out
    report, _ = pipeline.score(store_recording, tracks, progress=False, worker_process=False, from_s=from_s)
    (key, te), = trackeval_score(tmp_path / "mot").items()
    assert key == ("disturbed", "store_layout1-s0")
    assert report.id_switches >= 2 and report.false_positives > 5 and report.false_negatives > 5
    assert te["IDSW"] == report.id_switches and te["FP"] == report.false_positives
    assert te["FN"] == report.false_negatives
    for ours, theirs in ((report.mota, te["MOTA"]), (report.idf1, te["IDF1"]), (report.hota, te["HOTA"]),
                         (report.motp_m, te["MOTP_m"]), (report.deta, te["DetA"]), (report.assa, te["AssA"])):
        assert theirs == pytest.approx(ours, abs=1e-3)


def test_mot_of_a_tracks_file_without_its_recording_is_one_line(store_tracks, tmp_path, capsys):
    status = main(["--no-progress", "export", str(store_tracks), "--format", "mot", "-o", str(tmp_path / "m")])
    err = capsys.readouterr().err
    assert status == 2 and len(err.splitlines()) == 1 and "--recording" in err and str(store_tracks) in err
    assert not (tmp_path / "m").exists()


def test_coco_read_back_by_pycocotools(store_recording, tmp_path, capsys):
    pytest.importorskip("pycocotools")
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    _export([store_recording, "--format", "coco", "-o", tmp_path / "coco"], capsys)
    rec = open_recording(store_recording)
    camera = rec.cameras[0].name
    frames = [cf for cf in rec.frames() if cf.frame.camera == camera]
    gt = COCO(str(tmp_path / "coco" / f"{camera}_keypoints.json"))
    assert sorted(gt.getImgIds()) == list(range(1, len(frames) + 1))
    # Projected truth against the simulator's own true 2D joints of each detected person (another path).
    worst = 0.0
    for image_id, cf in enumerate(frames, start=1):
        anns = {a["person_id"]: np.reshape(a["keypoints"], (-1, 3)) for a in gt.loadAnns(gt.getAnnIds(image_id))}
        for pid, true_px in zip(cf.truth.person_ids, cf.truth.keypoints_px):
            if pid < 0 or pid not in anns:
                continue
            seen = np.isfinite(true_px).all(axis=1) & (anns[pid][:, 2] == 2)
            if seen.any():
                worst = max(worst, float(np.max(np.abs(anns[pid][seen, :2] - true_px[seen]))))
    assert worst < 1e-6
    # ... and against OpenCV's projection of the truth at each frame's capture (an independent camera model).
    import cv2

    cam = rec.cameras[0]
    rvec, _ = cv2.Rodrigues(cam.R_cam_from_world)
    worst, joints = 0.0, 0
    for image_id, cf in enumerate((cf for cf in rec.frames(with_poses=True) if cf.frame.camera == camera), start=1):
        anns = {a["person_id"]: np.reshape(a["keypoints"], (-1, 3)) for a in gt.loadAnns(gt.getAnnIds(image_id))}
        for pid, pose in zip(cf.poses_at_capture.person_ids, cf.poses_at_capture.poses):
            if int(pid) in anns:
                px, _ = cv2.projectPoints(pose.reshape(-1, 1, 3), rvec, cam.t_cam_from_world, cam.K, cam.dist)
                seen = anns[int(pid)][:, 2] == 2
                worst = max(worst, float(np.max(np.abs(px.reshape(-1, 2)[seen] - anns[int(pid)][seen, :2]))))
                joints += int(seen.sum())
    assert joints > 1000 and worst < 1e-6
    detections = json.loads((tmp_path / "coco" / f"{camera}_detections.json").read_text())
    assert len(detections) == sum(int(np.isfinite(cf.frame.keypoints_px).all(axis=-1).any(axis=-1).sum())
                                  for cf in frames)
    result = gt.loadRes(str(tmp_path / "coco" / f"{camera}_detections.json"))
    evaluation = COCOeval(gt, result, "keypoints")
    evaluation.evaluate()
    evaluation.accumulate()
    evaluation.summarize()
    capsys.readouterr()
    assert 0.1 < evaluation.stats[0] <= 1.0  # AP over OKS (0.31 on cam00): detections paired with the right images


def test_tracks_motion_takes_the_latest_output_at_each_tick():
    def out(t, x, target_id=1):
        pose = np.zeros((17, 3)) + x
        return TrackerOutput(t, "c", [Target(target_id, pose, t, TargetState.CONFIRMED)], np.zeros(0, dtype=np.int64))

    m = tracks_motion([out(0.0, 0.0), out(0.04, 1.0), out(0.05, 2.0), out(0.1, 3.0), out(0.12, 4.0, 2)], COCO17,
                      10.0)
    assert m.times.tolist() == [0.0, 0.1] and sorted(m.people) == [1]
    assert m.people[1][:, 0, 0].tolist() == [0.0, 3.0]


def test_bvh_of_a_tracks_file_with_a_person_missing_a_joint_is_one_line(store_tracks, tmp_path, capsys):
    tracks = open_tracks(store_tracks)
    first = min(t.id for out in tracks.outputs() for t in out.targets)
    broken = tmp_path / "no_knee.mcap"
    knee = COCO17.index("left_knee")
    with TracksWriter(broken, tracks.header, tracks.cameras) as writer:
        for out in tracks.outputs():
            targets = []
            for target in out.targets:
                pose = np.array(target.pose)
                if target.id == first:
                    pose[knee] = np.nan
                targets.append(dataclasses.replace(target, pose=pose))
            writer.write(TrackerOutput(out.stamp_s, out.camera, targets, out.detection_target_ids))
        writer.finish(tracks.summary)
    status = main(["--no-progress", "export", str(broken), "--format", "bvh", "-o", str(tmp_path / "b")])
    err = capsys.readouterr().err
    assert status == 2 and len(err.splitlines()) == 1 and f"person {first}: never seen with all 13 joints" in err
    assert "never known: left_knee)" in err and not (tmp_path / "b").exists()


@pytest.mark.parametrize("fmt", ["bvh", "mot"], ids=["bvh", "mot"])
def test_an_export_into_an_unwritable_place_is_one_line_and_leaves_nothing(fmt, store_recording, tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    status = main(["--no-progress", "export", str(store_recording), "--format", fmt, "-o", str(blocker / "out")])
    err = capsys.readouterr().err
    assert status == 2 and len(err.splitlines()) == 1 and str(blocker) in err
    assert blocker.read_text() == "x" and sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]


@pytest.mark.parametrize("fmt", ["bvh", "c3d", "mot"], ids=["bvh", "c3d", "mot"])
def test_an_export_is_the_same_bytes_every_time(fmt, store_recording, tmp_path, capsys):
    pytest.importorskip("c3d")
    for name in ("a", "b"):
        _export([store_recording, "--format", fmt, "-o", tmp_path / name], capsys)
    files = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*") if p.is_file())
    assert files and files == sorted(p.relative_to(tmp_path / "b") for p in (tmp_path / "b").rglob("*") if p.is_file())
    for f in files:
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes(), f


@pytest.mark.parametrize("args, named", [
    (["--format", "trc", "--recording", "REC"], "--recording"),
    (["--format", "mot", "--rate", "25"], "--rate 25"),
    (["--format", "bvh", "--from", "2"], "--from 2"),
    (["--format", "coco", "--tracks-file"], "expected here"),
], ids=["recording-without-mot", "rate-without-motion", "from-without-mot", "coco-of-tracks"])
def test_an_export_asked_what_its_format_does_not_take_is_one_line(args, named, store_recording, store_tracks,
                                                                    tmp_path, capsys):
    src = store_tracks if "--tracks-file" in args else store_recording
    args = [str(store_recording) if a == "REC" else a for a in args if a != "--tracks-file"]
    status = main(["--no-progress", "export", str(src), *args, "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status == 2 and len(err.splitlines()) == 1 and named in err
    assert not (tmp_path / "out").exists()


def test_bvh_of_the_campus_joints_ends_the_head_at_the_top_of_the_head(store_recording, tmp_path):
    import bvhio

    from core.layouts import coco17_to_campus14
    from core.types import CAMPUS14

    motion = read_motion(store_recording)
    person = sorted(motion.people)[0]
    campus = dataclasses.replace(motion, skeleton=CAMPUS14,
                                 people={person: coco17_to_campus14(motion.people[person][:60])},
                                 first={person: 0}, times=motion.times_of(person)[:60])
    result = bvh_person(campus, person)
    (tmp_path / "p.bvh").write_text(result.text)
    root = bvhio.readAsHierarchy(str(tmp_path / "p.bvh"))
    root.loadPose(30)
    head = next(j for j, _, _ in root.layout() if j.Name == "Head")
    top = campus.people[person][30, CAMPUS14.index("top_head")] @ Y_UP.T * 100.0
    bound = result.bone_change_cm["spine"] + result.bone_change_cm["neck"] + 1e-3
    assert np.linalg.norm(np.array(tuple(head.PositionWorld)) - top) <= bound


def test_bvh_fills_a_gap_by_interpolating_the_joints_and_counts_it(store_recording):
    motion = read_motion(store_recording)
    person = sorted(motion.people)[0]
    knee = COCO17.index("left_knee")
    whole = bvh_person(motion, person)
    motion.people[person][10:21, knee] = np.nan
    gapped = bvh_person(motion, person)
    assert whole.filled_frames == 0 and gapped.filled_frames == 11 and gapped.frames == whole.frames
    rows = gapped.text.splitlines()[-gapped.frames:]
    assert rows[:10] == whole.text.splitlines()[-whole.frames:][:10]  # before the gap: the same frames
