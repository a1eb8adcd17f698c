"""Per-camera clocks: nominal rate, phase, jitter, drops, stamp offset and delivery delay.

Camera c ticks at `phase_c + k / fps`. Its true capture time is the tick plus Gaussian jitter; the
stamp it writes is the capture time plus its own constant clock offset plus a small per-frame stamp
noise; the frame reaches the tracker after a Gamma-distributed delivery delay. Frames drop
independently and in bursts (a burst starts with some probability and lasts a geometric number of
frames).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from sim.config import bounded, check_ranges

MAX_FPS = 1000.0
_MAX_CLOCK_S = 60.0  # the largest jitter, offset, noise or delay a camera's clock may have


@dataclass(frozen=True)
class ClockConfig:
    """[clock]: how each camera's frames are timed.

    Attributes:
        fps: nominal frame rate.
        random_phase: each camera starts at a uniform random phase within one period (else all at 0).
        jitter_std_s: std of the true capture time around the nominal tick, at most a quarter period.
        offset_std_s: std of each camera's constant offset between true time and its stamps.
        stamp_noise_std_s: std of per-frame noise on the written stamp.
        drop_prob: probability that a frame is dropped on its own.
        burst_prob: probability that a burst of drops starts at a frame.
        burst_mean_frames: mean length of a burst of drops (geometric).
        delay_mean_s: mean delivery delay; > 0 when delay_std_s is.
        delay_std_s: std of the delivery delay (Gamma distributed; 0 gives a constant delay).
        in_order_delivery: each camera's frames reach the tracker in the order they were taken, as over
            one stream connection (a late frame holds back the ones behind it); frames of different
            cameras still interleave out of stamp order. False delivers each frame after its own delay.
    """

    fps: float = bounded(10.0, 0.0, MAX_FPS, low_open=True, unit="frames per second")
    random_phase: bool = True
    jitter_std_s: float = bounded(0.002, 0.0, _MAX_CLOCK_S)
    offset_std_s: float = bounded(0.002, 0.0, _MAX_CLOCK_S)
    stamp_noise_std_s: float = bounded(0.0005, 0.0, _MAX_CLOCK_S)
    drop_prob: float = bounded(0.01, 0.0, 1.0)
    burst_prob: float = bounded(0.002, 0.0, 1.0)
    burst_mean_frames: float = bounded(5.0, 1.0, 1e6, unit="frames")
    delay_mean_s: float = bounded(0.05, 0.0, _MAX_CLOCK_S)
    delay_std_s: float = bounded(0.02, 0.0, _MAX_CLOCK_S)
    in_order_delivery: bool = True

    def __post_init__(self):
        check_ranges(self)
        if self.jitter_std_s > 0.25 / self.fps:
            raise ValueError(
                f"jitter_std_s: {self.jitter_std_s} must be <= a quarter period "
                f"({0.25 / self.fps:g} s at {self.fps} fps)"
            )
        if self.delay_std_s > 0 and self.delay_mean_s == 0:
            raise ValueError(f"delay_mean_s: 0 must be > 0 when delay_std_s ({self.delay_std_s}) is > 0")

    @property
    def period_s(self) -> float:
        return 1.0 / self.fps


class Schedule(NamedTuple):
    """Every frame the rig's cameras really take and deliver, as a struct of (N,) arrays, sorted by true
    capture time (ties by camera index).

    Attributes:
        camera: (N,) int64 index of the camera in the rig.
        frame: (N,) int64 tick number k of that camera (gaps where frames dropped).
        capture_s: (N,) true capture time (jittered), seconds since the scenario start.
        stamp_s: (N,) the time the camera wrote on the frame (its clock).
        delivery_s: (N,) when the frame reaches the tracker (capture + delay).
    """

    camera: np.ndarray
    frame: np.ndarray
    capture_s: np.ndarray
    stamp_s: np.ndarray
    delivery_s: np.ndarray


def delays(config: ClockConfig, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n,) delivery delays: Gamma with mean `delay_mean_s` and std `delay_std_s`."""
    if config.delay_std_s == 0:
        return np.full(n, config.delay_mean_s)
    shape = (config.delay_mean_s / config.delay_std_s) ** 2
    return rng.gamma(shape, config.delay_std_s**2 / config.delay_mean_s, n)


def drop_mask(config: ClockConfig, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n,) bool, frames dropped independently (drop_prob) or in bursts (burst_prob, burst_mean_frames)."""
    dropped = rng.random(n) < config.drop_prob
    starts = np.nonzero(rng.random(n) < config.burst_prob)[0]
    lengths = rng.geometric(1.0 / config.burst_mean_frames, starts.size)
    for start, length in zip(starts, lengths):
        dropped[start : start + length] = True
    return dropped


def schedule(camera_names, config: ClockConfig, duration_s: float, rng: np.random.Generator) -> Schedule:
    """Every frame each camera takes in [0, duration_s), dropped frames removed.

    Args:
        camera_names: names of the rig's cameras (their number sets the schedule; names are unused).
        config: the clock model.
        duration_s: simulated duration, seconds.
        rng: the "clock" generator. Each camera draws from its own child stream, so adding a camera
            does not change the others' clocks.
    """
    if not duration_s >= 0:
        raise ValueError(f"duration_s: {duration_s} must be >= 0")
    seeds = rng.integers(0, 2**63 - 1, size=len(camera_names))
    columns: list = [[], [], [], [], []]
    period = config.period_s
    for c, seed in enumerate(seeds):
        cam_rng = np.random.default_rng(int(seed))
        phase = cam_rng.uniform(0.0, period) if config.random_phase else 0.0
        offset = cam_rng.normal(0.0, config.offset_std_s) if config.offset_std_s > 0 else 0.0
        n = max(int(math.ceil((duration_s - phase) / period)), 0) + 1
        ticks = phase + np.arange(n) * period
        capture = ticks + (cam_rng.normal(0.0, config.jitter_std_s, n) if config.jitter_std_s > 0 else 0.0)
        stamp = capture + offset + (cam_rng.normal(0.0, config.stamp_noise_std_s, n)
                                    if config.stamp_noise_std_s > 0 else 0.0)
        delivery = capture + delays(config, n, cam_rng)
        if config.in_order_delivery:
            delivery = np.maximum.accumulate(delivery)
        keep = np.nonzero(~drop_mask(config, n, cam_rng) & (capture >= 0) & (capture < duration_s))[0]
        for column, values in zip(columns, (np.full(keep.size, c), keep, capture[keep], stamp[keep], delivery[keep])):
            column.append(values)
    camera, frame, capture, stamp, delivery = (
        np.concatenate(column) if column else np.zeros(0, dtype=dtype)
        for column, dtype in zip(columns, (np.int64, np.int64, float, float, float)))
    # By capture time, ties by camera index (a stable sort: a camera's frames stay in order).
    order = np.lexsort((camera, capture))
    return Schedule(camera[order].astype(np.int64), frame[order].astype(np.int64), capture[order].astype(float),
                    stamp[order].astype(float), delivery[order].astype(float))
