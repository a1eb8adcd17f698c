"""Everything a user can type, given wrongly: one line naming the file, key or value and what would be
valid, exit status 2, no traceback, before any work (no output written). docs/reliability.md lists these
cases row by row."""

import json
import shutil
from pathlib import Path

import pytest

from crossview import cli
from crossview.cli import EXIT_BAD_INPUT, main
from sim import scenario

CAMPUS = Path(__file__).resolve().parents[1] / "data" / "campus"


def _refused(capsys, argv, tmp_path) -> str:
    """Runs `crossview ARGV`: exit 2, one line, no traceback, nothing written under tmp_path/out."""
    status = main(["--no-progress", *map(str, argv)])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT, err
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert not (tmp_path / "out").exists()
    return err


def _file(tmp_path: Path, name: str, content) -> Path:
    path = tmp_path / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    return path


# Scenario files and the options that override them: (id, file text or None for a shipped one, options,
# what the line must say).
SCENARIO_CASES = [
    ("wrong-type-in-table", '[crowd]\npeople = "3"\n', [], "crowd.people = '3' must be an integer"),
    ("table-not-a-table", "crowd = 5\n", ["--people", "2"], "crowd must be a table ([crowd]), got 5"),
    ("infinite-duration", "duration_s = inf\n", [], "duration_s: inf must be in (0, 86400] s"),
    ("nan-duration", "duration_s = nan\n", [], "duration_s: nan must be in (0, 86400] s"),
    ("nan-door-position", "[store]\nentrance_m = [nan, 1.0]\n", [], "entrance_m[0]: nan must be"),
    ("not-utf8", b'description = "\xff"\n', [], "cannot read scenario: 'utf-8' codec can't decode byte 0xff"),
    ("million-cameras", None, ["--cameras", "1000000"],
     "--cameras: 1000000 is more than the 10000 cameras a grid may hold"),
    ("huge-seed", None, ["--seed", str(10**30)], f"argument --seed: {10**30} must be in [0, 2^63 - 1]"),
    ("huge-crowd", None, ["--people", "100000000"], "people: 100000000 must be in [0, 2000] people"),
    ("calibration-missing", '[cameras]\ncalibration = "nowhere.json"\ncalibration_format = "dataset"\n', [],
     "s.toml: cameras.calibration: 'nowhere.json': no such file"),
    ("calibration-format-unknown", '[cameras]\ncalibration = "rig.json"\ncalibration_format = "opencv"\n', [],
     "cameras.calibration_format = 'opencv' is not one of ['panoptic', 'dataset']"),
    ("calibration-of-the-other-format",
     f'[cameras]\ncalibration = {json.dumps(str(CAMPUS / "calibration.json"))}\ncalibration_format = "panoptic"\n', [],
     "calibration.json' as a panoptic calibration: key 'cameras' must be an array of camera objects"),
    ("calibration-without-image-size",
     f'[cameras]\ncalibration = {json.dumps(str(CAMPUS / "calibration.json"))}\ncalibration_format = "dataset"\n', [],
     "calibration.json' as a dataset calibration: key 'image_wh' missing"),
    ("truth-head-unknown", '[scoring]\ntruth_head = "vertex"\n', [],
     "scoring.truth_head = 'vertex' is not one of ['evaluate', 'annotated']"),
    ("crowd-above-the-floor", None, ["--people", "400"],
     "crowd.people: 400 people need 400 m² of walkable floor (1.0 m² each) but the store has 12.8 m²; use at "
     "most 12 people"),
    ("nested-2000-deep", "a = " + "[" * 2000 + "]" * 2000 + "\n", [],  # (was a RecursionError)
     "s.toml: malformed TOML: tables or arrays nested more than 32 deep"),
    ("nested-40-deep", "a = " + "[" * 40 + "]" * 40 + "\n", [],
     "s.toml: malformed TOML: tables or arrays nested more than 32 deep"),
    ("too-many-camera-frames", None, ["--duration", "86400"],
     "schedules 10,368,000 camera frames, more than the 5,000,000 one recording may hold"),
    ("aisles-do-not-fit", "[store]\nwidth_m = 18.0\ndepth_m = 12.0\n[store.aisles]\ncount = 10\n", [],
     "s.toml: [store] aisles.count: 10 aisles between 9 gondolas 1.2 m wide do not fit across the floor's 18 m"),
    ("aisles-too-long", "[store]\nwidth_m = 18.0\ndepth_m = 12.0\n[store.aisles]\ngondola_length_m = 11.0\n", [],
     "s.toml: [store] aisles.gondola_length_m: 11 m gondolas leave less than 1 m of cross aisle"),
    ("checkout-lanes-do-not-fit", "[store]\nwidth_m = 18.0\ndepth_m = 12.0\n[store.checkout_lanes]\ncount = 10\n", [],
     "s.toml: [store] checkout_lanes.count: 10 lanes 1.2 m wide beside counters 0.8 m wide (20.00 m) do not fit "
     "across the floor's 18 m (at most 9 lanes)"),
    ("checkout-lanes-too-long", "[store]\nwidth_m = 18.0\ndepth_m = 12.0\n[store.checkout_lanes]\n"
     "counter_length_m = 10.0\n", [], "s.toml: [store] checkout_lanes.counter_length_m: 10 m counters from "
     "front_gap_m = 1.5 m leave 0.50 m of the floor's 12 m along y behind them, need >= 1 m (at most 9.50 m)"),
    ("checkout-lane-before-a-door", "[store]\nwidth_m = 12.0\ndepth_m = 8.0\nexit_m = [9.0, 0.0]\n"
     "[store.checkout_lanes]\nfront_gap_m = 1.2\n", [],
     "s.toml: store.exit_m: door at (9, 0) is blocked by store.checkout_lanes[2]"),
    ("trapped-back-half", (Path(__file__).resolve().parents[1] / "sim" / "data" / "trapped_back_half.toml").read_text(),
     [], "s.toml: store.shelves[0]: closes off 14.8 m² of walkable floor"),
]


