"""Every tunable parameter of the cross-view tracker, its units and valid range, and the Table S2 presets."""

from __future__ import annotations

import dataclasses
import enum
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

from core import tomlfile
from core.errors import ConfigError

BONE_SAMPLES = 25
"""Confident samples of each bone's length a target keeps (the newest); its length is their median."""


class Triangulation(enum.Enum):
    """How a target's joints are re-estimated from the latest point of each camera.

    PAPER: eq. (6)-(11), every camera's latest point constrains X(t), its rows weighted by
        w_i = e^(-λt (t - t_i)) / ||c_i|| (eq. 11).
    VELOCITY: beyond the paper: an older point constrains X(t) - V (t - t_i), V the target's joint
        velocity, so stale points of unsynchronised cameras are moved forward instead of only down-weighted.
    UNNORMALIZED: eq. (6)-(10) with w_i = e^(-λt (t - t_i)), without eq. (11)'s division by the row norm
        (Table 4's "Ours, w/o norm"; an ablation).
    CONVENTIONAL: the same points with unit weights, as if all were taken at one instant (eq. 8-9, the
        paper's "conventional triangulation" of Table 4 and Figure 5; an ablation).
    """

    PAPER = "paper"
    VELOCITY = "velocity"
    UNNORMALIZED = "unnormalized"
    CONVENTIONAL = "conventional"

    @property
    def normalizes_rows(self) -> bool:
        """Whether each row is divided by its norm (eq. 11)."""
        return self in (Triangulation.PAPER, Triangulation.VELOCITY)

    @property
    def weighs_time(self) -> bool:
        """Whether older points weigh less, e^(-λt (t - t_i)) (eq. 11)."""
        return self is not Triangulation.CONVENTIONAL


class RowNorm(enum.Enum):
    """What eq. (11) divides a row c_i of C by (with PAPER and VELOCITY triangulation).

    ROW: ||c_i|| over its four entries, as printed. Its fourth entry grows with the camera's distance from the
        world origin, so the same point's views weigh by where the origin happens to be (in the hypermarket,
        whose origin is a corner, up to 1,800 times apart).
    PLANE: beyond the paper: ||c_i[:3]||, so that c_i·X̃ / ||c_i[:3]|| is the distance in metres from X to the
        plane through the camera centre and the image line of the point, whatever the world origin.
    """

    ROW = "row"
    PLANE = "plane"


