"""Offscreen MuJoCo pictures of what a camera sees: the store and its people through the camera's own lens.

`SceneRenderer` builds a scenario's world again and renders it at any true time (what `crossview render` draws
on, and `FrameImages`, the JPEG pictures `crossview generate --images` stores).

MuJoCo renders a pinhole. A camera of the rig has OpenCV's lens model (`core.projection.in_image`), so each
camera is rendered as a wider pinhole (square pixels, centred principal point, large enough to hold every
pixel of the distorted image) and remapped with OpenCV: pixel (u, v) of the picture takes the render's
pixel at the undistorted ray of (u, v) (`cv2.undistortPoints`). Rendered pixels, the detector's pixels and
`in_image` then agree (tests/sim/test_cameras.py measures it).

MuJoCo chooses its OpenGL backend once, when it is first imported, from the environment variable
MUJOCO_GL: `choose_backend` must run before anything imports mujoco (`sim.world` does). It takes the
backend the caller names (or MUJOCO_GL names), checked to open, else the first of EGL (a GPU, or Mesa's
software EGL) and OSMesa (software, Debian's libosmesa6) with which MuJoCo opens an offscreen context here
(each probed in a fresh interpreter).
"""

from __future__ import annotations

import enum
import functools
import importlib.util
import logging
import math
import os
import subprocess
import sys
import time
from dataclasses import dataclass

import cv2
import numpy as np

from core.errors import CrossviewError
from core.types import Camera

log = logging.getLogger(__name__)

# Extra pinhole pixels around the remap's footprint, so that bilinear reads near the border stay inside.
_BORDER_PX = 2
# Undistortion by OpenCV's fixed-point iteration: enough iterations to converge to far below a pixel.
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
# Lighting: MuJoCo's headlight (the store model has no lights) brighter than its default.
_HEADLIGHT_AMBIENT = 0.45
_HEADLIGHT_DIFFUSE = 0.55
_PROBE_TIMEOUT_S = 60.0
_INSTALL_HINT = ("install Debian's libosmesa6 (apt-get install libosmesa6) for software rendering, or run where a "
                 "GPU gives EGL")


class GLBackend(enum.Enum):
    """MuJoCo's offscreen OpenGL backends, in the order they are tried."""

    EGL = "egl"
    OSMESA = "osmesa"


# What to do when a backend the user named does not open.
_BACKEND_HINTS = {
    GLBackend.EGL: "run where a GPU driver (or Mesa's libegl-mesa0) gives EGL, or choose OSMesa (--gl osmesa)",
    GLBackend.OSMESA: "install Debian's libosmesa6 (apt-get install libosmesa6)",
}


class RenderingUnavailable(CrossviewError):
    """No offscreen OpenGL context can be opened here (or MuJoCo was imported with rendering disabled)."""


class RenderKind(enum.Enum):
    """What a render holds per pixel."""

    RGB = "rgb"  # (H, W, 3) uint8 colours
    SEGMENTATION = "segmentation"  # (H, W, 2) int32 (object id, mjtObj type); (-1, -1) for the background
    DEPTH = "depth"  # (H, W) float32 metres along the optical axis


def _backend_env(backend: GLBackend) -> dict:
    return {**os.environ, "MUJOCO_GL": backend.value, "PYOPENGL_PLATFORM": backend.value}


