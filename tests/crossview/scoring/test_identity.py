"""Ground-plane identity metrics: a hand-counted story, an independent IDF1, and py-motmetrics itself."""

import motmetrics as mm
import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from crossview.scoring.identity import IdentityAccumulator, IdSwitch, body_roots


def _pose_at(x, y):
    """A COCO-17 pose whose hips straddle (x, y) on the floor."""
    pose = np.zeros((17, 3))
    pose[:, :2] = [x, y]
    pose[11, 0] -= 0.1
    pose[12, 0] += 0.1
    pose[:, 2] = 1.0
    return pose


def _poses(points):
    return np.array([_pose_at(*p) for p in points]).reshape(-1, 17, 3)


def test_body_root_is_hip_midpoint_and_survives_one_missing_hip():
    pose = _pose_at(2.0, 3.0)
    pose[12] = np.nan
    roots = body_roots(np.stack([_pose_at(2.0, 3.0), pose, np.full((17, 3), np.nan)]))
    np.testing.assert_allclose(roots[0], [2.0, 3.0])
    np.testing.assert_allclose(roots[1], [1.9, 3.0])
    assert np.isnan(roots[2]).all()


def test_hand_counted_story():
    acc = IdentityAccumulator(threshold_m=1.0)
    # Frame 0: persons 1 and 2 tracked by targets 10 and 20 (0.1 m and 0.3 m off).
    acc.update([1, 2], _poses([(0, 0), (5, 0)]), [10, 20], _poses([(0.1, 0), (5.3, 0)]))
    # Frame 1: person 2 missed; target 30 is a false positive far from everybody.
    acc.update([1, 2], _poses([(0, 0), (5, 0)]), [10, 30], _poses([(0, 0), (9, 9)]))
    # Frame 2: person 1 now carried by target 20 (switch); person 2 by target 20 is impossible, so 2 missed.
    acc.update([1, 2], _poses([(0, 0), (5, 0)]), [20], _poses([(0.2, 0)]))
    # Frame 3: target 10 is 1.2 m from person 1: beyond the gate, one miss and one false positive.
    acc.update([1], _poses([(0, 0)]), [10], _poses([(1.2, 0)]))
    s = acc.result()
    # Counts: 7 true instants; FN = 1 + 1 + 1 = 3; FP = 1 + 1 = 2; one switch (person 1: 10 -> 20).
    assert (s.num_truth, s.false_negatives, s.false_positives, s.id_switches) == (7, 3, 2, 1)
    assert acc.switches() == [IdSwitch(update=2, person_id=1, target_id=20)]
    assert s.mota == pytest.approx(1 - (3 + 2 + 1) / 7, abs=1e-12)
    # MOTP: distances 0.1, 0.3, 0.0, 0.2 over 4 matches.
    assert s.motp_m == pytest.approx(0.6 / 4, abs=1e-12)
    # IDF1: best one-to-one map 1->10 (frames 0, 1) and 2->20 (frame 0): IDTP = 3; 7 true, 6 predicted.
    assert s.idf1 == pytest.approx(2 * 3 / (7 + 6), abs=1e-12)


def _independent_idf1(frames, threshold_m):
    """IDF1 from its definition (Ristani et al. 2016): best one-to-one trajectory map by hand."""
    gts = sorted({g for f in frames for g in f[0]})
    hyps = sorted({h for f in frames for h in f[2]})
    overlap = np.zeros((len(gts), len(hyps)))
    n_gt = n_hyp = 0
    for g_ids, g_pos, h_ids, h_pos in frames:
        n_gt += len(g_ids)
        n_hyp += len(h_ids)
        for i, g in enumerate(g_ids):
            for j, h in enumerate(h_ids):
                if np.linalg.norm(g_pos[i] - h_pos[j]) <= threshold_m:
                    overlap[gts.index(g), hyps.index(h)] += 1
    rows, cols = linear_sum_assignment(-overlap)
    return 2 * overlap[rows, cols].sum() / (n_gt + n_hyp)


