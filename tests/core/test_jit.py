"""core.jit, the one compile switch: no other module uses numba, groups are closed under calls, the switch's
environment variables are checked, and a whole `crossview run` with compilation off gives what a compiled
one gives."""

from __future__ import annotations

import ast
import importlib
import json
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from core import jit, projection
from core.errors import ConfigError
from crossview.recording import wire

ROOT = Path(__file__).resolve().parents[2]
PRODUCT = ("core", "sim", "tracker", "crossview", "tools")
COMPILER = {"numba", "llvmlite"}


def _imported_packages(path: Path) -> set[str]:
    """The top-level packages a source file imports, anywhere in it."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def test_no_product_module_but_core_jit_imports_numba():
    offenders = [str(path.relative_to(ROOT)) for package in PRODUCT for path in sorted((ROOT / package).rglob("*.py"))
                 if path != ROOT / "core" / "jit.py" and _imported_packages(path) & COMPILER]
    assert offenders == []
    assert _imported_packages(ROOT / "core" / "jit.py") >= COMPILER  # (the scan sees imports where they are)


def _called_kernels(kernel) -> set:
    """The kernels a kernel's body names: its module's globals, and attributes of the modules it names."""
    body = kernel.py_func
    found = set()
    for name in body.__code__.co_names:
        value = body.__globals__.get(name)
        if isinstance(value, types.ModuleType):
            found.update(getattr(value, attribute) for attribute in body.__code__.co_names
                         if hasattr(getattr(value, attribute, None), "py_func"))
        elif hasattr(value, "py_func"):
            found.add(value)
    return found


def test_every_kernel_is_in_its_modules_group_and_no_group_calls_another():
    for modules in jit.GROUPS.values():
        for module in modules:
            importlib.import_module(module)
    group_of = {kernel: group for group, kernels in jit.KERNELS.items() for kernel in kernels}
    for group, kernels in jit.KERNELS.items():
        assert kernels, f"group {group} has no kernels"
        for kernel in kernels:
            assert kernel.py_func.__module__ in jit.GROUPS[group]
            for callee in _called_kernels(kernel):
                # a compiled kernel cannot call a plain one: kernels that call one another share a group
                assert group_of.get(callee, group) == group, (kernel.py_func.__qualname__, callee.py_func.__qualname__)
    assert jit.sort_prefix in jit.KERNELS["tracker.kernels"]


def test_the_switch_reads_its_environment_variables():
    assert jit._plain_groups({}) == frozenset()
    assert jit._plain_groups({"CROSSVIEW_JIT": "on"}) == frozenset()
    assert jit._plain_groups({"CROSSVIEW_JIT": "off"}) == frozenset(jit.GROUPS)
    listed = {"CROSSVIEW_JIT_PLAIN": " core.projection,crossview.recording.wire ,"}
    assert jit._plain_groups(listed) == {"core.projection", "crossview.recording.wire"}
    with pytest.raises(ConfigError, match=r"^CROSSVIEW_JIT_PLAIN: unknown kernel group 'sim.nope'; groups are sim"):
        jit._plain_groups({"CROSSVIEW_JIT_PLAIN": "core.projection,sim.nope"})
    with pytest.raises(ConfigError, match=r"^CROSSVIEW_JIT='fast': must be on .* or off"):
        jit._plain_groups({"CROSSVIEW_JIT": "fast"})


@pytest.mark.parametrize("value", [0.0, -0.0, 1.5, -3.25e-300, 5e-324, np.inf, -np.inf, np.nan, 2**52 + 1])
def test_the_plain_intrinsic_gives_numpys_bits(value):
    bits = int(np.array([value], dtype=np.float64).view(np.int64)[0])
    assert wire._plain_bits(value) == bits


def test_the_plain_fma_rounds_once():
    a, b, c = 1.0 + 2.0**-30, 1.0 - 2.0**-30, -1.0
    assert a * b + c == 0.0  # rounded twice: the product's -2^-60 is lost
    assert projection._plain_fma(a, b, c) == -(2.0**-60)  # rounded once, as LLVM's fma and OpenBLAS
    assert projection._plain_fma(0.1, 0.2, 0.3) == 0.1 * 0.2 + 0.3
    assert np.isnan(projection._plain_fma(np.inf, 0.0, 1.0))


def _run(tmp_path: Path, name: str, environ: dict) -> tuple[subprocess.CompletedProcess, Path]:
    out = tmp_path / name
    env = {k: v for k, v in os.environ.items() if k not in (jit.MODE_ENV, jit.PLAIN_ENV)} | environ
    process = subprocess.run([sys.executable, "-m", "crossview.cli", "--no-progress", "run", "--duration", "1",
                              "-o", str(out)], env=env, capture_output=True, text=True, cwd=tmp_path)
    return process, out


_TIMINGS = ("tracker_fps", "camera_frames_per_s")  # (wall-clock rates the score reports)


def test_a_run_with_compilation_off_writes_the_same_recording_and_scores_the_same(tmp_path):
    from crossview.recording.reader import open_tracks

    compiled, compiled_out = _run(tmp_path, "compiled", {})
    plain, plain_out = _run(tmp_path, "plain", {"CROSSVIEW_JIT": "off"})
    assert compiled.returncode == 0, compiled.stderr
    assert plain.returncode == 0, plain.stderr
    name = "store_layout1"  # the default scenario
    assert (plain_out / f"{name}.mcap").read_bytes() == (compiled_out / f"{name}.mcap").read_bytes()
    scores = [json.loads((out / f"{name}.score.json").read_text()) for out in (compiled_out, plain_out)]
    assert scores[0]["hota"] > 0 and scores[0]["pcp"] > 0
    for score in scores:
        for key in _TIMINGS:
            score.pop(key)
    assert scores[0] == scores[1]
    # The tracker's outputs as stored are the same; its float64 intermediates (the skeleton scene's points)
    # may differ in the last bits, where numba's and Python's maths libraries round differently.
    outputs = [list(open_tracks(out / f"{name}.tracks.mcap").outputs()) for out in (compiled_out, plain_out)]
    assert len(outputs[0]) == len(outputs[1]) > 0
    for a, b in zip(*outputs):
        assert a.stamp_s == b.stamp_s and a.camera == b.camera
        assert np.array_equal(a.detection_target_ids, b.detection_target_ids)
        assert [t.id for t in a.targets] == [t.id for t in b.targets]
        for s, t in zip(a.targets, b.targets):
            assert np.array_equal(s.pose, t.pose, equal_nan=True) and np.array_equal(s.joint_state, t.joint_state)


def test_an_unknown_kernel_group_is_one_line_exit_2(tmp_path):
    process, out = _run(tmp_path, "out", {"CROSSVIEW_JIT_PLAIN": "sim.nope"})
    assert process.returncode == 2
    assert process.stderr.count("\n") == 1 and "Traceback" not in process.stderr
    assert "CROSSVIEW_JIT_PLAIN: unknown kernel group 'sim.nope'" in process.stderr
    assert not out.exists()