@functools.cache
def backend_problem(backend: GLBackend) -> str | None:
    """Why MuJoCo cannot open an offscreen context with `backend` here, in one line (tried in a fresh
    interpreter: MuJoCo's backend cannot change once it is imported); None when it can."""
    probe = "import mujoco; mujoco.GLContext(8, 8).make_current()"
    try:
        done = subprocess.run([sys.executable, "-c", probe], env=_backend_env(backend), capture_output=True,
                              timeout=_PROBE_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return f"opening a context took more than {_PROBE_TIMEOUT_S:g} s"
    if done.returncode == 0:
        return None
    last = done.stderr.decode(errors="replace").strip().splitlines()[-1:]
    return last[0] if last else f"exit status {done.returncode}"


def probe_backend() -> GLBackend | None:
    """The first of `GLBackend` with which MuJoCo opens an offscreen context here (`backend_problem`); None
    when neither works."""
    for backend in GLBackend:
        problem = backend_problem(backend)
        if problem is None:
            return backend
        log.info("offscreen backend %s unavailable: %s", backend.value, problem)
    return None


def choose_backend(requested: str | None = None) -> GLBackend:
    """Chooses MuJoCo's offscreen backend for this process and sets MUJOCO_GL and PYOPENGL_PLATFORM.

    Args:
        requested: "egl" or "osmesa"; None takes the environment's MUJOCO_GL when it names one of them,
            else probes (`probe_backend`).

    Raises:
        RenderingUnavailable: PyOpenGL is missing, the requested backend is unknown, no backend works here, or
            mujoco was already imported without one (the one-line message says what to install).
    """
    names = ", ".join(b.value for b in GLBackend)
    if importlib.util.find_spec("OpenGL") is None:
        raise RenderingUnavailable("PyOpenGL is not installed (MuJoCo's EGL and OSMesa contexts need it): "
                                   "pip install '.[render]' in a checkout, or pip install 'crossview-testbed[render]'")
    from_env = None
    if requested is None:
        from_env = os.environ.get("MUJOCO_GL", "").strip().lower()
        from_env = from_env if from_env in {b.value for b in GLBackend} else None
        requested = from_env
    if requested is not None:
        try:
            backend = GLBackend(requested.strip().lower())
        except ValueError:
            raise RenderingUnavailable(f"--gl {requested}: unknown OpenGL backend (valid: {names})") from None
        _refuse_after_import(backend)  # (before the probe: a fresh process is needed whatever the machine has)
        problem = backend_problem(backend)
        if problem is not None:
            named = f"MUJOCO_GL={backend.value}" if from_env else f"--gl {backend.value}"
            raise RenderingUnavailable(f"{named}: MuJoCo cannot open an offscreen {backend.value} context here "
                                       f"({problem}); {_BACKEND_HINTS[backend]}")
    else:
        backend = probe_backend()
        if backend is None:
            raise RenderingUnavailable(f"MuJoCo cannot open an offscreen OpenGL context (tried {names}): "
                                       f"{_INSTALL_HINT}")
        _refuse_after_import(backend)
    os.environ["MUJOCO_GL"] = backend.value
    os.environ["PYOPENGL_PLATFORM"] = backend.value
    return backend


def _refuse_after_import(backend: GLBackend) -> None:
    """Raises RenderingUnavailable when mujoco was imported with another MUJOCO_GL than `backend` (it cannot
    change backend once imported)."""
    if "mujoco" in sys.modules and os.environ.get("MUJOCO_GL") != backend.value:
        raise RenderingUnavailable(f"mujoco was imported with MUJOCO_GL={os.environ.get('MUJOCO_GL')!r} before "
                                   f"the renderer chose {backend.value!r}; render in a fresh process")


@dataclass(frozen=True, eq=False)
class LensMap:
    """How a camera's distorted picture is read out of a pinhole render (it depends on the intrinsics only).

    Attributes:
        K: (3, 3) intrinsics of the pinhole MuJoCo renders: no distortion, square pixels, the principal point
            at the centre of its (larger) image.
        width_px, height_px: the pinhole render's size.
        map_x, map_y: (H, W) float32 pinhole pixel of each pixel of the camera's picture (`cv2.remap`).
    """

    K: np.ndarray
    width_px: int
    height_px: int
    map_x: np.ndarray
    map_y: np.ndarray

    def pinhole(self, camera: Camera) -> Camera:
        """The pinhole camera that MuJoCo renders for `camera`: its pose, these intrinsics."""
        return Camera(f"{camera.name}_pinhole", self.K, np.zeros(5), camera.R_cam_from_world,
                      camera.t_cam_from_world, self.width_px, self.height_px)


def lens_map(camera: Camera) -> LensMap:
    """The pinhole render and remap that give `camera`'s distorted picture (cached per intrinsics: a rig's
    cameras usually share them).

    Each picture pixel centre (u, v) (integer coordinates, as OpenCV's) is undistorted to its normalised
    ray (x, y) = undistort(K⁻¹ (u, v, 1)); the pinhole of focal length f = max(fx, fy) and principal point
    (c, c') at its image centre sees that ray at (c + f x, c' + f y).
    """
    return _lens_map(camera.K.tobytes(), camera.dist.tobytes(), camera.width_px, camera.height_px)


@functools.lru_cache(maxsize=16)
def _lens_map(K_bytes: bytes, dist_bytes: bytes, W: int, H: int) -> LensMap:
    K = np.frombuffer(K_bytes).reshape(3, 3)
    dist = np.frombuffer(dist_bytes)
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    pixels = np.stack([u.ravel(), v.ravel()], axis=-1).reshape(-1, 1, 2)
    rays = cv2.undistortPoints(pixels, K, dist, criteria=_UNDISTORT_CRITERIA).reshape(H, W, 2)
    f = float(max(K[0, 0], K[1, 1]))
    half_w = math.ceil(f * float(np.abs(rays[..., 0]).max())) + _BORDER_PX
    half_h = math.ceil(f * float(np.abs(rays[..., 1]).max())) + _BORDER_PX
    width, height = 2 * half_w + 1, 2 * half_h + 1  # odd: the centre pixel lies on the optical axis
    K_pinhole = np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])
    map_x = (K_pinhole[0, 2] + f * rays[..., 0]).astype(np.float32)
    map_y = (K_pinhole[1, 2] + f * rays[..., 1]).astype(np.float32)
    for a in (K_pinhole, map_x, map_y):
        a.flags.writeable = False
    return LensMap(K_pinhole, width, height, map_x, map_y)


