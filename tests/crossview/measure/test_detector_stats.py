"""Detector statistics: each figure recovers an effect injected into hand-made frames, exact detections measure
nothing, and real ground-truth 2D joints (the Campus fixture) agree with their projected 3D truth."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from core.records import CameraFrame, DetectionTruth, PoseTruth
from core.types import CAMPUS14, COCO17, Camera, Frame
from crossview import pipeline
from crossview.cli import main
from crossview.formats import datasets
from crossview.measure.detector_stats import (
    BAD_LIMB_FACTOR,
    GROSS_ERROR_FRAC,
    JOINTS_12,
    MISS_CAUSES,
    SHELF_OPENPOSE,
    SHELF_OPENPOSE_FILE,
    detector_stats,
    format_detector_stats,
    read_stats_file,
    recording_detector_stats,
)
from sim import scenario as scenario_mod
from sim.cameras import look_at
from sim.scenario import from_source_text

CAMPUS = Path(__file__).resolve().parents[2] / "data" / "campus"
J = COCO17.num_joints
IDX_12 = [COCO17.index(n) for n in JOINTS_12]
FPS = 25.0
KEYS = ("error_over_size_median", "error_over_size_p90", "error_over_size_p99", "lag1_error_correlation",
        "gross_error_rate", "miss_rate", "miss_persistence", "missed_person_view_rate",
        "false_positive_people_per_frame", "per_joint")

# Heights (m) and half-widths (m, along the body's left-right axis) of a standing person's COCO-17 joints.
_HEIGHT_M = {"nose": 1.62, "eye": 1.66, "ear": 1.64, "shoulder": 1.45, "elbow": 1.15, "wrist": 0.9, "hip": 0.95,
             "knee": 0.52, "ankle": 0.1}
_HALF_WIDTH_M = {"nose": 0.0, "eye": 0.035, "ear": 0.08, "shoulder": 0.2, "elbow": 0.25, "wrist": 0.27,
                 "hip": 0.12, "knee": 0.12, "ankle": 0.12}


def _standing(x_m: float, y_m: float) -> np.ndarray:
    """(17, 3) a person standing at (x, y), facing -x (their left towards -y)."""
    pose = np.zeros((J, 3))
    for j, name in enumerate(COCO17.joints):
        part = name.split("_")[-1]
        side = -1.0 if name.startswith("left") else 1.0 if name.startswith("right") else 0.0
        pose[j] = (x_m, y_m + side * _HALF_WIDTH_M[part], _HEIGHT_M[part])
    return pose


def _camera(name: str, position_m, target_m=(3.0, 0.0, 0.9), f_px: float = 800.0) -> Camera:
    """A distortion-free 1032 x 776 camera at `position_m` looking at `target_m`."""
    R = look_at(np.asarray(position_m, float), np.asarray(target_m, float))
    K = [[f_px, 0, 516.0], [0, f_px, 388.0], [0, 0, 1]]
    return Camera(name, K, np.zeros(5), R, -R @ np.asarray(position_m, float), 1032, 776)


def _project(camera: Camera, points_m: np.ndarray) -> np.ndarray:
    """(..., 2) the plain pinhole projection K (R X + t), dehomogenised: the test's own reference."""
    cam = points_m @ camera.R_cam_from_world.T + camera.t_cam_from_world
    uv = cam @ camera.K.T
    return uv[..., :2] / uv[..., 2:]


def _size_px(truth_px: np.ndarray) -> np.ndarray:
    """(P,) the larger side of the box of each person's 12 projected joints."""
    p = truth_px[:, IDX_12]
    return np.max(p.max(axis=1) - p.min(axis=1), axis=-1)


