"""`score --map`'s picture draws the score JSON's floor grid and time line where they belong."""

import numpy as np

from core.records import Box, BoxKind
from crossview.pictures.score_map import score_map_figure, score_map_png

SCORE = {
    "floor_grid": {"origin_m": [0.0, 0.0], "cell_m": 1.0, "shape": [2, 3],
                   "truth": [[10, 0, 4], [0, 0, 8]], "misses": [[5, 0, 0], [0, 0, 8]],
                   "false_positives": [[0, 3, 0], [0, 0, 0]], "id_switches": [[0, 0, 1], [0, 0, 0]]},
    "timeline": {"start_s": 2.0, "bin_s": 1.0, "bins": 3,
                 "people": {"1": {"matched": [10, 5, 0], "missed": [0, 5, 10], "pcp": [1.0, 0.5, 0.0],
                                  "switches": []},
                            "7": {"matched": [0, 10, 10], "missed": [0, 0, 0], "pcp": [None, 1.0, 0.9],
                                  "switches": [{"t_s": 3.5, "target_id": 2, "x_m": 2.5, "y_m": 0.5}]}}},
    "id_switch_events": [{"t_s": 3.5, "person_id": 7, "target_id": 2, "x_m": 2.5, "y_m": 0.5}],
}


def test_the_maps_hold_the_grids_and_the_time_line_the_missed_shares():
    figure = score_map_figure(SCORE, [Box(BoxKind.SHELF, (1.5, 1.0, 0.8), (1.0, 0.4, 1.6))], "t")
    missed, fps, switches, timeline = figure.axes[0], figure.axes[1], figure.axes[2], figure.axes[-1]
    # Missed share per cell, NaN where nobody was; rows along y from the origin (drawn with origin "lower").
    share = np.ma.filled(missed.images[0].get_array().astype(float), np.nan)
    np.testing.assert_array_equal(share, [[0.5, np.nan, 0.0], [np.nan, np.nan, 1.0]])
    assert missed.images[0].get_extent() == [0.0, 3.0, 0.0, 2.0]  # m
    assert fps.images[0].get_array()[0, 1] == 3 and switches.images[0].get_array()[0, 2] == 1
    line = np.ma.filled(timeline.images[0].get_array().astype(float), np.nan)
    np.testing.assert_array_equal(line, [[0.0, 0.5, 1.0], [np.nan, 0.0, 0.0]])
    assert [t.get_text() for t in timeline.get_yticklabels()] == ["person 1", "person 7"]
    assert score_map_png(SCORE)[:4] == b"\x89PNG"
