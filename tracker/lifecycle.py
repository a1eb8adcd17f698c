"""Target lifecycle: tentative -> confirmed <-> lost -> removed, timed in seconds. Every transition is here.

States are held as small integer codes in the tracker's arrays; `to_state` maps them to `TargetState`.
- born TENTATIVE (from an initialisation cluster);
- TENTATIVE -> CONFIRMED once it has `confirm_min_updates` matched detections, `confirm_min_age_s` of age and
  a body: its root (both hips) and `init_min_joints_3d` joints triangulated (so no output is a partial body
  whose missing joints would be guessed from a few);
- TENTATIVE -> REMOVED when not updated for `tentative_timeout_s`;
- CONFIRMED -> LOST when not updated for `lost_after_s` (lost targets are still matched, not output);
- LOST -> CONFIRMED when matched again;
- LOST -> REMOVED when not updated for `remove_after_s`. Removed targets are deleted; ids are never reused;
- any state -> REMOVED when the cameras' evidence says it is a ghost (`ghost`, from the tracker: matched in
  fewer than `ghost_min_seen_ratio` of the frames of cameras that should see it, or an observed body that
  stayed implausible for `implausible_after_s`).
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


def on_time(state: np.ndarray, last_update_s: np.ndarray, now_s: float, config: TrackerConfig,
            ghost: np.ndarray | None = None) -> np.ndarray:
    """Transitions caused by time passing (no match): returns the new (T,) state codes.

    Args:
        state: (T,) codes; last_update_s: (T,) time of each target's last matched detection, s; now_s: s.
        ghost: (T,) whether the cameras' evidence marks the target a ghost; None: none is.
    """
    idle = now_s - last_update_s
    new = state.copy()
    if ghost is not None:
        new[ghost] = REMOVED
    new[(state == TENTATIVE) & (idle > config.tentative_timeout_s)] = REMOVED
    new[(state == CONFIRMED) & (idle > config.lost_after_s)] = LOST
    new[(new == LOST) & (idle > config.remove_after_s)] = REMOVED
    return new


def on_match(
    state: np.ndarray, born_s: np.ndarray, num_updates: np.ndarray, now_s: float, config: TrackerConfig,
    has_body: np.ndarray | None = None,
) -> np.ndarray:
    """Transitions caused by a matched detection: returns the new (M,) state codes of the matched targets.

    Args:
        state, born_s, num_updates: (M,) codes, birth times (s) and matched-detection counts (after this match).
        has_body: (M,) whether each has its hips and enough joints triangulated; None: all have.
    """
    new = state.copy()
    ready = (num_updates >= config.confirm_min_updates) & (now_s - born_s >= config.confirm_min_age_s)
    if has_body is not None:
        ready &= has_body
    new[(state == TENTATIVE) & ready] = CONFIRMED
    new[state == LOST] = CONFIRMED
    return new
