"""Crowd motion: paths around shelves, gait, browsing, arrivals and departures."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class CrowdConfig:
    """[crowd]: who walks through the store and how."""

    people: int = 4

    def __post_init__(self):
        if self.people < 0:
            raise ValueError(f"people: {self.people} must be >= 0")
