"""TrackerConfig: validation, presets (Table S2), TOML files."""

import dataclasses

import pytest

from core.errors import ConfigError
from tracker.config import PRESETS, TABLE_S2, RowNorm, TrackerConfig, Triangulation
from tracker.triangulation import PLANE_ROW, UNIT_ROWS, WHOLE_ROW


def test_presets_keep_table_s2_and_the_paper_variants_are_verbatim():
    for name, row in TABLE_S2.items():
        paper = TrackerConfig.preset(f"{name}-paper")
        for key, value in row.items():
            assert getattr(paper, key) == value
        assert paper.triangulation is Triangulation.PAPER and paper.alpha_2d_floor_px == 0.0
        assert paper.row_norm is RowNorm.ROW and TrackerConfig.preset(name).row_norm is RowNorm.PLANE
        assert paper.reid_max_m == 0.0 and paper.reject_factor == 0.0  # the paper: every fresh view counts
        # Eq. (S2)'s epipolar threshold is α2D's number in pixels (Table S2 read per frame), in both presets.
        assert paper.alpha_epipolar_px == TrackerConfig.preset(name).alpha_epipolar_px == row["alpha_2d_px_per_frame"]
        tuned = TrackerConfig.preset(name)
        assert (tuned.alpha_3d_m, tuned.lambda_a_per_s, tuned.lambda_t_per_s) == (
            row["alpha_3d_m"], row["lambda_a_per_s"], row["lambda_t_per_s"])
        assert (tuned.w_2d, tuned.w_3d) == (0.4, 0.6)


def test_the_robust_pass_is_on_where_it_was_measured_to_help():
    # docs/tracker.md, "Robust triangulation": the stores and the Panoptic rig gain; three Campus cameras
    # leave it nothing to drop; there is no Shelf data to measure it on.
    assert TrackerConfig.preset("store").reject_factor == 3.0
    assert TrackerConfig.preset("campus").reject_factor == TrackerConfig.preset("shelf").reject_factor == 0.0


def test_the_paper_presets_keep_every_body_and_joint_prior_off():
    # docs/tracker.md, "Body and joint priors": the -paper presets are the paper's method exactly.
    off = TrackerConfig()
    for name in ("campus-paper", "shelf-paper", "store-paper"):
        paper = TrackerConfig.preset(name)
        for key in ("limb_velocity_window_s", "velocity_quadratic", "joint_gate_m", "bone_prior_tolerance",
                    "bone_symmetry", "head_bones", "bone_prior_resolve"):
            assert getattr(paper, key) == getattr(off, key), (name, key)
    assert off.limb_velocity_window_s == off.joint_gate_m == off.bone_prior_tolerance == 0.0
    assert not (off.velocity_quadratic or off.bone_symmetry or off.head_bones or off.bone_prior_resolve)


def test_unknown_preset_lists_the_valid_ones():
    with pytest.raises(ValueError, match="campus, campus-paper, shelf"):
        TrackerConfig.preset("nope")


@pytest.mark.parametrize("field, value", [
    ("alpha_3d_m", 0.0), ("score_threshold", 1.5), ("min_views", 1), ("velocity_history", 1.5),
    ("lambda_t_per_s", -1.0), ("triangulation", "sideways"), ("row_norm", "diagonal"), ("row_norm", 1),
    ("w_2d", float("nan")), ("reject_factor", -1.0), ("reject_floor_px", 0.0), ("ghost_cell_m", 0.1),
    ("ghost_cell_m", -1.0), ("ghost_map_prior_count", -1.0), ("alpha_2d_px_per_frame", 0.0),
    ("alpha_2d_px_per_frame", -25.0), ("alpha_2d_px_per_frame", float("nan")), ("reject_factor", 0.5),
    ("joint_gate_m", 0.005), ("joint_gate_m", -0.1), ("joint_gate_reset_s", 0.0), ("bone_prior_tolerance", 1.0),
    ("bone_prior_tolerance", -0.1), ("bone_prior_min_views", 1), ("bone_prior_min_samples", 0),
    ("bone_prior_min_samples", 26), ("bone_prior_sample_s", -1.0), ("limb_velocity_window_s", -0.2),
    ("velocity_quadratic", 1), ("bone_symmetry", "yes"), ("head_bones", 0),
    ("bone_prior_resolve", "on"),
])
def test_out_of_range_values_name_the_field(field, value):
    with pytest.raises(ConfigError, match=field):
        TrackerConfig(**{field: value})


def test_every_bad_value_of_every_field_is_a_config_error():
    """One class for every bad value, raised where it is checked: text, null or a list in any field is a
    ConfigError naming the field (score_threshold and ghost_min_seen_ratio once raised a TypeError)."""
    for f in dataclasses.fields(TrackerConfig):
        for bad in ("x", None, [1]):
            with pytest.raises(ConfigError, match=f.name):
                TrackerConfig(**{f.name: bad})


def test_a_toml_value_of_the_wrong_type_is_a_config_error_naming_the_file(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('score_threshold = "high"\n')
    with pytest.raises(ConfigError, match=r"bad\.toml: TrackerConfig\.score_threshold: 'high' is not a number"):
        TrackerConfig.from_toml(path)


def test_toml_overrides_a_preset(tmp_path):
    path = tmp_path / "t.toml"
    path.write_text('alpha_3d_m = 0.3\ntriangulation = "paper"\nrow_norm = "row"\n')
    config = TrackerConfig.from_toml(path, base="store")
    assert config.alpha_3d_m == 0.3 and config.triangulation is Triangulation.PAPER
    assert config.row_norm is RowNorm.ROW
    assert config.lambda_t_per_s == PRESETS["store"]["lambda_t_per_s"]


def test_toml_under_a_tracker_table_with_a_preset_key(tmp_path):
    path = tmp_path / "t.toml"
    path.write_text('[tracker]\npreset = "campus"\nmin_views = 3\n')
    config = TrackerConfig.from_toml(path)
    assert config.min_views == 3 and config.alpha_3d_m == 0.10


def test_toml_unknown_key_names_file_and_key(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("alpha_3d = 0.2\n")
    with pytest.raises(ValueError, match=r"bad\.toml.*'alpha_3d'"):
        TrackerConfig.from_toml(path)


def test_toml_bad_value_names_file_and_field(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("alpha_3d_m = -1.0\n")
    with pytest.raises(ValueError, match=r"bad\.toml.*alpha_3d_m"):
        TrackerConfig.from_toml(path)


def test_every_field_is_documented():
    doc = TrackerConfig.__doc__
    missing = [f.name for f in dataclasses.fields(TrackerConfig) if f.name not in doc]
    assert not missing


@pytest.mark.parametrize("preset, mode, lambda_t, velocity, row_norm", [
    ("store", "paper", 5.0, False, PLANE_ROW), ("store", "velocity", 5.0, True, PLANE_ROW),
    ("store", "unnormalized", 5.0, False, UNIT_ROWS), ("store", "conventional", 0.0, False, UNIT_ROWS),
    ("store-paper", "paper", 5.0, False, WHOLE_ROW), ("store-paper", "velocity", 5.0, True, WHOLE_ROW)])
def test_each_triangulation_reaches_the_update_kernel_as_its_weights(preset, mode, lambda_t, velocity, row_norm):
    from tests.tracker.synthetic import ceiling_rig
    from tracker.tracker import Tracker

    config = TrackerConfig.preset(preset).replace(triangulation=mode)
    params = Tracker(ceiling_rig(4, 5.0, 4.0), config)._update_params.triangulation
    assert (params.lambda_t_per_s, params.use_velocity, params.row_norm) == (lambda_t, velocity, row_norm)
