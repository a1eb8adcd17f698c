"""Ceiling camera rigs: placement, intrinsics from resolution and field of view, lens distortion."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class CameraRigConfig:
    """[cameras]: where the cameras hang and what lenses they have."""

    rows: int = 3
    cols: int = 4
    width_px: int = 1280
    height_px: int = 720
    hfov_deg: float = 90.0

    def __post_init__(self):
        if self.rows * self.cols < 1:
            raise ValueError(f"rows x cols: {self.rows} x {self.cols} gives no cameras; need at least 1")
        if not 0 < self.hfov_deg < 180:
            raise ValueError(f"hfov_deg: {self.hfov_deg} must be in (0, 180)")
