"""`crossview render`: what the cameras of a recording saw, rendered by MuJoCo, with the detections and tracks on it.

The recording keeps its scenario text and seed, and the simulation is deterministic: the world is built
again (`sim.world.World`, the crowd's own random stream) and advanced to a frame's true capture time, so
the humanoids stand exactly where the recorded truth has them (a test compares them bit for bit). Each
camera renders through its own lens (`sim.render`), so the detector's pixels, our projections and the
rendered bodies line up. Drawn over the render: the frame's detections (joints and bones coloured by the
true person, false positives grey, joints hidden by the store or another person crossed out at their true
pixel) and, with a tracks file, the tracker's skeletons after that frame, reprojected, with their ids.
"""

from __future__ import annotations

import enum
import io
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from core.errors import CrossviewError
from core.records import CameraFrame
from core.types import Camera, Skeleton
from crossview import pipeline
from crossview.outputs import write_bytes
from crossview.pictures.layout import FALSE_POSITIVE_BGR, person_bgr
from sim.render import SceneRenderer
from tracker.types import TrackerOutput

log = logging.getLogger(__name__)

PICTURE_SUFFIXES = (".png", ".jpg", ".jpeg")
CLIP_SUFFIXES = (".gif", ".mp4")
# Frames are delivered at most this long after their capture in the shipped scenarios (mean delay 0.05 s);
# reading stops this far past the last wanted capture time.
_READ_PAST_S = 5.0
_TRACK_BGR = (255, 255, 255)
_HEADER_PX = 28
_TILE_WIDTH_PX = 320
_FONT = cv2.FONT_HERSHEY_SIMPLEX


class RenderError(CrossviewError):
    """A render request that cannot be met: unknown camera, time outside the recording, bad output name."""


class OutputKind(enum.Enum):
    PICTURE = "picture"
    CLIP = "clip"


def output_kind(path: Path, *, clip: bool) -> OutputKind:
    """What `path`'s extension says to write; raises RenderError when it does not fit the request."""
    suffix = Path(path).suffix.lower()
    wanted = CLIP_SUFFIXES if clip else PICTURE_SUFFIXES
    if suffix not in wanted:
        what = "a clip (--from/--to)" if clip else "a picture"
        raise RenderError(f"{path}: {what} is written as {', '.join(wanted)}, not {suffix or 'a name without one'!r}")
    return OutputKind.CLIP if clip else OutputKind.PICTURE


def camera_index(cameras: list[Camera], name: str, where: Path) -> int:
    """Index of the camera called `name`; RenderError listing the valid names otherwise."""
    names = [c.name for c in cameras]
    if name not in names:
        raise RenderError(f"--camera {name}: no such camera in {where} (cameras: {', '.join(names)})")
    return names.index(name)


def check_time(t_s: float, duration_s: float, option: str, where: Path) -> None:
    if not 0.0 <= t_s <= duration_s:
        raise RenderError(f"{option} {t_s:g}: outside the recording {where} (0 to {duration_s:g} s)")


@dataclass(frozen=True)
class Inputs:
    """A recording, and the tracks file made from it (or None)."""

    recording: object
    tracks: object | None


def open_inputs(rec_path: Path, tracks_path: Path | None) -> Inputs:
    """Opens the recording and the tracks file and checks that the tracks were made from the recording."""
    from crossview import recording

    if tracks_path is None:
        return Inputs(recording.open_recording(rec_path), None)
    return Inputs(*pipeline.open_run(rec_path, tracks_path))


def frames_nearest(rec, cameras: list[int], times_s: list[float]) -> dict[tuple[int, float], CameraFrame]:
    """For each camera index and wanted time, the camera's delivered frame whose true capture time is nearest.

    Reads the recording's frames (delivery order) up to `_READ_PAST_S` past the latest wanted time.
    """
    names = {rec.cameras[i].name: i for i in cameras}
    wanted = sorted(times_s)
    best: dict[tuple[int, float], CameraFrame] = {}
    for frame in rec.frames():
        if frame.truth.delivery_s > wanted[-1] + _READ_PAST_S:
            break
        index = names.get(frame.frame.camera)
        if index is None:
            continue
        capture = frame.truth.capture_s
        for t in wanted:
            kept = best.get((index, t))
            if kept is None or abs(capture - t) < abs(kept.truth.capture_s - t):
                best[(index, t)] = frame
    return best


