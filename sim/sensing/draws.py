"""The detector's draws: person size in the image, and the compiled loop that turns visible joints into
detections (misses, drops, noise, gross errors, swaps, fragments, duplicates) and orders a frame's rows."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from core.jit import jit
from core.records import DetectionEffect, DetectionRows
from core.types import Skeleton
from sim.sensing.profiles import JOINT_GROUPS

# Body parts a fragment may keep (COCO-17 indices), each fewer than 6 joints.
FRAGMENTS_COCO17 = (
    (0, 1, 2, 3, 4), (5, 7, 9), (6, 8, 10), (5, 6, 7, 8), (11, 13, 15), (12, 14, 16), (11, 12, 13, 14),
    (0, 5, 6), (13, 14, 15, 16),
)
_GROSS_MIN_FRAC, _GROSS_MAX_FRAC = 0.2, 0.5
_DUPLICATE_OFFSET_FRAC = 0.05
_DUPLICATE_KEEP = 0.6  # share of its joints a duplicate repeats
_DUPLICATE_SCORE = 0.6  # its scores, relative to the original's
MIN_SCORE = 0.05
# A canonical standing COCO-17 person 1.7 m tall facing +x (body frame, metres), used for phantoms.
TEMPLATE_COCO17 = np.array([
    [0.08, 0.0, 1.62], [0.07, 0.03, 1.66], [0.07, -0.03, 1.66], [0.0, 0.07, 1.64], [0.0, -0.07, 1.64],
    [0.0, 0.19, 1.42], [0.0, -0.19, 1.42], [0.0, 0.23, 1.13], [0.0, -0.23, 1.13], [0.05, 0.24, 0.86],
    [0.05, -0.24, 0.86], [0.0, 0.1, 0.92], [0.0, -0.1, 0.92], [0.02, 0.1, 0.5], [0.02, -0.1, 0.5],
    [0.0, 0.1, 0.08], [0.0, -0.1, 0.08],
])


# What `draw_detections` writes: `DetectionRows`' arrays, then each row's capture in the block.
DrawnRows = NamedTuple("DrawnRows", [(name, np.ndarray) for name in (*DetectionRows._fields, "group")])


def person_size_px(keypoints_px: np.ndarray) -> np.ndarray:
    """The person's size in the image: the larger side of the bounding box of its true joints.

    Args:
        keypoints_px: (..., J, 2) true pixel positions, NaN where unknown.

    Returns:
        (...,) size in pixels (NaN when no joint is known).
    """
    kp = np.ascontiguousarray(keypoints_px, dtype=np.float64)
    sizes = _person_sizes(kp.reshape((int(np.prod(kp.shape[:-2])),) + kp.shape[-2:]))  # `_person_size` each
    return sizes.reshape(kp.shape[:-2])


def joint_groups(skeleton: Skeleton) -> np.ndarray:
    """(J,) int64 the index in `JOINT_GROUPS` of each joint (`Skeleton.joint_groups`)."""
    group = np.zeros(skeleton.num_joints, dtype=np.int64)
    for name, members in skeleton.joint_groups().items():
        group[list(members)] = JOINT_GROUPS.index(name)
    return group


def left_right_permutation(skeleton: Skeleton) -> np.ndarray:
    """(J,) joint order that swaps every left_* joint with its right_* partner."""
    order = np.arange(skeleton.num_joints)
    for i, name in enumerate(skeleton.joints):
        for a, b in (("left_", "right_"), ("right_", "left_")):
            if name.startswith(a) and b + name[len(a):] in skeleton.joints:
                order[i] = skeleton.index(b + name[len(a):])
    return order



_FRAGMENT, _GROSS_ERROR, _LEFT_RIGHT_SWAP, _DUPLICATE = (int(e) for e in (
    DetectionEffect.FRAGMENT, DetectionEffect.GROSS_ERROR, DetectionEffect.LEFT_RIGHT_SWAP, DetectionEffect.DUPLICATE))


@jit
def frame_order(frame, key, n_frames, order):
    """np.lexsort((key, frame)) into order (D,): rows by frame (0 <= frame < n_frames), each frame's by key,
    ties in input order (a counting sort, then an insertion sort of each frame's few rows)."""
    start = np.zeros(n_frames + 1, dtype=np.int64)
    for d in range(frame.shape[0]):
        start[frame[d] + 1] += 1
    for f in range(n_frames):
        start[f + 1] += start[f]
    fill = start[:n_frames].copy()
    for d in range(frame.shape[0]):
        order[fill[frame[d]]] = d
        fill[frame[d]] += 1
    for f in range(n_frames):
        for i in range(start[f] + 1, start[f + 1]):
            d = order[i]
            k = i - 1
            while k >= start[f] and key[order[k]] > key[d]:
                order[k + 1] = order[k]
                k -= 1
            order[k + 1] = d



@jit
def _person_size(px, p):
    """The size in the image of person-view px[p] (J, 2): the larger side of the bounding box of its known
    joints, NaN with none (`person_size_px` of any shape, compiled)."""
    high0 = high1 = -np.inf
    low0 = low1 = np.inf
    for j in range(px.shape[1]):
        x, y = px[p, j, 0], px[p, j, 1]
        if not np.isnan(x):
            high0, low0 = max(high0, x), min(low0, x)
        if not np.isnan(y):
            high1, low1 = max(high1, y), min(low1, y)
    extent = max(-np.inf, high0 - low0, high1 - low1)
    return extent if np.isfinite(extent) else np.nan


@jit
def _person_sizes(px):
    """(P,) `_person_size` of every person-view of px (P, J, 2)."""
    out = np.empty(px.shape[0])
    for p in range(px.shape[0]):
        out[p] = _person_size(px, p)
    return out


@jit
def large_enough(px, min_px):
    """(P,) whether each person-view of px (P, J, 2) is at least min_px[p] in the image (`person_size_px`)."""
    out = np.empty(px.shape[0], dtype=np.bool_)
    for p in range(px.shape[0]):
        out[p] = _person_size(px, p) >= min_px[p]
    return out


class Views(NamedTuple):
    """The person-views of a block that the draws turn into detections (P rows, every capture's people in turn).

    Attributes:
        person_ids: (P,) int64 true person of each row.
        px: (P, J, 2) the scoring truth's joints projected (distorted pixels; NaN where unknown).
        found_px: (P, J, 2) the detector's own joints projected (`sim.sensing.offsets`): what its noise is
            around (NaN: use px).
        in_img, occluded, self_occluded: (P, J) bool visibility of each true joint.
        group: (P,) int64 the capture each row belongs to.
        min_px: (P,) the size in pixels below which the row is not detected.
        slot: (P,) int64 the row of `DrawState` that holds this camera's state for this person.
        t_s: (P,) capture time of each row, seconds.
    """

    person_ids: np.ndarray
    px: np.ndarray
    found_px: np.ndarray
    in_img: np.ndarray
    occluded: np.ndarray
    self_occluded: np.ndarray
    group: np.ndarray
    min_px: np.ndarray
    slot: np.ndarray
    t_s: np.ndarray


class DrawState(NamedTuple):
    """What the draws remember between frames, per (camera, person) slot and joint: the detector's errors
    persist and its misses come in runs (docs/sensor-model.md).

    Attributes:
        noise: (S, J, 2) the latest noise of the joint, in units of its std (an AR(1) process in time).
        noise_t_s: (S, J) when it was drawn (-inf: never).
        missed: (S, J) bool whether the joint was missed then.
        gross: (S, J) bool whether the joint was off by a gross jump then.
        jump: (S, J, 2) that jump, as a fraction of the person's size.
        fail_t_s: (S, J) when `missed` and `gross` were drawn (-inf: never).

    The gross errors remember as the noise does (`noise_time_s`: they are its large excursions), the misses
    with their own `miss_time_s`.
    """

    noise: np.ndarray
    noise_t_s: np.ndarray
    missed: np.ndarray
    gross: np.ndarray
    jump: np.ndarray
    fail_t_s: np.ndarray

    @staticmethod
    def empty(slots: int, J: int) -> DrawState:
        return DrawState(np.zeros((slots, J, 2)), np.full((slots, J), -np.inf), np.zeros((slots, J), dtype=np.bool_),
                         np.zeros((slots, J), dtype=np.bool_), np.zeros((slots, J, 2)), np.full((slots, J), -np.inf))


class DrawTables(NamedTuple):
    """The skeleton's constants the draws need.

    Attributes:
        fragment_masks: (F, J) bool the body parts a fragment may keep.
        joint_group: (J,) int64 each joint's index in `profiles.JOINT_GROUPS`.
        swap_order: (J,) int64 the joint order that swaps left and right (`left_right_permutation`).
    """

    fragment_masks: np.ndarray
    joint_group: np.ndarray
    swap_order: np.ndarray


@jit
def _decay(now_s, then_s, time_s):
    """exp(-(now - then) / time): how much of a state drawn at `then_s` is left at `now_s` (0 when never drawn or
    with no memory)."""
    if not time_s > 0.0 or not then_s > -np.inf:
        return 0.0
    return math.exp(-max(now_s - then_s, 0.0) / time_s)


@jit
def draw_detections(rng, views, state, tables, model, out):
    """The detections of real people (`Detector._detections`): every draw from `rng` (a numpy Generator,
    whose stream numba reads and advances as numpy would) and what it does, person-view by person-view in
    the order of `views` (captures in time order, so each slot's state moves forward in time).

    Per person-view (`Views`): never detected with fewer than `min_visible` visible joints in the image or
    smaller than min_px in it (`person_size_px`), else missed with probability miss + gain x its occluded
    share. A detection reports each joint in the image unless it is missed: a two-state process per slot and
    joint whose stationary rate is the group's `joint_miss_prob`, or the occlusion's drop probability where
    that is larger, with memory `miss_time_s`. It may keep only one body part (fragment). A reported joint lies
    at the detector's own joint (`found_px`) plus noise scaled by the person's size in the image, the joint's
    occlusion and `noise_frac`: an AR(1) process per slot and joint, whose Student-t innovations keep its std
    (correlation exp(-Δt / noise_time_s) between draws Δt apart); plus, while the joint is in a gross error (a
    two-state process like the misses, rate `gross_error_prob`, memory `noise_time_s`), a jump of a uniform
    fraction of the size in a uniform direction, drawn when the error starts and kept while it lasts. Scores
    are clipped normals; left and right may be swapped. Joints not reported are NaN with score 0.
    A detection with a joint reported may come with a duplicate: a second copy shifted by a normal offset of
    `_DUPLICATE_OFFSET_FRAC` of the size, repeating each joint with probability `_DUPLICATE_KEEP`, at
    `_DUPLICATE_SCORE` of the scores.

    model: the `DetectorParams`. Writes the rows (detections in person-view order, then their duplicates)
    into `out` (a `DrawnRows` of 2P rows), updates `state` (`DrawState`), and returns how many rows it wrote.
    """
    ids, kp, scores, true_px, out_in, out_occluded, out_self, effects, out_group = out
    px, found, in_img, occluded, self_occluded = views.px, views.found_px, views.in_img, views.occluded, \
        views.self_occluded
    dof = model.noise_tail_dof
    heavy = math.isfinite(dof)
    # Student-t innovations scaled to unit variance, so that the AR(1) process keeps the std it is given.
    unit_t = math.sqrt((dof - 2.0) / dof) if heavy and dof > 2.0 else 1.0
    P, J = in_img.shape
    n_parts = tables.fragment_masks.shape[0]
    reported = np.empty(J, dtype=np.bool_)
    value = np.empty((J, 2))
    score = np.empty(J)
    n = 0
    originals = np.empty(P, dtype=np.int64)  # rows of the detections, for their duplicates
    sizes = np.empty(P)
    for p in range(P):
        n_in = n_visible = n_occluded = 0
        for j in range(J):
            n_in += in_img[p, j]
            n_visible += in_img[p, j] and not occluded[p, j]
            n_occluded += occluded[p, j]
        if n_in == 0 or n_visible < model.min_visible_joints:
            continue
        size = _person_size(px, p)
        if not size >= views.min_px[p]:  # too small to detect (NaN: no joint known)
            continue
        if rng.random() < model.miss_prob + model.miss_occlusion_gain * n_occluded / n_in:
            continue
        s, t = views.slot[p], views.t_s[p]
        effect = 0
        for j in range(J):
            reported[j] = False
            if not in_img[p, j]:
                continue
            # The joint's failures: P(missed), P(gross) relax from their last states to their stationary rates.
            memory = _decay(t, state.fail_t_s[s, j], model.miss_time_s)
            gross_memory = _decay(t, state.fail_t_s[s, j], model.noise_time_s)
            rate = model.joint_miss_prob[tables.joint_group[j]]
            if occluded[p, j]:
                rate = max(rate, model.occluded_drop_prob)
            elif self_occluded[p, j]:
                rate = max(rate, model.self_occluded_drop_prob)
            last = 1.0 if state.missed[s, j] else 0.0
            missed = rng.random() < rate + (last - rate) * memory
            last = 1.0 if state.gross[s, j] else 0.0
            gross = rng.random() < model.gross_error_prob + (last - model.gross_error_prob) * gross_memory
            if gross and not state.gross[s, j]:  # a new gross error: its own jump
                angle = rng.uniform(0.0, 2.0 * np.pi)
                jump = rng.uniform(_GROSS_MIN_FRAC, _GROSS_MAX_FRAC)
                state.jump[s, j, 0], state.jump[s, j, 1] = jump * math.cos(angle), jump * math.sin(angle)
            state.missed[s, j], state.gross[s, j], state.fail_t_s[s, j] = missed, gross, t
            reported[j] = not missed
        # Fragments keep one body part (if it holds a reported joint).
        if rng.random() < model.fragment_prob:
            part = rng.integers(0, n_parts)
            any_part = False
            for j in range(J):
                any_part = any_part or (reported[j] and tables.fragment_masks[part, j])
            if any_part:
                for j in range(J):
                    reported[j] = reported[j] and tables.fragment_masks[part, j]
                effect |= _FRAGMENT
        any_reported = False
        for j in range(J):
            if not in_img[p, j]:
                value[j, 0] = value[j, 1] = np.nan
                score[j] = 0.0
                continue
            # The camera's noise on this joint: AR(1) in time, drawn for every joint in the image so that its
            # memory does not depend on what was reported.
            rho = _decay(t, state.noise_t_s[s, j], model.noise_time_s)
            z0, z1 = rng.standard_normal(), rng.standard_normal()
            if heavy:  # Student-t: the normal core over the root of a chi-square / dof
                stretch = math.sqrt(dof / rng.chisquare(dof)) * unit_t
                z0, z1 = z0 * stretch, z1 * stretch
            keep = math.sqrt(1.0 - rho * rho)
            state.noise[s, j, 0] = rho * state.noise[s, j, 0] + keep * z0
            state.noise[s, j, 1] = rho * state.noise[s, j, 1] + keep * z1
            state.noise_t_s[s, j] = t
            if not reported[j]:
                value[j, 0] = value[j, 1] = np.nan
                score[j] = 0.0
                continue
            any_reported = True
            scale = model.noise_frac * size * (model.occluded_noise_scale if occluded[p, j] else (
                model.self_occluded_noise_scale if self_occluded[p, j] else 1.0))
            cx, cy = found[p, j, 0], found[p, j, 1]
            if not (cx == cx and cy == cy):  # the detector's joint did not project: the truth's instead
                cx, cy = px[p, j, 0], px[p, j, 1]
            value[j, 0], value[j, 1] = cx + scale * state.noise[s, j, 0], cy + scale * state.noise[s, j, 1]
            if state.gross[s, j]:
                value[j, 0] += state.jump[s, j, 0] * size
                value[j, 1] += state.jump[s, j, 1] * size
                effect |= _GROSS_ERROR
            base = model.score_occluded if occluded[p, j] else model.score_visible
            score[j] = min(max(base + model.score_std * rng.standard_normal(), MIN_SCORE), 1.0)
        if not any_reported:
            continue
        swap = rng.random() < model.swap_prob
        if swap:
            effect |= _LEFT_RIGHT_SWAP
        for j in range(J):
            k = tables.swap_order[j] if swap else j
            kp[n, j, 0], kp[n, j, 1], scores[n, j] = value[k, 0], value[k, 1], score[k]
            true_px[n, j, 0], true_px[n, j, 1] = px[p, j, 0], px[p, j, 1]
            out_in[n, j], out_occluded[n, j], out_self[n, j] = in_img[p, j], occluded[p, j], self_occluded[p, j]
        ids[n], effects[n], out_group[n] = views.person_ids[p], effect, views.group[p]
        originals[n], sizes[n] = p, size
        n += 1
    # Duplicates: a second, partial, shifted and less confident copy of a detection.
    D = n
    for d in range(D):
        if not rng.random() < model.duplicate_prob:
            continue
        p = originals[d]
        shift0 = _DUPLICATE_OFFSET_FRAC * sizes[d] * rng.standard_normal()
        shift1 = _DUPLICATE_OFFSET_FRAC * sizes[d] * rng.standard_normal()
        for j in range(J):
            repeat = not np.isnan(kp[d, j, 0]) and rng.random() < _DUPLICATE_KEEP
            kp[n, j, 0] = kp[d, j, 0] + shift0 if repeat else np.nan
            kp[n, j, 1] = kp[d, j, 1] + shift1 if repeat else np.nan
            scores[n, j] = scores[d, j] * _DUPLICATE_SCORE if repeat else 0.0
            true_px[n, j, 0], true_px[n, j, 1] = px[p, j, 0], px[p, j, 1]
            out_in[n, j], out_occluded[n, j], out_self[n, j] = in_img[p, j], occluded[p, j], self_occluded[p, j]
        ids[n], effects[n], out_group[n] = ids[d], effects[d] | _DUPLICATE, out_group[d]
        n += 1
    return n
