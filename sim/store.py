"""Store layouts: floor, walls, shelf rows, entrance, exit and checkout, built as MuJoCo geometry."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ShelfConfig:
    """One shelf unit: its footprint centre, full size and yaw."""

    center_m: tuple[float, float] = (0.0, 0.0)
    size_m: tuple[float, float, float] = (2.0, 0.5, 1.8)
    yaw_deg: float = 0.0


@dataclass(frozen=True)
class StoreConfig:
    """[store]: the floor rectangle [0, width] x [0, depth], ceiling height and fixtures."""

    width_m: float = 4.0
    depth_m: float = 3.0
    ceiling_m: float = 3.0
    shelves: tuple[ShelfConfig, ...] = ()

    def __post_init__(self):
        for name in ("width_m", "depth_m", "ceiling_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: {getattr(self, name)} must be > 0")