def outputs_for(tracks, frames: list[CameraFrame]) -> dict[int, TrackerOutput]:
    """The tracker output made from each frame (same camera and stamp), by position in `frames`; a frame
    the tracker did not report on gets the latest output stamped before it."""
    keys = {(f.frame.camera, f.frame.stamp_s): i for i, f in enumerate(frames)}
    latest_stamp = max(f.frame.stamp_s for f in frames)
    found: dict[int, TrackerOutput] = {}
    before: list[TrackerOutput] = []
    for output in tracks.outputs():
        i = keys.get((output.camera, output.stamp_s))
        if i is not None:
            found[i] = output
        before.append(output)
        if output.stamp_s > latest_stamp + _READ_PAST_S:
            break
    before.sort(key=lambda o: o.stamp_s)
    stamps = np.array([o.stamp_s for o in before])
    for i, f in enumerate(frames):
        if i not in found and stamps.size:
            j = int(np.searchsorted(stamps, f.frame.stamp_s, side="right")) - 1
            if j >= 0:
                found[i] = before[j]
    return found


def scene_of(rec, *, multisamples: int | None = None) -> SceneRenderer:
    """The world of an opened recording, built again from the scenario text and seed it keeps, ready to render
    through its cameras (`sim.render.SceneRenderer`)."""
    from sim.scenario import from_source_text

    scenario = from_source_text(rec.header.scenario_text, rec.header.scenario_name, str(rec.path))
    return SceneRenderer(scenario, rec.header.seed, rec.cameras, multisamples=multisamples)