@pytest.mark.parametrize(("text", "options", "expected"), [c[1:] for c in SCENARIO_CASES],
                         ids=[c[0] for c in SCENARIO_CASES])
def test_a_bad_scenario_is_refused_in_one_line(text, options, expected, tmp_path, capsys):
    scenario = "store_layout1" if text is None else _file(tmp_path, "s.toml", text)
    err = _refused(capsys, ["generate", scenario, "-o", tmp_path / "out" / "r.mcap", *options], tmp_path)
    assert expected in err, err


DEEP_TOML = "a = " + "[" * 100000 + "]" * 100000 + "\n"


# Every command that reads a TOML file reads it through core.tomlfile: nested 100,000 deep it is refused in
# one line naming the file (was a RecursionError): (id, the command with DEEP for the deep file).
DEEP_TOML_COMMANDS = [
    ("scenarios-show", ["scenarios", "--show", "DEEP"]),
    ("track-config", ["track", "REC", "-o", "OUT/t.mcap", "--config", "DEEP"]),
    ("fit-detector-start", ["fit-detector", "REC", "--start", "DEEP", "-o", "OUT/p.toml"]),
    ("profile-named-by-a-scenario", ["generate", "SCENARIO", "-o", "OUT/r.mcap"]),
]


@pytest.mark.parametrize("argv", [c[1] for c in DEEP_TOML_COMMANDS], ids=[c[0] for c in DEEP_TOML_COMMANDS])
def test_a_toml_file_nested_too_deep_is_refused_in_one_line(argv, campus_recording, tmp_path, capsys):
    deep = _file(tmp_path, "deep.toml", DEEP_TOML)
    scenario = _file(tmp_path, "s.toml", '[detector]\nprofile = "deep.toml"\n')
    names = {"DEEP": deep, "REC": campus_recording, "SCENARIO": scenario}
    argv = [str(tmp_path / "out") + a[3:] if a.startswith("OUT") else names.get(a, a) for a in argv]
    err = _refused(capsys, argv, tmp_path)
    assert f"{deep}: " in err and "nested more than 32 deep" in err, err


