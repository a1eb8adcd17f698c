"""Scenario files: every shipped one loads; bad files fail with the file and key named."""

from pathlib import Path

import pytest

from sim import scenario
from sim.detector import DetectorProfile

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
    with pytest.raises(scenario.ScenarioError, match="duration_s"):
        scenario.load(None, {"duration_s": -1.0})


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
    with pytest.raises(scenario.ScenarioError, match=expected):
        scenario.load(_write(tmp_path, text))


def test_missing_file_lists_the_shipped_scenarios(tmp_path):
    with pytest.raises(scenario.ScenarioError, match="no such scenario file.*store_layout1"):
        scenario.load(tmp_path / "nope.toml")
