"""HOTA with a ground-plane similarity: hand-computed cases and the TrackEval reference."""

import numpy as np
import pytest
from trackeval.metrics import HOTA as TrackEvalHOTA

from crossview.scoring.hota import ALPHAS, ground_similarity, hota


def _run(frames, zero_distance_m=2.0):
    """frames: list of (truth ids, truth xy (G, 2), target ids, target xy (H, 2))."""
    g = [np.asarray(f[0], dtype=np.int64) for f in frames]
    h = [np.asarray(f[2], dtype=np.int64) for f in frames]
    s = [ground_similarity(np.reshape(f[1], (-1, 2)), np.reshape(f[3], (-1, 2)), zero_distance_m) for f in frames]
    return hota(g, h, s)


def test_perfect_tracking_scores_one():
    frames = [([1, 2], [(0, 0), (5, 0)], [7, 8], [(0, 0), (5, 0)])] * 4
    r = _run(frames)
    assert (r.hota, r.deta, r.assa, r.loca) == (pytest.approx(1.0), pytest.approx(1.0), pytest.approx(1.0), 1.0)


def test_trajectory_split_in_two_halves_association():
    # One person for 4 instants, target 7 for the first two, target 8 for the last two, exact positions.
    frames = [([1], [(0, 0)], [7], [(0, 0)])] * 2 + [([1], [(0, 0)], [8], [(0, 0)])] * 2
    r = _run(frames)
    # Every TP c: TPA = 2, FNA = 2, FPA = 0 -> A(c) = 1/2 at every alpha; DetA = 1.
    assert r.deta == pytest.approx(1.0)
    assert r.assa == pytest.approx(0.5)
    assert r.hota == pytest.approx(np.sqrt(0.5))


def test_localisation_error_fails_the_strict_thresholds():
    # 0.5 m off with a 2 m zero distance: S = 0.75, a match for alpha <= 0.75 (15 of 19 thresholds).
    frames = [([1], [(0, 0)], [7], [(0.5, 0)])] * 3
    r = _run(frames)
    assert np.count_nonzero(r.hota_per_alpha) == 15
    assert r.hota == pytest.approx(15 / 19)
    # LocA is 0.75 where something matched and, by TrackEval's convention, 1 where nothing did.
    assert r.loca == pytest.approx((15 * 0.75 + 4 * 1.0) / 19)


def test_false_positive_and_miss_by_hand():
    # Instant 0: person 1 with target 7 exact plus a far false positive 9; instant 1: person 1 missed.
    frames = [([1], [(0, 0)], [7, 9], [(0, 0), (10, 10)]), ([1], [(0, 0)], [], np.zeros((0, 2)))]
    r = _run(frames)
    # TP 1, FN 1, FP 1: DetA = 1/3. The one TP: TPA 1, FNA 1 (instant 1), FPA 0 -> AssA = 1/2.
    assert r.deta == pytest.approx(1 / 3)
    assert r.assa == pytest.approx(1 / 2)
    assert r.hota == pytest.approx(np.sqrt(1 / 6))


def test_empty_sides_score_zero():
    assert _run([([1], [(0, 0)], [], np.zeros((0, 2)))]).hota == 0.0
    assert _run([([], np.zeros((0, 2)), [3], [(0, 0)])]).hota == 0.0
    assert _run([]).hota == 0.0


def test_random_case_agrees_with_trackeval():
    rng = np.random.default_rng(2024)
    truth_ids, target_ids, sims = [], [], []
    for _ in range(40):
        g = np.flatnonzero(rng.random(5) < 0.8)
        gxy = rng.uniform(0, 4, (5, 2))[g]
        perm = rng.permutation(5)
        ids = perm[g] if rng.random() < 0.3 else g  # now and then the tracks swap identities
        keep = rng.random(len(g)) < 0.9  # some persons missed
        h = ids[keep]
        hxy = gxy[keep] + rng.normal(0, 0.5, (keep.sum(), 2))  # metres of localisation noise
        truth_ids.append(g)
        target_ids.append(h)
        sims.append(ground_similarity(gxy, hxy))
    ours = hota(truth_ids, target_ids, sims)
    data = {
        "num_gt_dets": sum(len(x) for x in truth_ids),
        "num_tracker_dets": sum(len(x) for x in target_ids),
        "num_gt_ids": 5,
        "num_tracker_ids": 5,
        "gt_ids": truth_ids,
        "tracker_ids": target_ids,
        "similarity_scores": sims,
        "num_timesteps": len(sims),
    }
    ref = TrackEvalHOTA({"PRINT_CONFIG": False}).eval_sequence(data)
    np.testing.assert_allclose(ALPHAS, np.arange(0.05, 0.99, 0.05))
    assert 0.2 < ours.hota < 0.95
    np.testing.assert_allclose(ours.hota_per_alpha, ref["HOTA"], atol=1e-12)
    assert ours.hota == pytest.approx(float(np.mean(ref["HOTA"])), abs=1e-12)
    assert ours.deta == pytest.approx(float(np.mean(ref["DetA"])), abs=1e-12)
    assert ours.assa == pytest.approx(float(np.mean(ref["AssA"])), abs=1e-12)
    assert ours.loca == pytest.approx(float(np.mean(ref["LocA"])), abs=1e-12)
