"""Target lifecycle: tentative -> confirmed <-> lost -> removed, timed in seconds. Every transition is here.

States are held as small integer codes in the tracker's arrays; `to_state` maps them to `TargetState`.
- born TENTATIVE (from an initialisation cluster whose reconstruction has its root, both hips);
- TENTATIVE -> CONFIRMED once it has `confirm_min_updates` matched detections, `confirm_min_age_s` of age and
  a body: its root (both hips) and `init_min_joints_3d` joints triangulated (so no output is a partial body
  whose missing joints would be guessed from a few);
- TENTATIVE -> REMOVED when not updated for `tentative_timeout_s`;
- CONFIRMED -> LOST when not updated for `lost_after_s` (lost targets are still matched, not output);
- LOST -> CONFIRMED when matched again;
- LOST -> REMOVED when not updated for `remove_after_s`. Removed targets are deleted; ids are never reused;
- any state -> REMOVED when the cameras' evidence says it is a ghost (`ghosts`, from the tracker's counts:
  matched in fewer than `ghost_min_seen_ratio` of the frames of cameras that should see it, or an observed
  body that stayed implausible for `implausible_after_s`).

The rules run per target in plain Python loops over the arrays' values as lists (the tracker applies them at
every camera frame; compiled, they made no whole `crossview track` 1.3x faster: docs/benchmarks.md, "Kernel
ledger").
"""

from __future__ import annotations

import numpy as np

from tracker.config import TrackerConfig
from tracker.types import TargetState

TENTATIVE = 0
CONFIRMED = 1
LOST = 2
REMOVED = 3

_STATES = {TENTATIVE: TargetState.TENTATIVE, CONFIRMED: TargetState.CONFIRMED, LOST: TargetState.LOST,
           REMOVED: TargetState.REMOVED}


def to_state(code: int) -> TargetState:
    """The `TargetState` of a state code."""
    return _STATES[int(code)]


def ghosts(expected: np.ndarray, sighted: np.ndarray, state: np.ndarray, implausible_s: np.ndarray, now_s: float,
           config: TrackerConfig) -> np.ndarray:
    """(T,) whether the cameras' evidence marks each target a ghost: at least `ghost_min_expected` sightings
    expected and fewer than `ghost_min_seen_ratio` of them matched (not for a LOST target: it is out of the
    output and goes by the time rule, it may be a person hidden), or an observed body implausible since
    `implausible_after_s` or longer.

    Args:
        expected, sighted: (T,) decayed counts of the frames that should have seen each target and of those that
            matched it; state: (T,) codes; implausible_s: (T,) since when the body is implausible (NaN: it is not).
    """
    now_s, min_expected = float(now_s), float(config.ghost_min_expected)
    min_seen_ratio, implausible_after_s = float(config.ghost_min_seen_ratio), float(config.implausible_after_s)
    return np.array([(e >= min_expected and s < min_seen_ratio * e and code != LOST)
                     or now_s - since >= implausible_after_s  # False for NaN
                     for e, s, code, since in zip(expected.tolist(), sighted.tolist(), state.tolist(),
                                                  implausible_s.tolist())], dtype=np.bool_)


def on_time(state: np.ndarray, last_update_s: np.ndarray, now_s: float, config: TrackerConfig,
            ghost: np.ndarray | None = None) -> np.ndarray:
    """Transitions caused by time passing (no match): returns the new (T,) state codes. A ghost is removed,
    unless the lost rule applies to it first.

    Args:
        state: (T,) codes; last_update_s: (T,) time of each target's last matched detection, s; now_s: s.
        ghost: (T,) whether the cameras' evidence marks the target a ghost (`ghosts`); None: none is.
    """
    now_s, tentative_timeout_s = float(now_s), float(config.tentative_timeout_s)
    lost_after_s, remove_after_s = float(config.lost_after_s), float(config.remove_after_s)
    ghosts = [False] * state.shape[0] if ghost is None else ghost.tolist()
    codes = []
    for old, last_s, is_ghost in zip(state.tolist(), last_update_s.tolist(), ghosts):
        idle = now_s - last_s
        code = REMOVED if is_ghost else old
        if old == TENTATIVE and idle > tentative_timeout_s:
            code = REMOVED
        if old == CONFIRMED and idle > lost_after_s:
            code = LOST
        if code == LOST and idle > remove_after_s:
            code = REMOVED
        codes.append(code)
    return np.array(codes, dtype=state.dtype)


def on_match(
    state: np.ndarray, born_s: np.ndarray, num_updates: np.ndarray, now_s: float, config: TrackerConfig,
    has_body: np.ndarray | None = None,
) -> np.ndarray:
    """Transitions caused by a matched detection: returns the new (M,) state codes of the matched targets.

    Args:
        state, born_s, num_updates: (M,) codes, birth times (s) and matched-detection counts (after this match).
        has_body: (M,) whether each has its hips and enough joints triangulated; None: all have.
    """
    now_s, min_updates, min_age_s = float(now_s), int(config.confirm_min_updates), float(config.confirm_min_age_s)
    bodies = [True] * state.shape[0] if has_body is None else has_body.tolist()
    codes = []
    for old, born, updates, body in zip(state.tolist(), born_s.tolist(), num_updates.tolist(), bodies):
        code = old
        if old == TENTATIVE and updates >= min_updates and now_s - born >= min_age_s and body:
            code = CONFIRMED
        if old == LOST:
            code = CONFIRMED
        codes.append(code)
    return np.array(codes, dtype=state.dtype)
