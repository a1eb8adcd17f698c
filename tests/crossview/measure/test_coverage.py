"""`crossview coverage`: cameras per walkable floor cell against a closed-form footprint, the shares, the map, the
warning of generate, and bad input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from core.types import Camera
from crossview.cli import EXIT_BAD_INPUT, main
from crossview.measure.coverage import HEIGHTS_M, WARN_TWO_VIEW_SHARE, coverage
from sim import scenario as scenario_mod
from tests.crossview.test_cli import _run_bad

CEILING_M = 3.0
_DOWN = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])  # camera x = world x, looking down -z


def _room(tmp_path, text: str = "") -> scenario_mod.Scenario:
    path = tmp_path / "room.toml"
    path.write_text("[store]\nwidth_m = 6.0\ndepth_m = 4.0\n[crowd]\npeople = 2\n" + text)
    return scenario_mod.load(path)


def _looking_down(name: str, x_m: float, y_m: float) -> Camera:
    """A pinhole 640 x 480 px camera at the ceiling above (x, y), looking straight down."""
    K = np.array([[400.0, 0.0, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]])
    centre = np.array([x_m, y_m, CEILING_M])
    return Camera(name, K, np.zeros(5), _DOWN, -_DOWN @ centre, 640, 480)


def test_each_cell_is_counted_by_the_cameras_whose_footprint_holds_it(tmp_path):
    cameras = [_looking_down("a", 2.0, 2.0), _looking_down("b", 4.0, 2.0)]
    cov = coverage(_room(tmp_path), cameras)
    for h in cov.heights:
        # A pinhole looking down sees the rectangle |dx| <= (W/2) z / f, |dy| <= (H/2) z / f at depth z
        # (pixel centres at 0 .. W-1, the image's edges half a pixel beyond).
        z = CEILING_M - h.height_m
        expected = np.zeros(len(cov.cells_xy), int)
        for cam in cameras:
            c = cam.center_world
            dx, dy = np.abs(cov.cells_xy[:, 0] - c[0]), np.abs(cov.cells_xy[:, 1] - c[1])
            expected += (dx <= 320.0 * z / 400.0) & (dy <= 240.0 * z / 400.0)
        np.testing.assert_array_equal(h.counts, expected)
        assert 0 < h.share(2) < h.share(1) <= 1.0  # the two footprints overlap in the middle only
    assert [h.height_m for h in cov.heights] == [m for _, m in HEIGHTS_M]
    # Hip height is further from the ceiling than head height: each camera sees more of it.
    assert cov.heights[0].share(1) >= cov.heights[1].share(1)


def test_a_second_camera_in_the_same_place_doubles_every_count(tmp_path):
    room = _room(tmp_path)
    one = coverage(room, [_looking_down("a", 3.0, 2.0)])
    two = coverage(room, [_looking_down("a", 3.0, 2.0), _looking_down("b", 3.0, 2.0)])
    for h1, h2 in zip(one.heights, two.heights):
        np.testing.assert_array_equal(h2.counts, 2 * h1.counts)
        assert h2.share(2) == h1.share(1) and h1.share(2) == 0.0


def test_no_cameras_is_no_coverage_with_the_warning(tmp_path):
    cov = coverage(_room(tmp_path), [])
    assert all(h.share(1) == 0.0 for h in cov.heights)
    assert "only 0 % of the walkable floor is seen by two cameras or more" in cov.warning()
    assert len(cov.lines()) == 3


def test_the_scenario_rig_is_the_one_generate_builds_and_store_layout1_needs_no_warning():
    cov = coverage(scenario_mod.load("store_layout1"))
    assert len(cov.cameras) == 12
    assert cov.two_view_share() >= WARN_TWO_VIEW_SHARE and cov.warning() is None
    assert cov.floor_m2 == pytest.approx(12.8, abs=0.05)  # the walkable floor the crowd is checked against


def test_coverage_command_prints_the_shares_and_writes_both_maps(tmp_path, capsys):
    out = tmp_path / "maps" / "l1.png"
    assert main(["coverage", "store_layout1", "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert "store_layout1: 12 cameras" in captured.out and "head height 1.6 m" in captured.out
    assert captured.err == ""
    image = cv2.imread(str(out))
    assert image is not None and image.shape[1] > 2 * image.shape[0]  # hip and head maps side by side


def test_a_floor_no_camera_sees_is_a_one_line_warning_and_exit_0(tmp_path, capsys):
    # One camera in a corner looking out of the store: nothing of the floor is in its image.
    blind = tmp_path / "blind.toml"
    blind.write_text("[store]\nwidth_m = 4.0\ndepth_m = 4.0\n[crowd]\npeople = 2\n[[cameras.placements]]\n"
                     "position_m = [0.2, 0.2, 2.8]\nlook_at_m = [-5.0, -5.0, 2.0]\n")
    assert main(["coverage", str(blind)]) == 0
    captured = capsys.readouterr()
    assert ">= 1:   0.0 %" in captured.out
    assert len(captured.err.strip().splitlines()) == 1 and "only 0 %" in captured.err
    # generate warns in the same line, and still generates.
    rec = tmp_path / "blind.mcap"
    assert main(["--no-progress", "generate", str(blind), "--duration", "0.2", "-o", str(rec)]) == 0
    assert "only 0 % of the walkable floor" in capsys.readouterr().err and rec.exists()


def test_an_invalid_scenario_is_named_in_one_line_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[store]\nwidth_m = -3\n")
    err = _run_bad(capsys, ["coverage", str(bad), "-o", str(tmp_path / "map.png")])
    assert "bad.toml" in err and "width_m" in err
    assert not (tmp_path / "map.png").exists()
    assert main(["coverage", str(tmp_path / "missing.toml")]) == EXIT_BAD_INPUT
