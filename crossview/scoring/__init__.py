"""Scoring: pose accuracy, ground-plane identity metrics, HOTA and association accuracy in one run.

`score` (`orchestrate.py`) compares tracker outputs with the simulator's ground truth (`truth.py`:
`TruthTimeline`) on a regular evaluation grid, each metric from its own module's accumulator (`pose`,
`identity`, `hota`, `association`, `per_camera`) into one `ScoreReport` (`report`); `orchestrate`'s docstring
and docs/metrics.md define the grid, the scored area and the warm-up. `campus` is the Campus/Shelf protocol.
The names below are the package's interface.
"""

from core.tracks import OUTPUT_MAX_AGE_S
from crossview.scoring.orchestrate import (
    FLOOR_CELL_M,
    TIMELINE_BIN_S,
    WARM_UP_S,
    ScoringError,
    default_from_s,
    grid_ticks,
    score,
    scored_grid,
)
from crossview.scoring.report import JSON_KEYS, ScoreReport
from crossview.scoring.truth import TruthTimeline

__all__ = ["FLOOR_CELL_M", "JSON_KEYS", "OUTPUT_MAX_AGE_S", "ScoreReport", "ScoringError", "TIMELINE_BIN_S",
           "TruthTimeline", "WARM_UP_S", "default_from_s", "grid_ticks", "score", "scored_grid"]
