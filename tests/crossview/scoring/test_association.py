"""Association accuracy (the paper's Figure 4) and per-camera 2D scores of projected tracks (Table 5)."""

import cv2
import numpy as np
import pytest

from core.records import CameraFrame, DetectionTruth, PoseTruth
from core.types import Camera, Frame
from crossview.scoring import score
from crossview.scoring.association import (
    AssociationAccumulator,
    association_accuracy,
    may_project,
    pose_boxes,
    project_points,
    projection_volume,
)
from crossview.scoring.identity import body_roots
from tracker.types import Target, TargetArrays, TargetState, TrackerOutput


def _camera(name="top", center=(0.0, 0.0, 4.0), dist=(0.0, 0.0, 0.0, 0.0, 0.0)):
    """A camera looking straight down from `center` (OpenCV frame: z down the world's -z)."""
    R = np.diag([1.0, -1.0, -1.0])
    K = np.array([[400.0, 0, 320], [0, 400.0, 240], [0, 0, 1]])
    return Camera(name, K, np.array(dist), R, -R @ np.asarray(center), 640, 480)


def _camera_frame(camera, stamp, person_ids):
    d = len(person_ids)
    frame = Frame(camera, stamp, np.zeros((d, 17, 2)), np.ones((d, 17)))
    truth = DetectionTruth(
        capture_s=stamp, delivery_s=stamp, person_ids=np.asarray(person_ids, dtype=np.int64),
        keypoints_px=np.zeros((d, 17, 2)), in_image=np.ones((d, 17), bool), occluded=np.zeros((d, 17), bool),
        self_occluded=np.zeros((d, 17), bool), effects=np.zeros(d, dtype=np.int64),
    )
    return CameraFrame(frame, truth, PoseTruth(stamp, np.zeros(0, dtype=np.int64), np.zeros((0, 17, 3))))


def _output(camera, stamp, assigned, targets=()):
    targets = targets if isinstance(targets, TargetArrays) else list(targets)
    return TrackerOutput(stamp, camera, targets, np.asarray(assigned, dtype=np.int64))


def test_association_accuracy_by_hand():
    frames, outputs = [], []
    # Camera A: person 1 goes to target 10 three times; person 2 to 30, 30, then unassigned.
    for k, (a1, a2) in enumerate([(10, 30), (10, 30), (10, -1)]):
        frames.append(_camera_frame("A", 0.1 * k, [1, 2]))
        outputs.append(_output("A", 0.1 * k, [a1, a2]))
    # Camera B: person 1 to 20 once (wrong: 10 carries person 1), person 2 to 30, a false positive to 10.
    frames.append(_camera_frame("B", 0.05, [1, 2, -1]))
    outputs.append(_output("B", 0.05, [20, 30, 10]))
    # A frame the tracker never processed is left out.
    frames.append(_camera_frame("B", 0.15, [1]))
    s = association_accuracy(frames, outputs)
    assert s.per_camera == {"A": pytest.approx(5 / 6), "B": pytest.approx(1 / 2)}
    assert s.overall == pytest.approx(6 / 8)
    assert s.true_detections == {"A": 6, "B": 2}
    assert s.false_positive_assigned == 1.0 and s.frames_without_output == 1


def test_detection_count_mismatch_means_another_recording():
    with pytest.raises(ValueError, match="do not belong to this recording"):
        association_accuracy([_camera_frame("A", 0.0, [1, 2])], [_output("A", 0.0, [5])])


def test_projection_agrees_with_opencv_from_world_coordinates():
    cam = _camera(dist=(-0.2, 0.05, 0.001, -0.001, 0.0))
    pts = np.random.default_rng(5).uniform([-1.5, -1.0, 0.0], [1.5, 1.0, 1.8], (50, 3))
    rvec, _ = cv2.Rodrigues(cam.R_cam_from_world)
    ref, _ = cv2.projectPoints(pts, rvec, cam.t_cam_from_world, cam.K, cam.dist)
    np.testing.assert_allclose(project_points(cam, pts), ref.reshape(-1, 2), atol=1e-9)  # px
    # Behind the camera: NaN.
    assert np.isnan(project_points(cam, np.array([[0.0, 0.0, 5.0]]))).all()


