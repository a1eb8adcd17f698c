"""Detector profiles: the error model's parameters, the shipped presets, the scenario's [detector] section and
the profile file (what `crossview fit-detector` writes and a scenario's `detector.profile` may name)."""

from __future__ import annotations

import enum
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import core.types
from core import tomlfile
from core.errors import ScenarioError
from sim.config import bounded, check_ranges, from_dict, toml_value


class DetectorProfile(enum.Enum):
    """Preset error models: `ideal` (exact joints, no misses), `typical` (OpenPose on Shelf), `harsh`."""

    IDEAL = "ideal"
    TYPICAL = "typical"
    HARSH = "harsh"


JOINT_GROUPS = tuple(core.types.JOINT_GROUPS)
"""The joint groups a per-group parameter has one value for, in this order (head, shoulders, elbows, wrists,
hips, knees, ankles; `core.types.Skeleton.joint_groups` says which joints each holds)."""

Groups = tuple[float, float, float, float, float, float, float]
"""One number per joint group (`JOINT_GROUPS`)."""


class DetectorParams(NamedTuple):
    """The effective error model (a profile with the scenario's knobs applied); the compiled draws take it as
    it is (a named tuple of numbers and per-group tuples). docs/sensor-model.md gives the real statistic each
    `typical` value was set from.

    Attributes:
        noise_frac: per-axis std of one camera's noise on a joint, as a fraction of the person's size in the
            image (the larger side of the box of its true joints).
        noise_tail_dof: degrees of freedom of the Student-t noise (smaller: heavier tails; inf: Gaussian).
        noise_time_s: correlation time of that noise: one camera's errors on one joint of one person Δt apart
            correlate by exp(-Δt / noise_time_s) (0: independent frame to frame).
        occluded_noise_scale: noise multiplier on occluded joints.
        self_occluded_noise_scale: noise multiplier on self-occluded joints.
        offset_m: per joint group, per-axis std of the offset between the point the detector finds and the
            scoring truth's joint (metres; the same for every camera, so it survives triangulation), in the
            frame of the joint's body segment (it turns with the body).
        offset_tail_dof: degrees of freedom of the Student-t scale of a person's offsets (heavy tails across
            people and joints; inf: Gaussian).
        offset_time_s: correlation time of the offset (it varies slowly: sleeves, clothing, pose).
        lift_m: per joint group, how far above the truth's joint (world up, metres) the detector's joint sits.
        gross_error_prob: the share of frames in which a joint is off by a jump of 0.2-0.5 of the person's size
            (a two-state process like the misses, with the noise's memory `noise_time_s`: a gross error lasts).
        miss_prob: probability of missing a fully visible person.
        miss_occlusion_gain: extra miss probability per unit occluded share of the person's joints.
        min_visible_joints: people with fewer visible (unoccluded, in-image) joints are never detected.
        min_person_frac: people smaller in the image than this fraction of its height (the larger side of
            their joints' box) are never detected.
        occluded_drop_prob: the share of frames in which an occluded joint is not reported (its miss rate while
            occluded, where that is above its group's).
        self_occluded_drop_prob: the same for a self-occluded joint.
        joint_miss_prob: per joint group, the share of frames in which a detected person's visible joint is not
            reported (the stationary rate of a two-state miss process per camera, person and joint).
        miss_time_s: correlation time of the miss process: a joint missed at t is missed at t + Δt with
            probability rate + (1 - rate) exp(-Δt / miss_time_s).
        fragment_prob: probability that a detection keeps only one body part (fewer than 6 joints).
        swap_prob: probability that a detection has its left and right joints swapped.
        duplicate_prob: probability that a detection comes with a second, partial copy.
        phantom_rate: mean number of phantom skeletons (false-positive people) per frame (Poisson).
        phantom_keep_prob: probability that a phantom reports each of its joints inside the image.
        score_visible: mean score of a visible joint.
        score_occluded: mean score of an occluded joint.
        score_std: std of the joint scores.
        difficult_rate: the share of people the detector keeps getting wrong (sleeves, bags, an object in hand,
            an unusual build), drawn systematically over the people in the order they enter (person k is one
            when floor(rate (k + 1) + phase) > floor(rate k + phase), the phase drawn from the seed): any N
            people in a row hold floor or ceil of rate x N of them, whatever the seed.
        difficult_offset_scale: such a person's offsets (`offset_m`) are this many times larger.
        difficult_error_m: such a person has one chosen arm the detector gets grossly wrong: its wrist sits this
            far (metres, a direction drawn per person in the forearm's frame, the same in every camera) from
            the truth's, its elbow half as far, whenever the arm is in a bad episode.
        difficult_share: the share of the person's visit the chosen arm is in a bad episode (episodes come and
            go with the offsets' correlation time `offset_time_s`; the arm and direction hold for the visit).
    """

    noise_frac: float
    noise_tail_dof: float
    noise_time_s: float
    occluded_noise_scale: float
    self_occluded_noise_scale: float
    offset_m: Groups
    offset_tail_dof: float
    offset_time_s: float
    lift_m: Groups
    gross_error_prob: float
    miss_prob: float
    miss_occlusion_gain: float
    min_visible_joints: int
    min_person_frac: float
    occluded_drop_prob: float
    self_occluded_drop_prob: float
    joint_miss_prob: Groups
    miss_time_s: float
    fragment_prob: float
    swap_prob: float
    duplicate_prob: float
    phantom_rate: float
    phantom_keep_prob: float
    score_visible: float
    score_occluded: float
    score_std: float
    difficult_rate: float = 0.0
    difficult_offset_scale: float = 1.0
    difficult_error_m: float = 0.0
    difficult_share: float = 0.0


