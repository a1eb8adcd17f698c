"""`crossview render`: the rebuilt world is the recorded one, rendered pixels agree with detections and projections,
occluded joints sit behind what the render shows in front of them, and bad input gets one line and exit 2."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from core.projection import in_image
from crossview import pipeline, recording
from crossview.cli import EXIT_BAD_INPUT, main
from sim import scenario as scenario_mod
from sim.rng import child_rng
from tests.conftest import render_env
from tests.crossview.test_cli import _run_bad

DURATION_S = 1.0


def _make(folder, seed: int):
    """A short store_layout2 recording (shelves; the ideal detector, whose joints are the exact projections) and
    its tracks."""
    scenario = scenario_mod.load("store_layout2", {"duration_s": DURATION_S, "seed": seed, "detector.profile": "ideal"})
    rec = folder / f"l2_{seed}.mcap"
    tracks = folder / f"l2_{seed}.tracks.mcap"
    pipeline.generate(scenario, rec, progress=False)
    pipeline.track(rec, tracks, method="crossview", preset="store", config_path=None, progress=False)
    return rec, tracks


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    return _make(tmp_path_factory.mktemp("render"), seed=0)


def test_rebuilt_world_is_the_recorded_truth(made):
    # The recording keeps the scenario text and seed: the world built again from them and advanced to each truth
    # tick poses everybody exactly as the recorded truth has them.
    from sim.world import World

    rec = recording.open_recording(made[0])
    scenario = scenario_mod.from_source_text(rec.header.scenario_text, rec.header.scenario_name, str(rec.path))
    assert scenario.digest == rec.header.scenario_digest
    world = World(scenario, child_rng(rec.header.seed, "crowd"))
    ticks = list(rec.truth())
    assert len(ticks) > 50
    for tick in ticks[::7]:
        truth = world.advance(tick.t_s)
        np.testing.assert_array_equal(truth.person_ids, tick.person_ids)
        np.testing.assert_array_equal(truth.poses, tick.poses)


_PROBE_SCRIPT = """
import json, sys
from sim.render import RenderKind, choose_backend

choose_backend(sys.argv[3])
import mujoco
import numpy as np
from crossview import recording
from crossview.pictures.render import scene_of
from sim import humanoid

rec = recording.open_recording(sys.argv[1])
spec = json.loads(sys.argv[2])
index = spec["camera"]
scene = scene_of(rec)
world = scene.world_at(spec["capture_s"])
renderer = scene.renderer
seg = renderer.render(world.data, index, RenderKind.SEGMENTATION)
depth = renderer.render(world.data, index, RenderKind.DEPTH)
# Only the keypoint sites (group 4): each joint is a small rendered marker.
renderer.option.geomgroup[:] = 0
renderer.option.sitegroup[:] = 0
renderer.option.sitegroup[4] = 1
sites = renderer.render(world.data, index, RenderKind.SEGMENTATION)
model = world.model
kp_sites = {int(pid): [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"p{slot}_{name}")
                       for name in humanoid.KEYPOINT_NAMES]
            for slot, pid in enumerate(world.crowd.person_id.tolist()) if pid >= 0}
shelves = [g for g in range(model.ngeom) if model.geom(g).name.startswith("shelf")]
np.savez(spec["out"], seg=seg, depth=depth, sites=sites, geom_person=world.geom_person_ids(), shelves=shelves,
         kp_person=np.array(list(kp_sites), dtype=np.int64), kp_sites=np.array(list(kp_sites.values()), dtype=np.int64))