def _text(image: np.ndarray, text: str, org: tuple[int, int], scale: float, colour=(255, 255, 255)) -> None:
    """Text with a dark outline, readable on any background."""
    cv2.putText(image, text, org, _FONT, scale, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(image, text, org, _FONT, scale, colour, 1, cv2.LINE_AA)


def _point(p: np.ndarray) -> tuple[int, int]:
    return int(round(float(p[0]))), int(round(float(p[1])))


def draw_frame(image: np.ndarray, camera: Camera, frame: CameraFrame, skeleton: Skeleton,
               output: TrackerOutput | None = None) -> np.ndarray:
    """Draws a frame's detections, and the tracker's skeletons after it, over the camera's view.

    Args:
        image: (H, W, 3) uint8 BGR view of `camera`, drawn on in place.
        camera: the frame's camera.
        frame: the delivered frame with its per-detection truth.
        skeleton: the joint layout (its bones are drawn).
        output: the tracker's output after this frame; its targets are projected with `core.projection.in_image`.

    Returns:
        `image`.
    """
    from core.projection import in_image

    kp, truth = frame.frame.keypoints_px, frame.truth
    # Tracks first, so the detections stay on top: white skeletons with their ids.
    for target in (output.targets if output is not None else []):
        px, inside = in_image(camera, np.asarray(target.pose, dtype=np.float64))
        for a, b in skeleton.bones:
            if inside[a] and inside[b]:
                cv2.line(image, _point(px[a]), _point(px[b]), _TRACK_BGR, 1, cv2.LINE_AA)
        for j in np.nonzero(inside)[0]:
            cv2.rectangle(image, _point(px[j] - 2), _point(px[j] + 2), _TRACK_BGR, -1)
        if inside.any():
            top = px[inside][np.argmin(px[inside][:, 1])]
            _text(image, f"#{target.id}", _point(top + np.array([6.0, -10.0])), 0.5)
    for d in range(kp.shape[0]):
        pid = int(truth.person_ids[d])
        colour = person_bgr(pid) if pid >= 0 else FALSE_POSITIVE_BGR
        seen = np.all(np.isfinite(kp[d]), axis=-1)
        for a, b in skeleton.bones:
            if seen[a] and seen[b]:
                cv2.line(image, _point(kp[d, a]), _point(kp[d, b]), colour, 2, cv2.LINE_AA)
        for j in np.nonzero(seen)[0]:
            cv2.circle(image, _point(kp[d, j]), 4, (0, 0, 0), -1, cv2.LINE_AA)
            cv2.circle(image, _point(kp[d, j]), 3, colour, -1, cv2.LINE_AA)
        # Joints hidden by the store or another person: a cross at their true pixel.
        hidden = truth.occluded[d] & truth.in_image[d] & np.all(np.isfinite(truth.keypoints_px[d]), axis=-1)
        for j in np.nonzero(hidden)[0]:
            u, v = _point(truth.keypoints_px[d, j])
            for thickness, c in ((4, (0, 0, 0)), (2, colour)):
                cv2.line(image, (u - 6, v - 6), (u + 6, v + 6), c, thickness, cv2.LINE_AA)
                cv2.line(image, (u - 6, v + 6), (u + 6, v - 6), c, thickness, cv2.LINE_AA)
        if seen.any():
            top = kp[d][seen][np.argmin(kp[d][seen][:, 1])]
            _text(image, f"P{pid}" if pid >= 0 else "FP", _point(top + np.array([-24.0, -10.0])), 0.45, colour)
    return image


def _header(image: np.ndarray, lines: list[str]) -> np.ndarray:
    """`image` with a dark strip above it holding `lines` (one line each)."""
    strip = np.full((_HEADER_PX * len(lines), image.shape[1], 3), 30, np.uint8)
    for n, line in enumerate(lines):
        cv2.putText(strip, line, (8, 19 + _HEADER_PX * n), _FONT, 0.5, (235, 235, 235), 1, cv2.LINE_AA)
    return np.vstack([strip, image])


def _frame_caption(camera: Camera, frame: CameraFrame, output: TrackerOutput | None) -> str:
    ids = frame.truth.person_ids
    hidden = int((frame.truth.occluded & frame.truth.in_image).sum())
    caption = (f"{camera.name}  capture {frame.truth.capture_s:.3f} s  stamp {frame.frame.stamp_s:.3f} s  "
               f"{len(ids)} detections ({int((ids < 0).sum())} false)  {hidden} occluded joints (x)")
    if output is not None:
        caption += f"  {len(output.targets)} tracks (white)"
    return caption


@dataclass(frozen=True)
class RenderTiming:
    """How long the renders of a command took: `renders` MuJoCo renders (with the lens remap) in `render_s`."""

    renders: int
    render_s: float

    @property
    def per_image_s(self) -> float:
        return self.render_s / self.renders if self.renders else math.nan


class _Timer:
    def __init__(self):
        self.renders, self.seconds = 0, 0.0

    def view(self, scene: SceneRenderer, index: int, capture_s: float) -> np.ndarray:
        start = time.perf_counter()
        image = scene.view(index, capture_s)
        self.seconds += time.perf_counter() - start
        self.renders += 1
        return image

    def result(self) -> RenderTiming:
        return RenderTiming(self.renders, self.seconds)


def _camera_picture(rec, scene: SceneRenderer, timer: _Timer, index: int, frame: CameraFrame,
                    output: TrackerOutput | None) -> np.ndarray:
    camera = rec.cameras[index]
    image = draw_frame(timer.view(scene, index, frame.truth.capture_s), camera, frame, rec.skeleton, output)
    return _header(image, [_frame_caption(camera, frame, output)])


def _sheet_columns(count: int) -> int:
    return max(1, math.ceil(math.sqrt(count * 4 / 3)))


def _contact_sheet(rec, scene: SceneRenderer, timer: _Timer, frames: dict[int, CameraFrame],
                   outputs: dict[int, TrackerOutput], t_s: float, tile_width_px: int) -> np.ndarray:
    """Every camera's view (its frame nearest `t_s`) in a labelled grid, in rig order."""
    order = sorted(frames, key=lambda i: frames[i].truth.capture_s)  # the world only moves forward
    tiles: dict[int, np.ndarray] = {}
    for i in order:
        camera = rec.cameras[i]
        image = draw_frame(timer.view(scene, i, frames[i].truth.capture_s), camera, frames[i], rec.skeleton,
                           outputs.get(i))
        height = round(image.shape[0] * tile_width_px / image.shape[1])
        tile = cv2.resize(image, (tile_width_px, height), interpolation=cv2.INTER_AREA)
        _text(tile, f"{camera.name} {frames[i].truth.capture_s:.2f} s", (6, 18), 0.5)
        tiles[i] = tile
    cols = _sheet_columns(len(rec.cameras))
    rows = math.ceil(len(rec.cameras) / cols)
    th = max(t.shape[0] for t in tiles.values())
    sheet = np.full((rows * (th + 2), cols * (tile_width_px + 2), 3), 60, np.uint8)
    for i, tile in tiles.items():
        r, c = divmod(i, cols)
        y, x = r * (th + 2), c * (tile_width_px + 2)
        sheet[y:y + tile.shape[0], x:x + tile_width_px] = tile
    people = {int(p) for f in frames.values() for p in f.truth.person_ids if p >= 0}
    caption = (f"{rec.header.scenario_name} seed {rec.header.seed} at {t_s:g} s: {len(rec.cameras)} cameras, "
               f"{len(people)} people detected; joints by true person, grey false positives, x occluded"
               + (", white: tracks with ids" if outputs else ""))
    return _header(sheet, [caption])


def encode_picture(image: np.ndarray, path: Path) -> bytes:
    ok, data = cv2.imencode(Path(path).suffix.lower(), image)
    if not ok:
        raise RenderError(f"{path}: OpenCV cannot encode this picture format")
    return data.tobytes()


@dataclass(frozen=True)
class Request:
    """One `crossview render` request (the CLI's options).

    Attributes:
        recording, output, tracks: the paths.
        camera: camera name for a single view; None with `contact_sheet` or `top_down`.
        contact_sheet, top_down: the other two picture kinds.
        time_s: the instant of a picture; None for a clip or a top-down range.
        from_s, to_s: the range of a clip or of a top-down map's paths.
        gl: the OpenGL backend, None: the environment's MUJOCO_GL, else probed.
        fps: frame rate of a clip.
        tile_width_px: width of a contact sheet's tiles.
        progress: show a progress bar.
    """

    recording: Path
    output: Path
    tracks: Path | None = None
    camera: str | None = None
    contact_sheet: bool = False
    top_down: bool = False
    time_s: float | None = None
    from_s: float | None = None
    to_s: float | None = None
    gl: str | None = None
    fps: float = 10.0
    tile_width_px: int = _TILE_WIDTH_PX
    progress: bool = True


@dataclass(frozen=True)
class RenderResult:
    path: Path
    images: int
    timing: RenderTiming


MAX_TILE_WIDTH_PX = 4096
"""Widest tile of a contact sheet, pixels (a sheet of the hypermarket's 240 at this width is about 2 GB)."""
MAX_CLIP_IMAGES = 100_000
"""Most images one clip may hold (an hour at 25 images per second is 90,000)."""


def render(request: Request) -> RenderResult:
    """Does what `request` asks and writes its output atomically; every check comes before any rendering.

    Raises:
        RenderError, RecordingError, CrossviewError: bad input, in one line.
    """
    clip = request.from_s is not None or request.to_s is not None
    if clip and (request.from_s is None or request.to_s is None):
        raise RenderError("--from and --to: give both for a clip or a top-down range")
    if clip and request.time_s is not None:
        raise RenderError("--time: give either --time (one instant) or --from/--to (a range)")
    if not clip and request.time_s is None:
        raise RenderError("--time: give the instant to render (or --from/--to for a clip)")
    for option, value in (("--time", request.time_s), ("--from", request.from_s), ("--to", request.to_s)):
        if value is not None and not math.isfinite(value):
            raise RenderError(f"{option}: {value} is not a finite number of seconds")
    if not 1 <= request.tile_width_px <= MAX_TILE_WIDTH_PX:
        raise RenderError(f"--tile-width: {request.tile_width_px} must be in [1, {MAX_TILE_WIDTH_PX}] pixels")
    if clip and not request.top_down and (request.to_s - request.from_s) * request.fps + 1 > MAX_CLIP_IMAGES:
        raise RenderError(f"--from/--to/--fps: {request.from_s:g} to {request.to_s:g} s at {request.fps:g} images per "
                          f"second is more than the {MAX_CLIP_IMAGES:,} images a clip may hold; give a shorter range "
                          "or a lower --fps")
    if request.top_down:
        kind = output_kind(request.output, clip=False)
    else:
        kind = output_kind(request.output, clip=clip)
    inputs = (request.recording,) + ((request.tracks,) if request.tracks else ())
    pipeline.check_writable(request.output, inputs=inputs)
    data = open_inputs(request.recording, request.tracks)
    rec = data.recording
    duration = rec.header.duration_s
    if clip:
        check_time(request.from_s, duration, "--from", rec.path)
        check_time(request.to_s, duration, "--to", rec.path)
        if not request.to_s > request.from_s:
            raise RenderError(f"--to {request.to_s:g}: must be after --from {request.from_s:g}")
    else:
        check_time(request.time_s, duration, "--time", rec.path)
    if request.top_down:
        from crossview.pictures.layout import top_down_picture

        t0, t1 = (request.from_s, request.to_s) if clip else (0.0, request.time_s)
        image = top_down_picture(rec, data.tracks, t0, t1)
        write_bytes(encode_picture(image, request.output), request.output)
        return RenderResult(request.output, 1, RenderTiming(0, 0.0))
    indices = (list(range(len(rec.cameras))) if request.contact_sheet
               else [camera_index(rec.cameras, request.camera, rec.path)])
    from sim.render import choose_backend

    choose_backend(request.gl)
    if kind == OutputKind.PICTURE:
        return _render_picture(request, data, indices)
    return _render_clip(request, data, indices)


def _render_picture(request: Request, data: Inputs, indices: list[int]) -> RenderResult:
    rec = data.recording
    frames = frames_nearest(rec, indices, [request.time_s])
    frames = {i: frames[(i, request.time_s)] for i in indices if (i, request.time_s) in frames}
    if not frames:
        raise RenderError(f"--time {request.time_s:g}: no frame of the chosen camera in {rec.path}")
    listed = list(frames.items())
    outputs = {}
    if data.tracks is not None:
        found = outputs_for(data.tracks, [f for _, f in listed])
        outputs = {listed[k][0]: o for k, o in found.items()}
    scene = scene_of(rec)
    timer = _Timer()
    try:
        if request.contact_sheet:
            image = _contact_sheet(rec, scene, timer, frames, outputs, request.time_s, request.tile_width_px)
        else:
            (index, frame), = listed
            image = _camera_picture(rec, scene, timer, index, frame, outputs.get(index))
    finally:
        scene.close()
    write_bytes(encode_picture(image, request.output), request.output)
    return RenderResult(request.output, 1, timer.result())


def _render_clip(request: Request, data: Inputs, indices: list[int]) -> RenderResult:
    """A clip: one image every 1/fps seconds from --from to --to, each camera at its frame nearest then."""
    from tqdm import tqdm

    rec = data.recording
    step = 1.0 / request.fps
    count = int(math.floor((request.to_s - request.from_s) / step + 1e-9)) + 1
    times = [request.from_s + k * step for k in range(count)]
    frames = frames_nearest(rec, indices, times)
    keys = [(i, t) for t in times for i in indices if (i, t) in frames]
    outputs: dict[tuple[int, float], TrackerOutput] = {}
    if data.tracks is not None and keys:
        found = outputs_for(data.tracks, [frames[k] for k in keys])
        outputs = {keys[n]: o for n, o in found.items()}
    scene = scene_of(rec)
    timer = _Timer()
    try:
        with ClipWriter(request.output, request.fps) as clip:
            for t in tqdm(times, unit="image", desc="render", disable=not request.progress, leave=False):
                if request.contact_sheet:
                    at = {i: frames[(i, t)] for i in indices if (i, t) in frames}
                    outs = {i: outputs[(i, t)] for i in at if (i, t) in outputs}
                    if at:
                        clip.add(_contact_sheet(rec, scene, timer, at, outs, t, request.tile_width_px))
                elif (indices[0], t) in frames:
                    clip.add(_camera_picture(rec, scene, timer, indices[0], frames[(indices[0], t)],
                                             outputs.get((indices[0], t))))
            if not clip.count:
                raise RenderError(f"--from {request.from_s:g} --to {request.to_s:g}: no frame of the camera in that "
                                  "range")
    finally:
        scene.close()
    return RenderResult(request.output, clip.count, timer.result())


class ClipWriter:
    """Writes BGR images of one size, one at a time, as a GIF (Pillow; kept as 256-colour frames until the end)
    or an MP4 (OpenCV's MPEG-4 writer, streamed), under a temporary name renamed only when the clip is complete.

    Args:
        path: the clip, `.gif` or `.mp4`.
        fps: images per second.
    """

    def __init__(self, path: Path, fps: float):
        self.path = Path(path)
        self.fps = fps
        self.count = 0
        self._tmp = self.path.with_name(self.path.stem + ".tmp" + self.path.suffix.lower())
        self._gif: list | None = [] if self.path.suffix.lower() == ".gif" else None
        self._video = None

    def add(self, image: np.ndarray) -> None:
        if self._gif is not None:
            from PIL import Image

            self._gif.append(Image.fromarray(cv2.cvtColor(image, cv2.COLOR_BGR2RGB)).quantize(colors=256))
        else:
            if self._video is None:
                h, w = image.shape[:2]
                self._video = cv2.VideoWriter(str(self._tmp), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, (w, h))
                if not self._video.isOpened():
                    raise RenderError(f"{self.path}: OpenCV cannot write MP4 here (its video writer did not open)")
            self._video.write(image)
        self.count += 1

    def __enter__(self) -> ClipWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if self._video is not None:
                self._video.release()
            if exc_type is None and self.count:
                if self._gif is not None:
                    data = io.BytesIO()
                    self._gif[0].save(data, format="GIF", save_all=True, append_images=self._gif[1:],
                                      duration=round(1000 / self.fps), loop=0)
                    write_bytes(data.getvalue(), self.path)
                else:  # OpenCV's writer takes a path: its file goes out through the one atomic path too
                    write_bytes(self._tmp.read_bytes(), self.path)
        finally:
            self._tmp.unlink(missing_ok=True)
