"""HOTA (Luiten et al., IJCV 2021) with a ground-plane similarity, as in the AI City Challenge MTMC track.

Similarity of a true person and a target is S = max(0, 1 - d / zero_distance) with d the ground-plane
distance of their body roots: TrackEval's `_calculate_euclidean_similarity`, the similarity that the
AI City Challenge multi-camera people tracking evaluates 3D locations with. Its zero distance is an
argument; the default here is TrackEval's own default of 2 m (the MOT15-3D convention), under which the
middle localisation threshold alpha = 0.5 is the 1 m gate of the CLEAR-MOT metrics.

For each alpha in 0.05, 0.10, ..., 0.95:
    matching per instant: Hungarian on the score A_global(g, h) * S(g, h) (A_global: the alignment of the
    two whole trajectories, Luiten et al. eq. 13 computed with soft similarities), pairs kept when S >= alpha;
    DetA = |TP| / (|TP| + |FN| + |FP|);
    AssA = (1/|TP|) sum over TP c of |TPA(c)| / (|TPA(c)| + |FNA(c)| + |FPA(c)|);
    HOTA_alpha = sqrt(DetA * AssA);  LocA = mean S over TP.
HOTA, DetA, AssA and LocA are the means over alpha.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

HOTA_ZERO_DISTANCE_M = 2.0
"""Ground-plane distance at which the HOTA similarity reaches 0, metres."""

ALPHAS = np.arange(1, 20) * 0.05
_EPS = np.finfo(float).eps


@dataclass
class HotaScores:
    """HOTA and its parts, averaged over the 19 localisation thresholds (all 0 when nothing matches).

    Attributes:
        hota, deta, assa, loca: the means over alpha.
        hota_per_alpha: (19,) HOTA at each alpha in `ALPHAS`.
    """

    hota: float
    deta: float
    assa: float
    loca: float
    hota_per_alpha: np.ndarray


def ground_similarity(truth_roots: np.ndarray, target_roots: np.ndarray,
                      zero_distance_m: float = HOTA_ZERO_DISTANCE_M) -> np.ndarray:
    """(G, H) similarity max(0, 1 - d / zero_distance_m) of (x, y) roots; 0 for an unknown (NaN) root."""
    d = np.linalg.norm(truth_roots[:, None, :] - target_roots[None, :, :], axis=-1)
    s = np.maximum(0.0, 1.0 - d / zero_distance_m)
    return np.nan_to_num(s, nan=0.0).reshape(len(truth_roots), len(target_roots))


def hota(truth_ids: list[np.ndarray], target_ids: list[np.ndarray], similarities: list[np.ndarray]) -> HotaScores:
    """HOTA of one sequence.

    Args:
        truth_ids: per instant, (G_t,) int ids of the true persons present.
        target_ids: per instant, (H_t,) int ids of the targets reported.
        similarities: per instant, (G_t, H_t) similarity in [0, 1].

    Returns:
        the scores.
    """
    if not (len(truth_ids) == len(target_ids) == len(similarities)):
        raise ValueError(
            f"hota: {len(truth_ids)} truth, {len(target_ids)} target and {len(similarities)} similarity instants differ"
        )
    # Dense indices for the ids.
    g_keys = np.unique(np.concatenate([np.asarray(x, dtype=np.int64) for x in truth_ids] + [np.zeros(0, np.int64)]))
    h_keys = np.unique(np.concatenate([np.asarray(x, dtype=np.int64) for x in target_ids] + [np.zeros(0, np.int64)]))
    gt = [np.searchsorted(g_keys, np.asarray(x, dtype=np.int64)) for x in truth_ids]
    tr = [np.searchsorted(h_keys, np.asarray(x, dtype=np.int64)) for x in target_ids]
    n_alpha = len(ALPHAS)
    num_gt_dets = sum(len(x) for x in gt)
    num_tr_dets = sum(len(x) for x in tr)
    zeros = HotaScores(0.0, 0.0, 0.0, 1.0 if num_gt_dets + num_tr_dets else 0.0, np.zeros(n_alpha))
    if num_gt_dets == 0 or num_tr_dets == 0:
        return zeros

    # Global alignment of whole trajectories from soft (IoU-normalised) similarities.
    potential = np.zeros((len(g_keys), len(h_keys)))
    gt_count = np.zeros(len(g_keys))
    tr_count = np.zeros(len(h_keys))
    for g, h, s in zip(gt, tr, similarities, strict=True):
        s = np.asarray(s, dtype=np.float64).reshape(len(g), len(h))
        denom = s.sum(axis=0)[None, :] + s.sum(axis=1)[:, None] - s
        soft = np.divide(s, denom, out=np.zeros_like(s), where=denom > _EPS)
        potential[g[:, None], h[None, :]] += soft
        gt_count[g] += 1
        tr_count[h] += 1
    global_alignment = potential / (gt_count[:, None] + tr_count[None, :] - potential)

    tp = np.zeros(n_alpha)
    loc = np.zeros(n_alpha)
    match_counts = np.zeros((n_alpha, len(g_keys), len(h_keys)))
    for g, h, s in zip(gt, tr, similarities, strict=True):
        if len(g) == 0 or len(h) == 0:
            continue
        s = np.asarray(s, dtype=np.float64).reshape(len(g), len(h))
        rows, cols = linear_sum_assignment(-(global_alignment[g[:, None], h[None, :]] * s))
        for a, alpha in enumerate(ALPHAS):
            keep = s[rows, cols] >= alpha - _EPS
            r, c = rows[keep], cols[keep]
            tp[a] += len(r)
            loc[a] += s[r, c].sum()
            match_counts[a, g[r], h[c]] += 1
    fn = num_gt_dets - tp
    fp = num_tr_dets - tp
    assa = np.zeros(n_alpha)
    for a in range(n_alpha):
        m = match_counts[a]
        ass = m / np.maximum(1.0, gt_count[:, None] + tr_count[None, :] - m)
        assa[a] = (m * ass).sum() / max(1.0, tp[a])
    deta = tp / np.maximum(1.0, tp + fn + fp)
    per_alpha = np.sqrt(deta * assa)
    loca = np.maximum(1e-10, loc) / np.maximum(1e-10, tp)
    return HotaScores(float(per_alpha.mean()), float(deta.mean()), float(assa.mean()), float(loca.mean()), per_alpha)