def _camera_frame(camera: Camera, t_s: float, ids, poses, detections_px) -> CameraFrame:
    """A delivered frame: `detections_px` (D, 17, 2) with the truth `poses` (P, 17, 3) of people `ids` at t_s.
    The per-detection truth rows hold nothing (ids -1, NaN joints), as a converted real dataset's do."""
    kp = np.asarray(detections_px, dtype=float).reshape(-1, J, 2)
    D = len(kp)
    none = np.zeros((D, J), bool)
    truth = DetectionTruth(t_s, t_s, np.full(D, -1, np.int64), np.full((D, J, 2), np.nan), none, none, none,
                           np.zeros(D, np.int64))
    scores = np.where(np.isnan(kp[..., 0]), 0.0, 0.9)
    return CameraFrame(Frame(camera.name, t_s, kp, scores), truth,
                       PoseTruth(t_s, np.asarray(ids, np.int64), np.asarray(poses, float).reshape(-1, J, 3)))


CAM = _camera("c0", (0.0, 0.0, 1.0))
PEOPLE = np.stack([_standing(3.0, -0.8), _standing(3.2, 0.0), _standing(3.0, 0.8)])  # (3, 17, 3), ~450 px tall
IDS = [10, 11, 12]


def test_exact_detections_measure_no_error_no_miss_and_no_false_positive():
    truth_px = _project(CAM, PEOPLE)
    frames = [_camera_frame(CAM, k / FPS, IDS, PEOPLE, truth_px) for k in range(20)]
    stats = detector_stats(frames, [CAM], COCO17)
    assert stats["matched_detections"] == 60 and stats["person_views"] == 60
    assert stats["error_over_size_p99"] == pytest.approx(0.0, abs=1e-9)
    assert stats["miss_rate"] == 0.0 and stats["miss_persistence"] is None
    assert stats["missed_person_view_rate"] == 0.0 and stats["false_positive_people_per_frame"] == 0.0
    assert stats["person_size_px_median"] == pytest.approx(np.median(_size_px(truth_px)))
    assert set(KEYS) <= set(stats) and set(stats["per_joint"]) == set(JOINTS_12)


def test_a_vertical_offset_per_joint_group_is_recovered_in_px_at_400():
    # Hips 12 px above the truth at a 400 px person, wrists 7 px, everything else exact.
    truth_px = _project(CAM, PEOPLE)
    size = _size_px(truth_px)[:, None]
    detected = truth_px.copy()
    for names, px_at_400 in ((("left_hip", "right_hip"), -12.0), (("left_wrist", "right_wrist"), -7.0)):
        for name in names:
            detected[:, COCO17.index(name), 1] += px_at_400 / 400.0 * size[:, 0]
    stats = detector_stats([_camera_frame(CAM, 0.0, IDS, PEOPLE, detected)], [CAM], COCO17)
    groups = stats["per_group"]
    assert groups["hips"]["vertical_offset_px_at_400"] == pytest.approx(-12.0, abs=1e-6)
    assert groups["wrists"]["vertical_offset_px_at_400"] == pytest.approx(-7.0, abs=1e-6)
    assert groups["shoulders"]["vertical_offset_px_at_400"] == pytest.approx(0.0, abs=1e-6)
    assert groups["hips"]["error_over_size_median"] == pytest.approx(12.0 / 400.0, abs=1e-9)
    assert stats["per_joint"]["left_knee"]["error_over_size_median"] == pytest.approx(0.0, abs=1e-9)


def test_ar1_errors_give_their_lag1_correlation_and_size():
    # Each joint's error, per person, follows e_k = phi e_(k-1) + sqrt(1 - phi^2) sigma n_k from its stationary
    # start: lag-1 correlation phi; |e| of a 2D Gaussian has median sigma sqrt(2 ln 2).
    rng = np.random.default_rng(0)
    phi, sigma, n = 0.9, 0.01, 400
    truth_px = _project(CAM, PEOPLE)
    size = _size_px(truth_px)[:, None, None]
    e = np.empty((n, 3, J, 2))
    e[0] = rng.normal(0.0, sigma, (3, J, 2))
    for k in range(1, n):
        e[k] = phi * e[k - 1] + np.sqrt(1 - phi ** 2) * rng.normal(0.0, sigma, (3, J, 2))
    frames = [_camera_frame(CAM, k / FPS, IDS, PEOPLE, truth_px + e[k] * size) for k in range(n)]
    stats = detector_stats(frames, [CAM], COCO17)
    # The reference: the same estimator, written out on the injected errors (each joint's and axis's mean
    # taken out, pairs pooled).
    a, b = e[:-1][:, :, IDX_12], e[1:][:, :, IDX_12]
    a = a - a.mean(axis=(0, 1))
    b = b - b.mean(axis=(0, 1))
    assert stats["lag1_error_correlation"] == pytest.approx((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))
    assert stats["lag1_error_correlation"] == pytest.approx(phi, abs=0.02)
    assert stats["per_group"]["wrists"]["lag1_error_correlation"] == pytest.approx(phi, abs=0.05)
    assert stats["error_over_size_median"] == pytest.approx(sigma * np.sqrt(2 * np.log(2)), rel=0.05)
    assert stats["gross_error_rate"] == 0.0


