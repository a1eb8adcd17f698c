"""The lens remap of `sim.render` against our projection, and the backend choice's one-line errors (the renders
themselves are checked in tests/sim/test_cameras.py and tests/crossview/pictures/test_render.py)."""

import numpy as np
import pytest

from core.projection import in_image
from sim import render
from sim.cameras import build_rig
from sim.render import RenderingUnavailable, choose_backend, lens_map
from tests.sim.test_cameras import _scenario

pytestmark = pytest.mark.rendering  # the backend choice depends on the machine's OpenGL libraries


def test_lens_map_reads_each_picture_pixel_from_the_pinhole_pixel_of_its_ray():
    rng = np.random.default_rng(7)
    camera = build_rig(_scenario(rows=1, cols=2, k1=-0.25, k2=0.06, p1=0.002, p2=-0.001), rng)[1]
    lens = lens_map(camera)
    pinhole = lens.pinhole(camera)
    assert lens.map_x.shape == (camera.height_px, camera.width_px)
    # The pinhole's image holds every picture pixel's ray, so no picture pixel reads outside it.
    assert lens.map_x.min() >= 0 and lens.map_x.max() <= pinhole.width_px - 1
    assert lens.map_y.min() >= 0 and lens.map_y.max() <= pinhole.height_px - 1
    # A world point on the ray of a picture pixel (read back from the map's pinhole pixel) projects, through the
    # camera's own lens, onto that picture pixel.
    v = rng.integers(0, camera.height_px, 200)
    u = rng.integers(0, camera.width_px, 200)
    pinhole_px = np.column_stack([lens.map_x[v, u], lens.map_y[v, u], np.ones(200)]).astype(np.float64)
    rays = pinhole_px @ np.linalg.inv(pinhole.K).T
    points = (2.0 * rays - camera.t_cam_from_world) @ camera.R_cam_from_world  # 2 m in front, world frame
    px, inside = in_image(camera, points)
    assert inside.all()
    np.testing.assert_allclose(px, np.column_stack([u, v]), atol=2e-3)  # px (float32 maps)


def test_no_backend_is_one_line_naming_the_package(monkeypatch):
    monkeypatch.delenv("MUJOCO_GL", raising=False)
    monkeypatch.setattr(render, "probe_backend", lambda: None)  # a machine with neither EGL nor OSMesa
    with pytest.raises(RenderingUnavailable, match=r"install Debian's libosmesa6 \(apt-get install libosmesa6\)") as e:
        choose_backend()
    assert len(str(e.value).splitlines()) == 1


def test_a_backend_after_mujoco_was_imported_without_it_is_refused(monkeypatch):
    # Whatever this machine has (EGL, OSMesa, neither): a backend cannot be chosen once mujoco is imported.
    import mujoco  # noqa: F401  (the test session has imported it already, without an offscreen backend)

    monkeypatch.setenv("MUJOCO_GL", "disable")
    with pytest.raises(RenderingUnavailable, match="render in a fresh process"):
        choose_backend("osmesa")
    with pytest.raises(RenderingUnavailable, match="--gl glx: unknown OpenGL backend"):
        choose_backend("glx")


def test_missing_pyopengl_names_the_extra(monkeypatch):
    real = render.importlib.util.find_spec
    monkeypatch.setattr(render.importlib.util, "find_spec", lambda name: None if name == "OpenGL" else real(name))
    with pytest.raises(RenderingUnavailable, match=r"pip install '\.\[render\]' in a checkout, or pip install "
                                                    r"'crossview-testbed\[render\]'"):
        choose_backend("osmesa")
