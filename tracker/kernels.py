"""Compiled in-place updates of the tracker's target arrays: Algorithm 1's update of the matched targets.

`Tracker` (tracker/tracker.py) holds the arrays and calls these once per frame; each does in one pass what
would otherwise be a few hundred small numpy calls: `update_matched` (eq. 6-11 through
`triangulation.triangulate_point`, the bone gate, the velocity fit of eq. 5, the stale joints),
`split_detections` and `output_poses` (the frame's output).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from core.jit import jit, sort_prefix
from tracker.body import fill_poses, joint_states
from tracker.triangulation import Observations, TriangulationParams, solve_observations, triangulate_point

MIN_VELOCITY_SPAN_S = 0.02  # a velocity fit needs samples at least this far apart in time


class Priors(NamedTuple):
    """The temporal gate and the body prior of a matched target's update (`TrackerConfig`'s switches of the
    same names; docs/tracker.md, "Body and joint priors").

    Attributes:
        gate_m: a joint estimate farther than this from its eq. (5) prediction is refused, m; 0 off.
        gate_reset_s: a joint refused for this long takes the next estimate, s.
        tolerance: fraction by which a bone may differ from the person's length; 0 off.
        min_views: views both joints of a bone need for a confident sample of its length.
        min_samples: samples a bone needs before its length is used.
        sample_s: least time between two samples of a target's bones, s.
        symmetric: whether a bone's length pools its mirror's samples.
        bones: (B, 2) int64 (parent, child) joint pairs ordered outward; mirror: (B,) int64 each one's mirror
            bone, -1 none (`body.prior_bones`).
        resolve: a joint whose estimate breaks its bone is first triangulated again without each of its views in
            turn; the solve whose bone comes nearest the person's length is taken when within the tolerance.
        quadratic: eq. (5)'s velocity from a constant-acceleration fit (`_fit_velocities`).
        window_s: (J,) each joint's window of eq. (5)'s velocity fit, s (`velocity_window_s`, or
            `limb_velocity_window_s` for the joints of the forearms and shanks).
    """

    gate_m: float
    gate_reset_s: float
    tolerance: float
    min_views: int
    min_samples: int
    sample_s: float
    symmetric: bool
    bones: np.ndarray
    mirror: np.ndarray
    resolve: bool
    quadratic: bool
    window_s: np.ndarray


class UpdateParams(NamedTuple):
    """The `TrackerConfig` fields of a matched target's update (`update_matched`) and of the output poses.

    Attributes:
        max_observation_age_s: a camera's latest point of a joint older than this is left out of eq. (6), s.
        triangulation: `TriangulationParams` of eq. (6)-(11) (λt 0 where the configuration's triangulation
            mode does not weigh time).
        max_bone_m: the bone gate's length, m.
        velocity_window_s: eq. (5)'s velocity fits the samples of this last span, s.
        max_speed_m_per_s: a joint speed beyond this is clipped, m/s.
        stale_after_s: a joint not seen for this long moves with the body, s.
        max_predict_s: the longest horizon of eq. (5)'s prediction, s.
        prior: the `Priors` (beyond the paper).
    """

    max_observation_age_s: float
    triangulation: TriangulationParams
    max_bone_m: float
    velocity_window_s: float
    max_speed_m_per_s: float
    stale_after_s: float
    max_predict_s: float
    prior: Priors


class BodyLimits(NamedTuple):
    """When a matched target's observed body is implausible (`implausible_bodies`).

    Attributes:
        stale_after_s: a joint triangulated within this span is observed, s.
        min_bottom_m, max_top_m: the heights an observed joint should lie between, m.
        max_bone_m: the longest plausible observed bone, m.
        max_reprojection_px: the largest plausible median reprojection error, pixels.
        share: more than this share of the observed joints (or bones) out of the limits is implausible.
    """

    stale_after_s: float
    min_bottom_m: float
    max_top_m: float
    max_bone_m: float
    max_reprojection_px: float
    share: float


@jit
def update_matched(rows, cols, det_px, camera, stamp_s, targets, P, bones, params):
    """Updates the matched targets in place: eq. (6)-(11) per joint, bone gate, eq. (5) velocity, stale joints.

    For each matched pair (rows[m], cols[m]):
    1. the detection's joints become the target's latest points of `camera` (eq. 6);
    2. each joint the detection holds is triangulated from the latest point of every camera not older than
       `max_observation_age_s` (eq. 6-11, `triangulation.triangulate_point`; with `use_velocity` the
       velocity-compensated estimate is taken where it exists, the paper's one otherwise);
    3. a joint whose new estimate would make one of its bones longer than `max_bone_m` that was not already
       keeps its previous estimate (beyond the paper: a gross 2D error seen in two views);
    4. the paper's estimates (never the compensated ones: a velocity error would move the stale points, whose
       shifted estimate would grow the velocity error) enter the history, and the joint velocity is the linear
       least-squares slope over the samples of the last `velocity_window_s` (eq. 5), clipped in speed;
    5. a joint not seen for `stale_after_s` moves with the median velocity of the target's fresh joints.

    Args:
        rows: (M,) matched target rows; cols: (M,) their detections in det_px (D, J, 2) undistorted pixels.
        camera: the frame's camera index; stamp_s: its stamp t, s.
        targets: the `TargetRows` (pos, vel, joint_s, seen_s, obs_px, obs_s, cam_s, hist_pos, hist_s, hist_next,
            last_update_s, num_updates updated in place); its cam_s (T, C), the stamp of the last frame of each
            camera matched to the target (NaN none), >= every obs_s of that camera, lets only the cameras with a
            fresh point be visited per joint.
        P: (C, 3, 4) projection matrices; bones: (B, 2) int64 joint pairs.
        params: `UpdateParams`.
    """
    pos, vel, joint_s, seen_s = targets.pos, targets.vel, targets.joint_s, targets.seen_s
    obs_px, obs_s, cam_s = targets.obs_px, targets.obs_s, targets.cam_s
    hist_pos, hist_s, hist_next = targets.hist_pos, targets.hist_s, targets.hist_next
    max_observation_age_s, max_bone_m = params.max_observation_age_s, params.max_bone_m
    triangulation = params.triangulation
    lambda_t_per_s, use_velocity = triangulation.lambda_t_per_s, triangulation.use_velocity
    C, J = obs_s.shape[1], obs_s.shape[2]
    H = hist_s.shape[1]
    cams = np.empty(C, dtype=np.int64)
    points = np.empty((C, 2))
    dts = np.empty(C)
    decays = np.empty(C)
    cached_s = np.empty(C)  # the stamps of a camera's points mostly agree across joints: one e^x per stamp
    cached_decay = np.empty(C)
    work = np.empty((3, 4, 4))
    scratch = np.empty((4, 8))
    V = np.empty(3)
    plain = np.empty(3)
    compensated = np.empty(3)
    samples = np.empty((J, 3))  # the paper's estimates (eq. 10-11)
    X = np.empty((J, 3))  # the estimates taken
    update = np.empty(J, dtype=np.bool_)
    hit = np.empty(J, dtype=np.bool_)
    values = np.empty(J)
    num_views = np.zeros(J, dtype=np.int64)
    prior = params.prior
    lengths = np.empty(2 * prior.bones.shape[0] * targets.bone_samples.shape[1] + 1)
    fresh = np.empty(C, dtype=np.int64)
    observations = Observations(cams, points, dts, decays)  # refilled per joint
    # Each joint's observations of this update, for the bone prior's re-solve (`_resolve_bones`; empty without).
    Jr, Cr = (J, C) if prior.resolve else (0, 0)
    kept = Observations(np.empty((Jr, Cr), dtype=np.int64), np.empty((Jr, Cr, 2)), np.empty((Jr, Cr)),
                        np.empty((Jr, Cr)))
    subset = Observations(np.empty(Cr, dtype=np.int64), np.empty((Cr, 2)), np.empty(Cr), np.empty(Cr))
    for m in range(rows.size):
        r, d = rows[m], cols[m]
        cached_s[:] = np.nan
        # 1. Eq. (6): the new points replace this camera's latest points.
        for j in range(J):
            if np.isfinite(det_px[d, j, 0]):
                obs_px[r, camera, j, 0] = det_px[d, j, 0]
                obs_px[r, camera, j, 1] = det_px[d, j, 1]
                obs_s[r, camera, j] = stamp_s
        cam_s[r, camera] = stamp_s
        num_fresh = 0
        for k in range(C):
            if stamp_s - cam_s[r, k] <= max_observation_age_s:  # False for NaN (never matched)
                fresh[num_fresh] = k
                num_fresh += 1
        # 2. Eq. (6)-(11) for the joints the detection holds.
        for j in range(J):
            update[j] = False
            if not np.isfinite(det_px[d, j, 0]):
                continue
            num = 0
            for f in range(num_fresh):
                k = fresh[f]
                if stamp_s - obs_s[r, k, j] <= max_observation_age_s:  # False for NaN (no point)
                    cams[num] = k
                    points[num, 0] = obs_px[r, k, j, 0]
                    points[num, 1] = obs_px[r, k, j, 1]
                    dts[num] = max(stamp_s - obs_s[r, k, j], 0.0)
                    if obs_s[r, k, j] != cached_s[k]:
                        cached_s[k] = obs_s[r, k, j]
                        cached_decay[k] = np.exp(-2.0 * lambda_t_per_s * dts[num])
                    decays[num] = cached_decay[k]  # eq. (11): e^(-2 λt (t - t_i)), squared
                    num += 1
            V[0], V[1], V[2] = vel[r, j, 0], vel[r, j, 1], vel[r, j, 2]
            triangulate_point(P, observations, num, V, triangulation, plain, compensated, work, scratch)
            update[j] = np.isfinite(plain[0])
            num_views[j] = num
            if prior.resolve:
                for i in range(num):
                    kept.cam[j, i], kept.dts[j, i], kept.decays[j, i] = cams[i], dts[i], decays[i]
                    kept.points_px[j, i, 0], kept.points_px[j, i, 1] = points[i, 0], points[i, 1]
            use_compensated = use_velocity and np.isfinite(compensated[0])
            for k in range(3):
                samples[j, k] = plain[k]
                X[j, k] = compensated[k] if use_compensated else plain[k]
        # 2b. The temporal gate and the body prior (beyond the paper).
        if prior.gate_m > 0.0:
            _gate_jumps(pos, vel, joint_s, seen_s, r, stamp_s, params.max_predict_s, prior, X, update)
        if prior.tolerance > 0.0:
            _sample_bones(targets, r, stamp_s, X, update, num_views, prior, lengths)
            if prior.resolve:
                _resolve_bones(pos, vel, targets.bone_len, r, X, samples, update, prior, P, kept, num_views, subset,
                               triangulation, work, scratch)
            _bound_bones(pos, targets.bone_len, r, X, samples, update, prior)
        # 3. The bone gate (beyond the paper).
        for j in range(J):
            hit[j] = False
        for b in range(bones.shape[0]):
            a, e = bones[b, 0], bones[b, 1]
            if not (update[a] or update[e]):
                continue
            if _distance(pos, r, a, e) > max_bone_m:
                continue  # already long: the gate only keeps bones from becoming long
            new_sq = 0.0
            for k in range(3):
                xa = X[a, k] if update[a] else pos[r, a, k]
                xe = X[e, k] if update[e] else pos[r, e, k]
                new_sq += (xa - xe) * (xa - xe)
            if np.sqrt(new_sq) > max_bone_m:
                hit[a] = hit[a] or update[a]
                hit[e] = hit[e] or update[e]
        for j in range(J):
            update[j] = update[j] and not hit[j]
            if update[j]:
                for k in range(3):
                    pos[r, j, k] = X[j, k]
                joint_s[r, j] = stamp_s
                seen_s[r, j] = stamp_s
        # 4. Eq. (5)'s V: history ring buffer, then the least-squares slope of each updated joint.
        slot = hist_next[r]
        for j in range(J):
            hist_s[r, slot, j] = stamp_s if update[j] else np.nan
            for k in range(3):
                hist_pos[r, slot, j, k] = samples[j, k] if update[j] else np.nan
        hist_next[r] = (slot + 1) % H
        _fit_velocities(hist_pos, hist_s, r, update, stamp_s, prior.window_s, params.max_speed_m_per_s,
                        prior.quadratic, vel)
        # 5. Joints nobody has seen for `stale_after_s` move with the body (beyond the paper).
        _carry_stale(pos, vel, joint_s, seen_s, r, stamp_s, params.stale_after_s, params.max_predict_s, values)
        targets.last_update_s[r] = stamp_s
        targets.num_updates[r] += 1


@jit
def _gate_jumps(pos, vel, joint_s, seen_s, r, stamp_s, max_predict_s, prior, X, update):
    """Refuses (update[j] = False) each new estimate X[j] farther than `prior.gate_m` from the joint's eq. (5)
    prediction X_t' + V_t' (t - t'), the horizon clipped to [0, max_predict_s], unless the joint has taken no
    estimate for `prior.gate_reset_s` (or has none): the refused joint keeps its predicted path."""
    for j in range(X.shape[0]):
        if not update[j] or not stamp_s - seen_s[r, j] <= prior.gate_reset_s or not np.isfinite(pos[r, j, 0]):
            continue
        horizon = min(max(stamp_s - joint_s[r, j], 0.0), max_predict_s)
        sq = 0.0
        for k in range(3):
            d = X[j, k] - (pos[r, j, k] + vel[r, j, k] * horizon)
            sq += d * d
        if sq > prior.gate_m * prior.gate_m:
            update[j] = False


@jit
def _sample_bones(targets, r, stamp_s, X, update, num_views, prior, lengths):
    """Adds the lengths of the bones whose both joints this update triangulated from `prior.min_views` views or
    more to target r's ring of samples (at most once per `prior.sample_s`), and sets its bone lengths to the
    medians of their samples (pooled with the mirror bone's when `prior.symmetric`; NaN with fewer than
    `prior.min_samples`)."""
    if stamp_s - targets.bone_sampled_s[r] < prior.sample_s:
        return
    bones, samples = prior.bones, targets.bone_samples
    B, K = bones.shape[0], samples.shape[1]
    slot = targets.bone_next[r]
    any_sample = False
    for b in range(B):
        a, e = bones[b, 0], bones[b, 1]
        samples[r, slot, b] = np.nan
        if update[a] and update[e] and num_views[a] >= prior.min_views and num_views[e] >= prior.min_views:
            sq = 0.0
            for k in range(3):
                sq += (X[a, k] - X[e, k]) * (X[a, k] - X[e, k])
            samples[r, slot, b] = np.sqrt(sq)
            any_sample = True
    if not any_sample:
        return
    targets.bone_next[r] = (slot + 1) % K
    targets.bone_sampled_s[r] = stamp_s
    for b in range(B):
        n = 0
        for side in range(2):
            o = b if side == 0 else prior.mirror[b]
            if side == 1 and not (prior.symmetric and o >= 0):
                continue
            for h in range(K):
                if np.isfinite(samples[r, h, o]):
                    lengths[n] = samples[r, h, o]
                    n += 1
        if n < prior.min_samples * (2 if prior.symmetric and prior.mirror[b] >= 0 else 1):
            targets.bone_len[r, b] = np.nan
        else:
            sort_prefix(lengths, n)
            targets.bone_len[r, b] = (lengths[(n - 1) // 2] + lengths[n // 2]) / 2.0


@jit
def _resolve_bones(pos, vel, bone_len, r, X, samples, update, prior, P, kept, num_views, subset, triangulation, work,
                   scratch):
    """Re-solves each joint whose new estimate makes a bone of target r differ from the person's length L by more
    than `prior.tolerance` L: eq. (6)-(11) again from its views of this update (`kept`) without one view, each view
    in turn (a view that disagrees with the others, which the robust pass left in); of the solves whose views
    agree (each view's reprojection error within `reject_floor_px`), the one whose bone length comes nearest L
    replaces the estimate when it lies within the tolerance (parents before children: a parent's re-solved
    estimate is the child's end). Without such a solve, or with fewer than min_views + 1 views, the
    estimate is left to `_bound_bones`."""
    bones, tol = prior.bones, prior.tolerance
    min_views, use_velocity = triangulation.min_views, triangulation.use_velocity
    floor_px = triangulation.reject_floor_px
    V = np.empty(3)
    plain = np.empty(3)
    compensated = np.empty(3)
    best = np.empty(3)
    best_plain = np.empty(3)
    for b in range(bones.shape[0]):
        p, c = bones[b, 0], bones[b, 1]
        L = bone_len[r, b]
        num = num_views[c]
        if not update[c] or not np.isfinite(L) or num < min_views + 1:
            continue
        if abs(_length_to(pos, r, X, update, p, X[c, 0], X[c, 1], X[c, 2]) - L) <= tol * L:
            continue  # within the tolerance (or no parent: NaN, no re-solve either)
        V[0], V[1], V[2] = vel[r, c, 0], vel[r, c, 1], vel[r, c, 2]
        best_gap = np.inf
        for left_out in range(num):
            n = 0
            for i in range(num):
                if i != left_out:
                    subset.cam[n], subset.dts[n], subset.decays[n] = kept.cam[c, i], kept.dts[c, i], kept.decays[c, i]
                    subset.points_px[n, 0], subset.points_px[n, 1] = kept.points_px[c, i, 0], kept.points_px[c, i, 1]
                    n += 1
            solve_observations(P, subset, n, V, triangulation, plain, compensated, work, scratch)
            if not np.isfinite(plain[0]):
                continue
            use_compensated = use_velocity and np.isfinite(compensated[0])
            x0 = compensated[0] if use_compensated else plain[0]
            x1 = compensated[1] if use_compensated else plain[1]
            x2 = compensated[2] if use_compensated else plain[2]
            gap = abs(_length_to(pos, r, X, update, p, x0, x1, x2) - L)
            if gap < best_gap and _views_agree(P, subset, n, x0, x1, x2, V, use_velocity, floor_px):
                best_gap = gap
                best[0], best[1], best[2] = x0, x1, x2
                best_plain[0], best_plain[1], best_plain[2] = plain[0], plain[1], plain[2]
        if best_gap <= tol * L:
            for k in range(3):
                X[c, k] = best[k]
                samples[c, k] = best_plain[k]


@jit
def _views_agree(P, observations, num, x0, x1, x2, V, use_velocity, floor_px):
    """Whether every one of the first `num` observations reprojects within floor_px of the point (moved back to
    the observation's time with V when use_velocity, as `triangulate_point` judges its views)."""
    for i in range(num):
        k, dt = observations.cam[i], observations.dts[i] if use_velocity else 0.0
        y0, y1, y2 = x0 - V[0] * dt, x1 - V[1] * dt, x2 - V[2] * dt
        u = P[k, 0, 0] * y0 + P[k, 0, 1] * y1 + P[k, 0, 2] * y2 + P[k, 0, 3]
        v = P[k, 1, 0] * y0 + P[k, 1, 1] * y1 + P[k, 1, 2] * y2 + P[k, 1, 3]
        w = P[k, 2, 0] * y0 + P[k, 2, 1] * y1 + P[k, 2, 2] * y2 + P[k, 2, 3]
        du, dv = u / w - observations.points_px[i, 0], v / w - observations.points_px[i, 1]
        if not du * du + dv * dv <= floor_px * floor_px:
            return False
    return True


@jit
def _length_to(pos, r, X, update, p, x0, x1, x2):
    """Distance from (x0, x1, x2) to joint p's new estimate (or its held one), NaN when p is unknown."""
    a0, a1, a2 = (X[p, 0], X[p, 1], X[p, 2]) if update[p] else (pos[r, p, 0], pos[r, p, 1], pos[r, p, 2])
    return np.sqrt((x0 - a0) * (x0 - a0) + (x1 - a1) * (x1 - a1) + (x2 - a2) * (x2 - a2))


@jit
def _bound_bones(pos, bone_len, r, X, samples, update, prior):
    """Bounds each bone of target r that a new estimate of its child joint makes longer or shorter than the
    person's length L by more than `prior.tolerance` L: the child moves along the bone's measured direction
    onto the nearer bound, from its parent's new estimate (or its held one), parents before children (the
    prior's bones are ordered outward). The velocity sample (`samples`) moves with it."""
    bones, tol = prior.bones, prior.tolerance
    for b in range(bones.shape[0]):
        p, c = bones[b, 0], bones[b, 1]
        L = bone_len[r, b]
        if not update[c] or not np.isfinite(L):
            continue
        sq = 0.0
        for k in range(3):
            parent = X[p, k] if update[p] else pos[r, p, k]
            sq += (X[c, k] - parent) * (X[c, k] - parent)
        length = np.sqrt(sq)  # NaN when the parent is unknown: no bound
        bound = min(max(length, L * (1.0 - tol)), L * (1.0 + tol))
        if not np.isfinite(length) or bound == length or length < 1e-9:
            continue
        for k in range(3):
            parent = X[p, k] if update[p] else pos[r, p, k]
            moved = parent + (X[c, k] - parent) * (bound / length)
            samples[c, k] += moved - X[c, k]
            X[c, k] = moved


@jit
def _distance(pos, r, a, e):
    """|pos[r, a] - pos[r, e]|, NaN when either joint is unknown."""
    sq = 0.0
    for k in range(3):
        sq += (pos[r, a, k] - pos[r, e, k]) * (pos[r, a, k] - pos[r, e, k])
    return np.sqrt(sq)


@jit
def _fit_velocities(hist_pos, hist_s, r, update, stamp_s, window_s, max_speed, quadratic, vel):
    """vel[r, j] of each updated joint j = slope of the linear least-squares fit of position on time over the
    history samples of the joint's last `window_s[j]`, clipped to `max_speed` (eq. 5's V); with `quadratic` (beyond the
    paper) the slope at the newest time of the least-squares fit x = a + b u + c u² (the joint's acceleration
    in the window: the linear slope is the velocity of the window's middle, half a window late), the linear
    slope where that fit is not determined (fewer than 3 samples, a singular system).

    One pass over the joint's history accumulates the count, the first and last sample time and the sums of
    u, u², u³, u⁴, x, u x, u² x with u = t_i - t (times relative to now keep the sums well conditioned).
    """
    H, J = hist_s.shape[1], hist_s.shape[2]
    for j in range(J):
        if not update[j]:
            continue
        n = su = suu = suuu = suuuu = sx0 = sx1 = sx2 = sux0 = sux1 = sux2 = suux0 = suux1 = suux2 = 0.0
        first, last = np.inf, -np.inf
        for h in range(H):
            s = hist_s[r, h, j]
            if stamp_s - s <= window_s[j]:  # False for empty slots (NaN)
                u = s - stamp_s
                x0, x1, x2 = hist_pos[r, h, j, 0], hist_pos[r, h, j, 1], hist_pos[r, h, j, 2]
                n += 1.0
                su += u
                suu += u * u
                sx0 += x0
                sx1 += x1
                sx2 += x2
                sux0 += u * x0
                sux1 += u * x1
                sux2 += u * x2
                if quadratic:
                    suuu += u * u * u
                    suuuu += u * u * u * u
                    suux0 += u * u * x0
                    suux1 += u * u * x1
                    suux2 += u * u * x2
                first, last = min(first, s), max(last, s)
        sxx = suu - su * su / max(n, 1.0)  # Σ (u - ū)²
        v0 = v1 = v2 = 0.0
        if n >= 2 and last - first >= MIN_VELOCITY_SPAN_S and sxx > 0.0:
            # Σ (u - ū)(x - x̄) = Σ u x - ū Σ x
            v0 = (sux0 - su / n * sx0) / sxx
            v1 = (sux1 - su / n * sx1) / sxx
            v2 = (sux2 - su / n * sx2) / sxx
            if quadratic and n >= 3:
                # Normal equations [n su suu; su suu suuu; suu suuu suuuu] (a, b, c) = (Σx, Σux, Σu²x): b by
                # Cramer's rule, where the determinant is clear of the rounding of its terms.
                det = (n * (suu * suuuu - suuu * suuu) - su * (su * suuuu - suuu * suu)
                       + suu * (su * suuu - suu * suu))
                if abs(det) > 1e-9 * n * suu * suuuu:
                    c0, c1 = n * suuuu - suu * suu, su * suuuu - suuu * suu
                    c2 = n * suuu - su * suu
                    v0 = (c0 * sux0 - c1 * sx0 - c2 * suux0) / det
                    v1 = (c0 * sux1 - c1 * sx1 - c2 * suux1) / det
                    v2 = (c0 * sux2 - c1 * sx2 - c2 * suux2) / det
        speed = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        scale = max_speed / max(speed, 1e-12) if speed > max_speed else 1.0
        vel[r, j, 0], vel[r, j, 1], vel[r, j, 2] = v0 * scale, v1 * scale, v2 * scale


@jit
def _carry_stale(pos, vel, joint_s, seen_s, r, stamp_s, stale_after_s, max_predict_s, values):
    """Moves the known joints of target r not seen for `stale_after_s` with the median velocity of its fresh
    joints (zero without any), over the time since their last estimate (at most `max_predict_s`)."""
    J = pos.shape[1]
    any_stale = False
    for j in range(J):
        if not stamp_s - seen_s[r, j] <= stale_after_s and np.isfinite(pos[r, j, 0]):
            any_stale = True
    if not any_stale:
        return
    body = np.zeros(3)
    for k in range(3):
        n = 0
        for j in range(J):
            if stamp_s - seen_s[r, j] <= stale_after_s and not np.isnan(vel[r, j, k]):
                values[n] = vel[r, j, k]
                n += 1
        if n:
            sort_prefix(values, n)
            body[k] = (values[(n - 1) // 2] + values[n // 2]) / 2.0
    for j in range(J):
        if not stamp_s - seen_s[r, j] <= stale_after_s and np.isfinite(pos[r, j, 0]):
            dt = min(max(stamp_s - joint_s[r, j], 0.0), max_predict_s)
            for k in range(3):
                pos[r, j, k] = pos[r, j, k] + body[k] * dt
                vel[r, j, k] = body[k]
            joint_s[r, j] = stamp_s


@jit
def split_detections(usable, min_joints, rows, cols, ids):
    """Where the frame's detections went: (D,) id of each one's matched target (-1: none), and the indices of
    the unmatched ones with at least `min_joints` usable joints (the candidates for initialisation).

    Args:
        usable: (D,) usable joints per detection; rows, cols: (M,) matched targets and detections; ids: (T,).
    """
    assigned = np.full(usable.size, -1, dtype=np.int64)
    for m in range(rows.size):
        assigned[cols[m]] = ids[rows[m]]
    unmatched = np.empty(usable.size, dtype=np.int64)
    n = 0
    for d in range(usable.size):
        if assigned[d] < 0 and usable[d] >= min_joints:
            unmatched[n] = d
            n += 1
    return assigned, unmatched[:n].copy()


@jit
def output_poses(state, code, ids, pos, vel, joint_s, seen_s, stamp_s, max_predict_s, stale_after_s, model, bones):
    """The frame's output: the ids (K,) of the targets in lifecycle state `code`, their poses (K, J, 3) predicted
    to stamp_s by eq. (5), X_t' + V_t' (t - t'), the horizon clipped to [0, max_predict_s], with the joints never
    triangulated filled from the target's own body (`body.fill_poses`, model and bones), and their (K, J)
    `JointState` codes (`body.joint_states`, stale after `stale_after_s`); the arrays as in `TargetRows`.

    (Twelve arguments, the target arrays among them one by one: a NamedTuple argument costs numba's dispatch
    microseconds per call, and this runs for every frame.)"""
    rows = np.flatnonzero(state == code)
    J = pos.shape[1]
    out = np.empty((rows.size, J, 3))
    known = np.empty((rows.size, J), dtype=np.bool_)
    seen = np.empty((rows.size, J))
    for i in range(rows.size):
        r = rows[i]
        for j in range(J):
            horizon = min(max(stamp_s - joint_s[r, j], 0.0), max_predict_s)
            for k in range(3):
                out[i, j, k] = pos[r, j, k] + vel[r, j, k] * horizon
            known[i, j] = np.isfinite(out[i, j, 0])
            seen[i, j] = seen_s[r, j]
    codes = joint_states(seen, known, stamp_s, stale_after_s)
    fill_poses(out, model, bones)
    return ids[rows], out, codes


@jit
def has_body(pos, rows, hips, min_joints):
    """(M,) whether each target of rows has both hips and at least `min_joints` joints triangulated (pos NaN
    where not): the body a confirmation needs (`Tracker._has_body`)."""
    out = np.empty(rows.size, dtype=np.bool_)
    for m in range(rows.size):
        r = rows[m]
        count = 0
        for j in range(pos.shape[1]):
            if np.isfinite(pos[r, j, 0]):
                count += 1
        ok = count >= min_joints
        for h in range(hips.size):
            ok = ok and np.isfinite(pos[r, hips[h], 0])
        out[m] = ok
    return out


@jit
def implausible_bodies(rows, cols, det_px, P, pos, seen_s, stamp_s, bones, limits, out):
    """out[m] = whether matched target rows[m]'s observed body (pos (T, J, 3), seen_s (T, J) of `TargetRows`)
    is implausible (see `Tracker._record_evidence`) by the `BodyLimits` limits: more than `share` of its
    observed joints (triangulated within `stale_after_s`) outside [min_bottom_m, max_top_m] or of its observed
    bones (B, 2) longer than `max_bone_m`, or a median reprojection error (through P (3, 4), against detection
    cols[m] of det_px (D, J, 2)) above `max_reprojection_px`."""
    stale_after_s, share = limits.stale_after_s, limits.share
    J, B = pos.shape[1], bones.shape[0]
    observed = np.empty(J, dtype=np.bool_)
    errors = np.empty(J)
    for m in range(rows.size):
        r, d = rows[m], cols[m]
        count = off = n = 0
        for j in range(J):
            observed[j] = stamp_s - seen_s[r, j] <= stale_after_s and np.isfinite(pos[r, j, 0])
            if not observed[j]:
                continue
            count += 1
            z = pos[r, j, 2]
            if z < limits.min_bottom_m or z > limits.max_top_m:
                off += 1
            h0 = P[0, 0] * pos[r, j, 0] + P[0, 1] * pos[r, j, 1] + P[0, 2] * pos[r, j, 2] + P[0, 3]
            h1 = P[1, 0] * pos[r, j, 0] + P[1, 1] * pos[r, j, 1] + P[1, 2] * pos[r, j, 2] + P[1, 3]
            h2 = P[2, 0] * pos[r, j, 0] + P[2, 1] * pos[r, j, 1] + P[2, 2] * pos[r, j, 2] + P[2, 3]
            e = np.sqrt((h0 / h2 - det_px[d, j, 0]) ** 2 + (h1 / h2 - det_px[d, j, 1]) ** 2)
            if not np.isnan(e):
                errors[n] = e
                n += 1
        both = long = 0
        for b in range(B):
            a, e = bones[b, 0], bones[b, 1]
            if observed[a] and observed[e]:
                both += 1
                if _distance(pos, r, a, e) > limits.max_bone_m:
                    long += 1
        bad = off > share * max(count, 1) or long > share * max(both, 1)
        if n:
            sort_prefix(errors, n)
            bad = bad or (errors[(n - 1) // 2] + errors[n // 2]) / 2.0 > limits.max_reprojection_px
        out[m] = bad