def test_markov_joint_misses_give_their_rate_and_persistence():
    # Each (person, joint) is missed by a two-state chain: P(miss | seen before) = 0.05, P(miss | missed before)
    # = 0.8; stationary miss rate 0.05 / (0.05 + 0.2) = 0.2.
    rng = np.random.default_rng(1)
    p01, p11, n = 0.05, 0.8, 600
    missed = np.zeros((n, 3, 12), bool)
    missed[0] = rng.random((3, 12)) < 0.2
    for k in range(1, n):
        missed[k] = rng.random((3, 12)) < np.where(missed[k - 1], p11, p01)
    missed[:, :, 0] &= ~missed.all(axis=2)  # a detection keeps at least one of the 12 joints
    truth_px = _project(CAM, PEOPLE)
    frames = []
    for k in range(n):
        detected = truth_px.copy()
        hole = np.zeros((3, J), bool)
        hole[:, IDX_12] = missed[k]
        detected[hole] = np.nan
        frames.append(_camera_frame(CAM, k / FPS, IDS, PEOPLE, detected))
    stats = detector_stats(frames, [CAM], COCO17)
    # The reference: the same counts on the injected chains (every joint is inside the image).
    assert stats["miss_rate"] == pytest.approx(missed.mean())
    assert stats["miss_persistence"] == pytest.approx((missed[:-1] & missed[1:]).sum() / missed[:-1].sum())
    assert stats["miss_rate"] == pytest.approx(p01 / (p01 + 1 - p11), abs=0.03)
    assert stats["miss_persistence"] == pytest.approx(p11, abs=0.03)
    wrist = JOINTS_12.index("left_wrist")
    assert stats["per_joint"]["left_wrist"]["miss_rate"] == pytest.approx(missed[:, :, wrist].mean())


def test_false_positive_people_missed_person_views_and_gross_errors_are_counted():
    truth_px = _project(CAM, PEOPLE)
    size = _size_px(truth_px)
    # A person-like phantom (all joints) far to the right of everybody, and a 3-joint fragment far left.
    phantom = _project(CAM, _standing(3.0, 1.9))
    fragment = np.full((J, 2), np.nan)
    fragment[IDX_12[:3]] = _project(CAM, _standing(3.0, -1.9))[IDX_12[:3]]
    # A fourth person stands behind the camera: never a person-view.
    poses = np.concatenate([PEOPLE, _standing(-2.0, 0.0)[None]])
    frames = []
    for k in range(10):
        detected = truth_px.copy()
        detected[0, COCO17.index("left_wrist"), 0] += 0.3 * size[0]  # one gross error a frame
        people = detected if k % 2 else detected[:2]  # person 12 missed in every other frame
        frames.append(_camera_frame(CAM, k / FPS, [*IDS, 13], poses, [*people, phantom, fragment]))
    stats = detector_stats(frames, [CAM], COCO17)
    assert stats["person_views"] == 30
    assert stats["missed_person_view_rate"] == pytest.approx(5 / 30)
    assert stats["false_positive_people_per_frame"] == pytest.approx(2.0)
    assert stats["false_positive_people_ge6_per_frame"] == pytest.approx(1.0)
    assert stats["gross_error_rate"] == pytest.approx(10 / (25 * 12))
    assert 0.3 > GROSS_ERROR_FRAC
    assert stats["per_joint"]["left_wrist"]["gross_error_rate"] == pytest.approx(10 / 25)
    assert stats["per_camera"]["c0"]["false_positive_people_per_frame"] == pytest.approx(2.0)