_NONE = (0.0,) * len(JOINT_GROUPS)

PROFILES: dict[DetectorProfile, DetectorParams] = {
    DetectorProfile.IDEAL: DetectorParams(
        noise_frac=0.0, noise_tail_dof=math.inf, noise_time_s=0.0, occluded_noise_scale=1.0,
        self_occluded_noise_scale=1.0, offset_m=_NONE, offset_tail_dof=math.inf, offset_time_s=0.0, lift_m=_NONE,
        gross_error_prob=0.0, miss_prob=0.0, miss_occlusion_gain=0.0, min_visible_joints=1, min_person_frac=0.0,
        occluded_drop_prob=0.0, self_occluded_drop_prob=0.0, joint_miss_prob=_NONE, miss_time_s=0.0,
        fragment_prob=0.0, swap_prob=0.0, duplicate_prob=0.0, phantom_rate=0.0, phantom_keep_prob=1.0,
        score_visible=1.0, score_occluded=1.0, score_std=0.0,
    ),
    # Fitted to real OpenPose (BODY25) on the Shelf dataset as `crossview detector-stats` measures it (the file
    # crossview/measure/data/shelf-openpose-detector-stats.json) on the Shelf dataset's rig (scenarios/shelf.toml):
    # `crossview fit-detector --target shelf-openpose --start PREVIOUS.toml --duration 20 --rounds 6`, the last of
    # three such fits (docs/sensor-model.md gives the chain), rounded to 3 digits; every headline statistic within
    # 17 % of the real one. Set by hand from the real file's statistics, not fitted: the difficult people's
    # (docs/sensor-model.md). Not fitted (no real figure): the head's offset and misses, the tails, self-occlusion
    # drops, swaps, duplicates, scores; the false-positive people (the real file counts an unannotated person).
    # The head's offset is the shoulders' scaled by COCO's per-keypoint sigmas (face points 0.025-0.035,
    # shoulders 0.079: three times better defined). Shelf's people are all large: min_person_frac follows COCO
    # instead (docs/sensor-model.md, "People too small to detect").
    DetectorProfile.TYPICAL: DetectorParams(
        noise_frac=0.0117, noise_tail_dof=5.0, noise_time_s=0.795, occluded_noise_scale=1.6,
        self_occluded_noise_scale=1.3,
        offset_m=(0.005, 0.011, 0.00828, 0.0225, 0.0262, 0.0149, 0.00709), offset_tail_dof=4.0, offset_time_s=2.0,
        lift_m=(0.0, 0.0236, 0.0112, 0.0238, 0.0322, 0.01, 0.00159),
        gross_error_prob=0.0189, miss_prob=0.0, miss_occlusion_gain=0.0581, min_visible_joints=2,
        min_person_frac=0.1, occluded_drop_prob=0.108, self_occluded_drop_prob=0.05,
        joint_miss_prob=(0.08, 0.0207, 0.11, 0.175, 0.0, 0.0, 0.0), miss_time_s=0.165,
        fragment_prob=0.0, swap_prob=0.002, duplicate_prob=0.01, phantom_rate=0.301, phantom_keep_prob=0.564,
        score_visible=0.8, score_occluded=0.45, score_std=0.12,
        difficult_rate=0.333, difficult_offset_scale=1.0, difficult_error_m=0.4, difficult_share=0.082,
    ),
    DetectorProfile.HARSH: DetectorParams(
        noise_frac=0.018, noise_tail_dof=3.0, noise_time_s=0.1, occluded_noise_scale=2.5,
        self_occluded_noise_scale=1.5,
        offset_m=(0.01, 0.03, 0.03, 0.05, 0.05, 0.025, 0.025), offset_tail_dof=3.0, offset_time_s=2.0,
        lift_m=(0.0, 0.035, 0.02, 0.035, 0.055, 0.0, 0.0),
        gross_error_prob=0.01, miss_prob=0.10, miss_occlusion_gain=0.4, min_visible_joints=4,
        min_person_frac=0.13, occluded_drop_prob=0.6, self_occluded_drop_prob=0.2,
        joint_miss_prob=(0.12, 0.08, 0.18, 0.28, 0.06, 0.07, 0.1), miss_time_s=0.4,
        fragment_prob=0.15, swap_prob=0.02, duplicate_prob=0.05, phantom_rate=0.6, phantom_keep_prob=0.5,
        score_visible=0.7, score_occluded=0.35, score_std=0.15,
    ),
}