"""


@pytest.fixture(scope="module")
def probed(made, offscreen_backend, tmp_path_factory):
    """The frame with the most joints hidden by the store or other people, and its camera's renders (colours'
    segmentation, depth, keypoint sites alone) at its capture time, made in a fresh interpreter."""
    rec = recording.open_recording(made[0])
    frames = list(rec.frames(with_poses=True))
    frame = max(frames, key=lambda f: int((f.truth.occluded & f.truth.in_image).sum()))
    index = [c.name for c in rec.cameras].index(frame.frame.camera)
    out = tmp_path_factory.mktemp("probe") / "renders.npz"
    spec = {"camera": index, "capture_s": frame.truth.capture_s, "out": str(out)}
    subprocess.run([sys.executable, "-c", _PROBE_SCRIPT, str(made[0]), json.dumps(spec), offscreen_backend],
                   env=render_env(offscreen_backend), check=True, capture_output=True, text=True)
    return rec.cameras[index], frame, dict(np.load(out))


def _uniform(labels: np.ndarray, u: int, v: int, radius: int = 3) -> bool:
    """Whether the segmentation is one object in the (2 radius + 1)² square around pixel (u, v): away from edges,
    where a few millimetres of motion or a pixel of rasterisation could change what is seen."""
    h, w = labels.shape[:2]
    if not (radius <= u < w - radius and radius <= v < h - radius):
        return False
    patch = labels[v - radius:v + radius + 1, u - radius:u + radius + 1, 0]
    return bool((patch == patch[0, 0]).all())


def test_rendered_marker_detection_and_projection_agree_within_a_pixel(probed):
    camera, frame, renders = probed
    sites, kp_person, kp_sites = renders["sites"], renders["kp_person"], renders["kp_sites"]
    truth, kp = frame.truth, frame.frame.keypoints_px
    poses = frame.poses_at_capture
    compared = 0
    for d, pid in enumerate(truth.person_ids.tolist()):
        if pid < 0:
            continue
        projected, _ = in_image(camera, poses.poses[list(poses.person_ids).index(pid)])
        for j in np.nonzero(np.isfinite(kp[d]).all(axis=-1) & ~truth.occluded[d] & ~truth.self_occluded[d])[0]:
            site = kp_sites[list(kp_person).index(pid), j]
            rows, cols = np.nonzero((sites[..., 0] == site) & (sites[..., 1] == 6))  # 6: mjOBJ_SITE
            edge = rows.size and (rows.min() == 0 or cols.min() == 0 or rows.max() == camera.height_px - 1
                                  or cols.max() == camera.width_px - 1)
            if rows.size < 5 or edge:
                continue
            marker = np.array([cols.mean(), rows.mean()])
            np.testing.assert_allclose(kp[d, j], projected[j], atol=1.0)  # px: the detection is our projection
            np.testing.assert_allclose(marker, kp[d, j], atol=1.0)  # px: where MuJoCo draws the joint
            compared += 1
    assert compared >= 20


def test_occluded_joints_lie_behind_what_the_render_shows_there(probed):
    camera, frame, renders = probed
    seg, depth, owner, shelves = renders["seg"], renders["depth"], renders["geom_person"], set(renders["shelves"])
    truth, poses = frame.truth, frame.poses_at_capture
    on_shelf = occluded = visible = 0
    for d, pid in enumerate(truth.person_ids.tolist()):
        if pid < 0:
            continue
        pose = poses.poses[list(poses.person_ids).index(pid)]
        depth_m = (pose @ camera.R_cam_from_world.T + camera.t_cam_from_world)[:, 2]
        for j in np.nonzero(truth.in_image[d])[0]:
            u, v = (int(round(c)) for c in truth.keypoints_px[d, j])
            if not _uniform(seg, u, v):
                continue
            geom = int(seg[v, u, 0])
            assert seg[v, u, 1] == 5 and geom >= 0  # 5: mjOBJ_GEOM; the store is closed, every ray hits a geom
            if truth.occluded[d, j]:
                # Hidden by the store or another person: what the render shows there is not this person, and it is
                # nearer to the camera than the joint.
                assert owner[geom] != pid
                assert depth[v, u] < depth_m[j]
                occluded += 1
                on_shelf += geom in shelves
            elif not truth.self_occluded[d, j]:
                assert owner[geom] == pid  # seen: the render shows this person's own body there
                visible += 1
    assert occluded >= 3 and visible >= 10
    assert on_shelf >= 1  # a joint hidden by a shelf: its pixel in the render belongs to the shelf


def test_unknown_camera_lists_the_valid_ones(made, tmp_path, capsys):
    out = tmp_path / "view.png"
    err = _run_bad(capsys, ["render", str(made[0]), "--camera", "cam99", "--time", "0.5", "-o", str(out)])
    assert "--camera cam99: no such camera" in err and "cam00, cam01" in err and "cam27" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv", [["--time", "7.5"], ["--time", "-1"], ["--from", "0.2", "--to", "3"]])
def test_time_outside_the_recording_is_refused(made, tmp_path, capsys, argv):
    out = tmp_path / ("clip.gif" if "--from" in argv else "view.png")
    err = _run_bad(capsys, ["render", str(made[0]), "--camera", "cam00", *argv, "-o", str(out)])
    assert "outside the recording" in err and f"0 to {DURATION_S:g} s" in err
    assert list(tmp_path.iterdir()) == []


def test_tracks_of_another_recording_are_refused(made, tmp_path, capsys):
    _, other_tracks = _make(tmp_path, seed=1)
    out = tmp_path / "view.png"
    err = _run_bad(capsys, ["render", str(made[0]), "--camera", "cam00", "--time", "0.5", "--tracks",
                            str(other_tracks), "-o", str(out)])
    assert "l2_1.tracks.mcap: tracks were made from scenario 'store_layout2' seed 1" in err
    assert not out.exists()


@pytest.mark.parametrize("argv, name", [(["--time", "0.5"], "view.bmp"), (["--time", "0.5"], "view.gif"),
                                        (["--from", "0", "--to", "0.5"], "clip.png"), (["--time", "0.5"], "view")])
def test_output_that_is_not_a_picture_or_clip_format_is_refused(made, tmp_path, capsys, argv, name):
    out = tmp_path / name
    err = _run_bad(capsys, ["render", str(made[0]), "--camera", "cam00", *argv, "-o", str(out)])
    assert f"{out}: a" in err and "is written as" in err
    assert list(tmp_path.iterdir()) == []


def test_unknown_backend_is_refused(made, tmp_path, capsys):
    status = main(["render", str(made[0]), "--camera", "cam00", "--time", "0.5", "--gl", "glx", "-o",
                   str(tmp_path / "v.png")])
    assert status == EXIT_BAD_INPUT and "invalid choice: 'glx'" in capsys.readouterr().err


def _cli(args, backend):
    done = subprocess.run([sys.executable, "-m", "crossview.cli", "--no-progress", "render", *map(str, args)],
                          env=render_env(backend), capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_render_writes_a_view_a_contact_sheet_a_top_down_map_and_a_clip(made, offscreen_backend, tmp_path):
    import cv2
    from PIL import Image

    rec, tracks = made
    cameras = recording.open_recording(rec).cameras
    # One camera: its own image size under a caption strip.
    out = _cli([rec, "--camera", "cam10", "--time", "0.5", "--tracks", tracks, "-o", tmp_path / "view.png"],
               offscreen_backend)
    assert "view.png: 1 image; 1 camera views rendered" in out
    view = cv2.imread(str(tmp_path / "view.png"))
    assert view.shape[1] == cameras[10].width_px and view.shape[0] > cameras[10].height_px
    # Every camera in a grid of 7 columns (28 cameras).
    out = _cli([rec, "--contact-sheet", "--time", "0.5", "-o", tmp_path / "sheet.jpg"], offscreen_backend)
    assert "28 camera views rendered" in out
    assert cv2.imread(str(tmp_path / "sheet.jpg")).shape[1] == 7 * (320 + 2)
    # The plan needs no rendering.
    _cli([rec, "--top-down", "--from", "0", "--to", "1", "--tracks", tracks, "-o", tmp_path / "plan.png"],
         offscreen_backend)
    assert cv2.imread(str(tmp_path / "plan.png")).shape[2] == 3
    # A clip at 10 images per second: 0.2, 0.3, 0.4, 0.5 s.
    out = _cli([rec, "--camera", "cam03", "--from", "0.2", "--to", "0.5", "-o", tmp_path / "clip.gif"],
               offscreen_backend)
    assert "clip.gif: 4 images" in out
    with Image.open(tmp_path / "clip.gif") as gif:
        assert gif.n_frames == 4 and gif.size == (cameras[3].width_px, view.shape[0])
    # The same as MP4 (OpenCV's writer), of the contact sheet.
    _cli([rec, "--contact-sheet", "--tile-width", "160", "--from", "0.2", "--to", "0.3", "-o", tmp_path / "clip.mp4"],
         offscreen_backend)
    video = cv2.VideoCapture(str(tmp_path / "clip.mp4"))
    assert video.get(cv2.CAP_PROP_FRAME_COUNT) == 2 and video.get(cv2.CAP_PROP_FRAME_WIDTH) == 7 * (160 + 2)
    video.release()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.gif", "clip.mp4", "plan.png", "sheet.jpg", "view.png"]


# `crossview generate --images`: rendered pictures stored in the recording.

_IMAGES_ARGS = ["store_layout2", "--duration", "1", "--seed", "0", "--cameras", "4"]
_IMAGES_RATE = 5.0  # of 10 fps: every other frame of each camera

_VIEWS_SCRIPT = """
import json, sys
from sim.render import choose_backend