def test_the_per_person_spread_names_the_share_of_people_with_a_bad_limb():
    truth_px = _project(CAM, PEOPLE)
    size = _size_px(truth_px)
    frames = []
    for k in range(30):
        detected = truth_px.copy()
        # Every limb joint of everybody 0.02 of the size off; person 11's right wrist 0.15 off, every frame.
        detected[:, IDX_12, 0] += 0.02 * size[:, None]
        detected[1, COCO17.index("right_wrist"), 0] += 0.13 * size[1]
        frames.append(_camera_frame(CAM, k / FPS, IDS, PEOPLE, detected))
    spread = detector_stats(frames, [CAM], COCO17)["per_person"]
    assert spread["people_measured"] == 3
    # The test's own reference: per person the worst limb joint's mean error / size, their median, the share
    # above BAD_LIMB_FACTOR x the median.
    assert spread["limb_error_by_person"]["11"] == pytest.approx(0.15)
    assert spread["limb_error_by_person"]["10"] == pytest.approx(0.02)
    assert spread["limb_error_median"] == pytest.approx(0.02)
    assert 0.15 > BAD_LIMB_FACTOR * 0.02
    assert spread["bad_limb_person_share"] == pytest.approx(1 / 3)
    table = format_detector_stats(detector_stats(frames, [CAM], COCO17))
    assert "people with a limb error > 2 x the median" in table and "33 % of 3" in table
    # Seen in fewer than MIN_PERSON_JOINT_VIEWS frames, nobody is measured.
    assert detector_stats(frames[:10], [CAM], COCO17)["per_person"]["people_measured"] == 0


def test_a_joint_offset_shared_by_every_camera_shows_in_3d_not_in_cross_view_agreement():
    # What a detector calls the wrist lies 5 cm from the annotated wrist, the same in every camera: the views
    # agree (reprojection ~0) on a point 5 cm from the truth. Three cameras, captured 4 ms apart.
    cams = [_camera(f"c{i}", (3.0 - 3.0 * np.cos(a), 3.0 * np.sin(a), 2.2)) for i, a in enumerate((-0.6, 0.0, 0.6))]
    shifted = PEOPLE.copy()
    for name in ("left_wrist", "right_wrist"):
        shifted[:, COCO17.index(name)] += (0.0, 0.03, 0.04)  # 5 cm
    frames = [_camera_frame(cam, k / FPS + 0.004 * i, IDS, PEOPLE, _project(cam, shifted))
              for k in range(5) for i, cam in enumerate(cams)]
    stats = detector_stats(frames, cams, COCO17)
    groups = stats["per_group"]
    assert stats["cross_view_joints"] == 5 * 3 * 12
    assert groups["wrists"]["cross_view_error_m"] == pytest.approx(0.05, abs=1e-6)
    assert groups["wrists"]["cross_view_reprojection_px_at_400"] == pytest.approx(0.0, abs=1e-3)
    assert groups["hips"]["cross_view_error_m"] == pytest.approx(0.0, abs=1e-6)
    assert groups["wrists"]["error_over_size_median"] > 0.005  # seen from each camera, the wrists are off


@pytest.fixture(scope="module")
def campus_recording(tmp_path_factory) -> Path:
    """The Campus fixture converted: its ground-truth 2D joints as the detections, its 3D truth."""
    out = tmp_path_factory.mktemp("campus") / "campus.mcap"
    datasets.convert(CAMPUS, out, check_scenario=from_source_text)
    return out


