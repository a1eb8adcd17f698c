"""Camera clocks: rates, phases, jitter, stamp offsets, drops and delays follow their configuration."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np
import pytest
from scipy import stats

from sim.clock import ClockConfig, Schedule
from sim.clock import schedule as schedule_columns


class _Capture(NamedTuple):
    camera_index: int
    frame_index: int
    capture_s: float
    stamp_s: float
    delivery_s: float


def schedule(*args) -> list[_Capture]:
    """The schedule's frames one by one, in its order."""
    return [_Capture(*row) for row in zip(*(column.tolist() for column in schedule_columns(*args)))]


def _by_camera(captures, n):
    return [[c for c in captures if c.camera_index == i] for i in range(n)]


def test_ideal_clock_ticks_at_the_nominal_rate_from_a_phase_within_one_period():
    config = ClockConfig(fps=10.0, jitter_std_s=0, offset_std_s=0, stamp_noise_std_s=0, drop_prob=0, burst_prob=0,
                         delay_mean_s=0.04, delay_std_s=0)
    captures = schedule(["a", "b", "c"], config, 10.0, np.random.default_rng(1))
    for cam in _by_camera(captures, 3):
        t = np.array([c.capture_s for c in cam])
        assert 0 <= t[0] < 0.1 and len(t) == 100
        np.testing.assert_allclose(np.diff(t), 0.1, atol=1e-12)  # s
        np.testing.assert_allclose([c.stamp_s for c in cam], t, atol=1e-12)  # s
        np.testing.assert_allclose([c.delivery_s - c.capture_s for c in cam], 0.04, atol=1e-12)  # s
    assert [c.capture_s for c in captures] == sorted(c.capture_s for c in captures)


def test_jitter_offset_and_stamp_noise_have_their_configured_spread():
    config = ClockConfig(fps=20.0, jitter_std_s=0.004, offset_std_s=0.01, stamp_noise_std_s=0.001, drop_prob=0,
                         burst_prob=0)
    names = [f"c{i}" for i in range(40)]
    captures = schedule(names, config, 50.0, np.random.default_rng(2))
    jitters, offsets, stamp_noise = [], [], []
    for cam in _by_camera(captures, len(names)):
        t = np.array([c.capture_s for c in cam])
        k = np.array([c.frame_index for c in cam])
        # Jitter: capture time minus the best-fitting nominal tick line.
        phase = np.mean(t - k / config.fps)
        jitters.append(t - k / config.fps - phase)
        d = np.array([c.stamp_s - c.capture_s for c in cam])
        offsets.append(d.mean())
        stamp_noise.append(d - d.mean())
    assert np.std(np.concatenate(jitters)) == pytest.approx(0.004, rel=0.03)
    assert np.std(offsets) == pytest.approx(0.01, rel=0.3)
    assert np.std(np.concatenate(stamp_noise)) == pytest.approx(0.001, rel=0.03)


def test_delays_are_gamma_with_configured_mean_and_std_and_reorder_cameras():
    config = ClockConfig(delay_mean_s=0.05, delay_std_s=0.02, drop_prob=0, burst_prob=0, in_order_delivery=False)
    captures = schedule([f"c{i}" for i in range(12)], config, 60.0, np.random.default_rng(3))
    delays = np.array([c.delivery_s - c.capture_s for c in captures])
    assert delays.min() > 0
    assert delays.mean() == pytest.approx(0.05, rel=0.02)
    assert delays.std() == pytest.approx(0.02, rel=0.05)
    shape = (0.05 / 0.02) ** 2
    assert stats.kstest(delays, stats.gamma(shape, scale=0.02**2 / 0.05).cdf).pvalue > 0.01
    # Delivery order differs from stamp order: frames arrive out of stamp order.
    stamps_in_delivery_order = [c.stamp_s for c in sorted(captures, key=lambda c: c.delivery_s)]
    assert stamps_in_delivery_order != sorted(stamps_in_delivery_order)


