"""Fitting a detector profile: each parameter moves toward its statistic, a short fit recovers a changed
profile's direction, the fitted file is a profile a scenario accepts, and bad input writes nothing."""

from __future__ import annotations

import copy
import json
import math
import re
from pathlib import Path

import pytest

from crossview.cli import main
from crossview.measure import detector_fit
from crossview.measure.detector_stats import SHELF_OPENPOSE, SHELF_OPENPOSE_FILE, recording_detector_stats
from sim import scenario as scenario_mod
from sim.sensing.profiles import JOINT_GROUPS, PROFILES, DetectorProfile, profile_params

TYPICAL = PROFILES[DetectorProfile.TYPICAL]
WRISTS = JOINT_GROUPS.index("wrists")


def _target() -> dict:
    """Real OpenPose's table with every range read as its midpoint."""
    target = copy.deepcopy(SHELF_OPENPOSE)
    return target


def _short_of(target: dict) -> dict:
    """A measured table short of `target` on every fitted statistic (errors, lifts, misses, memory, FPs)."""
    stats = copy.deepcopy(target)
    for key in ("error_over_size_median", "lag1_error_correlation", "miss_rate", "miss_persistence",
                "missed_person_view_rate", "gross_error_rate", "false_positive_people_per_frame",
                "cross_view_reprojection_px_at_400"):
        stats[key] = detector_fit.value(target, key) * 0.7
    for group, table in stats["per_group"].items():
        for key in ("error_over_size_median", "miss_rate", "vertical_offset_px_at_400"):
            if detector_fit.value(target, key, group) is not None:
                table[key] = detector_fit.value(target, key, group) * 0.7
    return stats


def test_each_fitted_parameter_moves_toward_its_statistic():
    target = _target()
    moved = detector_fit.update(TYPICAL, _short_of(target), target)
    # Too small an error: more offset; too small an upward offset (less negative px): more lift; too few
    # misses: a higher rate; too little memory: longer times; too few false positives and person misses: more.
    assert moved.offset_m[WRISTS] > TYPICAL.offset_m[WRISTS]
    assert moved.lift_m[WRISTS] > TYPICAL.lift_m[WRISTS]
    assert moved.joint_miss_prob[WRISTS] > TYPICAL.joint_miss_prob[WRISTS]
    assert moved.noise_time_s > TYPICAL.noise_time_s and moved.miss_time_s > TYPICAL.miss_time_s
    assert moved.phantom_rate > TYPICAL.phantom_rate and moved.miss_prob > TYPICAL.miss_prob
    assert moved.gross_error_prob > TYPICAL.gross_error_prob and moved.noise_frac > TYPICAL.noise_frac
    # No statistic for the head: its parameters stay.
    head = JOINT_GROUPS.index("head")
    assert moved.offset_m[head] == TYPICAL.offset_m[head] and moved.lift_m[head] == TYPICAL.lift_m[head]
    # What occlusion misses is lowered only once a group's (or the person-view's) own miss probability is 0.
    assert moved.occluded_drop_prob == TYPICAL.occluded_drop_prob
    hips = JOINT_GROUPS.index("hips")
    floor = TYPICAL._replace(joint_miss_prob=tuple(0.0 if g == hips else p for g, p in
                                                   enumerate(TYPICAL.joint_miss_prob)), miss_prob=0.0)
    too_many = copy.deepcopy(target)
    too_many["per_group"]["hips"]["miss_rate"] = 2 * target["per_group"]["hips"]["miss_rate"]
    too_many["missed_person_view_rate"] = 2 * target["missed_person_view_rate"]
    lowered = detector_fit.update(floor, too_many, target)
    assert lowered.occluded_drop_prob < TYPICAL.occluded_drop_prob
    assert lowered.miss_occlusion_gain < TYPICAL.miss_occlusion_gain
    # A table that meets the target changes nothing.
    assert detector_fit.update(TYPICAL, target, target) == TYPICAL
    assert max(abs(d) for d in detector_fit.deviations(target, target).values()) == 0.0