choose_backend(sys.argv[3])
import cv2
from crossview import recording
from crossview.pictures.render import scene_of
from sim.render import IMAGE_MULTISAMPLES, JPEG_QUALITY

rec = recording.open_recording(sys.argv[1])
scene = scene_of(rec, multisamples=IMAGE_MULTISAMPLES)
for n, (index, capture_s) in enumerate(json.loads(sys.argv[2])):
    ok, data = cv2.imencode(".jpg", scene.view(index, capture_s), [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    open(f"{sys.argv[4]}/{n}.jpg", "wb").write(data.tobytes())
"""


def _generate(argv, backend, env=None):
    return subprocess.run([sys.executable, "-m", "crossview.cli", "--no-progress", "generate", *map(str, argv)],
                          env={**render_env(backend), **(env or {})}, capture_output=True, text=True)


@pytest.fixture(scope="module")
def pictured(offscreen_backend, tmp_path_factory):
    """A short recording made with --images, twice, and the same scenario made without."""
    folder = tmp_path_factory.mktemp("images")
    made = []
    for name in ("a.mcap", "b.mcap"):
        done = _generate([*_IMAGES_ARGS, "--images", _IMAGES_RATE, "-o", folder / name], offscreen_backend)
        assert done.returncode == 0, done.stderr
        made.append(folder / name)
    assert "pictures rendered in" in done.stdout
    plain = folder / "plain.mcap"
    pipeline.generate(pipeline.load_scenario("store_layout2", duration_s=1.0, seed=0, cameras=4), plain,
                      progress=False)
    return made[0], made[1], plain


def test_generate_images_gives_the_same_bytes_twice(pictured):
    a, b, _ = pictured
    assert a.read_bytes() == b.read_bytes()


def test_generate_images_adds_pictures_and_changes_nothing_else(pictured):
    with_images, _, plain = pictured
    rec, ref = recording.open_recording(with_images), recording.open_recording(plain)
    # The same truth and frames as without pictures (and without them the bytes are those the other tests pin).
    for got, want in zip(rec.truth(), ref.truth(), strict=True):
        np.testing.assert_array_equal(got.poses, want.poses)
    for got, want in zip(rec.frames(), ref.frames(), strict=True):
        assert (got.frame.camera, got.frame.stamp_s, got.truth.capture_s) == \
            (want.frame.camera, want.frame.stamp_s, want.truth.capture_s)
        np.testing.assert_array_equal(got.frame.keypoints_px, want.frame.keypoints_px)
    backdrops = list(ref.images())
    images = list(rec.images())
    assert [i for i in images if i.format == "png"] == backdrops and len(backdrops) == 4
    jpegs = [i for i in images if i.format == "jpeg"]
    assert len(jpegs) == len(images) - 4 > 0


def test_each_camera_pictures_every_other_frame_as_crossview_render_sees_it(pictured, offscreen_backend, tmp_path):
    import cv2

    rec = recording.open_recording(pictured[0])
    names = [c.name for c in rec.cameras]
    frames = sorted(rec.frames(), key=lambda f: f.truth.capture_s)
    # Rate 5 of 10 fps: each camera's frames 0, 2, 4, ... in capture order, at the frame's delivery time.
    chosen = [f for c in names for f in [g for g in frames if g.frame.camera == c][::2]]
    jpegs = [i for i in rec.images() if i.format == "jpeg"]
    assert sorted((i.camera, i.log_time_ns) for i in jpegs) == \
        sorted((f.frame.camera, recording.to_ns(f.truth.delivery_s)) for f in chosen)
    by_key = {(i.camera, i.log_time_ns): i.data for i in jpegs}
    for f in chosen:
        camera = rec.cameras[names.index(f.frame.camera)]
        picture = cv2.imdecode(np.frombuffer(by_key[(camera.name, recording.to_ns(f.truth.delivery_s))], np.uint8),
                               cv2.IMREAD_COLOR)
        assert picture.shape == (camera.height_px, camera.width_px, 3)
    # A stored picture is `crossview render`'s view of its frame (the world built again and posed at its capture
    # time, at random access rather than in order), to the byte.
    picked = [chosen[0], chosen[-1]]
    spec = [(names.index(f.frame.camera), f.truth.capture_s) for f in picked]
    subprocess.run([sys.executable, "-c", _VIEWS_SCRIPT, str(pictured[0]), json.dumps(spec), offscreen_backend,
                    str(tmp_path)], env=render_env(offscreen_backend), check=True, capture_output=True, text=True)
    for n, f in enumerate(picked):
        assert (tmp_path / f"{n}.jpg").read_bytes() == by_key[(f.frame.camera, recording.to_ns(f.truth.delivery_s))]


@pytest.mark.parametrize("rate, message", [("11", "--images 11: pictures per second per camera must be > 0 and at "
                                                   "most the cameras' frame rate, 10 fps in"),
                                           ("0", "argument --images: 0 must be > 0"),
                                           ("nan", "argument --images: nan must be > 0"),
                                           ("fast", "argument --images: 'fast' is not a number")])
def test_image_rate_that_is_not_positive_or_above_the_frame_rate_is_refused(tmp_path, capsys, rate, message):
    out = tmp_path / "rec.mcap"
    err = _run_bad(capsys, ["generate", *_IMAGES_ARGS, "--images", rate, "-o", str(out)])
    assert message in err
    assert list(tmp_path.iterdir()) == []


def test_generate_images_without_pyopengl_names_the_extra(tmp_path, capsys, monkeypatch):
    from sim import render as sim_render

    real = sim_render.importlib.util.find_spec
    monkeypatch.setattr(sim_render.importlib.util, "find_spec", lambda name: None if name == "OpenGL" else real(name))
    out = tmp_path / "rec.mcap"
    err = _run_bad(capsys, ["generate", *_IMAGES_ARGS, "--images", "1", "-o", str(out)])
    assert "PyOpenGL is not installed" in err and "pip install '.[render]'" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.rendering
def test_generate_images_with_an_egl_that_does_not_open(tmp_path):
    # No EGL vendor library for glvnd's libEGL: EGL cannot open, as on a machine without a GPU or Mesa's EGL.
    no_egl = {"__EGL_VENDOR_LIBRARY_FILENAMES": str(tmp_path / "none.json")}
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")} | no_egl
    probe = ("import json; from sim.render import GLBackend, backend_problem as p; "
             "print(json.dumps([p(GLBackend.EGL), p(GLBackend.OSMESA)]))")
    egl_problem, osmesa_problem = json.loads(subprocess.run([sys.executable, "-c", probe], env=env,
                                                            capture_output=True, text=True, check=True).stdout)
    if egl_problem is None:
        pytest.skip("EGL opens here even without a vendor library (not glvnd's libEGL)")
    out = tmp_path / "rec.mcap"
    argv = [sys.executable, "-m", "crossview.cli", "--no-progress", "generate", *_IMAGES_ARGS, "--duration", "0.2",
            "--images", "1", "-o", str(out)]
    # Asked for by name: one line saying what to do, exit 2, nothing written.
    done = subprocess.run([*argv, "--gl", "egl"], env=env, capture_output=True, text=True)
    assert done.returncode == EXIT_BAD_INPUT and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "--gl egl: MuJoCo cannot open an offscreen egl context here" in done.stderr and "--gl osmesa" in done.stderr
    assert not out.exists()
    if osmesa_problem is not None:
        pytest.skip(f"OSMesa does not open here either ({osmesa_problem}): no fall-back to show")
    # Chosen automatically (no --gl, no MUJOCO_GL): OSMesa instead.
    done = subprocess.run(argv, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "4 pictures rendered" in done.stdout