MAX_PHANTOM_RATE = 100.0  # phantom skeletons per frame, on average
MAX_TIME_S = 3600.0  # correlation times: an hour is already "constant over any recording"
MIN_OFFSET_TAIL_DOF = 1.0
"""The heaviest tail a person's offsets may have: a Cauchy's (1 degree of freedom). The offsets' Student-t is a
scale mixture per person and joint (`sim.sensing.offsets`), which needs no finite variance; real OpenPose's p99
on Shelf (0.374 of the person's size against a median of 0.028) needs tails heavier than 2 degrees of freedom."""


@dataclass(frozen=True)
class DetectorConfig:
    """[detector]: the error model of the 2D pose detector.

    `profile` picks the preset; every other key, when given, replaces that one parameter of the
    profile (see `DetectorParams` for their meaning).

    Attributes:
        profile: the preset error model: ideal (no errors), typical (set from OpenPose on Shelf) or harsh; a
            scenario may name a profile file instead (`load_profile_file`), whose parameters it then holds.
        self_hit_margin_m: rays that end this close to a keypoint on its own body count as reaching it.
        occlusion: cast rays for occlusion by shelves, other people and the person's own body (false: every
            joint inside the image counts as visible).
    """

    profile: DetectorProfile = DetectorProfile.TYPICAL
    noise_frac: float | None = bounded(None, 0.0, 1.0)
    noise_tail_dof: float | None = bounded(None, 2.0, low_open=True, finite=False, unit="degrees of freedom")
    noise_time_s: float | None = bounded(None, 0.0, MAX_TIME_S)
    occluded_noise_scale: float | None = bounded(None, 1.0, 100.0, unit="times")
    self_occluded_noise_scale: float | None = bounded(None, 1.0, 100.0, unit="times")
    offset_m: Groups | None = bounded(None, 0.0, 1.0)
    offset_tail_dof: float | None = bounded(None, MIN_OFFSET_TAIL_DOF, finite=False, unit="degrees of freedom")
    offset_time_s: float | None = bounded(None, 0.0, MAX_TIME_S)
    lift_m: Groups | None = bounded(None, -1.0, 1.0)
    gross_error_prob: float | None = bounded(None, 0.0, 1.0)
    miss_prob: float | None = bounded(None, 0.0, 1.0)
    miss_occlusion_gain: float | None = bounded(None, 0.0, 10.0, unit="probability per occluded share")
    min_visible_joints: int | None = bounded(None, 1, 1000, unit="joints")
    min_person_frac: float | None = bounded(None, 0.0, 1.0, unit="fraction of the image height")
    occluded_drop_prob: float | None = bounded(None, 0.0, 1.0)
    self_occluded_drop_prob: float | None = bounded(None, 0.0, 1.0)
    joint_miss_prob: Groups | None = bounded(None, 0.0, 1.0)
    miss_time_s: float | None = bounded(None, 0.0, MAX_TIME_S)
    fragment_prob: float | None = bounded(None, 0.0, 1.0)
    swap_prob: float | None = bounded(None, 0.0, 1.0)
    duplicate_prob: float | None = bounded(None, 0.0, 1.0)
    phantom_rate: float | None = bounded(None, 0.0, MAX_PHANTOM_RATE, unit="skeletons per frame")
    phantom_keep_prob: float | None = bounded(None, 0.0, 1.0)
    score_visible: float | None = bounded(None, 0.0, 1.0, unit="score")
    score_occluded: float | None = bounded(None, 0.0, 1.0, unit="score")
    score_std: float | None = bounded(None, 0.0, 1.0, unit="score")
    difficult_rate: float | None = bounded(None, 0.0, 1.0, unit="share of people")
    difficult_offset_scale: float | None = bounded(None, 1.0, 100.0, unit="times")
    difficult_error_m: float | None = bounded(None, 0.0, 2.0)
    difficult_share: float | None = bounded(None, 0.0, 1.0)
    self_hit_margin_m: float = bounded(0.2, 0.0, 2.0)
    occlusion: bool = True

    def __post_init__(self):
        check_ranges(self)

    def params(self) -> DetectorParams:
        """The profile's parameters with every knob that was set applied."""
        overrides = {name: getattr(self, name) for name in DetectorParams._fields if getattr(self, name) is not None}
        return PROFILES[self.profile]._replace(**overrides)