def test_a_fit_moves_toward_a_changed_profile_and_writes_a_profile_scenarios_accept(tmp_path):
    # A recording made with typical but wrists missed twice as often and three times the phantoms.
    profile = tmp_path / "p.toml"
    profile.write_text('base = "typical"\njoint_miss_prob = [0.08, 0.0653, 0.134, 0.45, 0.0337, 0.04, 0.06]\n'
                       "phantom_rate = 0.9\n")
    shelf = scenario_mod.resolve_path("shelf").read_text().replace('profile = "typical"', f'profile = "{profile}"')
    rig = scenario_mod.SCENARIO_DIR / "calibrations" / "shelf_calibration.json"  # (the copy is elsewhere)
    shelf = shelf.replace('"calibrations/shelf_calibration.json"', f'"{rig}"')
    (tmp_path / "s.toml").write_text(shelf)
    rec, fitted = tmp_path / "p.mcap", tmp_path / "fitted.toml"
    assert main(["--no-progress", "generate", str(tmp_path / "s.toml"), "-o", str(rec), "--duration", "4"]) == 0
    # One update from typical, measured on the recording's own rig and seed: both move most of the way there.
    target = recording_detector_stats(rec)
    scenario = scenario_mod.load(tmp_path / "s.toml")
    rounds = []
    detector_fit.fit(target, scenario, TYPICAL, seed=scenario.seed, duration_s=4.0, rounds=2,
                     on_round=lambda k, r: rounds.append(r))
    moved = rounds[1].params
    assert moved.joint_miss_prob[WRISTS] > TYPICAL.joint_miss_prob[WRISTS] + 0.1
    assert moved.phantom_rate > 0.55
    # The command writes the best round as a profile, which is a profile wherever a profile name goes.
    assert main(["--no-progress", "fit-detector", str(rec), "-o", str(fitted), "--duration", "2", "--rounds", "1"]) == 0
    params = profile_params(str(fitted))
    assert params == TYPICAL  # (one round: the starting profile, as measured)
    again = scenario_mod.load("shelf", {"detector.profile": str(fitted)})
    assert again.detector.params() == params


