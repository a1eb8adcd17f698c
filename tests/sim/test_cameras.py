"""Camera rigs and projection: agreement with OpenCV, rig geometry, calibration files, bad input."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from core.errors import ScenarioError
from core.projection import in_image
from core.types import Camera
from sim import scenario as scenario_mod
from sim.cameras import CalibrationFormat, CameraPlacement, build_rig, load_panoptic, look_at, mujoco_camera_pose
from tests.conftest import render_env
from tests.reference import cameras as reference

# The Panoptic dome's 31 HD cameras, shipped with the dome scenario (cut by tests/data/cut_fixtures.py).
PANOPTIC = scenario_mod.SCENARIO_DIR / "calibrations" / "panoptic_160906_hd.json"
# Campus's calibration.json with its image size, shipped with the campus scenario (cut by the same script).
CAMPUS_RIG = scenario_mod.SCENARIO_DIR / "calibrations" / "campus_calibration.json"
CAMPUS = Path(__file__).resolve().parents[1] / "data" / "campus"


@pytest.fixture
def rng():
    return np.random.default_rng(7)


def _scenario(**cameras):
    base = scenario_mod.Scenario(name="t")
    return dataclasses.replace(base, cameras=dataclasses.replace(base.cameras, **cameras))


def test_projection_agrees_with_cv2_project_points(rng):
    camera = Camera("c", [[900, 0, 640], [0, 880, 350], [0, 0, 1]], [-0.2, 0.08, 0.001, -0.002, -0.01],
                    look_at([0.5, 0.2, 3.0], [2.0, 1.5, 0.5]), [0.1, -0.2, 3.0], 1280, 720)
    points = camera.center_world + rng.normal(0, 0.5, (200, 3)) + 3.0 * camera.R_cam_from_world[2]
    rvec, _ = cv2.Rodrigues(camera.R_cam_from_world)
    theirs, _ = cv2.projectPoints(points, rvec, camera.t_cam_from_world, camera.K, camera.dist)
    # The numpy reference and the product's compiled projection both give OpenCV's pixels.
    ref, in_front = reference.project(camera, points)
    ours, _ = in_image(camera, points)
    assert in_front.all()
    np.testing.assert_allclose(ref, theirs[:, 0], atol=1e-6)  # px
    np.testing.assert_allclose(ours, theirs[:, 0], atol=1e-6)  # px


def test_projection_keeps_leading_shape_and_flags_points_behind(rng):
    camera = build_rig(_scenario(rows=1, cols=1), rng)[0]
    points = np.stack([camera.center_world + [0.1, 0.1, -2.0], camera.center_world + [0.0, 0.0, 1.0]])
    px, inside = in_image(camera, points.reshape(1, 2, 3))
    assert px.shape == (1, 2, 2) and inside.tolist() == [[True, False]]
    assert np.isnan(px[0, 1]).all()


def test_grid_cameras_hang_below_ceiling_inside_store_and_look_down(rng):
    scenario = _scenario(rows=2, cols=3)
    cams = build_rig(scenario, rng)
    assert [c.name for c in cams] == [f"cam{i:02d}" for i in range(6)]
    store = scenario.store
    for cam in cams:
        c = cam.center_world
        assert 0 <= c[0] <= store.width_m and 0 <= c[1] <= store.depth_m
        np.testing.assert_allclose(c[2], store.ceiling_m - scenario.cameras.ceiling_gap_m, atol=1e-9)  # m
        forward = cam.R_cam_from_world[2]
        assert forward[2] < -0.3
        # Tilted toward the store centre: the optical axis points inward.
        to_centre = np.array([store.width_m / 2, store.depth_m / 2]) - c[:2]
        assert forward[:2] @ to_centre >= 0
        # The centre of the floor is in every camera's image.
        _, inside = in_image(cam, np.array([store.width_m / 2, store.depth_m / 2, 1.0]))
        assert inside


def test_intrinsics_follow_resolution_and_fov(rng):
    cam = build_rig(_scenario(rows=1, cols=1, width_px=640, height_px=480, hfov_deg=90.0), rng)[0]
    np.testing.assert_allclose(cam.K, [[320, 0, 319.5], [0, 320, 239.5], [0, 0, 1]])


def test_explicit_placements_replace_the_grid(rng):
    placements = (CameraPlacement((0.5, 0.5, 2.8), (2.0, 1.5, 1.0), name="door"),
                  CameraPlacement((3.5, 2.5, 2.8), (2.0, 1.5, 0.0)))
    cams = build_rig(_scenario(placements=placements), rng)
    assert [c.name for c in cams] == ["door", "cam01"]
    np.testing.assert_allclose(cams[0].center_world, [0.5, 0.5, 2.8], atol=1e-12)  # m
    px, _ = in_image(cams[0], np.array([2.0, 1.5, 1.0]))
    np.testing.assert_allclose(px, cams[0].K[:2, 2], atol=1e-9)  # px: the aim point is the image centre


def test_camera_outside_store_is_a_scenario_error(rng):
    placements = (CameraPlacement((9.0, 0.5, 2.8), (2.0, 1.5, 1.0)),)
    with pytest.raises(ScenarioError, match=r"cameras.placements\[0\].*outside the store"):
        build_rig(_scenario(placements=placements), rng)


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("[cameras]\nrows = 0\n", "rows: 0 must be in [1, 100]"),
        ("[cameras]\nhfov_deg = 0\n", "hfov_deg"),
        ("[cameras]\nhfov_deg = 180\n", "hfov_deg"),
        ("[[cameras.placements]]\nposition_m = [1.0, 1.0, 2.5]\nlook_at_m = [1.0, 1.0, 3.0]\n", "look_at_m"),
        ("[clock]\nfps = -10.0\n", "fps"),
        ("[clock]\ndrop_prob = 1.5\n", "drop_prob"),
        ("[detector]\nmiss_prob = 2.0\n", "miss_prob"),
    ],
)
def test_bad_sensor_keys_are_one_line_scenario_errors(tmp_path, text, key):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError) as err:
        scenario_mod.load(path)
    message = str(err.value)
    assert key in message and "\n" not in message and str(path) in message


def test_panoptic_hd_cameras_reproject_their_own_calibration():
    cams = load_panoptic(PANOPTIC, "hd", z_up=False)
    assert len(cams) == 31 and all((c.width_px, c.height_px) == (1920, 1080) for c in cams)
    # Panoptic's own model in centimetres, through OpenCV, matches ours in metres.
    entry = next(e for e in json.loads(PANOPTIC.read_text())["cameras"] if e["type"] == "hd")
    point_cm = np.array([[10.0, -120.0, 30.0]])
    rvec, _ = cv2.Rodrigues(np.array(entry["R"]))
    theirs, _ = cv2.projectPoints(point_cm, rvec, np.array(entry["t"]), np.array(entry["K"]),
                                  np.array(entry["distCoef"]))
    ours, _ = in_image(cams[0], point_cm * 0.01)
    np.testing.assert_allclose(ours, theirs[:, 0], atol=1e-3)  # px


def test_panoptic_z_up_keeps_the_images_and_puts_cameras_above_the_floor():
    y_down = load_panoptic(PANOPTIC, "hd", z_up=False)
    z_up = load_panoptic(PANOPTIC, "hd", origin_m=(5.0, 5.0, 0.0))
    point_pan = np.array([0.1, -1.2, 0.3])
    point_ours = np.array([0.1, 0.3, 1.2]) + [5.0, 5.0, 0.0]
    for a, b in zip(y_down, z_up):
        np.testing.assert_allclose(in_image(a, point_pan)[0], in_image(b, point_ours)[0], atol=1e-6)  # px
    assert min(c.center_world[2] for c in z_up) > -0.5


def test_mujoco_pose_axes_are_opencv_axes_flipped(rng):
    cam = build_rig(_scenario(rows=1, cols=2), rng)[1]
    import mujoco

    pos, quat, fovy = mujoco_camera_pose(cam)
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, quat)
    world_from_mj = mat.reshape(3, 3)
    np.testing.assert_allclose(pos, cam.center_world)
    # MuJoCo looks down its -z: that is the OpenCV forward axis; its y is OpenCV's -y.
    np.testing.assert_allclose(-world_from_mj[:, 2], cam.R_cam_from_world[2], atol=1e-12)
    np.testing.assert_allclose(-world_from_mj[:, 1], cam.R_cam_from_world[1], atol=1e-12)
    np.testing.assert_allclose(fovy, np.degrees(2 * np.arctan(360 / cam.K[1, 1])))


_RENDER_SCRIPT = """
import json, sys
import numpy as np
from core.types import Camera
from sim.render import CameraRenderer, RenderKind, choose_backend

