"""The synthetic 2D detector: projection, visibility, occlusion, noise, misses and false positives."""

from __future__ import annotations

import enum
from dataclasses import dataclass


class DetectorProfile(enum.Enum):
    IDEAL = "ideal"
    TYPICAL = "typical"
    HARSH = "harsh"


@dataclass(frozen=True)
class DetectorConfig:
    """[detector]: the error model of the 2D pose detector."""

    profile: DetectorProfile = DetectorProfile.TYPICAL