def test_poses_left_out_of_a_camera_project_to_nothing_there():
    """`may_project` leaves out only poses of which `project_points` projects no joint (no box, so no part in
    the camera's 2D scores), and keeps every pose with a joint projected, also a joint just past the edge."""
    rng = np.random.default_rng(8)
    for cam in (_camera(), _camera(dist=(-0.2, 0.05, 0.001, -0.001, 0.0)),
                _camera(center=(1.0, -2.0, 3.0), dist=(0.1, -0.02, 0.0, 0.0, 0.01))):
        volume = projection_volume(cam)
        poses = rng.uniform([-12.0, -12.0, -1.0], [12.0, 12.0, 6.0], (3000, 1, 3)) + rng.normal(0, 0.3, (3000, 17, 3))
        poses[::7, ::3] = np.nan
        projected = np.isfinite(project_points(cam, poses.reshape(-1, 3))).all(axis=1).reshape(3000, 17).any(axis=1)
        kept = may_project(volume, poses)
        assert not (projected & ~kept).any()  # nothing projected is left out
        assert (~kept).sum() > 1000 and projected.sum() > 100
        # The volume is what project_points projects, within its micrometre: keeping is rare without projecting.
        assert (kept & ~projected).sum() <= 0.01 * kept.sum()
    # A joint on the volume's edge (a quarter pixel further out is beyond it) is kept.
    cam = _camera()
    edge = (-0.5 * 640 + 1e-9 - 320) / 400 * 4.0  # x of the column u = -0.5 W, 4 m below the camera at z = 0
    assert may_project(projection_volume(cam), np.array([[[edge, 0.0, 0.0]]])).tolist() == [True]
    assert may_project(projection_volume(cam), np.array([[[edge - 0.25 / 400 * 4, 0.0, 0.0]]])).tolist() == [False]


def test_box_mostly_outside_the_image_does_not_count():
    cam = _camera()
    pose = np.zeros((17, 3))
    pose[:, 0] = np.linspace(-0.2, 0.2, 17)
    pose[:, 1] = np.linspace(-0.1, 0.1, 17)
    pose[:, 2] = np.linspace(0.0, 1.7, 17)
    # Seen from 4 m above, the second pose lies mostly beyond the right edge of the image.
    boxes, visible = pose_boxes(cam, np.stack([pose, pose + [3.3, 0, 0]]))
    assert visible.tolist() == [True, False]


def _walker(pid, t):
    pose = np.zeros((17, 3))
    pose[:, 0] = np.linspace(-0.25, 0.25, 17) + (pid - 1.5) * 1.5 + 0.1 * t
    pose[:, 1] = np.linspace(-0.1, 0.1, 17)
    pose[:, 2] = np.linspace(0.1, 1.7, 17)
    return pose


def test_projected_truth_tracks_score_perfectly_in_2d_and_a_swap_is_one_switch_each():
    cam = _camera()
    times = np.arange(0, 2.001, 0.01)
    truth = [PoseTruth(t, np.array([1, 2]), np.stack([_walker(1, t), _walker(2, t)])) for t in times]
    stamps = np.arange(0, 2.001, 0.1)
    good = [_output("top", t, [], [Target(10, _walker(1, t), t), Target(20, _walker(2, t), t)]) for t in stamps]
    r = score(truth, good, cameras=[cam])
    s = r.camera_2d["top"]
    assert (s.mota, s.idf1, s.false_positives, s.false_negatives, s.id_switches) == (1.0, 1.0, 0, 0, 0)
    assert s.num_frames == len(stamps) and s.num_truth == 2 * len(stamps)
    # Swap identities at 1 s: one switch per person in the camera's 2D view too.
    swapped = []
    for t in stamps:
        a, b = (10, 20) if t < 1 else (20, 10)
        swapped.append(_output("top", t, [], [Target(a, _walker(1, t), t), Target(b, _walker(2, t), t)]))
    swap = score(truth, swapped, cameras=[cam])
    assert swap.camera_2d["top"].id_switches == 2
    # On the ground plane too, each switch with its instant and where the person stood.
    assert swap.id_switches == 2
    assert [e[:3] for e in swap.id_switch_events] == [(1.0, 1, 20), (1.0, 2, 10)]
    for (_, pid, _, x, y) in swap.id_switch_events:
        np.testing.assert_allclose([x, y], body_roots(_walker(pid, 1.0)[None])[0], atol=1e-12)  # m


