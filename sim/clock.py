"""Per-camera clocks: nominal rate, phase, jitter, drops, stamp offset and delivery delay."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ClockConfig:
    """[clock]: how each camera's frames are timed."""

    fps: float = 10.0

    def __post_init__(self):
        if not self.fps > 0:
            raise ValueError(f"fps: {self.fps} must be > 0")
