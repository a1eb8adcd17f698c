"""Foxglove messages: geometry checked against OpenCV and SciPy, exact schema names, the shipped layout."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from scipy.spatial.transform import Rotation

from core.records import Box, BoxKind, CameraFrame, DetectionTruth, PoseTruth
from core.types import COCO17, Camera, Frame
from crossview import recording
from crossview.recording import foxglove
from tests.reference.foxglove import tracker_skeletons, truth_skeletons
from tracker.types import Target, TrackerOutput

LAYOUT = Path(__file__).resolve().parents[3] / "crossview" / "foxglove" / "layout.json"


@pytest.fixture
def camera() -> Camera:
    rng = np.random.default_rng(11)
    R = Rotation.from_euler("xyz", rng.uniform(-np.pi, np.pi, 3)).as_matrix()
    K = np.array([[700.0, 0.0, 630.0], [0.0, 705.0, 350.0], [0.0, 0.0, 1.0]])
    return Camera("cam07", K, [0.01, -0.02, 0.001, 0.0005, 0.003], R, rng.normal(0, 2, 3), 1280, 720)


def quaternion_matrix(q) -> np.ndarray:
    return Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()


def test_transform_maps_camera_points_to_world(camera):
    rng = np.random.default_rng(0)
    (tf,) = foxglove.frame_transforms([camera], t_ns=0).transforms
    assert (tf.parent_frame_id, tf.child_frame_id) == ("world", "camera_cam07")
    # A world point, taken into the camera frame by the calibration, comes back through the transform.
    X_world = rng.normal(0, 3, (10, 3))
    X_cam = X_world @ camera.R_cam_from_world.T + camera.t_cam_from_world
    R_world_from_cam = quaternion_matrix(tf.rotation)
    t = np.array([tf.translation.x, tf.translation.y, tf.translation.z])
    np.testing.assert_allclose(X_cam @ R_world_from_cam.T + t, X_world, atol=1e-9)  # m


@pytest.mark.parametrize("seed", range(20))
def test_quaternion_agrees_with_scipy(seed):
    R = Rotation.random(random_state=seed).as_matrix()
    q = foxglove._quaternion_from_matrix(R)
    np.testing.assert_allclose(quaternion_matrix(q), R, atol=1e-12)
    assert q.x**2 + q.y**2 + q.z**2 + q.w**2 == pytest.approx(1.0, abs=1e-12)


def test_calibration_projects_like_opencv(camera):
    calibration = foxglove.camera_calibration(camera, t_ns=0)
    assert calibration.frame_id == "camera_cam07" and calibration.distortion_model == "plumb_bob"
    assert (calibration.width, calibration.height) == (1280, 720)
    # P of the calibration projects camera-frame points as OpenCV does without distortion ...
    P = np.array(calibration.P).reshape(3, 4)
    X_cam = np.array([[0.3, -0.2, 2.0], [-1.0, 0.5, 4.0]])
    uvw = np.hstack([X_cam, np.ones((2, 1))]) @ P.T
    expected, _ = cv2.projectPoints(X_cam, np.zeros(3), np.zeros(3), camera.K, None)
    np.testing.assert_allclose(uvw[:, :2] / uvw[:, 2:], expected.reshape(-1, 2), atol=1e-9)  # px
    # ... and D with K reproduce OpenCV's distorted projection.
    distorted, _ = cv2.projectPoints(X_cam, np.zeros(3), np.zeros(3), np.array(calibration.K).reshape(3, 3),
                                     np.array(calibration.D))
    reference, _ = cv2.projectPoints(X_cam, np.zeros(3), np.zeros(3), camera.K, camera.dist)
    np.testing.assert_allclose(distorted, reference, atol=1e-9)


def test_frustum_corners_lie_on_the_image_corners(camera):
    scene = foxglove.store_scene([], [camera])
    (entity,) = scene.entities
    assert entity.frame_id == "camera_cam07"
    points = np.array([[p.x, p.y, p.z] for p in entity.lines[0].points])
    far = points[np.abs(points[:, 2]) > 1e-12]
    assert np.allclose(far[:, 2], foxglove.FRUSTUM_DEPTH_M)
    pixels = far @ camera.K.T
    pixels = np.unique(np.round(pixels[:, :2] / pixels[:, 2:], 9), axis=0)
    np.testing.assert_allclose(pixels, [[0, 0], [0, 720], [1280, 0], [1280, 720]], atol=1e-6)  # px


def test_store_boxes_become_yawed_cubes():
    box = Box(BoxKind.SHELF, (2.0, 1.0, 0.9), (2.0, 0.5, 1.8), 0.7)
    (entity,) = foxglove.store_scene([box], []).entities
    cube = entity.cubes[0]
    assert (cube.size.x, cube.size.y, cube.size.z) == (2.0, 0.5, 1.8)
    assert (cube.pose.position.x, cube.pose.position.y, cube.pose.position.z) == (2.0, 1.0, 0.9)
    np.testing.assert_allclose(quaternion_matrix(cube.pose.orientation),
                               Rotation.from_euler("z", 0.7).as_matrix(), atol=1e-12)


def test_truth_skeleton_draws_only_bones_with_both_ends_known():
    pose = np.arange(17 * 3, dtype=float).reshape(17, 3)
    pose[9] = np.nan  # left wrist: the bone (7, 9) disappears
    update = truth_skeletons(PoseTruth(0.5, np.array([4]), pose[None]), COCO17, t_ns=500_000_000)
    assert update.deletions[0].type == update.deletions[0].ALL
    (entity,) = update.entities
    assert entity.id == "person/4" and entity.frame_id == "world"
    points = np.array([[p.x, p.y, p.z] for p in entity.lines[0].points])
    expected = np.array([pose[i] for a, b in COCO17.bones if 9 not in (a, b) for i in (a, b)])
    np.testing.assert_array_equal(points, expected)
    assert entity.timestamp.seconds == 0 and entity.timestamp.nanos == 500_000_000


def test_tracker_colours_differ_from_truth_colours():
    pose = np.zeros((17, 3))
    for identity in range(1, 10):
        output = TrackerOutput(0.0, "cam00", [Target(identity, pose, 0.0)], np.zeros(0, np.int64))
        track = tracker_skeletons(output, COCO17, 0).entities[0].lines[0].color
        truth = truth_skeletons(PoseTruth(0.0, np.array([identity]), pose[None]), COCO17, 0)
        pale = truth.entities[0].lines[0].color
        assert (track.r, track.g, track.b) != (pale.r, pale.g, pale.b)
        assert track.a == 1.0 and pale.a < 1.0


def test_image_annotations_hold_the_detected_pixels():
    from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations

    J = COCO17.num_joints
    kp = np.random.default_rng(2).uniform(0, 500, (2, J, 2))
    kp[1, 3] = np.nan
    scores = np.where(np.isnan(kp[..., 0]), 0.0, 0.9)
    truth = DetectionTruth(0.1, 0.13, np.array([3, -1]), kp, np.ones((2, J), bool), np.zeros((2, J), bool),
                           np.zeros((2, J), bool), np.zeros(2, np.int64))
    cf = CameraFrame(Frame("cam00", 0.1, kp, scores), truth, PoseTruth(0.1, np.zeros(0, np.int64), np.zeros((0, J, 3))))
    # What the recording writes for the frame (stamped at its delivery), read by Foxglove's own protobuf class.
    annotations = ImageAnnotations.FromString(recording.Encoder(COCO17).camera_frames([cf])[0].annotations)
    joints = [a for a in annotations.points if a.type == a.POINTS]
    assert [len(a.points) for a in joints] == [J, J - 1]
    np.testing.assert_array_equal([[p.x, p.y] for p in joints[1].points], np.delete(kp[1], 3, axis=0))
    lines = [a for a in annotations.points if a.type == a.LINE_LIST]
    expected = [kp[1, i] for a, b in COCO17.bones if 3 not in (a, b) for i in (a, b)]
    np.testing.assert_array_equal([[p.x, p.y] for p in lines[1].points], expected)
    assert len(lines[0].points) == 2 * len(COCO17.bones)
    assert annotations.points[0].timestamp.nanos == 130_000_000
    grey = joints[1].outline_color
    assert (grey.r, grey.g, grey.b) == foxglove.FALSE_POSITIVE_COLOR[:3]


def test_file_descriptor_set_rebuilds_the_message_class():
    data = foxglove.file_descriptor_set(foxglove.SceneUpdate.DESCRIPTOR)
    assert data == foxglove.file_descriptor_set(foxglove.SceneUpdate.DESCRIPTOR)  # deterministic
    fds = descriptor_pb2.FileDescriptorSet.FromString(data)
    names = [f.name for f in fds.file]
    assert names[-1] == "foxglove/SceneUpdate.proto"
    # Dependencies come before their users, so a fresh pool accepts the files in order.
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName("foxglove.SceneUpdate"))
    original = truth_skeletons(PoseTruth(0.0, np.array([1]), np.ones((1, 17, 3))), COCO17, 5)
    assert cls.FromString(original.SerializeToString()).SerializeToString() == original.SerializeToString()


def test_layout_is_valid_and_names_channels_the_recording_writes():
    layout = json.loads(LAYOUT.read_text())
    panels = layout["configById"]
    assert "3D!store" in panels and any(key.startswith("Image!") for key in panels)

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])

    assert sorted(leaves(layout["layout"])) == sorted(panels)
    written = {recording.TOPIC_STORE, recording.TOPIC_TRUTH_SCENE, recording.TOPIC_TRACK_SCENE,
               recording.TOPIC_HEADER}
    for name in ("cam00", "cam01"):
        written |= {recording.camera_topic(name, what) for what in ("calibration", "detections", "image")}
    named = set(panels["3D!store"]["topics"])
    for key, panel in panels.items():
        if key.startswith("Image!"):
            mode = panel["imageMode"]
            named |= {mode["imageTopic"], mode["calibrationTopic"], *mode["annotations"]}
    named.add(panels["RawMessages!header"]["topicPath"])
    assert named <= written


def test_camera_backdrop_is_a_png_of_the_camera_size(camera):
    image = foxglove.camera_backdrop(camera, t_ns=0)
    assert image.format == "png" and image.frame_id == "camera_cam07"
    # OpenCV's PNG decoder, an independent reader, sees a uniform image of the calibration's size.
    pixels = cv2.imdecode(np.frombuffer(image.data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert pixels.shape == (camera.height_px, camera.width_px) and pixels.dtype == np.uint8
    assert np.all(pixels == foxglove.BACKDROP_GREY)
    assert len(image.data) < 5000  # bytes: a blank picture costs next to nothing


def test_compiled_annotations_are_what_protobuf_writes():
    """The recording writes 2D detections with a compiled encoder from cached wire pieces; the bytes must
    equal protobuf's serialisation of the message built point by point, zero coordinates (left out)
    included, and protobuf's parser must read them back."""
    from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
    from foxglove_schemas_protobuf.Point2_pb2 import Point2
    from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation

    rng = np.random.default_rng(4)
    truth = PoseTruth(0.37, np.array([3, 8, 12, 1000]), rng.normal(0, 2, (4, 17, 3)))
    encoder = recording.Encoder(COCO17)
    base = rng.uniform(0, 600, (3, 17, 2))
    base[0, ::3] = np.nan
    # Without and with zero coordinates (+0.0 is left out, -0.0 kept).
    for zero in (False, True):
        kp = base.copy()
        if zero:
            kp[2, 4] = (0.0, 17.0)
            kp[1, 2] = (-0.0, 0.0)
            kp[1, 7] = (0.0, 0.0)
        scores = np.where(np.isnan(kp[..., 0]), 0.0, 0.7)
        flags = np.zeros((3, 17), dtype=bool)
        cf = CameraFrame(
            Frame("cam00", 0.1, kp, scores),
            DetectionTruth(0.1, 0.12, np.array([4, -1, 9]), kp, ~flags, flags, flags, np.zeros(3, dtype=np.int64)),
            truth,
        )
        # An independent reference built point by point with protobuf objects.
        reference = ImageAnnotations()
        for d, pid in enumerate([4, -1, 9]):
            rgba = foxglove.truth_color(pid) if pid >= 0 else foxglove.color(foxglove.FALSE_POSITIVE_COLOR)
            rgba.a = 1.0
            known = np.isfinite(kp[d]).all(axis=1)
            ends = [e for a, b in COCO17.bones if known[a] and known[b] for e in (a, b)]
            for kind, joints, extra in ((PointsAnnotation.LINE_LIST, ends, {}),
                                        (PointsAnnotation.POINTS, np.nonzero(known)[0].tolist(), {"fill_color": rgba})):
                if joints:
                    reference.points.append(PointsAnnotation(
                        timestamp=foxglove.timestamp(120_000_000), type=kind, outline_color=rgba,
                        thickness=foxglove.DETECTION_LINE_PX * (1 if kind == PointsAnnotation.LINE_LIST else 2),
                        points=[Point2(x=x, y=y) for x, y in kp[d, joints].tolist()], **extra))
        data = encoder.camera_frames([cf])[0].annotations
        assert data == reference.SerializeToString()
        assert ImageAnnotations.FromString(data) == reference
        assert len(reference.points) == 6