class CameraRenderer:
    """Renders a MuJoCo model through the cameras of a rig, each with its own lens.

    Args:
        model: the `mujoco.MjModel` to render (a `sim.world.World`'s); its offscreen buffer is enlarged to the
            largest pinhole render and its headlight brightened.
        cameras: the rig.
        multisamples: samples per pixel of the offscreen buffer (the model's `vis.quality.offsamples`, 4 by
            default: None keeps it); 0 renders about twice as fast in software, with harder edges.

    Attributes:
        option: the `mujoco.MjvOption` of every render (which geom and site groups are drawn).

    Call `choose_backend` before mujoco is first imported. Use as a context manager or call `close`.
    """

    def __init__(self, model, cameras: list[Camera], *, multisamples: int | None = None):
        import mujoco

        if getattr(mujoco, "GLContext", None) is None:
            raise RenderingUnavailable(f"mujoco was imported with MUJOCO_GL={os.environ.get('MUJOCO_GL')!r} "
                                       "(no OpenGL backend); choose one before importing it")
        self._mujoco = mujoco
        self.model = model
        self.cameras = list(cameras)
        self._renderers: dict[tuple[int, int], object] = {}
        self.model.vis.headlight.ambient[:] = _HEADLIGHT_AMBIENT
        self.model.vis.headlight.diffuse[:] = _HEADLIGHT_DIFFUSE
        if multisamples is not None:  # (read when each renderer's context is made)
            self.model.vis.quality.offsamples = int(multisamples)
        # What is drawn (MuJoCo's defaults: geom groups 0-2, site groups 0-2; the keypoint sites are group 4).
        self.option = mujoco.MjvOption()

    def _renderer(self, width: int, height: int):
        key = (width, height)
        if key not in self._renderers:
            g = self.model.vis.global_
            g.offwidth, g.offheight = max(g.offwidth, width), max(g.offheight, height)
            self._renderers[key] = self._mujoco.Renderer(self.model, height, width)
        return self._renderers[key]

    def render(self, data, index: int, kind: RenderKind = RenderKind.RGB) -> np.ndarray:
        """What camera `index` sees of `data`'s scene, through its lens.

        Args:
            data: the `mujoco.MjData` with its kinematics computed (`World.data`).
            index: the camera's index in the rig.
            kind: colours, segmentation or depth (`RenderKind`).

        Returns:
            (H, W, 3) uint8 RGB, (H, W, 2) int32 segmentation or (H, W) float32 depth, at the camera's size.
        """
        from sim.cameras import mujoco_camera_pose

        mujoco = self._mujoco
        lens = lens_map(self.cameras[index])
        pinhole = lens.pinhole(self.cameras[index])
        renderer = self._renderer(pinhole.width_px, pinhole.height_px)
        renderer.update_scene(data, scene_option=self.option)
        # The scene's two (stereo) eye cameras become the pinhole: pose by the one OpenCV-to-MuJoCo
        # conversion, vertical field of view of its focal length (the width follows the aspect ratio).
        pos, quat, fovy_deg = mujoco_camera_pose(pinhole)
        world_from_mj = np.zeros(9)
        mujoco.mju_quat2Mat(world_from_mj, quat)
        world_from_mj = world_from_mj.reshape(3, 3)
        near = float(self.model.vis.map.znear * self.model.stat.extent)
        half_height = near * math.tan(math.radians(fovy_deg) / 2)
        for eye in renderer.scene.camera:
            eye.pos[:] = pos
            eye.forward[:] = -world_from_mj[:, 2]
            eye.up[:] = world_from_mj[:, 1]
            eye.frustum_center = 0.0
            eye.frustum_width = 0.0
            eye.frustum_bottom = -half_height
            eye.frustum_top = half_height
            eye.frustum_near = near
        if kind == RenderKind.RGB:
            image = renderer.render()
            return cv2.remap(image, lens.map_x, lens.map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        if kind == RenderKind.SEGMENTATION:
            renderer.enable_segmentation_rendering()
            try:
                ids = renderer.render()
            finally:
                renderer.disable_segmentation_rendering()
            # (nearest: labels do not blend)
            return np.stack([cv2.remap(np.ascontiguousarray(ids[..., c]).astype(np.float32), lens.map_x, lens.map_y,
                                       cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE) for c in (0, 1)],
                            axis=-1).astype(np.int32)
        renderer.enable_depth_rendering()
        try:
            depth = renderer.render()
        finally:
            renderer.disable_depth_rendering()
        return cv2.remap(depth, lens.map_x, lens.map_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE)

    def close(self) -> None:
        for renderer in self._renderers.values():
            renderer.close()
        self._renderers.clear()

    def __enter__(self) -> CameraRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class SceneRenderer:
    """A scenario's world, built again and posed at any true time, rendered through its cameras.

    Args:
        scenario: the `sim.scenario.Scenario` simulated (a recording's: `crossview.pictures.render.scene_of`).
        seed: its seed (the crowd's random stream is `child_rng(seed, "crowd")`, as the simulation's).
        cameras: the rig.
        multisamples: the renders' samples per pixel (`CameraRenderer`); None: MuJoCo's 4.

    Call `choose_backend` first (before mujoco is imported).
    """

    def __init__(self, scenario, seed: int, cameras: list[Camera], *, multisamples: int | None = None):
        self.scenario = scenario
        self.seed = int(seed)
        self.cameras = list(cameras)
        self.multisamples = multisamples
        self._world = None
        self._world_t = math.inf
        self.renderer = None
        self._build_world()

    def _build_world(self) -> None:
        """A new world at time 0, with a renderer of its model."""
        from sim.rng import child_rng
        from sim.world import World

        if self.renderer is not None:
            self.renderer.close()
        self._world = World(self.scenario, child_rng(self.seed, "crowd"))
        self._world_t = 0.0
        self.renderer = CameraRenderer(self._world.model, self.cameras, multisamples=self.multisamples)

    def world_at(self, t_s: float):
        """The world advanced to true time `t_s` (built again when an earlier time is asked for)."""
        if t_s < self._world_t:  # the world only moves forward: start again
            self._build_world()
        self._world.advance(t_s)
        self._world_t = t_s
        return self._world

    def view(self, index: int, capture_s: float) -> np.ndarray:
        """(H, W, 3) uint8 BGR: camera `index`'s view at true time `capture_s`."""
        world = self.world_at(capture_s)
        return cv2.cvtColor(self.renderer.render(world.data, index), cv2.COLOR_RGB2BGR)

    def close(self) -> None:
        self.renderer.close()


JPEG_QUALITY = 85
"""OpenCV's JPEG quality (0-100; its default is 95) of the pictures `crossview generate --images` stores."""
IMAGE_MULTISAMPLES = 0
"""Samples per pixel of those pictures' renders: none, for half the time of MuJoCo's 4 in software; the lens
remap's bilinear reads soften the edges anyway."""
# Rates are compared as k · rate / fps against whole numbers: this much below one still counts as one.
_COUNT_EPS = 1e-9


def check_image_rate(images_per_s: float, fps: float, where: str) -> None:
    """CrossviewError unless 0 < `images_per_s` <= `fps` (one picture per frame at most)."""
    if not (math.isfinite(images_per_s) and 0 < images_per_s <= fps):
        raise CrossviewError(f"--images {images_per_s:g}: pictures per second per camera must be > 0 and at most "
                             f"the cameras' frame rate, {fps:g} fps in {where} (one picture per frame at most)")


class FrameImages:
    """JPEG pictures of what the cameras saw for some of a generation's frames (`crossview generate --images`).

    A camera's delivered frames are counted in capture order from k = 0, and frame k gets a picture when
    floor(k r) > floor((k - 1) r), r = `images_per_s` / `fps`: its first frame, then evenly spread, every
    frame at r = 1. The picture is `SceneRenderer`'s view (the world `crossview render` builds again, posed at
    the frame's true capture time, through the camera's lens) without overlays, rendered with
    `IMAGE_MULTISAMPLES` and JPEG-encoded by OpenCV at `JPEG_QUALITY`.

    Args:
        scenario, seed, cameras: what is simulated (`SceneRenderer`).
        images_per_s: pictures per second per camera, in (0, fps].
        fps: the cameras' frame rate.

    Attributes:
        count: pictures made so far; render_s: seconds spent making them (render, lens remap, JPEG).

    Call `choose_backend` first. Use as a context manager or call `close`.
    """

    def __init__(self, scenario, seed: int, cameras: list[Camera], images_per_s: float, fps: float):
        self.scene = SceneRenderer(scenario, seed, cameras, multisamples=IMAGE_MULTISAMPLES)
        self._ratio = float(images_per_s) / float(fps)
        self._taken = [0] * len(cameras)
        self.count = 0
        self.render_s = 0.0

    def _wanted(self, camera: int) -> bool:
        k = self._taken[camera]
        self._taken[camera] += 1
        return k == 0 or math.floor(k * self._ratio + _COUNT_EPS) > math.floor((k - 1) * self._ratio + _COUNT_EPS)

    def pictures(self, cameras: list[int], capture_s: list[float]) -> list[bytes | None]:
        """The JPEG bytes of each frame that gets a picture, None for the others.

        Args:
            cameras: the frames' camera indices.
            capture_s: their true capture times, seconds, ascending across calls (the world moves forward).
        """
        out: list[bytes | None] = []
        for camera, t in zip(cameras, capture_s, strict=True):
            if not self._wanted(camera):
                out.append(None)
                continue
            start = time.perf_counter()
            ok, data = cv2.imencode(".jpg", self.scene.view(camera, t), [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
            if not ok:
                raise RuntimeError("OpenCV could not encode a rendered picture as JPEG")
            out.append(data.tobytes())
            self.render_s += time.perf_counter() - start
            self.count += 1
        return out

    def close(self) -> None:
        self.scene.close()

    def __enter__(self) -> FrameImages:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