# ---------------------------------------------------------------- the profile file

PROFILE_FILE_SUFFIX = ".toml"


def is_profile_file(profile) -> bool:
    """Whether a `detector.profile` value names a profile file rather than a shipped profile."""
    return isinstance(profile, str) and profile.endswith(PROFILE_FILE_SUFFIX)


def load_profile_file(path: Path) -> dict:
    """A detector profile file (what `crossview fit-detector` writes): `base`, the shipped profile it starts
    from (default typical), and any parameters of `DetectorParams`, each checked as a [detector] key is.

    Returns:
        {"profile": base, parameter: value, ...} as TOML values.

    Raises:
        ScenarioError: the file is missing, unreadable or malformed, or a key is unknown or invalid; the
            message names the file and the key.
    """
    try:
        tree = tomlfile.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ScenarioError(f"{path}: no such detector profile file (detector.profile names a shipped profile, "
                            f"{', '.join(p.value for p in DetectorProfile)}, or a profile file)") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ScenarioError(f"{path}: cannot read the detector profile: {e}") from None
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{path}: malformed TOML: {e}") from None
    base = tree.pop("base", DetectorProfile.TYPICAL.value)
    valid = [p.value for p in DetectorProfile]
    if base not in valid:
        raise ScenarioError(f"{path}: base = {base!r} is not one of {valid}")
    unknown = sorted(set(tree) - set(DetectorParams._fields))
    if unknown:
        raise ScenarioError(f"{path}: unknown key '{unknown[0]}' (valid keys: base, "
                            f"{', '.join(DetectorParams._fields)})")
    from_dict(DetectorConfig, {**tree, "profile": base}, str(path), "")  # every value checked, naming the file
    return {"profile": base, **tree}


def profile_params(profile: str) -> DetectorParams:
    """The parameters of a shipped profile (by name) or of a profile file (a path ending in .toml)."""
    if is_profile_file(profile):
        return from_dict(DetectorConfig, load_profile_file(Path(profile)), profile, "").params()
    valid = [p.value for p in DetectorProfile]
    if profile not in valid:
        raise ScenarioError(f"profile {profile!r}: not one of {valid} nor a profile file (.toml)")
    return PROFILES[DetectorProfile(profile)]


def profile_file_text(params: DetectorParams, base: DetectorProfile, comment: str) -> str:
    """A profile file holding every parameter of `params` (what `load_profile_file` reads back)."""
    lines = [f"# {line}" if line else "#" for line in comment.splitlines()]
    lines += ["", f"base = {toml_value(base.value)}"]
    lines += [f"{name} = {toml_value(getattr(params, name))}" for name in DetectorParams._fields]
    return "\n".join(lines) + "\n"