# Command-line values outside their type or bound.
OPTION_CASES = [
    ("world-stats-infinite", ["world-stats", "store_layout1", "--duration", "inf"], "inf must be at most 86400 s"),
    ("world-stats-huge", ["world-stats", "store_layout1", "--duration", "1e12"], "1e12 must be at most 86400 s"),
    ("minutes-huge", ["world-stats", "store_layout1", "--minutes", "1e12"], "1e12 must be at most 1440 minutes"),
    ("minutes-and-duration", ["world-stats", "store_layout1", "--minutes", "1", "--duration", "60"],
     "argument --duration: not allowed with argument --minutes"),
    ("output-old-and-new", ["sweep", "store_layout1", "-o", "OUT/a", "--out", "OUT/b"],
     "argument --out: not allowed with argument -o/--output"),
    ("output-json-and-o", ["score", "OUT/r.mcap", "OUT/t.mcap", "--json", "OUT/a.json", "-o", "OUT/b.json"],
     "argument -o/--output: not allowed with argument --json"),
    ("duration-nan", ["generate", "store_layout1", "-o", "OUT/r.mcap", "--duration", "nan"], "nan must be > 0"),
    ("duration-not-a-number", ["run", "--duration", "ten", "-o", "OUT"], "'ten' is not a number"),
    ("bench-duration-huge", ["bench", "--duration", "1e9", "-o", "OUT/b.json"],  # (blamed store_layout1.toml)
     "argument --duration: 1e9 must be at most 86400 s (a day)"),
    ("fit-detector-duration-infinite", ["fit-detector", "OUT/r.mcap", "--duration", "inf", "-o", "OUT/p.toml"],
     "argument --duration: inf must be at most 86400 s (a day)"),  # (was an OverflowError)
    ("fit-detector-duration-huge", ["fit-detector", "OUT/r.mcap", "--duration", "1e9", "-o", "OUT/p.toml"],
     "argument --duration: 1e9 must be at most 86400 s (a day)"),  # (allocated 74.5 GiB)
    ("sweep-duration-huge", ["sweep", "store_layout1", "--duration", "1e9", "-o", "OUT/s"],
     "argument --duration: 1e9 must be at most 86400 s (a day)"),
    ("fit-detector-seed-huge", ["fit-detector", "OUT/r.mcap", "--seed", str(2**64), "-o", "OUT/p.toml"],
     f"argument --seed: {2**64} must be in [0, 2^63 - 1]"),  # (was accepted)
    ("coverage-seed-huge", ["coverage", "hypermarket", "--seed", str(2**63), "-o", "OUT/c.png"],
     f"argument --seed: {2**63} must be in [0, 2^63 - 1]"),
    ("plan-duration-huge", ["plan", "store_layout1", "--target-pcp", "0.9", "--confirm", "--duration", "1e9", "-o",
                            "OUT/plan.json"], "argument --duration: 1e9 must be at most 86400 s (a day)"),
    ("cameras-no-grid", ["coverage", "hypermarket", "--cameras", "9973", "-o", "OUT/c.png"],  # (a prime)
     "--cameras: 9973 cameras make no grid of at most 100 rows and 100 columns"),
    ("cameras-huge", ["generate", "store_layout1", "-o", "OUT/r.mcap", "--cameras", "1000000000"],
     "--cameras: 1000000000 is more than the 10000 cameras a grid may hold"),
    ("tile-width-huge", ["render", "OUT/r.mcap", "--contact-sheet", "--time", "1", "--tile-width", "100000", "-o",
                         "OUT/x.png"], "--tile-width: 100000 must be in [1, 4096] pixels"),
    ("clip-too-long", ["render", "OUT/r.mcap", "--camera", "cam00", "--from", "0", "--to", "1e6", "-o", "OUT/x.gif"],
     "is more than the 100,000 images a clip may hold"),
    ("convert-fps-infinite", ["convert", "OUT/op", "-o", "OUT/r.mcap", "--fps", "inf"],
     "argument --fps: inf must be in (0, 1000] frames per second"),
    ("convert-fps-huge", ["convert", "OUT/op", "-o", "OUT/r.mcap", "--fps", "1e300"],
     "argument --fps: 1e300 must be in (0, 1000] frames per second"),
    ("time-nan", ["render", "OUT/r.mcap", "--camera", "cam00", "--time", "nan", "-o", "OUT/x.png"],
     "--time: nan is not a finite number of seconds"),
    ("from-negative", ["score", "OUT/r.mcap", "OUT/t.mcap", "--from", "-1"], "'-1' must be a number of seconds >= 0"),
    ("sweep-from-past-the-cells", ["sweep", "store_layout1", "--duration", "2", "--from", "3", "-o", "OUT/s"],
     "--from 3: the warm-up reaches past the end of the cells, which simulate 2 s; give at most 2"),
]