choose_backend(sys.argv[2])
import mujoco

spec = json.loads(sys.argv[1])
xml = f\"\"\"
<mujoco>
  <visual><headlight ambient="0 0 0" diffuse="0 0 0" specular="0 0 0"/></visual>
  <asset><material name="glow" emission="1" rgba="1 0 0 1"/></asset>
  <worldbody><geom type="sphere" size="{spec['radius']}" pos="{spec['marker']}" material="glow"/></worldbody>
</mujoco>\"\"\"
model = mujoco.MjModel.from_xml_string(xml)
data = mujoco.MjData(model)
mujoco.mj_forward(model, data)
c = spec["camera"]
camera = Camera("c", np.array(c["K"]), np.array(c["dist"]), np.array(c["R"]), np.array(c["t"]), c["width"],
                c["height"])
with CameraRenderer(model, [camera]) as renderer:
    renderer.model.vis.headlight.ambient[:] = 0.0  # (the renderer brightens it; the marker glows alone)
    renderer.model.vis.headlight.diffuse[:] = 0.0
    weight = renderer.render(data, 0, RenderKind.RGB)[..., 0].astype(np.float64) / 255.0
rows, cols = np.mgrid[:weight.shape[0], :weight.shape[1]]
print(json.dumps([(weight * cols).sum() / weight.sum(), (weight * rows).sum() / weight.sum()]))
"""


def _render_marker(camera: Camera, marker_m: np.ndarray, radius_m: float, backend: str) -> np.ndarray:
    """(2,) centroid in pixels of a small glowing sphere rendered by the product's `sim.render.CameraRenderer`
    (a pinhole placed by `mujoco_camera_pose`, remapped through the camera's lens), in a fresh interpreter with
    the offscreen `backend` (EGL or OSMesa)."""
    spec = {"radius": radius_m, "marker": " ".join(map(repr, map(float, marker_m))),
            "camera": {"K": camera.K.tolist(), "dist": camera.dist.tolist(), "R": camera.R_cam_from_world.tolist(),
                       "t": camera.t_cam_from_world.tolist(), "width": camera.width_px, "height": camera.height_px}}
    out = subprocess.run([sys.executable, "-c", _RENDER_SCRIPT, json.dumps(spec), backend], env=render_env(backend),
                         check=True, capture_output=True, text=True)
    return np.array(json.loads(out.stdout))


@pytest.mark.parametrize("lens", ["pinhole", "distorted"])
def test_projection_agrees_with_mujoco_renderer(rng, offscreen_backend, lens):
    # A tilted ceiling camera: a pinhole (what MuJoCo renders itself), and one with strong barrel distortion that
    # the renderer remaps into; a marker near the image corner shows the distortion most.
    k1, k2 = (0.0, 0.0) if lens == "pinhole" else (-0.25, 0.06)
    scenario = _scenario(rows=2, cols=2, width_px=320, height_px=240, hfov_deg=80.0, k1=k1, k2=k2, aim_inward=0.5)
    camera = build_rig(scenario, rng)[3]
    store = scenario.store
    markers = [np.array([store.width_m / 2, store.depth_m / 2, 1.0]), np.array([1.2, 1.0, 0.4]),
               np.array([3.2, 0.7, 1.6])]
    for marker in markers:
        expected, inside = in_image(camera, marker)
        assert inside
        np.testing.assert_allclose(_render_marker(camera, marker, 0.03, offscreen_backend), expected, atol=1.0)  # px


def test_shipped_dome_scenario_takes_the_panoptic_calibration_beside_it(rng):
    # The shipped scenario names its calibration relative to its own file, wherever it is installed.
    dome = scenario_mod.load("panoptic_dome")
    cams = build_rig(dome, rng)
    assert len(cams) == 31 and cams[0].name == "hd_00_00" and (cams[0].width_px, cams[0].height_px) == (1920, 1080)
    # The dome's centre, 1 m up, is in most of its cameras' images.
    seen = [in_image(c, np.array([3.0, 3.0, 1.0]))[1] for c in cams]
    assert sum(seen) >= 25
    # The same file read directly gives the same cameras, 3 m over.
    direct = load_panoptic(PANOPTIC, "hd", origin_m=(3.0, 3.0, 0.0))
    np.testing.assert_allclose([c.center_world for c in direct], [c.center_world for c in cams])


def test_calibration_count_takes_cameras_spread_over_the_rig(rng):
    every = build_rig(scenario_mod.load("panoptic_dome"), rng)
    six = build_rig(scenario_mod.load("panoptic_dome", {"cameras.calibration_count": 6}), rng)
    assert [c.name for c in six] == [every[i].name for i in (0, 6, 12, 18, 24, 30)]
    with pytest.raises(ScenarioError, match="cameras.calibration_count: 40 is more than the 31 cameras"):
        build_rig(scenario_mod.load("panoptic_dome", {"cameras.calibration_count": 40}), rng)


def test_calibration_path_is_taken_from_the_scenario_file_folder(tmp_path, rng):
    (tmp_path / "rigs").mkdir()
    (tmp_path / "rigs" / "dome.json").write_bytes(PANOPTIC.read_bytes())
    text = scenario_mod.resolve_path("panoptic_dome").read_text()
    (tmp_path / "mine.toml").write_text(text.replace("calibrations/panoptic_160906_hd.json", "rigs/dome.json"))
    assert len(build_rig(scenario_mod.load(tmp_path / "mine.toml"), rng)) == 31


def test_bad_calibrations_are_scenario_errors_naming_the_key(rng):
    from sim.store import StoreConfig

    base = scenario_mod.Scenario(name="dome", store=StoreConfig(width_m=6.0, depth_m=6.0, ceiling_m=3.5))
    config = dataclasses.replace(base.cameras, calibration=str(PANOPTIC), calibration_origin_m=(3.0, 3.0, 0.0))
    assert len(build_rig(dataclasses.replace(base, cameras=config), rng)) == 31
    # Calibrated cameras may stand around a floor smaller than the dome (a real rig stands where it stands).
    small = dataclasses.replace(base, store=StoreConfig(width_m=4.0, depth_m=4.0, ceiling_m=3.5), cameras=config)
    assert len(build_rig(small, rng)) == 31
    # An origin that puts the floor out of every view (metres taken for centimetres), cameras under the floor
    # or a missing file is a scenario error naming the key.
    far = dataclasses.replace(config, calibration_origin_m=(300.0, 300.0, 0.0))
    with pytest.raises(ScenarioError, match=r"cameras.calibration\[\d+\]: camera hd_\S+ at .* sees none of the floor"):
        build_rig(dataclasses.replace(base, cameras=far), rng)
    sunk = dataclasses.replace(config, calibration_origin_m=(3.0, 3.0, -10.0))
    with pytest.raises(ScenarioError, match=r"cameras.calibration\[\d+\]: .* must stand above the floor"):
        build_rig(dataclasses.replace(base, cameras=sunk), rng)
    missing = dataclasses.replace(base, cameras=dataclasses.replace(config, calibration="nowhere.json"))
    with pytest.raises(ScenarioError, match="cameras.calibration.*nowhere.json"):
        build_rig(missing, rng)


def test_shipped_campus_scenario_takes_the_dataset_layout_calibration_beside_it(rng):
    campus = scenario_mod.load("campus")
    assert campus.cameras.calibration_format is CalibrationFormat.DATASET
    cams = build_rig(campus, rng)
    origin = np.array(campus.cameras.calibration_origin_m)
    raw = json.loads(CAMPUS_RIG.read_text())["cameras"]
    assert [c.name for c in cams] == ["Camera0", "Camera1", "Camera2"]
    for cam in cams:
        # Where the file puts the camera (Tw's translation, cm), moved by the origin; its K at 360 x 288 pixels.
        Tw = np.array(raw[cam.name]["Tw"])
        np.testing.assert_allclose(cam.center_world, Tw[:3, 3] / 100 + origin, atol=1e-9)
        np.testing.assert_allclose(cam.K, np.array(raw[cam.name]["K"]) * [[360], [288], [1]])
        np.testing.assert_allclose(cam.dist[:4], raw[cam.name]["dist_coeffs"])
        assert (cam.width_px, cam.height_px) == (360, 288)
        # Standing around the square, not over it, at the height of a tripod.
        x, y, z = cam.center_world
        assert not (0 <= x <= campus.store.width_m and 0 <= y <= campus.store.depth_m) and 1.5 < z < 2.5
        assert in_image(cam, np.array([campus.store.width_m / 2, campus.store.depth_m / 2, 1.0]))[1]


def test_campus_rig_reprojects_the_real_campus_annotations():
    """The scenario's cameras (without their lens distortion, as the published 2D points are undistorted) put
    the real 3D truth where the real 2D annotation has it: an independent check of K, Tw and the origin."""
    campus = scenario_mod.load("campus")
    cams = {c.name: c for c in build_rig(campus, np.random.default_rng(0))}
    origin = np.array(campus.cameras.calibration_origin_m)
    truth = json.loads((CAMPUS / "annotation_3d.json").read_text())
    frames = json.loads((CAMPUS / "annotation_2d.json").read_text())["frames"]
    errors = []
    for frame in frames.values():
        index = round(frame["timestamp"] * 25)
        poses_3d = {p["id"]: np.array(p["points_3d"]) / 100 + origin for p in truth[index]["poses"]} \
            if index < len(truth) else {}
        cam = dataclasses.replace(cams[frame["camera"]], dist=np.zeros(5))
        for pose in frame["poses"]:
            if pose["id"] in poses_3d:
                px, _ = in_image(cam, poses_3d[pose["id"]])
                errors.extend(np.linalg.norm(px - np.array(pose["points_2d"]), axis=-1))
    assert len(errors) > 1000
    assert np.median(errors) < 1.0  # px (the published files agree to 0.3 px)


def _campus_scenario(tmp_path, calibration_text: str | bytes | None, fmt: str = "dataset"):
    """The shipped campus scenario with its calibration replaced by `calibration_text` in tmp_path (None: no file)."""
    if calibration_text is not None:
        data = calibration_text if isinstance(calibration_text, bytes) else calibration_text.encode()
        (tmp_path / "rig.json").write_bytes(data)
    text = scenario_mod.resolve_path("campus").read_text()
    text = text.replace("calibrations/campus_calibration.json", "rig.json")
    text = text.replace('calibration_format = "dataset"', f'calibration_format = "{fmt}"')
    (tmp_path / "campus.toml").write_text(text)
    return scenario_mod.load(tmp_path / "campus.toml")


def _campus_rig_with(change) -> str:
    data = json.loads(CAMPUS_RIG.read_text())
    change(data)
    return json.dumps(data)


BAD_DATASET_CALIBRATIONS = [
    ("missing", None, "dataset", r"cameras.calibration: 'rig.json': no such file"),
    ("not-json", "{", "dataset", r"rig.json' as a dataset calibration: Expecting property name"),
    ("not-utf8", b'{"cameras": "\xff"}', "dataset", r"rig.json' as a dataset calibration: .*codec can't decode"),
    ("not-an-object", "[1, 2]", "dataset", r"the file must be an object, got list"),
    ("cameras-a-list", _campus_rig_with(lambda d: d.update(cameras=list(d["cameras"].values()))), "dataset",
     r"key 'cameras' \(camera name -> \{K, Tw\}\) must be an object, got list"),
    ("no-image-size", _campus_rig_with(lambda d: d.pop("image_wh")), "dataset", r"key 'image_wh' missing"),
    ("bad-image-size", _campus_rig_with(lambda d: d.update(image_wh=[360])), "dataset",
     r"key 'image_wh' = \[360\] must be \[width, height\]"),
    ("no-pose", _campus_rig_with(lambda d: d["cameras"]["Camera1"].pop("Tw")), "dataset",
     r"camera 'Camera1': key 'Tw' missing or not numeric"),
    ("wrong-shape", _campus_rig_with(lambda d: d["cameras"]["Camera2"].update(K=[[1, 0], [0, 1]])), "dataset",
     r"camera 'Camera2': K must be 3x3 and Tw 4x4, got \(2, 2\)"),
    ("null-in-pose", _campus_rig_with(lambda d: d["cameras"]["Camera0"]["Tw"][0].__setitem__(3, None)), "dataset",
     r"camera 'Camera0': K and Tw must hold numbers"),
    ("panoptic-file-as-dataset", PANOPTIC.read_text(), "dataset",
     r"key 'cameras' \(camera name -> \{K, Tw\}\) must be an object, got list"),
    ("dataset-file-as-panoptic", CAMPUS_RIG.read_text(), "panoptic",
     r"as a panoptic calibration: key 'cameras' must be an array .* calibration_format = \"dataset\""),
]


@pytest.mark.parametrize(("text", "fmt", "expected"), [c[1:] for c in BAD_DATASET_CALIBRATIONS],
                         ids=[c[0] for c in BAD_DATASET_CALIBRATIONS])
def test_bad_dataset_calibrations_are_scenario_errors_naming_file_and_key(tmp_path, rng, text, fmt, expected):
    scenario = _campus_scenario(tmp_path, text, fmt)
    with pytest.raises(ScenarioError, match=expected) as caught:
        build_rig(scenario, rng)
    message = str(caught.value)
    assert message.startswith(f"{tmp_path / 'campus.toml'}: cameras.calibration: ") and "\n" not in message


def _stacked_rig(rig) -> tuple:
    """R, t, K, dist, size, monotonic radius of every camera, stacked as the compiled projection takes them."""
    from core.projection import monotonic_radius

    return (np.array([c.R_cam_from_world for c in rig]), np.array([c.t_cam_from_world for c in rig]),
            np.array([c.K for c in rig]), np.array([c.dist for c in rig]),
            np.array([(c.width_px, c.height_px) for c in rig], dtype=float),
            np.array([monotonic_radius(c.dist) for c in rig]))


@pytest.mark.parametrize("layout", ["store_layout2", "store_layout1"])
def test_in_image_many_agrees_with_in_image_per_camera(layout):
    """The compiled projection of a block's captures gives what `in_image` (numpy) gives camera by camera,
    bit for bit, for cameras straight down (store_layout2) and tilted (store_layout1)."""
    from core.projection import in_image_many

    rig = build_rig(scenario_mod.load(layout), np.random.default_rng(0))
    rng = np.random.default_rng(2)
    R, t, K, dist, size, radius = _stacked_rig(rig)
    cams = np.array([0, 5, 5, len(rig) - 1, len(rig) // 2])
    points = rng.uniform([-1, -1, -0.5], [9, 7, 3.5], (len(cams), 200, 3))
    points[2, :10] = np.nan
    px, inside = in_image_many(R, t, K, dist, size, radius, points, cams)
    for i, c in enumerate(cams):
        ref_px, ref_inside = reference.in_image(rig[c], points[i])
        np.testing.assert_array_equal(inside[i], ref_inside)
        np.testing.assert_array_equal(px[i], ref_px)
    assert inside.any() and not inside.all()


def test_in_image_many_kernel_agrees_with_in_image_on_single_skeletons():
    """The detector projects each phantom skeleton (17 points, one camera) with the compiled kernel: the
    pixels and flags are `in_image`'s bit for bit, whatever the camera's lens terms."""
    from core.projection import in_image_many_kernel
    from sim.sensing.draws import TEMPLATE_COCO17 as _TEMPLATE_COCO17

    for layout in ("store_layout2", "store_layout1"):
        rig = build_rig(scenario_mod.load(layout), np.random.default_rng(0))
        R, t, K, dist, size, radius = _stacked_rig(rig)
        rng = np.random.default_rng(5)
        seen = 0
        for _ in range(300):
            c = int(rng.integers(len(rig)))
            yaw = rng.uniform(0, 2 * np.pi)
            rot = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
            points = _TEMPLATE_COCO17 * rng.uniform(0.85, 1.1) @ rot.T + [rng.uniform(-1, 9), rng.uniform(-1, 7), 0]
            px, inside = np.empty((1, 17, 2)), np.empty((1, 17), dtype=bool)
            in_image_many_kernel(R, t, K, dist, size, radius, points[None], np.array([c]),
                                 np.array([bool(dist[c, 2:4].any())]), np.array([bool(K[c, 0, 1])]), px, inside)
            ref_px, ref_inside = reference.in_image(rig[c], points)
            assert px[0].tobytes() == ref_px.tobytes() and inside[0].tobytes() == ref_inside.tobytes()
            seen += int(ref_inside.sum())
        assert seen > 300  # plenty of the joints land in the image


# Camera "0" of the Shelf calibration as its source publishes it (zhangyux15/4d_association,
# data/shelf/calibration.json): K in pixels and the world-to-camera [R | t] in metres.
SHELF_SOURCE_K0 = [[1063.5121, 0.0, 511.73825], [0.0, 1071.8636, 350.08829], [0.0, 0.0, 1.0]]
SHELF_SOURCE_RT0 = [[0.65097713, -0.7587173, 0.02402735, -0.5942785],
                    [-0.01886197, -0.04781039, -0.99867845, 0.9719739],
                    [0.758863, 0.649664, -0.045434, 2.624511]]


def test_shipped_shelf_scenario_is_the_real_shelf_rig_and_every_person_is_seen_by_three_cameras():
    from core.types import COCO17
    from crossview.measure.detector_stats import JOINTS_12
    from sim.rng import child_rng
    from sim.world import World

    shelf = scenario_mod.load("shelf")
    assert shelf.cameras.calibration_format is CalibrationFormat.DATASET
    cams = build_rig(shelf, np.random.default_rng(0))
    origin = np.array(shelf.cameras.calibration_origin_m)
    assert [c.name for c in cams] == [f"Camera{i}" for i in range(5)]
    assert all((c.width_px, c.height_px) == (1032, 776) for c in cams)
    # Camera 0 projects as the source's K [R | t] does (OpenCV's projection, the points in the source's frame).
    rt = np.array(SHELF_SOURCE_RT0)
    points = np.array([[0.0, 0.0, 1.0], [0.5, -0.5, 0.2], [-0.3, 0.6, 1.6]])
    expected, _ = cv2.projectPoints(points, cv2.Rodrigues(rt[:, :3])[0], rt[:, 3], np.array(SHELF_SOURCE_K0), None)
    got, _ = in_image(cams[0], points + origin)
    np.testing.assert_allclose(got, expected.reshape(-1, 2), atol=1e-3)  # px
    # Over 20 s (two seeds), every person's 12 limb joints: at least half inside the images of 3 or more
    # cameras nearly all the time, at about Shelf's person size (398 px).
    joints = [COCO17.index(n) for n in JOINTS_12]
    for seed in (0, 1):
        world = World(shelf, child_rng(seed, "crowd"))
        seen, sizes = {}, []
        for k in range(20 * 5 + 1):
            truth = world.advance(k / 5)
            for i, pid in enumerate(truth.person_ids.tolist()):
                views = 0
                for cam in cams:
                    px, inside = in_image(cam, truth.poses[i, joints])
                    if inside.mean() >= 0.5:
                        views += 1
                        sizes.append(np.ptp(px[inside], axis=0).max())
                seen.setdefault(pid, []).append(views)
        assert len(seen) == shelf.crowd.people
        assert all(np.mean(np.array(v) >= 3) >= 0.9 for v in seen.values()), seen
        assert 300 < np.median(sizes) < 500  # px
