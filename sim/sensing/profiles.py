"""Detector profiles: the error model's parameters, the shipped presets and the scenario's [detector] section."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import NamedTuple

from sim.config import bounded, check_ranges


class DetectorProfile(enum.Enum):
    """Preset error models: `ideal` (exact joints, no misses), `typical` (OpenPose on Shelf), `harsh`."""

    IDEAL = "ideal"
    TYPICAL = "typical"
    HARSH = "harsh"


class DetectorParams(NamedTuple):
    """The effective error model (a profile with the scenario's knobs applied); the compiled draws take it as
    it is (a named tuple of numbers).

    Attributes:
        noise_frac: per-axis std of the joint noise core, as a fraction of the person's size in the image.
        noise_tail_dof: degrees of freedom of the Student-t noise (smaller: heavier tails; inf: Gaussian).
        occluded_noise_scale: noise multiplier on occluded joints.
        self_occluded_noise_scale: noise multiplier on self-occluded joints.
        gross_error_prob: per-joint probability of a jump of 0.2-0.5 of the person's size.
        miss_prob: probability of missing a fully visible person.
        miss_occlusion_gain: extra miss probability per unit occluded share of the person's joints.
        min_visible_joints: people with fewer visible (unoccluded, in-image) joints are never detected.
        min_person_frac: people smaller in the image than this fraction of its height (the larger side of
            their joints' box) are never detected.
        occluded_drop_prob: probability that an occluded joint is not reported.
        self_occluded_drop_prob: probability that a self-occluded joint is not reported.
        joint_drop_prob: probability that a visible joint is not reported.
        fragment_prob: probability that a detection keeps only one body part (fewer than 6 joints).
        swap_prob: probability that a detection has its left and right joints swapped.
        duplicate_prob: probability that a detection comes with a second, partial copy.
        phantom_rate: mean number of phantom skeletons per frame (Poisson).
        score_visible: mean score of a visible joint.
        score_occluded: mean score of an occluded joint.
        score_std: std of the joint scores.
    """

    noise_frac: float
    noise_tail_dof: float
    occluded_noise_scale: float
    self_occluded_noise_scale: float
    gross_error_prob: float
    miss_prob: float
    miss_occlusion_gain: float
    min_visible_joints: int
    min_person_frac: float
    occluded_drop_prob: float
    self_occluded_drop_prob: float
    joint_drop_prob: float
    fragment_prob: float
    swap_prob: float
    duplicate_prob: float
    phantom_rate: float
    score_visible: float
    score_occluded: float
    score_std: float


PROFILES: dict[DetectorProfile, DetectorParams] = {
    DetectorProfile.IDEAL: DetectorParams(
        noise_frac=0.0, noise_tail_dof=math.inf, occluded_noise_scale=1.0, self_occluded_noise_scale=1.0,
        gross_error_prob=0.0, miss_prob=0.0, miss_occlusion_gain=0.0, min_visible_joints=1, min_person_frac=0.0,
        occluded_drop_prob=0.0, self_occluded_drop_prob=0.0, joint_drop_prob=0.0, fragment_prob=0.0,
        swap_prob=0.0, duplicate_prob=0.0, phantom_rate=0.0, score_visible=1.0, score_occluded=1.0, score_std=0.0,
    ),
    # Calibrated against OpenPose (BODY25) detections on the Shelf dataset; see docs/sensor-model.md. Shelf's
    # people are all large: min_person_frac follows COCO instead (docs/sensor-model.md, "People too small to
    # detect").
    DetectorProfile.TYPICAL: DetectorParams(
        noise_frac=0.013, noise_tail_dof=5.0, occluded_noise_scale=1.6, self_occluded_noise_scale=1.3,
        gross_error_prob=0.001, miss_prob=0.03, miss_occlusion_gain=0.15, min_visible_joints=2, min_person_frac=0.1,
        occluded_drop_prob=0.4, self_occluded_drop_prob=0.1, joint_drop_prob=0.02, fragment_prob=0.07,
        swap_prob=0.002, duplicate_prob=0.01, phantom_rate=0.02, score_visible=0.8, score_occluded=0.45,
        score_std=0.12,
    ),
    DetectorProfile.HARSH: DetectorParams(
        noise_frac=0.022, noise_tail_dof=3.0, occluded_noise_scale=2.5, self_occluded_noise_scale=1.5,
        gross_error_prob=0.01, miss_prob=0.10, miss_occlusion_gain=0.4, min_visible_joints=4, min_person_frac=0.13,
        occluded_drop_prob=0.6, self_occluded_drop_prob=0.2, joint_drop_prob=0.05, fragment_prob=0.15,
        swap_prob=0.02, duplicate_prob=0.05, phantom_rate=0.2, score_visible=0.7, score_occluded=0.35,
        score_std=0.15,
    ),
}

MAX_PHANTOM_RATE = 100.0  # phantom skeletons per frame, on average


@dataclass(frozen=True)
class DetectorConfig:
    """[detector]: the error model of the 2D pose detector.

    `profile` picks the preset; every other key, when given, replaces that one parameter of the
    profile (see `DetectorParams` for their meaning).

    Attributes:
        profile: the preset error model: ideal (no errors), typical (calibrated to OpenPose on Shelf) or harsh.
        self_hit_margin_m: rays that end this close to a keypoint on its own body count as reaching it.
        occlusion: cast rays for occlusion by shelves, other people and the person's own body (false: every
            joint inside the image counts as visible).
    """

    profile: DetectorProfile = DetectorProfile.TYPICAL
    noise_frac: float | None = bounded(None, 0.0, 1.0)
    noise_tail_dof: float | None = bounded(None, 2.0, low_open=True, finite=False, unit="degrees of freedom")
    occluded_noise_scale: float | None = bounded(None, 1.0, 100.0, unit="times")
    self_occluded_noise_scale: float | None = bounded(None, 1.0, 100.0, unit="times")
    gross_error_prob: float | None = bounded(None, 0.0, 1.0)
    miss_prob: float | None = bounded(None, 0.0, 1.0)
    miss_occlusion_gain: float | None = bounded(None, 0.0, 10.0, unit="probability per occluded share")
    min_visible_joints: int | None = bounded(None, 1, 1000, unit="joints")
    min_person_frac: float | None = bounded(None, 0.0, 1.0, unit="fraction of the image height")
    occluded_drop_prob: float | None = bounded(None, 0.0, 1.0)
    self_occluded_drop_prob: float | None = bounded(None, 0.0, 1.0)
    joint_drop_prob: float | None = bounded(None, 0.0, 1.0)
    fragment_prob: float | None = bounded(None, 0.0, 1.0)
    swap_prob: float | None = bounded(None, 0.0, 1.0)
    duplicate_prob: float | None = bounded(None, 0.0, 1.0)
    phantom_rate: float | None = bounded(None, 0.0, MAX_PHANTOM_RATE, unit="skeletons per frame")
    score_visible: float | None = bounded(None, 0.0, 1.0, unit="score")
    score_occluded: float | None = bounded(None, 0.0, 1.0, unit="score")
    score_std: float | None = bounded(None, 0.0, 1.0, unit="score")
    self_hit_margin_m: float = bounded(0.2, 0.0, 2.0)
    occlusion: bool = True

    def __post_init__(self):
        check_ranges(self)

    def params(self) -> DetectorParams:
        """The profile's parameters with every knob that was set applied."""
        overrides = {name: getattr(self, name) for name in DetectorParams._fields if getattr(self, name) is not None}
        return PROFILES[self.profile]._replace(**overrides)