def test_every_duration_and_seed_option_has_a_scenario_s_bound():
    assert cli.MAX_DURATION_S == scenario.MAX_DURATION_S and cli.MAX_SEED == scenario.MAX_SEED


@pytest.mark.parametrize(("argv", "expected"), [c[1:] for c in OPTION_CASES], ids=[c[0] for c in OPTION_CASES])
def test_a_bad_option_is_refused_in_one_line(argv, expected, tmp_path, capsys):
    argv = [str(tmp_path / "out") + a[3:] if a.startswith("OUT") else a for a in argv]
    assert expected in _refused(capsys, argv, tmp_path)


@pytest.fixture(scope="module")
def campus_recording(tmp_path_factory) -> Path:
    """The Campus fixture converted to a recording (3 cameras, 14 joints)."""
    out = tmp_path_factory.mktemp("campus") / "campus.mcap"
    assert main(["--no-progress", "convert", str(CAMPUS), "-o", str(out)]) == 0
    return out


# Tracker configuration files.
CONFIG_CASES = [
    ("infinite-value", "alpha_3d_m = inf\n", "TrackerConfig.alpha_3d_m: inf must be finite and at most 1000"),
    ("huge-count", "velocity_history = 100000000000\n", "velocity_history: 100000000000 must be finite and at most"),
    ("wrong-type", 'w_2d = "x"\n', "TrackerConfig.w_2d: 'x' is not a number"),
    ("more-views-than-cameras", "min_views = 1000\n", "min_views: 1000 is more than the 3 cameras of the input"),
    ("more-joints-than-the-skeleton", "init_min_joints = 15\n", "init_min_joints: 15 is more than the 14 joints"),
    ("not-utf8", b"w_2d = 0.5\n\xff\n", "cannot read tracker config: not UTF-8 text (byte 11)"),
    ("unknown-key", "w2d = 0.5\n", "unknown key 'w2d'"),
    ("malformed", "[tracker\n", "cannot read tracker config"),
    ("alpha-2d-negative", "alpha_2d_px_per_frame = -25.0\n", "TrackerConfig.alpha_2d_px_per_frame: -25.0 must be > 0"),
    ("alpha-2d-zero", "alpha_2d_px_per_frame = 0.0\n", "TrackerConfig.alpha_2d_px_per_frame: 0.0 must be > 0"),
    ("alpha-2d-nan", "alpha_2d_px_per_frame = nan\n", "TrackerConfig.alpha_2d_px_per_frame: nan is not a number"),
    ("alpha-2d-per-second", "alpha_2d_px_per_s = 625.0\n", "key 'alpha_2d_px_per_s' is now 'alpha_2d_px_per_frame'"),
    ("reject-factor-below-1", "reject_factor = 0.5\n", "TrackerConfig.reject_factor: 0.5 must be 0 (no rejection) or"),
    ("bone-prior-tolerance-1", "bone_prior_tolerance = 1.0\n",
     "TrackerConfig.bone_prior_tolerance: 1.0 must be 0 (no bone prior) or in (0, 1)"),
    ("joint-gate-below-1cm", "joint_gate_m = 0.001\n", "TrackerConfig.joint_gate_m: 0.001 must be 0 (no gate) or at"),
    ("unknown-switch", "bone_prior = true\n", "unknown key 'bone_prior'"),
]


@pytest.mark.parametrize(("text", "expected"), [c[1:] for c in CONFIG_CASES], ids=[c[0] for c in CONFIG_CASES])
def test_a_bad_tracker_config_is_refused_in_one_line(text, expected, campus_recording, tmp_path, capsys):
    config = _file(tmp_path, "c.toml", text)
    err = _refused(capsys, ["track", campus_recording, "-o", tmp_path / "out" / "t.mcap", "--config", config,
                            "--preset", "campus"], tmp_path)
    assert "c.toml: " in err and expected in err, err