@dataclass(frozen=True)
class TrackerConfig:
    """Parameters of `tracker.Tracker` (Chen et al., CVPR 2020). Defaults are the Shelf row of Table S2.

    Affinity, eq. (1)-(5):
        w_2d: weight of the 2D term (eq. 2), unitless; the paper fixes 0.4.
        w_3d: weight of the 3D term (eq. 4), unitless; the paper fixes 0.6.
        alpha_2d_px_per_frame: 2D velocity threshold α2D of eq. (2), pixels per frame of the camera (Table S2's
            unit: the supplement uses the same number as a pixel distance in eq. S2). Eq. (2)'s threshold is
            α2D times the number of that camera's frame periods between t'' and t; the tracker takes each
            camera's period from its own stamps (`Tracker.frame_period_s`), so cameras of different frame
            rates get the same threshold per frame.
        alpha_3d_m: point-to-ray distance threshold α3D, metres (eq. 4).
        lambda_a_per_s: time penalty rate λa of the affinity, 1/s (eq. 2, 4).
        alpha_2d_floor_px: least 2D distance threshold of eq. (2), pixels; 0 is the paper (see
            tracker.affinity.affinity_matrix).
        alpha_2d_floor_px_per_s: least speed eq. (2)'s threshold allows, pixels per second; 0 is the paper.
            Beyond the paper: α2D per frame bounds a joint's move between two frames however long they are
            apart, so at a low frame rate walking people fail it (store_layout1 at 2.5 fps, the `store` preset
            without it: IDF1 0.54, 13 identity switches in 20 s; with it 0.97, 2). The threshold is then
            max(α2D·frames, this·(t - t''), alpha_2d_floor_px).
        score_threshold: joints with a detector score below this are ignored everywhere, [0, 1].
        view_margin_m: a target whose predicted body lies farther than this outside a camera's view volume is
            not scored against that camera's frame, and two cameras whose views (in the band of heights where
            joints can be) do not come this close are never linked at initialisation, metres (see
            tracker.visibility). At least alpha_3d_m, so that no pair left out could have a positive 3D term.
        normalize_affinity: False sums eq. (1) over joints as the paper writes it; True divides the sum by the
            number of joints compared (a detection with few joints then counts as much as a full one).
        velocity_window_s: history span for the linear least-squares joint velocity of eq. (5), s.
        velocity_history: number of past joint positions kept per target for that fit. A sample is taken at
            every matched camera frame, so the slots must outlast the window: 12 cameras at 10 fps see a
            person up to 120 times a second. With 12 slots the fit spanned 0.1 s instead of 0.4 s and the
            nose's velocity erred by 1-4 m/s; 48 slots: store_layout1 seeds 0/1/2 PCP 0.994/0.992/0.991 ->
            0.998/0.995/0.994 (head 0.96/0.97/0.94 -> 0.985/0.985/0.964), store_layout2 0.973/0.976/0.974 ->
            0.979/0.982/0.981, MPJPE -3 to -4 mm; Campus PCP unchanged.
        max_speed_m_per_s: joint speeds above this are clipped (a guard against a bad fit), m/s.
        max_predict_s: a joint is predicted forward (eq. 5) at most this long past its last update, s.
        stale_after_s: a joint not updated for this long moves with the body's velocity (beyond the paper), s.
        max_bone_m: a joint update that would make one of its bones longer than this is not taken (a gross
            2D error triangulated), metres; beyond the paper.
    A body that keeps its shape, joints that move like joints (beyond the paper; every switch off in the `-paper`
    presets; docs/tracker.md, "Body and joint priors", gives the maths and the measurements):
        limb_velocity_window_s: the window of eq. (5)'s velocity fit for the wrists and ankles
            (`tracker.body.LIMB_END_JOINTS`), s; 0 is the paper (`velocity_window_s` for every joint). A linear
            fit's slope is the velocity of its window's middle: half a window late for a joint that
            accelerates, and the limbs' ends accelerate most (a reaching wrist, a swinging ankle), while a
            short window's noisier velocity costs the head (the nose carries the protocol's head) and, on the
            elbows, the upper arms. 0.2 in `store` (docs/tracker.md, "Body and joint priors").
        velocity_quadratic: eq. (5)'s velocity V is the slope at the newest sample of the least-squares fit of a
            constant acceleration, x = a + b u + c u², over the window, instead of the linear fit's slope (the
            velocity of the window's middle, half a window late when the joint accelerates: a reaching wrist).
        joint_gate_m: a joint's new estimate farther than this from its constant-velocity prediction
            X_t' + V_t' (t - t') (eq. 5) is not taken: the joint keeps its predicted path through the jump or
            the run of misses, metres; 0 is the paper (every estimate taken), else at least 0.01.
        joint_gate_reset_s: a joint whose estimates were refused for this long (no estimate taken since) takes
            the next one whatever it is (the person did move), s.
        bone_prior_tolerance: each target learns its own bone lengths (the median of the lengths measured in
            its confident frames); a new estimate that makes a bone differ from the person's length by more than
            this fraction is pulled onto the nearest length within it, along the bone's measured direction, from
            the end nearer the hips; 0 is the paper (no bone prior), else in (0, 1). A target without enough
            confident frames keeps the paper's estimates.
        bone_prior_min_views: a frame is confident for a bone when both its joints were triangulated from at
            least this many views.
        bone_prior_min_samples: confident samples a bone needs before its length is used, at most
            `BONE_SAMPLES` (the samples kept per bone, the newest).
        bone_prior_sample_s: least time between two samples of a target's bone lengths, s (so the kept samples
            span `BONE_SAMPLES` times this, poses of several seconds rather than one).
        bone_symmetry: the left and right bones of a pair share one length, the median of both sides' samples.
        head_bones: the prior also holds the nose to each shoulder (the person's own neck and head proportions;
            the Campus protocol places the head on the line from the mid-shoulders to the nose,
            `core.layouts.coco17_to_campus14`), so that a nose estimate that breaks them is pulled back.
        bone_prior_resolve: a new estimate that breaks its bone is first triangulated again without each of its
            views in turn (eq. 6-11 from the others); of the solves whose views agree (each reprojects within
            `reject_floor_px`), the one whose bone comes nearest the person's length is taken when it lies within
            the tolerance (one view that disagrees, which the robust pass left in,
            as where a joint has few views); otherwise the bound applies.
    Triangulation, eq. (6)-(11):
        lambda_t_per_s: time penalty rate λt of eq. (11), 1/s.
        triangulation: PAPER (eq. 6-11), VELOCITY (stale points moved forward with the joint velocity), or the
            ablations UNNORMALIZED and CONVENTIONAL (see `Triangulation`).
        row_norm: ROW (eq. 11 as printed) or PLANE (each row's norm without its constant term, beyond the
            paper; see `RowNorm`): what a row is divided by in PAPER and VELOCITY triangulation, and in a new
            target's reconstruction. PLANE in the measured presets: the hypermarket's first 6 s, PCP 0.957 ->
            0.993; supermarket 100 people 10 s, MPJPE 41.7 -> 33.0 mm (docs/tracker.md, "Row norms").
        max_observation_age_s: a camera's last point older than this is left out of eq. (6), s.
        min_views: least number of cameras a joint needs to be triangulated (the paper: 2).
        reject_factor: beyond the paper: after eq. (6)-(11), a view whose reprojection error exceeds both
            `reject_floor_px` and this many times the median error of the joint's views is left out and the
            joint is triangulated again; 0 is the paper (every fresh view counts), else at least 1. An older
            point is judged against the estimate moved back to its own time with the joint's velocity (VELOCITY
            triangulation), so a stale point is dropped only when it lies beyond its prediction. 3 in the
            `store` preset, chosen on the project's own data and never per test frame (docs/tracker.md, "Robust
            triangulation"): MPJPE 0.7-0.8 mm lower on the stores, 1.7 mm on the Panoptic rig, PCP equal or higher; off
            in `campus` (three cameras leave it nothing to drop: no change on the Campus rig or the real Campus)
            and `shelf` (no Shelf data to measure it on), and in the `-paper` presets. Score-weighted views (w_i
            times the detector score) were tried too and were slightly worse (MPJPE +0.3-0.5 mm), so they are
            not offered.
        reject_floor_px: least reprojection error for that rejection, pixels.
    Initialisation (supplement, eq. S1-S5):
        alpha_epipolar_px: epipolar distance threshold of eq. (S2), pixels (the paper uses α2D's number, which
            the presets take from Table S2).
        init_window_s: unmatched detections older than this (before the newest stamp) are not clustered, s.
        init_min_joints: least number of confident joints a detection needs to take part in initialisation.
        init_min_common_joints: least number of joints two detections must share to get an affinity (S2).
        milp_max_nodes: graph-partitioning components up to this many detections are solved exactly with
            scipy.optimize.milp (eq. S3-S5); larger ones use the greedy merge (see tracker.initialization).
        init_max_reprojection_px: median reprojection error a new target may have, pixels.
        init_min_joints_3d: least number of triangulated joints a new target needs.
        init_max_bone_m: longest bone a new target may have, metres.
        init_min_top_m / init_max_top_m: range of the highest joint's height above the floor (z = 0), metres.
        init_min_bottom_m: lowest allowed joint height, metres (negative: below the floor).
        init_min_separation_m: a new target closer than this (mean joint distance) to an existing one is a
            duplicate and is dropped, metres.
        init_consensus_m: a new detection's candidate views from other cameras must place it, each triangulated
            with it alone, within this ground distance of where most of them do (beyond the paper: in a crowd
            seen by many cameras most epipolar matches are other people on its ray, see tracker.initialization),
            metres.
    Lifecycle (seconds, see tracker.lifecycle):
        confirm_min_updates: matched detections (including the initial views) before a target is confirmed.
        confirm_min_age_s: least time between a target's birth and its confirmation, s.
        tentative_timeout_s: a tentative target not updated for this long is removed, s.
        lost_after_s: a confirmed target not updated for this long becomes lost (no longer output), s.
        remove_after_s: a lost target not updated for this long (since its last update) is removed, s.
        reid_max_m: a new target born within reach of a LOST target takes its identity back; the reach is
            `reid_speed_m_per_s` times the time since the lost target's last update, clipped to
            [0.5, reid_max_m] metres; 0 disables it (the paper). Beyond the paper, and off in every preset:
            with arrivals and departures (store_layout1, seed 1) a newcomer took a departed person's identity
            (IDF1 0.99 -> 0.87).
        reid_speed_m_per_s: assumed walking speed for that reach, m/s.
    Evidence against ghosts (beyond the paper; see docs/tracker.md "No ghosts"):
        ghost_window_s: time constant of the decaying counts of a target's expected and actual sightings, s.
        ghost_inside_m: a camera is expected to see a target when the target's predicted hip centre lies at
            least this far inside the camera's view volume, metres.
        ghost_min_expected: the decayed count of expected sightings before the next rule may act.
        ghost_min_seen_ratio: a target matched in fewer than this share of the sightings expected of it is
            removed (a ghost: cameras that should see a person there see nobody), in [0, 1]; 0 disables.
        ghost_cell_m: side of the floor cells of each camera's sight map: how often the camera matched the
            confirmed targets whose hips stood in each cell while inside its view volume (shelves and crowds
            hide people from some cameras in some places); a frame adds that rate, not 1, to a target's
            expected sightings. 0 disables the map (every frame of a camera whose view holds it counts 1), m.
        ghost_map_prior_count: weight, in sightings, of what a cell's rate assumes before it has its own: the
            camera's rate over all cells (whose own prior is 1 with this weight).
        implausible_after_s: a target whose observed body stays implausible this long (the init_* limits of
            height above the floor, bone length and median reprojection error, checked at every match) is
            removed, s.
    Input:
        max_lateness_s: a frame stamped more than this before the newest processed stamp is dropped, s.

    Upper bounds (beyond the lower bounds above): every real value is finite and at most 86400 s, 1000 m,
    1000 m/s, 1e6 px, 1e6 px per frame or 1e6 /s by its unit, 1e6 without one; counts at most 1000, but
    velocity_history 10000, milp_max_nodes 200, confirm_min_updates 100000 and bone_prior_min_samples
    BONE_SAMPLES. `check_fits` refuses counts
    of cameras or joints the input lacks.
    """

    w_2d: float = 0.4
    w_3d: float = 0.6
    alpha_2d_px_per_frame: float = 60.0
    alpha_3d_m: float = 0.15
    lambda_a_per_s: float = 5.0
    alpha_2d_floor_px: float = 0.0
    alpha_2d_floor_px_per_s: float = 0.0
    score_threshold: float = 0.2
    normalize_affinity: bool = False
    view_margin_m: float = 0.5
    velocity_window_s: float = 0.3
    velocity_history: int = 48
    max_speed_m_per_s: float = 6.0
    max_predict_s: float = 0.5
    max_bone_m: float = 0.8
    stale_after_s: float = 0.3
    limb_velocity_window_s: float = 0.0
    velocity_quadratic: bool = False
    joint_gate_m: float = 0.0
    joint_gate_reset_s: float = 0.3
    bone_prior_tolerance: float = 0.0
    bone_prior_min_views: int = 3
    bone_prior_min_samples: int = 5
    bone_prior_sample_s: float = 0.2
    bone_symmetry: bool = False
    head_bones: bool = False
    bone_prior_resolve: bool = False
    lambda_t_per_s: float = 10.0
    triangulation: Triangulation = Triangulation.PAPER
    row_norm: RowNorm = RowNorm.ROW
    max_observation_age_s: float = 1.0
    min_views: int = 2
    reject_factor: float = 0.0
    reject_floor_px: float = 10.0
    alpha_epipolar_px: float = 60.0
    init_window_s: float = 0.1
    init_min_joints: int = 5
    init_min_common_joints: int = 3
    milp_max_nodes: int = 14
    init_max_reprojection_px: float = 30.0
    init_min_joints_3d: int = 6
    init_max_bone_m: float = 1.0
    init_min_top_m: float = 0.4
    init_max_top_m: float = 2.6
    init_min_bottom_m: float = -0.5
    init_min_separation_m: float = 0.3
    init_consensus_m: float = 0.3
    confirm_min_updates: int = 3
    confirm_min_age_s: float = 0.0
    tentative_timeout_s: float = 0.5
    lost_after_s: float = 0.5
    remove_after_s: float = 3.0
    reid_max_m: float = 0.0
    reid_speed_m_per_s: float = 1.5
    ghost_window_s: float = 1.0
    ghost_inside_m: float = 0.3
    ghost_min_expected: float = 10.0
    ghost_min_seen_ratio: float = 0.35
    ghost_cell_m: float = 1.0
    ghost_map_prior_count: float = 10.0
    implausible_after_s: float = 0.5
    max_lateness_s: float = 0.5

    def __post_init__(self):
        if isinstance(self.triangulation, str):
            object.__setattr__(self, "triangulation", _enum_value("triangulation", Triangulation, self.triangulation))
        if not isinstance(self.triangulation, Triangulation):
            raise ConfigError(f"TrackerConfig.triangulation: {self.triangulation!r} is not one of "
                              f"{[m.value for m in Triangulation]}")
        if isinstance(self.row_norm, str):
            object.__setattr__(self, "row_norm", _enum_value("row_norm", RowNorm, self.row_norm))
        if not isinstance(self.row_norm, RowNorm):
            raise ConfigError(f"TrackerConfig.row_norm: {self.row_norm!r} is not one of {[m.value for m in RowNorm]}")
        nonneg = ("w_2d", "w_3d", "lambda_a_per_s", "alpha_2d_floor_px", "alpha_2d_floor_px_per_s", "lambda_t_per_s",
                  "max_predict_s", "init_window_s", "confirm_min_age_s", "max_lateness_s", "reid_max_m",
                  "reid_speed_m_per_s", "reject_factor", "ghost_inside_m", "ghost_min_expected", "ghost_cell_m",
                  "ghost_map_prior_count", "joint_gate_m", "bone_prior_tolerance", "bone_prior_sample_s",
                  "limb_velocity_window_s")
        positive = ("ghost_window_s", "joint_gate_reset_s", "implausible_after_s", "alpha_2d_px_per_frame",
                    "alpha_3d_m", "view_margin_m", "velocity_window_s", "max_speed_m_per_s",
                    "max_observation_age_s", "alpha_epipolar_px", "reject_floor_px", "max_bone_m", "stale_after_s",
                    "init_max_reprojection_px", "init_max_bone_m", "init_consensus_m",
                    "tentative_timeout_s", "lost_after_s", "remove_after_s")
        for name in nonneg + positive:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value:
                raise ConfigError(f"TrackerConfig.{name}: {value!r} is not a number")
            if name in positive and not value > 0:
                raise ConfigError(f"TrackerConfig.{name}: {value} must be > 0")
            if name in nonneg and not value >= 0:
                raise ConfigError(f"TrackerConfig.{name}: {value} must be >= 0")
        for name in ("init_min_top_m", "init_max_top_m", "init_min_bottom_m", "init_min_separation_m",
                     "ghost_min_seen_ratio", "score_threshold"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value:
                raise ConfigError(f"TrackerConfig.{name}: {value!r} is not a number")
        if 0.0 < self.ghost_cell_m < 0.5:
            raise ConfigError(f"TrackerConfig.ghost_cell_m: {self.ghost_cell_m} must be 0 (no sight map) or at "
                              "least 0.5 m")
        if not 0.0 <= self.ghost_min_seen_ratio <= 1.0:
            raise ConfigError(f"TrackerConfig.ghost_min_seen_ratio: {self.ghost_min_seen_ratio} must be in [0, 1]")
        if 0.0 < self.reject_factor < 1.0:
            raise ConfigError(f"TrackerConfig.reject_factor: {self.reject_factor} must be 0 (no rejection) or at least "
                              "1 (a view is dropped when its error exceeds this many times the median)")
        if 0.0 < self.joint_gate_m < 0.01:
            raise ConfigError(f"TrackerConfig.joint_gate_m: {self.joint_gate_m} must be 0 (no gate) or at least 0.01 m")
        if not self.bone_prior_tolerance < 1.0:
            raise ConfigError(f"TrackerConfig.bone_prior_tolerance: {self.bone_prior_tolerance} must be 0 (no bone "
                              "prior) or in (0, 1), a fraction of the person's bone length")
        if not 0.0 <= self.score_threshold <= 1.0:
            raise ConfigError(f"TrackerConfig.score_threshold: {self.score_threshold} must be in [0, 1]")
        ints = {"velocity_history": 2, "min_views": 2, "init_min_joints": 1, "init_min_common_joints": 1,
                "milp_max_nodes": 2, "init_min_joints_3d": 1, "confirm_min_updates": 1, "bone_prior_min_views": 2,
                "bone_prior_min_samples": 1}
        for name, low in ints.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ConfigError(f"TrackerConfig.{name}: {value!r} must be an integer >= {low}")
        _check_upper_bounds(self)
        for name in ("normalize_affinity", "velocity_quadratic", "bone_symmetry", "head_bones", "bone_prior_resolve"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"TrackerConfig.{name}: {getattr(self, name)!r} must be true or false")
        if self.init_min_top_m >= self.init_max_top_m:
            raise ConfigError(f"TrackerConfig.init_min_top_m: {self.init_min_top_m} must be below "
                              f"init_max_top_m {self.init_max_top_m}")
        if not self.view_margin_m >= self.alpha_3d_m:
            raise ConfigError(f"TrackerConfig.view_margin_m: {self.view_margin_m} must be >= alpha_3d_m "
                              f"{self.alpha_3d_m}")
        if self.lost_after_s > self.remove_after_s:
            raise ConfigError(f"TrackerConfig.lost_after_s: {self.lost_after_s} must not exceed "
                              f"remove_after_s {self.remove_after_s}")

    @classmethod
    def preset(cls, name: str) -> TrackerConfig:
        """Parameters for a dataset: "campus", "shelf", "store" (Table S2 with the measured departures of PRESETS)
        or "campus-paper", "shelf-paper", "store-paper" (Table S2 verbatim, α2D in pixels per frame, the paper's
        triangulation)."""
        if name not in PRESETS:
            raise ConfigError(f"unknown tracker preset {name!r}; valid presets: {', '.join(sorted(PRESETS))}")
        return cls(**PRESETS[name])

    @classmethod
    def from_toml(cls, path, base: str | None = None) -> TrackerConfig:
        """Reads a TOML file of `field = value` lines (top level, or under a `[tracker]` table).

        Args:
            path: the file.
            base: a preset the file's values override; None starts from the defaults.

        Raises:
            ConfigError: unreadable file, unknown key (named with the file), or a value out of range.
        """
        path = Path(path)
        try:
            with path.open("rb") as f:
                data = tomlfile.load(f)
        except (OSError, tomllib.TOMLDecodeError) as exc:
            raise ConfigError(f"{path}: cannot read tracker config: {exc}") from exc
        except UnicodeDecodeError as exc:
            raise ConfigError(f"{path}: cannot read tracker config: not UTF-8 text (byte {exc.start})") from None
        if set(data) == {"tracker"} and isinstance(data["tracker"], dict):
            data = data["tracker"]
        if "preset" in data:
            if base is not None and base != data["preset"]:
                raise ConfigError(f"{path}: key 'preset' = {data['preset']!r} conflicts with base preset {base!r}")
            base = data.pop("preset")
        names = {f.name for f in dataclasses.fields(cls)}
        for key in data:
            if key in _RENAMED:
                raise ConfigError(f"{path}: key {key!r} is now {_RENAMED[key]}")
            if key not in names:
                raise ConfigError(f"{path}: unknown key {key!r}; valid keys: {', '.join(sorted(names))}")
        if base is not None and base not in PRESETS:
            raise ConfigError(f"{path}: unknown base preset {base!r}; valid presets: {', '.join(sorted(PRESETS))}")
        values = dict(PRESETS[base]) if base is not None else {}
        values.update(data)
        try:
            return cls(**values)
        except ConfigError as exc:  # every bad value is one, raised where it is checked; anything else is a bug
            raise ConfigError(f"{path}: {exc}") from exc

    def check_fits(self, num_cameras: int, num_joints: int) -> None:
        """Raises ConfigError when a count asks for more cameras or joints than the input has (a tracker
        that could then never triangulate or start a target, silently)."""
        for name, available, what in (("min_views", num_cameras, "cameras"),
                                      ("init_min_joints", num_joints, "joints"),
                                      ("init_min_common_joints", num_joints, "joints"),
                                      ("init_min_joints_3d", num_joints, "joints")):
            if getattr(self, name) > available:
                raise ConfigError(f"TrackerConfig.{name}: {getattr(self, name)} is more than the {available} {what} "
                                  "of the input; no target could ever be made")

    def replace(self, **changes) -> TrackerConfig:
        """A copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes)


# Keys of earlier versions, and what a file that sets one must say now.
_RENAMED = {"alpha_2d_px_per_s": "'alpha_2d_px_per_frame', pixels per frame of the camera (a value in pixels per "
                                 "second divided by the camera's frame rate)"}

# Upper bounds of every number (past them a value can only be a typo or exhaust memory): by unit suffix for
# the real-valued fields, by name for the counts; every real value must also be finite.
_MAX_BY_SUFFIX = (("_m_per_s", 1e3), ("_px_per_frame", 1e6), ("_per_s", 1e6), ("_px", 1e6), ("_s", 86400.0),
                  ("_m", 1e3))
_MAX_UNITLESS = 1e6
_MAX_COUNT = {"velocity_history": 10_000, "milp_max_nodes": 200, "confirm_min_updates": 100_000,
              "bone_prior_min_samples": BONE_SAMPLES}
_MAX_OTHER_COUNT = 1_000


def _check_upper_bounds(config: TrackerConfig) -> None:
    """Raises ConfigError naming the first number of `config` that is not finite or above its upper bound."""
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            continue
        if f.type in ("int", int):
            high = _MAX_COUNT.get(f.name, _MAX_OTHER_COUNT)
        else:
            high = next((h for suffix, h in _MAX_BY_SUFFIX if f.name.endswith(suffix)), _MAX_UNITLESS)
        if not (math.isfinite(value) and abs(value) <= high):
            raise ConfigError(f"TrackerConfig.{f.name}: {value!r} must be finite and at most {high:g} in size")


def _enum_value(name: str, enum_type, value: str):
    try:
        return enum_type(value)
    except ValueError:
        raise ConfigError(f"TrackerConfig.{name}: {value!r} is not one of {[m.value for m in enum_type]}") from None


# Table S2 of the supplement, verbatim: α2D (pixels per frame), α3D (m), λa, λt per dataset; w2D = 0.4, w3D = 0.6
# everywhere. The table prints α2D's unit as "pixel / second", but the supplement uses the same number as a pixel
# distance in eq. (S2), and both uses fit only as pixels per frame: read per second, eq. (2) lets a joint move
# α2D·(t - t'') pixels between two frames of one camera, 1 px at Campus's 25 fps and 7 px at the stores' 10 fps,
# below any detector's noise, so walking people fail eq. (2) and are dropped and reborn (docs/tracker.md, "What
# Table S2's α2D means": store_layout1 IDF1 0.42 read per second, 1.00 per frame).
TABLE_S2: dict[str, dict] = {
    "campus": dict(alpha_2d_px_per_frame=25.0, alpha_3d_m=0.10, lambda_a_per_s=5.0, lambda_t_per_s=10.0),
    "shelf": dict(alpha_2d_px_per_frame=60.0, alpha_3d_m=0.15, lambda_a_per_s=5.0, lambda_t_per_s=10.0),
    "store": dict(alpha_2d_px_per_frame=70.0, alpha_3d_m=0.25, lambda_a_per_s=3.0, lambda_t_per_s=5.0),
}

# The measured presets' α2D, pixels per frame: set from the image resolution when α2D was read per second (100,
# 240 and 400 px/s at 25, 25 and 10 fps), kept so that they track as measured at their datasets' frame rates,
# and those speeds kept as the least speed eq. (2) allows (alpha_2d_floor_px_per_s), so that at a lower frame
# rate (Figure 5's) a walking joint does not fail α2D per frame. With the floor of eq. (2)'s threshold
# (alpha_2d_floor_px), which absorbs the detector noise between close frames, they track as Table S2 does per
# frame at the datasets' rates; docs/tracker.md ("The presets' departures from Table S2") measures them against
# it. The floor scales with the image width: Campus with the simulator's `typical` detector noise, PCP 0.66
# without, 0.99 with 15 px.
# The measured presets also divide eq. (11)'s rows by the norm of their first three entries (RowNorm.PLANE):
# the whole row's norm weighs a camera's views by its distance from the world origin.
_MEASURED_ALPHA_2D = {"campus": 4.0, "shelf": 9.6, "store": 40.0}
_MEASURED_SPEED_PX_PER_S = {"campus": 100.0, "shelf": 240.0, "store": 400.0}
_MEASURED_FLOOR_PX = {"campus": 15.0, "shelf": 40.0, "store": 50.0}

# Campus and Shelf run at 25 fps, the Store at 10 fps: the windows below scale with the frame period. Eq. (S2)'s
# epipolar threshold is α2D's number of Table S2 in pixels, in every preset.
_COMMON: dict[str, dict] = {
    "campus": dict(init_window_s=0.05, init_max_reprojection_px=15.0),
    "shelf": dict(init_window_s=0.05),
    "store": dict(init_window_s=0.12, velocity_window_s=0.4, triangulation=Triangulation.VELOCITY),
}

# The robust pass after eq. (6)-(11) (reject_factor), in the measured presets where it was measured to help.
_MEASURED_REJECT_FACTOR = {"campus": 0.0, "shelf": 0.0, "store": 3.0}

# The body and joint priors (beyond the paper) in the measured presets where they were measured to help
# (docs/tracker.md, "Body and joint priors"): the limbs' shorter velocity window on the stores; the temporal
# gate, the constant-acceleration fit and the bone prior cost more than they gave there, so no preset has them;
# no Shelf data to measure on.
_MEASURED_PRIORS: dict[str, dict] = {"campus": {}, "shelf": {}, "store": {"limb_velocity_window_s": 0.2}}

PRESETS: dict[str, dict] = {}
for _name, _row in TABLE_S2.items():
    _common = {**_COMMON[_name], "alpha_epipolar_px": _row["alpha_2d_px_per_frame"]}
    PRESETS[_name] = {**_common, **_row, "alpha_2d_px_per_frame": _MEASURED_ALPHA_2D[_name],
                      "alpha_2d_floor_px_per_s": _MEASURED_SPEED_PX_PER_S[_name],
                      "alpha_2d_floor_px": _MEASURED_FLOOR_PX[_name], "row_norm": RowNorm.PLANE,
                      "reject_factor": _MEASURED_REJECT_FACTOR[_name], **_MEASURED_PRIORS[_name]}
    PRESETS[f"{_name}-paper"] = {**_common, **_row, "triangulation": Triangulation.PAPER}