def test_campus_ground_truth_2d_joints_agree_with_the_projected_3d_truth(campus_recording):
    stats = recording_detector_stats(campus_recording)
    # Only the frames with 3D truth (test frames 350-470 and 650-750 of each of the 3 cameras) are measured.
    assert 600 < stats["frames_measured"] < stats["frames"]
    assert stats["error_over_size_median"] < 0.01 and stats["gross_error_rate"] == 0.0
    assert stats["miss_rate"] == 0.0 and stats["missed_person_view_rate"] == 0.0
    assert stats["false_positive_people_per_frame"] == 0.0
    assert stats["cross_view_error_m"] < 0.005  # m


def test_coco17_detections_beside_the_published_14_joint_truth_are_measured_alike(campus_recording, tmp_path):
    # A folder shaped as the published Shelf one: COCO-17 detection.json (here the Campus ground-truth 2D
    # joints under their COCO-17 names, face unknown) beside the 14-joint annotation_3d.json.
    folder = tmp_path / "coco"
    folder.mkdir()
    for name in ("calibration.json", "annotation_3d.json"):
        (folder / name).write_bytes((CAMPUS / name).read_bytes())
    data = json.loads((CAMPUS / "annotation_2d.json").read_text())
    to_coco = [(COCO17.index(name), CAMPUS14.index(name)) for name in JOINTS_12]
    for frame in data["frames"].values():
        for pose in frame["poses"]:
            points, scores = [[0.0, 0.0]] * J, [0.0] * J
            for c, k in to_coco:
                points[c], scores[c] = pose["points_2d"][k], 1.0
            pose.update(points_2d=points, scores=scores, id=-1)
    (folder / "detection.json").write_text(json.dumps(data))
    out = tmp_path / "coco.mcap"
    datasets.convert(folder, out, check_scenario=from_source_text)
    coco, campus = recording_detector_stats(out), recording_detector_stats(campus_recording)
    for key in ("matched_detections", "person_views", "joints_measured", "false_positive_people_per_frame"):
        assert coco[key] == campus[key], key
    for key in ("error_over_size_median", "error_over_size_p99", "cross_view_error_m"):
        assert coco[key] == pytest.approx(campus[key], abs=1e-9), key


def test_the_ideal_detector_measures_no_error_in_a_generated_recording(tmp_path):
    out = tmp_path / "shelf.mcap"
    # (No occlusion: on the Shelf rig a person behind the shelf unit or another person is hidden from a camera
    # now and then, and even the ideal detector misses whom it cannot see.)
    pipeline.generate(scenario_mod.load("shelf", {"duration_s": 1.0, "seed": 0, "detector.profile": "ideal",
                                                  "detector.occlusion": False}), out, progress=False)
    stats = recording_detector_stats(out)
    assert stats["matched_detections"] > 100
    assert 350 < stats["person_size_px_median"] < 450  # px: the shelf rig sees people at about Shelf's size
    assert stats["error_over_size_p99"] < 1e-6
    assert stats["miss_rate"] == 0.0 and stats["missed_person_view_rate"] == 0.0
    assert stats["false_positive_people_per_frame"] == 0.0
    assert stats["cross_view_error_m"] < 1e-4  # m