# Recordings that detector-stats cannot measure: (id, the Campus fixture's files to keep, frames of its 2D
# input to keep (None: all), what the line must say).
DETECTOR_STATS_CASES = [
    ("no-truth", ("calibration.json", "annotation_2d.json"), None, "no 3D truth at the times of its 1353 camera "
     "frames; detector-stats needs a recording with truth"),
    ("too-few-matches", ("calibration.json", "annotation_2d.json", "annotation_3d.json"),
     ("Camera0/0014.000.jpg", "Camera0/0014.040.jpg"), "only 2 detections match a true person"),
]


@pytest.mark.parametrize("files, frames, expected", [c[1:] for c in DETECTOR_STATS_CASES],
                         ids=[c[0] for c in DETECTOR_STATS_CASES])
def test_detector_stats_refuses_a_recording_it_cannot_measure(files, frames, expected, tmp_path, capsys):
    dataset = tmp_path / "dataset"
    dataset.mkdir()
    for name in files:
        shutil.copy(CAMPUS / name, dataset / name)
    if frames is not None:
        d = json.loads((dataset / "annotation_2d.json").read_text())
        d["frames"] = {k: d["frames"][k] for k in frames}
        (dataset / "annotation_2d.json").write_text(json.dumps(d))
    rec = tmp_path / "rec.mcap"
    assert main(["--no-progress", "convert", str(dataset), "-o", str(rec)]) == 0
    err = _refused(capsys, ["detector-stats", rec, "--json", tmp_path / "out" / "stats.json"], tmp_path)
    assert f"{rec}: {expected}" in err, err


def _cam0(d):
    return next(iter(d["cameras"].values()))


def _first_frame_with_poses(d):
    return next(f for f in d["frames"].values() if f["poses"])


# Dataset folders: (id, file, change to its JSON (returns the new document or text), what the line must say).
DATASET_CASES = [
    ("cameras-a-list", "calibration.json", lambda d: {"cameras": list(d["cameras"].values())},
     "key 'cameras' (camera name -> {K, Tw}) must be an object, got list"),
    ("frames-a-list", "annotation_2d.json", lambda d: {**d, "frames": list(d["frames"].values())},
     "key 'frames' (frame name -> frame) must be an object, got list"),
    ("singular-intrinsics", "calibration.json", lambda d: _cam0(d).update(K=[[0, 0, 0], [0, 0, 0], [0, 0, 1]]),
     "is not a pinhole intrinsic matrix"),
    ("null-in-camera-pose", "calibration.json", lambda d: _cam0(d)["Tw"][0].__setitem__(0, None),
     "K and Tw must hold numbers (no null)"),
    ("nan-in-calibration", "calibration.json", lambda d: json.dumps(d).replace("1.1945368357487924", "NaN"),
     "calibration.json: NaN is not a JSON number"),
    ("huge-timestamp", "annotation_2d.json", lambda d: next(iter(d["frames"].values())).update(timestamp=1e300),
     "timestamp 1e+300 must be in [-4e+09, 4e+09] s"),
    ("huge-id", "annotation_2d.json", lambda d: _first_frame_with_poses(d)["poses"][0].update(id=10**30),
     f"id {10**30} must be an integer in [-2^63, 2^63)"),
    ("huge-image", "annotation_2d.json", lambda d: {**d, "image_wh": [10**30, 5]},
     "key 'image_wh' = [1000000000000000000000000000000, 5] must be [width, height], integers in [1, 100000]"),
    ("not-utf8", "calibration.json", lambda d: b'{"cameras": "\xff"}', "calibration.json: not UTF-8 text (byte 13)"),
    ("truth-entries-not-objects", "annotation_3d.json", lambda d: [[1]],
     "annotation_3d.json: entry 0 must be an object"),
    ("truth-pose-empty", "annotation_3d.json", lambda d: d[0]["poses"][0].update(points_3d=[]) if d[0]["poses"]
     else d[0].update(poses=[{"id": 1, "points_3d": []}]), "points_3d must be 14x3 for each pose"),
    ("missing-calibration", "calibration.json", None, "calibration.json: file not found"),
    ("too-many-cameras", "calibration.json", lambda d: {"cameras": {f"c{i}": _cam0(d) for i in range(10_001)}},
     "key 'cameras' holds 10,001 cameras, more than the 10,000 one recording may hold"),  # (was a struct.error)
    ("huge-joints-2d", "annotation_2d.json", lambda d: _one_pose_of_10_000_joints(d),
     "key 'points_2d' of camera 'Camera0' at 13.28 s holds 10,000 joints per pose"),  # (named neither file nor key)
    ("huge-joints-3d", "annotation_3d.json", lambda d: next(e for e in d if e["poses"])["poses"][0].update(
        points_3d=[[1.0, 1.0, 1.0]] * 10_000), "points_3d must be 14x3 for each pose; got (10000, 3)"),
    ("infinite-pixel", "annotation_2d.json", lambda d: _with_1e400(d, "points_2d"),
     "pose 0: points_2d holds inf; expected pixels finite, within 1e6"),
    ("infinite-score", "annotation_2d.json", lambda d: _with_1e400(d, "scores"),
     "pose 0: scores holds inf; expected scores finite"),
]


