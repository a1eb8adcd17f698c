"""Test-suite options: where the full real datasets are, for the longer checks that the fixtures cannot make.

The suite passes in a fresh clone with nothing beside it: the real-data tests read the small fixtures cut into
tests/data/ (tests/data/README.md). The checks on the whole Campus sequence take its folder from
`--campus-data DIR` or the environment variable CROSSVIEW_CAMPUS_DATA, and skip with a reason without it.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parent / "data"
CAMPUS_FILES = ("calibration.json", "annotation_2d.json", "annotation_3d.json", "result_3d.json")
CAMPUS_ENV = "CROSSVIEW_CAMPUS_DATA"


def pytest_addoption(parser):
    parser.addoption("--campus-data", metavar="DIR", default=os.environ.get(CAMPUS_ENV) or None,
                     help=f"the whole Campus dataset in the crossview layout ({', '.join(CAMPUS_FILES)}); "
                          f"default: ${CAMPUS_ENV}")


def campus_data_problem(path: Path) -> str | None:
    """Why `path` is not a Campus dataset folder in the crossview layout, in one line (None: it is)."""
    if not path.is_dir():
        return f"--campus-data {path}: no such folder (expected the Campus dataset in the crossview layout)"
    missing = [name for name in CAMPUS_FILES if not (path / name).is_file()]
    if missing:
        expected = ", ".join(CAMPUS_FILES)
        return f"--campus-data {path}: lacks {', '.join(missing)} (expected the crossview layout: {expected})"
    return None


def pytest_report_header(config):
    given = config.getoption("--campus-data")
    if not given:
        return f"full Campus data: not given (--campus-data DIR or ${CAMPUS_ENV}); the fixtures in tests/data are used"
    return f"full Campus data: {campus_data_problem(Path(given)) or given}"


@pytest.fixture(scope="session")
def campus_full(request) -> Path:
    """The whole Campus dataset folder; the test skips without one and fails in one line on a bad one."""
    given = request.config.getoption("--campus-data")
    if not given:
        pytest.skip(f"full Campus data not given (pass --campus-data DIR or set ${CAMPUS_ENV})")
    path = Path(given)
    problem = campus_data_problem(path)
    if problem:
        pytest.fail(problem, pytrace=False)
    return path


@pytest.fixture(scope="session", params=["fixture", "full"])
def campus_dir(request) -> Path:
    """The Campus dataset: the cut in tests/data/campus, then (with --campus-data) the whole sequence."""
    if request.param == "fixture":
        return DATA / "campus"
    return request.getfixturevalue("campus_full")


# What CI expects of offscreen rendering (.ci/run): "required" (a missing backend fails instead of skipping) or
# "absent" (a backend that opens fails: the step that hid EGL and OSMesa did not hide them). Unset: skip.
RENDERING_ENV = "CROSSVIEW_RENDERING"
_RENDERING_EXPECTATIONS = ("required", "absent")


def pytest_configure(config):
    config.addinivalue_line("markers", "rendering: renders through MuJoCo offscreen, or depends on what OpenGL "
                            "libraries the machine has (`pytest -m rendering`)")
    expected = os.environ.get(RENDERING_ENV)
    if expected and expected not in _RENDERING_EXPECTATIONS:
        raise pytest.UsageError(f"{RENDERING_ENV}={expected}: expected one of {', '.join(_RENDERING_EXPECTATIONS)} "
                                "or unset")


def pytest_collection_modifyitems(items):
    for item in items:  # every test that renders is a rendering test, whatever its file
        if "offscreen_backend" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.rendering)


@pytest.fixture(scope="session")
def offscreen_backend() -> str:
    """The MuJoCo offscreen backend that works here ("egl" or "osmesa", probed by `sim.render.probe_backend`,
    each in a fresh interpreter); the test skips without one, or fails where CI expects otherwise
    (`RENDERING_ENV`). Renders run in a fresh interpreter with MUJOCO_GL set to it (MuJoCo picks its backend
    at import)."""
    from sim.render import GLBackend, backend_problem, probe_backend

    backend = probe_backend()
    expected = os.environ.get(RENDERING_ENV)
    if backend is None:
        problems = "; ".join(f"{b.value}: {backend_problem(b)}" for b in GLBackend)
        reason = (f"MuJoCo cannot open an offscreen OpenGL context here ({problems}); install Debian's libosmesa6 "
                  "for OSMesa, or run where EGL works")
        if expected == "required":
            pytest.fail(f"{reason}; {RENDERING_ENV}=required, so this may not skip", pytrace=False)
        pytest.skip(reason)
    if expected == "absent":
        pytest.fail(f"{RENDERING_ENV}=absent, but MuJoCo opens an offscreen {backend.value} context here",
                    pytrace=False)
    return backend.value


def render_env(backend: str) -> dict:
    """The environment of a fresh interpreter that renders with `backend`."""
    return {**os.environ, "MUJOCO_GL": backend, "PYOPENGL_PLATFORM": backend}
