"""Synthetic multi-camera input for tracker tests and benchmarks: walking COCO-17 stick figures seen by
ceiling cameras with their own clocks. Independent of the simulator (no mujoco)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.types import COCO17, Camera, Frame
from tests.reference.cameras import project as project_distorted_px

# A standing COCO-17 pose in the body frame (x forward, y left, z up), metres.
_REST = np.array([
    [0.10, 0.00, 1.62], [0.08, 0.03, 1.66], [0.08, -0.03, 1.66], [0.02, 0.07, 1.64], [0.02, -0.07, 1.64],
    [0.00, 0.19, 1.42], [0.00, -0.19, 1.42], [0.00, 0.23, 1.13], [0.00, -0.23, 1.13], [0.02, 0.24, 0.87],
    [0.02, -0.24, 0.87], [0.00, 0.11, 0.93], [0.00, -0.11, 0.93], [0.02, 0.11, 0.50], [0.02, -0.11, 0.50],
    [0.00, 0.11, 0.07], [0.00, -0.11, 0.07],
])


def look_at_camera(name: str, center, target, f_px: float = 700.0, size=(1280, 720), dist=None) -> Camera:
    """A pinhole camera at `center` (3,) looking at `target` (3,), world z up, OpenCV camera frame."""
    center, target = np.asarray(center, float), np.asarray(target, float)
    forward = target - center
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])
    K = np.array([[f_px, 0, size[0] / 2], [0, f_px, size[1] / 2], [0, 0, 1]])
    return Camera(name=name, K=K, dist=np.zeros(5) if dist is None else dist, R_cam_from_world=R,
                  t_cam_from_world=-R @ center, width_px=size[0], height_px=size[1])


def ceiling_rig(num_cameras: int, width_m: float, depth_m: float, height_m: float = 3.0, dist=None) -> list[Camera]:
    """Cameras evenly on the ceiling border and inside, each looking at a point across the room."""
    cams = []
    rng = np.random.default_rng(1234)
    for i in range(num_cameras):
        a = 2 * np.pi * i / num_cameras
        ring = 0.5 if i % 2 else 0.9
        c = np.array([width_m / 2 * (1 + ring * np.cos(a)), depth_m / 2 * (1 + ring * np.sin(a)), height_m])
        tgt = np.array([width_m / 2 * (1 - 0.3 * np.cos(a)), depth_m / 2 * (1 - 0.3 * np.sin(a)), 0.9])
        tgt[:2] += rng.normal(0, 0.2, 2)
        cams.append(look_at_camera(f"cam{i:02d}", c, tgt, dist=dist))
    return cams


@dataclass
class Walkers:
    """People walking on ellipses inside a room; `poses(t)` gives (P, 17, 3) COCO-17 joints, metres."""

    centers: np.ndarray  # (P, 2)
    radii: np.ndarray  # (P, 2)
    phases: np.ndarray  # (P,)
    speeds_m_per_s: np.ndarray  # (P,)

    @classmethod
    def random(cls, num_people: int, width_m: float, depth_m: float, rng: np.random.Generator) -> Walkers:
        centers = np.stack([rng.uniform(0.35, 0.65, num_people) * width_m,
                            rng.uniform(0.35, 0.65, num_people) * depth_m], axis=1)
        radii = np.stack([rng.uniform(0.2, 0.32, num_people) * width_m,
                          rng.uniform(0.2, 0.32, num_people) * depth_m], axis=1)
        return cls(centers, radii, rng.uniform(0, 2 * np.pi, num_people), rng.uniform(0.8, 1.4, num_people))

    def poses(self, t: float) -> np.ndarray:
        out = []
        for c, r, ph, v in zip(self.centers, self.radii, self.phases, self.speeds_m_per_s):
            omega = v / np.mean(r)
            a = ph + omega * t
            pos = c + r * np.array([np.cos(a), np.sin(a)])
            heading = np.array([-r[0] * np.sin(a), r[1] * np.cos(a)])
            heading /= np.linalg.norm(heading)
            left = np.array([-heading[1], heading[0]])
            body = _REST.copy()
            swing = 0.25 * np.sin(2 * np.pi * 0.9 * t + ph)
            body[[9, 16], 0] += swing  # left wrist, right ankle forward together
            body[[10, 15], 0] -= swing
            body[[7, 14], 0] += 0.4 * swing
            body[[8, 13], 0] -= 0.4 * swing
            world = pos + body[:, :1] * heading + body[:, 1:2] * left
            out.append(np.concatenate([world, body[:, 2:3]], axis=1))
        return np.stack(out)


def make_frames(cameras: list[Camera], walkers: Walkers, duration_s: float, fps: float,
                rng: np.random.Generator, noise_px: float = 2.0, miss_rate: float = 0.02,
                jitter_s: float = 0.002) -> tuple[list[Frame], dict[float, np.ndarray]]:
    """Frames of every camera at `fps` with random phases, sorted by stamp; and truth poses at each stamp.

    Each camera's detections are the projected joints (distorted pixels) plus Gaussian noise, with joints
    missed at `miss_rate`, and persons outside the image dropped. The frame stamp is the capture time.
    """
    frames, truth = [], {}
    for cam in cameras:
        t = rng.uniform(0, 1 / fps)
        while t < duration_s:
            stamp = t + rng.normal(0, jitter_s)
            poses = walkers.poses(stamp)
            kp = project_distorted_px(cam, poses)[0]  # (P, J, 2)
            kp = kp + rng.normal(0, noise_px, kp.shape)
            scores = rng.uniform(0.6, 1.0, kp.shape[:2])
            miss = rng.random(kp.shape[:2]) < miss_rate
            inside = (kp[..., 0] >= 0) & (kp[..., 0] < cam.width_px) & (kp[..., 1] >= 0) & (kp[..., 1] < cam.height_px)
            miss |= ~inside
            kp[miss] = np.nan
            scores[miss] = 0.0
            keep = np.sum(~miss, axis=1) >= 4
            order = rng.permutation(int(keep.sum()))
            frames.append(Frame(cam.name, float(stamp), kp[keep][order], scores[keep][order]))
            truth[float(stamp)] = poses
            t += 1 / fps
    frames.sort(key=lambda f: f.stamp_s)
    return frames, truth


STORE_LAYOUTS = {
    # name: (cameras, people, width m, depth m) after Table 1 (areas 12 m² and 23 m² inside the camera hull).
    "layout1": (12, 4, 4.5, 4.0),
    "layout2": (28, 16, 7.0, 5.5),
}


def store_like(layout: str, duration_s: float, seed: int, fps: float = 10.0, **kwargs):
    """Cameras, frames and truth shaped like a Store layout (see STORE_LAYOUTS)."""
    num_cameras, num_people, width, depth = STORE_LAYOUTS[layout]
    rng = np.random.default_rng(seed)
    cams = ceiling_rig(num_cameras, width, depth)
    walkers = Walkers.random(num_people, width, depth, rng)
    frames, truth = make_frames(cams, walkers, duration_s, fps, rng, **kwargs)
    return cams, walkers, frames, truth


__all__ = ["COCO17", "Walkers", "ceiling_rig", "look_at_camera", "make_frames", "store_like"]