def _independent_clear_mot(frames, threshold_m):
    """MOTA and switches from CLEAR-MOT (Bernardin and Stiefelhagen 2008), written out by hand.

    Per frame: a person keeps the target it last matched (py-motmetrics keeps it across gaps) when that
    target is present and within the threshold; the rest are matched for the most pairs at the least
    total distance; a switch is a person matched to a target other than the one it last matched.
    """
    last = {}
    fn = fp = switches = num_gt = 0
    for g_ids, g_pos, h_ids, h_pos in frames:
        num_gt += len(g_ids)
        d = np.linalg.norm(np.asarray(g_pos)[:, None] - np.asarray(h_pos)[None], axis=-1)
        d = d.reshape(len(g_ids), len(h_ids))
        pairs = {}
        for i, g in enumerate(g_ids):
            h = last.get(g)
            if h in h_ids and h not in pairs.values() and d[i, h_ids.index(h)] <= threshold_m:
                pairs[g] = h
        free_g = [i for i, g in enumerate(g_ids) if g not in pairs]
        free_h = [j for j, h in enumerate(h_ids) if h not in pairs.values()]
        sub = d[np.ix_(free_g, free_h)]
        cost = np.where(sub <= threshold_m, sub, 1e6)  # an infeasible pair costs more than any feasible set
        for r, c in zip(*linear_sum_assignment(cost), strict=True):
            if cost[r, c] < 1e6:
                g, h = g_ids[free_g[r]], h_ids[free_h[c]]
                switches += g in last and last[g] != h
                pairs[g] = h
        last.update(pairs)
        fn += len(g_ids) - len(pairs)
        fp += len(h_ids) - len(pairs)
    return 1 - (fn + fp + switches) / num_gt, switches


def test_random_sequence_agrees_with_motmetrics_and_an_independent_idf1():
    rng = np.random.default_rng(42)
    frames = []
    for _ in range(60):
        g_ids = np.flatnonzero(rng.random(6) < 0.8)
        g_pos = rng.uniform(0, 6, (6, 2))[g_ids]
        # Targets: noisy copies under shuffled ids (switches), some dropped, some false positives.
        perm = rng.permutation(6) + 100
        keep = rng.random(len(g_ids)) < 0.85
        h_ids = list(perm[g_ids][keep]) + list(rng.integers(200, 205, size=rng.integers(0, 2)))
        h_pos = np.vstack(
            [g_pos[keep] + rng.normal(0, 0.4, (keep.sum(), 2)), rng.uniform(0, 6, (len(h_ids) - keep.sum(), 2))]
        )
        h_ids, uniq = np.unique(h_ids, return_index=True)
        frames.append((g_ids.tolist(), g_pos, h_ids.tolist(), h_pos[uniq]))
    ours = IdentityAccumulator(threshold_m=1.0)
    ref = mm.MOTAccumulator(auto_id=True)
    for g_ids, g_pos, h_ids, h_pos in frames:
        ours.update(g_ids, _poses(g_pos), h_ids, _poses(h_pos))
        # Reference: py-motmetrics fed the floor points directly, gate by squared distance.
        ref.update(g_ids, h_ids, np.sqrt(mm.distances.norm2squared_matrix(g_pos, h_pos, max_d2=1.0)))
    s = ours.result()
    r = mm.metrics.create().compute(ref, metrics=["mota", "idf1", "motp", "num_switches"], name="r").loc["r"]
    assert s.mota == pytest.approx(r["mota"], abs=1e-9)
    assert s.idf1 == pytest.approx(r["idf1"], abs=1e-9)
    assert s.motp_m == pytest.approx(r["motp"], abs=1e-9)
    assert s.id_switches == r["num_switches"] > 0
    assert s.idf1 == pytest.approx(_independent_idf1(frames, 1.0), abs=1e-9)
    mota, switches = _independent_clear_mot(frames, 1.0)
    assert s.mota == pytest.approx(mota, abs=1e-9)
    assert s.id_switches == switches


def test_no_targets_at_all_give_mota_zero_and_idf1_zero():
    acc = IdentityAccumulator()
    acc.update([1, 2], _poses([(0, 0), (3, 0)]), [], np.zeros((0, 17, 3)))
    s = acc.result()
    assert (s.mota, s.idf1, s.false_negatives, s.false_positives) == (0.0, 0.0, 2, 0)


def test_target_with_unknown_hips_cannot_match():
    pose = _pose_at(0, 0)
    pose[11:13] = np.nan
    acc = IdentityAccumulator()
    acc.update([1], _poses([(0, 0)]), [10], pose[None])
    s = acc.result()
    assert (s.false_negatives, s.false_positives, s.mota) == (1, 1, -1.0)