def test_the_command_prints_the_table_beside_openpose_and_writes_the_json(campus_recording, tmp_path, capsys):
    out = tmp_path / "stats.json"
    assert main(["detector-stats", str(campus_recording), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "real OpenPose, Shelf" in text and "P(joint missed next frame | missed now)" in text
    assert "0.800" in text  # the reference column: real OpenPose's miss persistence
    written = json.loads(out.read_text())
    assert set(KEYS) <= set(written)
    assert set(written["per_joint"]["left_wrist"]) >= set(KEYS) - {"per_joint", "missed_person_view_rate",
                                                                     "false_positive_people_per_frame"}
    # What detector-stats writes is a statistics file fit-detector --target reads.
    assert read_stats_file(out)["per_group"]["wrists"]["miss_rate"] == written["per_group"]["wrists"]["miss_rate"]


def test_the_shipped_real_table_is_the_file_detector_stats_wrote_on_shelf():
    # An independent read of the shipped file (plain json) against the module's table: every key, unchanged.
    shipped = json.loads(SHELF_OPENPOSE_FILE.read_text(encoding="utf-8"))
    assert shipped == SHELF_OPENPOSE
    assert shipped["miss_persistence"] == pytest.approx(0.8004, abs=1e-4)
    assert shipped["error_over_size_p99"] == pytest.approx(0.3739, abs=1e-4)
    assert shipped["person_views"] == 2550 and shipped["frames"] == 1505


def test_format_gives_a_dash_for_what_was_not_measured():
    truth_px = _project(CAM, PEOPLE)
    stats = detector_stats([_camera_frame(CAM, 0.0, IDS, PEOPLE, truth_px)], [CAM], COCO17)
    lines = {line[:56].strip(): line[56:].split() for line in format_detector_stats(stats).splitlines()}
    assert lines["P(joint missed next frame | missed now)"][0] == "-"
    assert lines["joint error / person size: median"] == ["0.000", "0.028"]


def test_the_geometry_explains_every_miss_of_a_detector_that_misses_nobody_it_can_see(tmp_path):
    """One person in the convenience store, a detector whose only misses are the rig's geometry (no miss_prob, no
    occlusion gain, nobody else to hide behind): every missed person-view is put down to the profile's size limit,
    the image edge or the shelves, as the simulator ruled; the causes add up to the missed share."""
    profile = tmp_path / "p.toml"
    profile.write_text('base = "typical"\nmiss_prob = 0.0\nmiss_occlusion_gain = 0.0\n')
    text = scenario_mod.resolve_path("convenience").read_text()
    assert 'profile = "typical"' in text
    (tmp_path / "s.toml").write_text(text.replace('profile = "typical"', f'profile = "{profile}"'))
    rec = tmp_path / "s.mcap"
    assert main(["--no-progress", "generate", str(tmp_path / "s.toml"), "-o", str(rec), "--duration", "1",
                 "--people", "1"]) == 0
    stats = recording_detector_stats(rec)
    causes = stats["missed_person_views_by_cause"]
    assert set(causes) == set(MISS_CAUSES)
    assert stats["missed_person_view_rate"] > 0.05  # (the shelves hide a lone shopper from some cameras)
    assert causes["detector_or_people"] == 0.0
    assert causes["hidden_by_shelves"] > 0.0
    assert sum(causes.values()) == pytest.approx(stats["missed_person_view_rate"], abs=1e-12)



def test_a_person_out_of_the_lens_range_takes_no_detection_of_the_people_in_view():
    """A barrel lens folds the projections of points far outside its field out to 1e9 px and more: a person
    standing under the camera (no joint in the image) once had a person size so large that a detection matched it
    at error / size 0.000 (a phantom counted as a detection, or a real person missed). Such joints have no size,
    such a person takes no detection."""
    from core.projection import in_image

    barrel = Camera("c1", CAM.K, np.array([-0.3, 0.0, 0.0, 0.0, 0.0]), CAM.R_cam_from_world, CAM.t_cam_from_world,
                    CAM.width_px, CAM.height_px)
    under = _standing(0.0, -0.25)  # around the camera, at (0, 0, 1): nothing of it in the image
    px, inside = in_image(barrel, np.stack([PEOPLE[1], under, PEOPLE[0]]))
    assert inside[0].all() and not inside[1].any() and np.nanmax(np.abs(px[1])) > 1e6
    # The person in view detected exactly, and a phantom where nobody of the truth stands (PEOPLE[0]'s place).
    frames = [_camera_frame(barrel, k / FPS, [11, 99], np.stack([PEOPLE[1], under]), px[[0, 2]]) for k in range(20)]
    stats = detector_stats(frames, [barrel], COCO17)
    assert stats["matched_detections"] == 20 and stats["missed_person_view_rate"] == 0.0
    assert stats["false_positive_people_per_frame"] == 1.0  # (the phantom, which the person under it once took)
    assert stats["error_over_size_p99"] == pytest.approx(0.0, abs=1e-9)
