"""Property: any scenario file, however wrong, loads into a valid Scenario or is refused with a
ScenarioError naming the file; a scenario that loads round-trips through its resolved TOML."""

import dataclasses
import json
import math
import tempfile
import typing
from pathlib import Path

from hypothesis import event, given
from hypothesis import strategies as st

from core.errors import ScenarioError
from sim import scenario as scenario_mod
from tests.fuzz import FUZZ

HINTS = typing.get_type_hints(scenario_mod.Scenario)
SECTIONS = {f.name: HINTS[f.name] for f in dataclasses.fields(scenario_mod.Scenario)
            if dataclasses.is_dataclass(HINTS[f.name])}
TOP_KEYS = ("description", "duration_s", "seed")

scalars = st.one_of(
    st.integers(-2**63, 2**63 - 1), st.integers(-3, 40),
    st.floats(allow_nan=True, allow_infinity=True), st.floats(-5.0, 100.0),
    st.booleans(), st.text(max_size=8), st.sampled_from(["typical", "ideal", "clean", "paper", "nan"]),
)
values = st.one_of(scalars, st.lists(scalars, max_size=4), st.lists(st.floats(-1.0, 20.0), min_size=2, max_size=2))


def _key_values(cls):
    keys = [f.name for f in dataclasses.fields(cls) if f.init]
    return st.dictionaries(st.one_of(st.sampled_from(keys), st.sampled_from(["typo", "people "])), values, max_size=4)


@st.composite
def trees(draw):
    tree = draw(st.dictionaries(st.sampled_from(TOP_KEYS), values, max_size=2))
    for section in draw(st.lists(st.sampled_from(sorted(SECTIONS)), max_size=3, unique=True)):
        tree[section] = draw(st.one_of(_key_values(SECTIONS[section]), values))  # (a value where a table goes)
    return tree


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return ("nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")) if not math.isfinite(v) else repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    return "[" + ", ".join(_toml_value(x) for x in v) + "]"


def to_toml(tree: dict) -> str:
    plain = [f"{json.dumps(k)} = {_toml_value(v)}" for k, v in tree.items() if not isinstance(v, dict)]
    tables = [f"[{k}]\n" + "".join(f"{json.dumps(kk)} = {_toml_value(vv)}\n" for kk, vv in v.items())
              for k, v in tree.items() if isinstance(v, dict)]
    return "\n".join(plain) + "\n" + "\n".join(tables)


@FUZZ
@given(trees())
def test_fuzz_any_scenario_file_loads_valid_or_is_refused_naming_the_file(tree):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "s.toml"
        path.write_text(to_toml(tree), encoding="utf-8")
        try:
            scenario = scenario_mod.load(path)
        except ScenarioError as e:
            assert str(e).startswith(f"{path}: "), e
            assert "\n" not in str(e)
            event("refused")
            return
        event("loaded")
        # A loaded scenario is valid through and through, and its resolved file loads back as the same.
        again = Path(folder) / "s.toml"
        again.write_text(scenario_mod.resolved_toml(scenario), encoding="utf-8")
        assert scenario_mod.load(again) == scenario


@FUZZ
@given(st.floats(2.0, 25.0), st.floats(2.0, 25.0), st.integers(1, 12), st.sampled_from(["x", "y"]),
       st.floats(0.2, 20.0), st.floats(0.2, 2.0), st.one_of(st.none(), st.floats(1.0, 5.0)), st.booleans(),
       st.booleans(), st.floats(0.2, 1.5))
def test_fuzz_an_aisles_layout_that_fits_is_a_store_people_can_walk(width, depth, count, along, length, gondola,
                                                                   front, back, sides, wall_depth):
    """Any [store.aisles] layout on any floor is refused naming an `aisles.` key, or expands to shelves inside
    the floor, apart, and leaving no floor cut off (at worst a door lands against one: the doors are [store]'s)."""
    from sim.store import AisleAxis, AislesConfig, StoreConfig, StoreGeometry

    aisles = AislesConfig(count=count, along=AisleAxis(along), gondola_length_m=length, gondola_width_m=gondola,
                          front_aisle_m=front, back_wall_shelf=back, side_wall_shelves=sides,
                          wall_shelf_depth_m=wall_depth)
    try:
        store = StoreConfig(width_m=width, depth_m=depth, ceiling_m=3.0, aisles=aisles)
    except ValueError as e:
        assert str(e).startswith("aisles."), e
        event("refused: does not fit")
        return
    try:
        StoreGeometry(store)
    except ScenarioError as e:
        assert str(e).startswith(("store: store.entrance_m: ", "store: store.exit_m: door")), e
        event("refused: a door against a shelf")
        return
    event("built")


@FUZZ
@given(st.integers(1, 3000), st.sampled_from([("[", "]"), ("{ a = ", " }")]),
       st.sampled_from(["duration_s", "crowd.people", "detector.offset_m"]))
def test_fuzz_a_value_nested_to_any_depth_is_refused_naming_the_file(depth, brackets, key):
    """Arrays or inline tables nested 1 to 3,000 deep (a RecursionError from 1,000 on, before core.tomlfile)."""
    opener, closer = brackets
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "s.toml"
        path.write_text(f"{key} = {opener * depth}1.0{closer * depth}\n", encoding="utf-8")
        try:
            scenario_mod.load(path)
        except ScenarioError as e:
            assert str(e).startswith(f"{path}: ") and "\n" not in str(e), e
            if depth >= 32 or depth <= 29:  # (a dotted key's tables count too: from 30 to 31 it depends on the key)
                assert ("nested more than 32 deep" in str(e)) == (depth >= 32), e
            return
        raise AssertionError(f"{key} nested {depth} deep was loaded")