def test_fit_detector_refuses_what_it_cannot_fit_and_writes_nothing(tmp_path, capsys):
    empty, out = tmp_path / "empty.mcap", tmp_path / "fitted.toml"
    assert main(["--no-progress", "generate", "shelf", "-o", str(empty), "--duration", "1", "--people", "0"]) == 0
    capsys.readouterr()
    assert main(["--no-progress", "fit-detector", str(empty), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(empty) in err[0]
    assert not out.exists() and not list(tmp_path.glob("*.tmp"))
    assert main(["fit-detector", "-o", str(out)]) == 2  # neither a recording nor a target
    assert main(["fit-detector", "--target", "shelf-openpose", "--start", "rough", "-o", str(out)]) == 2
    assert "rough" in capsys.readouterr().err and not out.exists()


@pytest.mark.parametrize(("text", "message"), [
    ("noise_fracc = 0.1\n", r"bad\.toml: unknown key 'noise_fracc'"),
    ("noise_frac = -0.1\n", r"bad\.toml: noise_frac: -0\.1 must be in \[0, 1\]"),
    ("noise_frac = nan\n", r"bad\.toml: noise_frac: nan must be"),
    ("miss_prob = 1.5\n", r"bad\.toml: miss_prob: 1\.5 must be in \[0, 1\]"),
    ("joint_miss_prob = [0.1, 0.1, 0.1, 1.2, 0.1, 0.1, 0.1]\n", r"bad\.toml: joint_miss_prob\[3\]: 1\.2 must be"),
    ('base = "perfect"\n', r"bad\.toml: base = 'perfect' is not one of"),
    ("offset_m = [0.1]\n", r"bad\.toml: offset_m must have 7 elements"),
    ("difficult_rate = 1.5\n", r"bad\.toml: difficult_rate: 1\.5 must be in \[0, 1\]"),
], ids=["unknown-key", "negative", "nan", "probability-above-1", "group-probability-above-1", "unknown-base",
        "wrong-length", "difficult-rate-above-1"])
def test_a_bad_profile_file_names_the_file_and_the_key(tmp_path, text, message, capsys):
    (tmp_path / "bad.toml").write_text(text)
    (tmp_path / "s.toml").write_text('[detector]\nprofile = "bad.toml"\n')
    with pytest.raises(scenario_mod.ScenarioError, match=message):
        scenario_mod.load(tmp_path / "s.toml")
    out = tmp_path / "x.mcap"
    assert main(["--no-progress", "generate", str(tmp_path / "s.toml"), "-o", str(out), "--duration", "1"]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1 and not out.exists()


def test_a_profile_file_a_command_reads_is_never_one_of_its_outputs(tmp_path, capsys):
    profile = tmp_path / "p.toml"
    profile.write_text('base = "ideal"\n')
    (tmp_path / "s.toml").write_text('[detector]\nprofile = "p.toml"\n')
    kept = profile.read_bytes()
    # The scenario's profile as generate's output, and fit-detector's starting profile as its output.
    assert main(["--no-progress", "generate", str(tmp_path / "s.toml"), "-o", str(profile), "--duration", "1"]) == 2
    assert main(["fit-detector", "--target", "shelf-openpose", "--start", str(profile), "-o", str(profile)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all("is also an input" in line for line in err), err
    assert profile.read_bytes() == kept


def test_a_recording_made_with_a_profile_file_replays_without_it(tmp_path):
    profile = tmp_path / "p.toml"
    profile.write_text('base = "ideal"\nnoise_frac = 0.02\nnoise_tail_dof = inf\n')
    (tmp_path / "s.toml").write_text('[detector]\nprofile = "p.toml"\nswap_prob = 0.1\n')
    scenario = scenario_mod.load(tmp_path / "s.toml")
    profile.unlink()
    again = scenario_mod.from_source_text(scenario.source_text, "s", "rec")
    assert again.detector == scenario.detector
    assert again.detector.params().noise_frac == 0.02 and again.detector.params().swap_prob == 0.1  # the scenario's
    assert Path(scenario.source_path).name == "s.toml"


def test_a_statistics_file_is_a_target_its_column_is_labelled_by_it_and_unreached_rows_say_why(tmp_path, capsys):
    # The shipped real table copied to a file of its own: fit-detector reads it as any detector-stats file.
    target = tmp_path / "mine.json"
    target.write_text(SHELF_OPENPOSE_FILE.read_text(encoding="utf-8"), encoding="utf-8")
    out = tmp_path / "fitted.toml"
    assert main(["--no-progress", "fit-detector", "--target", str(target), "-o", str(out), "--duration", "1",
                 "--rounds", "1"]) == 0
    text = capsys.readouterr().out
    header = next(line for line in text.splitlines() if line.startswith("statistic"))
    assert header.split()[-1] == "mine.json"
    # A file's false-positive people are a target (only the shipped Shelf table's are not: NOT_TARGETS).
    assert "false_positive_people_per_frame:" in text
    assert "rows further than 25 % from the target" in text
    assert profile_params(str(out)) == TYPICAL


def test_unreached_rows_name_their_parameter_and_why():
    target = _target()
    stats = copy.deepcopy(target)
    stats["error_over_size_p99"] = target["error_over_size_p99"] * 0.5  # no parameter is fitted to it
    stats["per_group"]["hips"]["miss_rate"] = target["per_group"]["hips"]["miss_rate"] * 3  # with misses near 0
    stats["lag1_error_correlation"] = target["lag1_error_correlation"] * 0.7
    hips = JOINT_GROUPS.index("hips")
    miss = list(TYPICAL.joint_miss_prob)
    miss[hips] = 0.005
    rows = detector_fit.unreached(detector_fit.FitRound(TYPICAL._replace(joint_miss_prob=tuple(miss)), stats, 1.0),
                                  target)
    why = {(key, group): text for key, group, _, text in rows}
    assert set(why) == {("error_over_size_p99", None), ("miss_rate", "hips"), ("lag1_error_correlation", None)}
    assert rows[0][:2] == ("miss_rate", "hips")  # worst first (+200 %)
    assert "no parameter is fitted" in why["error_over_size_p99", None]
    assert "occluded_drop_prob" in why["miss_rate", "hips"]
    assert why["lag1_error_correlation", None].startswith("noise_time_s = ")


@pytest.mark.parametrize(("content", "message"), [
    ("[1, 2]\n", r"bad\.json: per_group: missing; not a detector statistics file"),
    ("not json", r"bad\.json: not JSON"),
    ("drop:gross_error_rate", r"bad\.json: gross_error_rate: missing"),
    ("nan:per_group.wrists.miss_rate", r"bad\.json: per_group\.wrists\.miss_rate: nan is not a finite number"),
    ("text:miss_rate", r"bad\.json: miss_rate: 'high' is not a finite number"),
], ids=["not-stats", "not-json", "missing-key", "nan", "not-a-number"])
def test_a_bad_target_file_names_the_file_and_the_key_and_writes_nothing(tmp_path, content, message, capsys):
    bad, out = tmp_path / "bad.json", tmp_path / "fitted.toml"
    if ":" in content:
        how, _, key = content.partition(":")
        table = copy.deepcopy(SHELF_OPENPOSE)
        *path, last = key.split(".")
        where = table
        for part in path:
            where = where[part]
        if how == "drop":
            del where[last]
        else:
            where[last] = math.nan if how == "nan" else "high"
        bad.write_text(json.dumps(table))  # (json writes NaN as NaN, which Python's reader takes)
    else:
        bad.write_text(content)
    assert main(["fit-detector", "--target", str(bad), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.search(message, err[0]), err
    assert not out.exists() and not list(tmp_path.glob("*.tmp"))