def test_targets_given_as_arrays_score_as_the_same_targets_listed():
    """The scorer reads a `TargetArrays` (the built-in tracker's, and the tracks reader's) through its arrays:
    the same report, 3D and per camera, as the same targets in a list; targets in a state that is not scored
    count in neither."""
    cams = [_camera(), _camera("side", center=(3.0, 0.0, 4.0), dist=(-0.1, 0.01, 0.0, 0.0, 0.0))]
    times = np.arange(0, 2.001, 0.01)
    truth = [PoseTruth(t, np.array([1, 2]), np.stack([_walker(1, t), _walker(2, t)])) for t in times]
    listed, arrays = [], []
    for k, t in enumerate(np.arange(0, 2.001, 0.05)):
        ids = (10, 20) if t < 1 else (20, 10)
        state = TargetState.TENTATIVE if k % 7 == 3 else TargetState.LOST if k % 5 == 1 else TargetState.CONFIRMED
        poses = np.stack([_walker(1, t), _walker(2, t)]) + 0.02 * np.sin(k)
        codes = np.zeros((2, 17), dtype=np.uint8)
        camera = cams[k % 2].name
        listed.append(_output(camera, t, [], [Target(i, p, t, state, c) for i, p, c in zip(ids, poses, codes)]))
        arrays.append(_output(camera, t, [], TargetArrays(np.array(ids), poses, codes, t, state)))
    a, b = score(truth, listed, cameras=cams), score(truth, arrays, cameras=cams)
    run = dict(scenario="two walkers", seed=0, num_cameras=2, num_people=2, duration_s=2.0)
    assert a.to_json(**run) == b.to_json(**run) and a.camera_2d == b.camera_2d
    assert a.camera_2d["side"].num_truth > 0 and a.id_switches == 2


def test_the_2d_scores_of_some_cameras_are_those_of_all():
    """`projected` names the cameras whose 2D scores `score` computes (`crossview.pipeline.score` leaves the
    others to a second process): each is what scoring every camera gives, and the 3D report is unchanged."""
    cams = [_camera(), _camera("side", center=(3.0, 0.0, 4.0), dist=(-0.1, 0.01, 0.0, 0.0, 0.0))]
    truth = [PoseTruth(t, np.array([1, 2]), np.stack([_walker(1, t), _walker(2, t)]))
             for t in np.arange(0, 2.001, 0.01)]
    outputs = [_output(cams[k % 2].name, t, [], [Target(i, _walker(p, t) + 0.03 * np.cos(k), t) for i, p in
                                                 ((10, 1), (20, 2) if t < 1 else (20, 1))])
               for k, t in enumerate(np.arange(0, 2.001, 0.05))]
    whole = score(truth, outputs, cameras=cams)
    run = dict(scenario="two walkers", seed=0, num_cameras=2, num_people=2, duration_s=2.0)
    assert set(whole.camera_2d) == {"top", "side"} and whole.camera_2d["side"].num_truth > 0
    for names in ({"side"}, {"top"}, set()):
        part = score(truth, outputs, cameras=cams, projected=names)
        assert part.camera_2d == {n: whole.camera_2d[n] for n in ("top", "side") if n in names}
        part.camera_2d = whole.camera_2d
        assert part.to_json(**run) == whole.to_json(**run)
    assert score(truth, outputs, cameras=cams, projected=False).camera_2d == {}


def test_output_without_targets_counts_visible_people_as_misses_in_2d():
    cam = _camera()
    truth = [PoseTruth(t, np.array([1]), _walker(1, t)[None]) for t in np.arange(0, 1.001, 0.01)]
    r = score(truth, [_output("top", 0.5, [])], cameras=[cam])
    assert (r.camera_2d["top"].false_negatives, r.camera_2d["top"].mota) == (1, 0.0)


def test_outputs_that_match_no_frame_of_the_recording_are_refused():
    truth = [PoseTruth(t, np.array([1]), _walker(1, t)[None]) for t in np.arange(0, 1.001, 0.01)]
    frames = [_camera_frame("top", 0.1 * k, [1]) for k in range(5)]
    outputs = [_output("top", 0.1 * k + 0.013, [10]) for k in range(5)]
    with pytest.raises(ValueError, match="another recording"):
        score(truth, outputs, frames)


def test_accumulator_pairs_frames_and_outputs_in_any_order_as_the_whole_lists_do():
    rng = np.random.default_rng(11)
    frames, outputs = [], []
    for k in range(40):
        camera = ("A", "B", "C")[k % 3]
        persons = rng.choice([-1, 1, 2, 3], size=rng.integers(0, 5))
        frames.append(_camera_frame(camera, 0.05 * k, persons))
        outputs.append(_output(camera, 0.05 * k, rng.choice([-1, 10, 20, 30], size=len(persons))))
    whole = association_accuracy(frames, outputs[:-3])  # the last three frames were never processed
    for order in ("outputs first", "frames first", "interleaved late"):
        acc = AssociationAccumulator()
        if order == "outputs first":
            for o in outputs[:-3]:
                acc.add_output(o)
            for f in frames:
                acc.add_frame(f)
        elif order == "frames first":
            for f in frames:
                acc.add_frame(f)
            for o in outputs[:-3]:
                acc.add_output(o)
        else:  # each output two frames behind its frame
            for k, f in enumerate(frames):
                acc.add_frame(f)
                if 2 <= k < len(frames) - 1:
                    acc.add_output(outputs[k - 2])
        s = acc.result()
        assert s == whole, order
        assert list(s.per_camera) == ["A", "B", "C"] and s.frames_without_output == 3
