"""Scenario files: every shipped one loads; bad files fail with the file and key named."""

from pathlib import Path

import pytest

from core.errors import ScenarioError
from sim import scenario, scenario_reference
from sim.sensing.profiles import DetectorProfile

SHIPPED = sorted(scenario.SCENARIO_DIR.glob("*.toml"))


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_every_shipped_scenario_loads(path):
    loaded = scenario.load(path)
    assert loaded.name == path.stem
    assert loaded.digest == scenario.load(path).digest


def test_default_is_store_layout1_with_its_published_shape():
    default = scenario.load()
    assert default.name == "store_layout1"
    assert default.cameras.rows * default.cameras.cols == 12
    assert default.crowd.people == 4
    assert default.clock.fps == 10.0
    assert default.detector.profile is DetectorProfile.TYPICAL


def test_overrides_are_validated_and_change_the_digest():
    base = scenario.load()
    changed = scenario.load(None, {"duration_s": 10.0, "crowd.people": 2})
    assert (changed.duration_s, changed.crowd.people) == (10.0, 2)
    assert changed.digest != base.digest
    with pytest.raises(ScenarioError, match="duration_s"):
        scenario.load(None, {"duration_s": -1.0})


def test_source_text_gives_back_the_scenario_with_its_overrides():
    # What a recording keeps (the file's text with the overrides noted under it) is the scenario that ran.
    ran = scenario.load("store_layout2", {"duration_s": 10.0, "crowd.people": 3, "cameras.rows": 2,
                                          "detector.profile": "ideal", "store.entrance_m": [0.0, 1.5]})
    again = scenario.from_source_text(ran.source_text, ran.name, "rec.mcap")
    assert again == ran and again.digest == ran.digest
    assert (again.crowd.people, again.cameras.rows, again.store.entrance_m) == (3, 2, (0.0, 1.5))
    with pytest.raises(ScenarioError, match="rec.mcap: unreadable override note"):
        scenario.from_source_text(ran.source_text + "\n# override: crowd.people = three", ran.name, "rec.mcap")


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    "text, expected",
    [
        ("[store]\nwidth_m = 4.0\ncolour = 'red'\n", r"bad\.toml: unknown key 'store\.colour'"),
        ("duration_s = -5\n", r"bad\.toml: duration_s: -5\.0 must be in \(0, 86400\] s"),
        ("[clock]\nfps = nan\n", r"bad\.toml: \[clock\] fps: nan must be in \(0, 1000\] frames per second"),
        ("[crowd]\nspeed_range_m_s = [1.0, 9.0]\n",
         r"\[crowd\] speed_range_m_s\[1\]: 9\.0 must be in \[0\.3, 2\] m/s"),
        ("[cameras]\nrows = 1000\n", r"\[cameras\] rows: 1000 must be in \[1, 100\] cameras"),
        ("[detector]\nphantom_rate = inf\n", r"\[detector\] phantom_rate: inf must be in \[0, 100\]"),
        ("[store]\nwidth_m = 'wide'\n", r"bad\.toml: store\.width_m = 'wide' must be a number"),
        ("[detector]\nprofile = 'perfect'\n", r"bad\.toml: detector\.profile = 'perfect' is not one of"),
        ("[store\nwidth_m = 4\n", r"bad\.toml: malformed TOML"),
        ("store = 3\n", r"bad\.toml: \[store\] must be a table"),
    ],
)
def test_bad_files_name_the_file_and_key(tmp_path, text, expected):
    with pytest.raises(ScenarioError, match=expected):
        scenario.load(_write(tmp_path, text))


def test_missing_file_lists_the_shipped_scenarios(tmp_path):
    with pytest.raises(ScenarioError, match="no such scenario file.*store_layout1"):
        scenario.load(tmp_path / "nope.toml")


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_a_resolved_scenario_loads_back_as_the_same_scenario(path, tmp_path):
    original = scenario.load(path)
    copy = tmp_path / "elsewhere" / f"{path.stem}.toml"
    copy.parent.mkdir()
    copy.write_text(scenario.resolved_toml(original))
    again = scenario.load(copy)
    # Every section equal; a relative calibration path now points at the same file from anywhere.
    for section in ("store", "crowd", "clock", "detector"):
        assert getattr(again, section) == getattr(original, section), section
    assert (again.name, again.duration_s, again.seed, again.description) == (
        original.name, original.duration_s, original.seed, original.description)
    if original.cameras.calibration:
        assert Path(again.cameras.calibration).is_absolute()
        assert Path(again.cameras.calibration).read_bytes() == (path.parent / original.cameras.calibration).read_bytes()
    else:
        assert again.cameras == original.cameras


def test_docs_scenarios_md_is_the_reference_of_the_configuration_classes():
    # The page is the generated reference, then the notes on the shipped scenarios written by hand.
    docs = (Path(__file__).resolve().parents[2] / "docs" / "scenarios.md").read_text()
    reference = scenario_reference.reference_markdown()
    notes = docs[len(reference):]
    assert docs[:len(reference)] == reference and notes.startswith("\n## Notes on the shipped scenarios\n"), (
        "docs/scenarios.md is stale: replace its part above the shipped scenarios' notes by "
        "`crossview scenarios --reference`")


def _holds_numbers(hint) -> bool:
    import typing

    return hint in (float, int) or any(_holds_numbers(a) for a in typing.get_args(hint) if a is not Ellipsis)


def test_every_key_has_a_meaning_and_every_number_a_range():
    import typing

    from sim.config import field_range, file_keys, is_table

    for section, cls, _ in scenario_reference._sections():
        docs = scenario_reference.attribute_docs(cls)
        hints = typing.get_type_hints(cls)
        for f in file_keys(cls):
            if is_table(hints[f.name]):
                continue
            assert docs.get(f.name), f"{section}{f.name} has no meaning in {cls.__name__}'s Attributes"
            if _holds_numbers(hints[f.name]):
                assert field_range(f) is not None, f"{section}{f.name} declares no range"


def test_megastore_is_the_hypermarket_four_times_over_at_its_density():
    # Issue 47's store beyond one core: a rig of 1,000 ceiling cameras and a crowd of 800 that its walkable floor
    # holds, at the hypermarket's cameras and people per m² of walkable floor (within 5 %). Nothing simulated.
    from sim.cameras import build_rig
    from sim.crowd import validate
    from sim.rng import child_rng
    from sim.store import StoreGeometry

    mega, hyper = scenario.load("megastore"), scenario.load("hypermarket")
    store = StoreGeometry(mega.store, name="megastore")
    rig = build_rig(mega, child_rng(mega.seed, "cameras"))
    validate(mega.crowd, store)
    cameras, people, floor = len({c.name for c in rig}), mega.crowd.people, store.free_area_m2
    assert (cameras, people) == (1000, 800)
    h_floor = StoreGeometry(hyper.store, name="hypermarket").free_area_m2
    h_cameras, h_people = hyper.cameras.rows * hyper.cameras.cols, hyper.crowd.people
    assert (h_cameras, h_people) == (240, 200)
    assert floor == pytest.approx(4 * h_floor, rel=0.05)
    assert cameras / floor == pytest.approx(h_cameras / h_floor, rel=0.05)
    assert people / floor == pytest.approx(h_people / h_floor, rel=0.05)
