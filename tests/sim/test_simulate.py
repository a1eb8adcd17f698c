"""The simulation driver: one time-ordered stream of truth and delivered frames, reproducible."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from core.records import CameraFrame, PoseTruth
from sim import scenario as scenario_mod
from sim.simulate import Simulation


@pytest.fixture(scope="module")
def small():
    scenario = scenario_mod.load("store_layout1", {"crowd.people": 3, "cameras.rows": 2, "cameras.cols": 2})
    return scenario


def _log_time(event):
    return event.truth.delivery_s if isinstance(event, CameraFrame) else event.t_s


def test_events_come_in_log_time_order_with_truth_at_100_hz(small):
    events = list(Simulation(small, seed=3).events(2.0))
    times = [_log_time(e) for e in events]
    assert times == sorted(times)
    truths = [e for e in events if isinstance(e, PoseTruth)]
    np.testing.assert_allclose([t.t_s for t in truths], np.arange(201) / 100, atol=1e-12)  # s
    frames = [e for e in events if isinstance(e, CameraFrame)]
    # 4 cameras at 10 fps for 2 s, less a few drops.
    assert 70 <= len(frames) <= 80
    for f in frames:
        assert f.truth.delivery_s >= f.truth.capture_s
        assert f.poses_at_capture.t_s == f.truth.capture_s
        assert f.frame.keypoints_px.shape[1:] == (17, 2)
    # Frames of different cameras reach the tracker out of stamp order.
    stamps = [f.frame.stamp_s for f in frames]
    assert stamps != sorted(stamps)


def test_same_seed_same_stream_other_seed_other_stream(small):
    def digest(seed):
        return [(type(e).__name__, _log_time(e), np.nan_to_num(e.frame.keypoints_px).sum() if isinstance(e, CameraFrame)
                 else e.poses.sum()) for e in Simulation(small, seed=seed).events(1.0)]

    assert digest(5) == digest(5)
    assert digest(5) != digest(6)


def test_frames_without_poses_are_the_same_frames(small):
    """`with_poses=False` (what a recording writer asks for) changes nothing but leaving the poses out."""
    sim = Simulation(small, seed=2)
    full = [e for e in sim.events(0.6) if isinstance(e, CameraFrame)]
    bare = [e for e in sim.events(0.6, with_poses=False) if isinstance(e, CameraFrame)]
    assert all(f.poses_at_capture is None for f in bare) and len(bare) == len(full) > 0
    assert [f.frame.keypoints_px.tobytes() for f in bare] == [f.frame.keypoints_px.tobytes() for f in full]


def test_a_second_pass_replays_the_same_events(small):
    sim = Simulation(small, seed=1)
    first = [_log_time(e) for e in sim.events(0.5)]
    assert [_log_time(e) for e in sim.events(0.5)] == first


def test_frames_project_the_poses_at_capture(small):
    from core.projection import in_image

    sim = Simulation(dataclasses.replace(small, detector=dataclasses.replace(small.detector, profile=type(
        small.detector.profile).IDEAL)), seed=2)
    names = {c.name: c for c in sim.cameras}
    checked = 0
    for event in sim.events(1.0):
        if isinstance(event, CameraFrame) and event.truth.person_ids.size:
            truth = event.truth
            poses = event.poses_at_capture
            for row, pid in enumerate(truth.person_ids):
                px, _ = in_image(names[event.frame.camera], poses.poses[list(poses.person_ids).index(pid)])
                ok = truth.in_image[row]
                np.testing.assert_allclose(event.frame.keypoints_px[row][ok], px[ok], atol=1e-9)  # px
                checked += 1
    assert checked > 10


def _fingerprint(event):
    if isinstance(event, PoseTruth):
        return ("truth", event.t_s, event.person_ids.tobytes(), event.poses.tobytes())
    f, t = event.frame, event.truth
    return ("frame", f.camera, f.stamp_s, f.keypoints_px.tobytes(), f.scores.tobytes(), t.capture_s, t.delivery_s,
            t.person_ids.tobytes(), t.keypoints_px.tobytes(), t.in_image.tobytes(), t.occluded.tobytes(),
            t.self_occluded.tobytes(), t.effects.tobytes(), event.poses_at_capture.poses.tobytes())


@pytest.mark.parametrize("min_person_frac", [None, 0.35])
def test_a_worker_process_gives_the_same_events_bit_for_bit(small, min_person_frac):
    """Simulating in a forked worker (the default where there are two cores) changes nothing in the stream,
    nor in the detector's visibility counts; also where the person-views too small to detect stay in the
    worker (a bound of 0.35 of the image height leaves out some of these people, not all)."""
    scenario = small
    if min_person_frac is not None:
        scenario = dataclasses.replace(small, detector=dataclasses.replace(small.detector,
                                                                           min_person_frac=min_person_frac))
    here = Simulation(scenario, seed=4, worker_process=False)
    there = Simulation(scenario, seed=4, worker_process=True)
    events = [_fingerprint(e) for e in here.events(1.5)]
    assert events == [_fingerprint(e) for e in there.events(1.5)]
    assert here.detector.visibility_counts.tolist() == there.detector.visibility_counts.tolist()
    assert here.detector.visibility_counts.sum() > 0
    if min_person_frac is not None:
        detections = sum(e.truth.person_ids.size for e in Simulation(scenario, seed=4).events(1.5)
                         if isinstance(e, CameraFrame))
        unbounded = sum(e.truth.person_ids.size for e in Simulation(small, seed=4).events(1.5)
                        if isinstance(e, CameraFrame))
        assert 0 < detections < unbounded


def test_the_worker_process_never_outlives_the_stream(small, monkeypatch):
    import multiprocessing

    from sim.sensing.detector import Detector

    # A consumer that stops early (or is interrupted) leaves no worker behind.
    events = Simulation(small, seed=4).events(5.0)
    next(events)
    with pytest.raises(KeyboardInterrupt):
        for i, _ in enumerate(events):
            if i == 20:
                raise KeyboardInterrupt
    events.close()
    assert multiprocessing.active_children() == []
    # A failure in the worker is raised here, as what it was, and the worker is gone.
    def broken(self, *args):
        raise ArithmeticError("detector broke")

    monkeypatch.setattr(Detector, "block_visibility", broken)  # (the worker's part: projection and rays)
    with pytest.raises(ArithmeticError, match="detector broke") as failure:
        list(Simulation(small, seed=4).events(1.0))
    assert any("raised in the simulation worker process" in note for note in failure.value.__notes__)
    assert multiprocessing.active_children() == []


def test_a_consumer_failure_mid_pass_stops_the_worker_at_once(small):
    """An error raised while the consumer handles a block (inside the pass's `with`, as `generate` and
    `events` hold it) stops the worker then and there, even while the caller keeps the traceback (as a
    long-lived process, or pytest, does): nothing is left for a garbage collection to stop later, in whatever
    process."""
    import multiprocessing

    kept = []
    for seed in range(3):  # (again and again in one process, each failure kept)
        with pytest.raises(ArithmeticError, match="consumer broke") as failure:
            with Simulation(small, seed=seed).blocks(5.0, with_poses=False) as blocks:
                for i, _ in enumerate(blocks):
                    if i == 2:
                        raise ArithmeticError("consumer broke")
        kept.append(failure)
        assert multiprocessing.active_children() == []


def test_a_pass_starts_on_entering_and_is_iterated_once(small):
    """Entered, a pass has its worker simulating before the first block is asked for (where there is one:
    two cores and fork), so that the consumer can get ready meanwhile; a pass is iterated once."""
    import multiprocessing

    from core import processes

    sim = Simulation(small, seed=1)
    with sim.blocks(0.5) as blocks:
        assert len(multiprocessing.active_children()) == int(processes.can_fork_worker())
        first = list(blocks)
        with pytest.raises(RuntimeError, match="iterated once"):
            iter(blocks)
    assert multiprocessing.active_children() == []
    # Another pass replays the same blocks.
    again = list(sim.blocks(0.5))
    assert [(b.t, [r.delivery_s for r in b.requests]) for b in again] == [
        (b.t, [r.delivery_s for r in b.requests]) for b in first]


def test_blocks_cover_time_in_order_and_events_are_their_contents_in_log_time_order(small):
    """Each block holds the truth ticks after the previous block's time up to its own, and the captures
    taken in that stretch, delivered after their capture; `events` gives exactly the blocks' truths and
    frames, sorted by log time, then truth before frames, then camera index, then capture time (a sort of
    everything at once: the reference for the streaming merge)."""
    blocks = list(Simulation(small, seed=6, worker_process=False).blocks(2.0))
    previous_t = -1.0
    for block in blocks:
        assert all(previous_t < p.t_s <= block.t for p in block.truths)
        assert all(previous_t < r.capture_s <= block.t and r.delivery_s >= r.capture_s for r in block.requests)
        assert len(block.bounds) == len(block.requests) + 1
        previous_t = block.t
    assert blocks[-1].t == pytest.approx(2.0)
    keys = [(p.t_s, 0, -1, p.t_s) for b in blocks for p in b.truths]
    keys += [(r.delivery_s, 1, r.camera, r.capture_s) for b in blocks for r in b.requests]
    sim = Simulation(small, seed=6, worker_process=False)
    index = {c.name: i for i, c in enumerate(sim.cameras)}
    assert [(e.t_s, 0, -1, e.t_s) if isinstance(e, PoseTruth) else
            (e.truth.delivery_s, 1, index[e.frame.camera], e.truth.capture_s) for e in sim.events(2.0)] == sorted(keys)