def test_in_order_delivery_keeps_each_cameras_frames_in_order_but_not_the_streams():
    # Long-tailed delays: without in-order delivery a camera's own frames overtake each other.
    config = ClockConfig(delay_mean_s=0.1, delay_std_s=0.08, drop_prob=0, burst_prob=0)
    names = [f"c{i}" for i in range(12)]
    loose = schedule(names, dataclasses.replace(config, in_order_delivery=False), 60.0, np.random.default_rng(8))
    fifo = schedule(names, config, 60.0, np.random.default_rng(8))

    def overtaken(captures):
        return sum(
            int(np.any(np.diff([c.capture_s for c in sorted(cam, key=lambda c: c.delivery_s)]) < 0))
            for cam in _by_camera(captures, 12)
        )

    assert overtaken(loose) > 0
    assert overtaken(fifo) == 0
    # A frame is never delivered before its own delay has passed, and the streams still interleave.
    assert all(f.delivery_s >= g.delivery_s for f, g in zip(fifo, loose))
    stamps_in_delivery_order = [c.stamp_s for c in sorted(fifo, key=lambda c: c.delivery_s)]
    assert stamps_in_delivery_order != sorted(stamps_in_delivery_order)


def test_independent_drops_happen_at_the_configured_rate():
    config = ClockConfig(drop_prob=0.1, burst_prob=0)
    captures = schedule([f"c{i}" for i in range(10)], config, 100.0, np.random.default_rng(4))
    kept = len(captures) / (10 * 1000)
    assert kept == pytest.approx(0.9, abs=0.01)


def test_burst_drops_remove_runs_of_geometric_length():
    config = ClockConfig(drop_prob=0, burst_prob=0.01, burst_mean_frames=8.0)
    captures = schedule([f"c{i}" for i in range(10)], config, 200.0, np.random.default_rng(5))
    gaps = []
    for cam in _by_camera(captures, 10):
        k = np.array([c.frame_index for c in cam])
        gaps.extend(np.diff(k)[np.diff(k) > 1] - 1)
    gaps = np.array(gaps)
    # Bursts start on 1 % of frames and last 8 frames on average (overlaps merge a few).
    assert gaps.mean() == pytest.approx(8.0, rel=0.15)
    expected_dropped = 1 - (1 - 0.01) ** 8
    assert 1 - len(captures) / (10 * 2000) == pytest.approx(expected_dropped, rel=0.15)


def test_adding_a_camera_does_not_change_the_others_clocks():
    config = ClockConfig()
    a = schedule(["a", "b"], config, 5.0, np.random.default_rng(9))
    b = schedule(["a", "b", "c"], config, 5.0, np.random.default_rng(9))
    assert [c for c in a] == [c for c in b if c.camera_index < 2]


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [({"fps": -10.0}, "fps"), ({"fps": 0.0}, "fps"), ({"drop_prob": 1.5}, "drop_prob"),
     ({"burst_prob": -0.1}, "burst_prob"), ({"jitter_std_s": 0.2}, "jitter_std_s"),
     ({"delay_std_s": -1.0}, "delay_std_s"), ({"burst_mean_frames": 0.5}, "burst_mean_frames")],
)
def test_bad_clock_values_name_the_key(kwargs, key):
    with pytest.raises(ValueError, match=key):
        ClockConfig(**kwargs)


def test_simultaneous_captures_come_by_camera_index_and_the_columns_say_the_same():
    config = ClockConfig(fps=10.0, random_phase=False, jitter_std_s=0, offset_std_s=0, stamp_noise_std_s=0,
                         drop_prob=0.2, burst_prob=0)
    names = [f"c{i}" for i in range(5)]
    captures = schedule(names, config, 3.0, np.random.default_rng(6))
    # Every camera ticks at the same instants: each instant lists its cameras in index order.
    keys = [(c.capture_s, c.camera_index) for c in captures]
    assert keys == sorted(keys) and len(set(keys)) == len(keys)
    for cam in _by_camera(captures, len(names)):
        assert [c.frame_index for c in cam] == sorted(c.frame_index for c in cam)
    # The columns: indices as int64, times as float64, one per field.
    columns = schedule_columns(names, config, 3.0, np.random.default_rng(6))
    assert isinstance(columns, Schedule) and [column.dtype for column in columns] == [np.int64, np.int64, float,
                                                                                       float, float]