def _one_pose_of_10_000_joints(d):
    """The 2D file with one frame left, holding one pose of 10,000 joints."""
    key, frame = next((k, f) for k, f in d["frames"].items() if f["poses"])
    frame["poses"] = [{**frame["poses"][0], "points_2d": [[1.0, 1.0]] * 10_000, "scores": [1.0] * 10_000}]
    return {**d, "frames": {key: frame}}


def _with_1e400(d, key):
    """The 2D file's text with its first pose's first value of `key` written 1e400 (which JSON reads as inf)."""
    pose = _first_frame_with_poses(d)["poses"][0]
    if key == "points_2d":
        pose[key][0][0] = 123456.789
    else:
        pose[key][0] = 123456.789
    return json.dumps(d).replace("123456.789", "1e400")


def _dataset(tmp_path: Path, name: str, change) -> Path:
    folder = tmp_path / "campus"
    shutil.copytree(CAMPUS, folder)
    path = folder / name
    if change is None:
        path.unlink()
        return folder
    data = json.loads(path.read_text())
    changed = change(data)
    changed = data if changed is None else changed
    path.write_bytes(changed if isinstance(changed, bytes) else
                     (changed if isinstance(changed, str) else json.dumps(changed)).encode())
    return folder


@pytest.mark.parametrize(("name", "change", "expected"), [c[1:] for c in DATASET_CASES],
                         ids=[c[0] for c in DATASET_CASES])
def test_a_bad_dataset_folder_is_refused_in_one_line(name, change, expected, tmp_path, capsys):
    folder = _dataset(tmp_path, name, change)
    err = _refused(capsys, ["convert", folder, "-o", tmp_path / "out" / "c.mcap"], tmp_path)
    assert f"{name}: " in err and expected in err, err


# Result files given to `evaluate`.
RESULT_CASES = [
    ("not-a-list", {"a": 1}, "expected a JSON list of {timestamp, poses} entries"),
    ("id-a-string", [{"timestamp": 1.0, "poses": [{"id": "x", "points_3d": [[0, 0, 0]] * 17}]}],
     "entry 0: id 'x' must be an integer"),
    ("id-too-large", [{"timestamp": 1.0, "poses": [{"id": 2**70, "points_3d": [[0, 0, 0]] * 17}]}],
     f"entry 0: id {2**70} must be an integer in [-2^63, 2^64)"),
    ("timestamp-a-string", [{"timestamp": "noon", "poses": []}], "entry 0: timestamp 'noon' must be a number"),
    ("nan-joint", '[{"timestamp": 1.0, "poses": [{"id": 1, "points_3d": [[NaN, 0, 0]]}]}]', "NaN is not a JSON number"),
    ("wrong-joint-count", [{"timestamp": 1.0, "poses": [{"id": 1, "points_3d": [[0, 0, 0]] * 14}]}],
     "points_3d has shape (14, 3), expected (17, 3)"),
]


@pytest.mark.parametrize(("content", "expected"), [c[1:] for c in RESULT_CASES], ids=[c[0] for c in RESULT_CASES])
def test_a_bad_result_file_is_refused_in_one_line(content, expected, tmp_path, capsys):
    result = _file(tmp_path, "result.json", content if isinstance(content, str) else json.dumps(content))
    err = _refused(capsys, ["evaluate", CAMPUS, result], tmp_path)
    assert "result.json: " in err and expected in err, err
