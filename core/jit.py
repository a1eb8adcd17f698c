"""The one compiler switch of the project's numeric kernels (numba's njit, or plain Python), and the small
compiled helpers the kernels share. No other module imports numba or llvmlite.

Kernels decorated with `jit` are written in the subset of Python and numpy that numba compiles (scalar loops
over preallocated arrays), so they run unchanged as plain Python; `kernel.py_func` is that plain version.
Each kernel belongs to a group, `GROUPS`: the kernels of one module, or of a few modules whose kernels call
one another (a compiled kernel cannot call a plain one, so such modules compile, or not, together).

The switch, read once when this module is imported (before any kernel is defined):

- ``CROSSVIEW_JIT=off`` runs every kernel as plain Python (``on``, the default, compiles them);
- ``CROSSVIEW_JIT_PLAIN=group,group`` runs the listed groups' kernels as plain Python and compiles the rest.

Without numba every kernel is plain Python. An unknown value or group name is a one-line error. Plain runs
write the same recordings as compiled ones (the intrinsics' plain versions compute the same bits); they are
for checking that and for measuring what compiling a group buys (`tools/kernel_ledger.py`).
"""

from __future__ import annotations

import contextlib
import gc
import mmap
import os
import sys
from collections.abc import Callable
from pathlib import Path

from core.errors import ConfigError

MODE_ENV = "CROSSVIEW_JIT"
PLAIN_ENV = "CROSSVIEW_JIT_PLAIN"
GROUPS: dict[str, tuple[str, ...]] = {
    # group: the modules whose kernels it holds
    "sim.world": ("sim.world",),
    "sim.crowd": ("sim.crowd",),
    "sim.store": ("sim.store",),
    "sim.gestures": ("sim.gestures",),
    "core.poses": ("core.poses",),
    "core.projection": ("core.projection",),
    "sim.sensing.rays": ("sim.sensing.rays",),
    "sim.sensing.draws": ("sim.sensing.draws",),
    "sim.sensing.offsets": ("sim.sensing.offsets",),
    "crossview.recording.wire": ("crossview.recording.wire",),
    "tracker.geometry": ("tracker.geometry",),
    "tracker.visibility": ("tracker.visibility",),
    "tracker.affinity": ("tracker.affinity",),
    "tracker.initialization": ("tracker.initialization",),
    # the frame's kernels call the body's and triangulation's, which call `sort_prefix` (below)
    "tracker.kernels": ("tracker.kernels", "tracker.body", "tracker.triangulation", "core.jit"),
}
_GROUP_OF_MODULE = {module: group for group, modules in GROUPS.items() for module in modules}
KERNELS: dict[str, list] = {group: [] for group in GROUPS}
"""Every kernel defined so far (the modules imported), by group."""


def _plain_groups(environ) -> frozenset[str]:
    """The groups that run as plain Python under the switch's environment variables."""
    mode = environ.get(MODE_ENV, "on").strip().lower()
    if mode not in ("on", "off"):
        raise ConfigError(f"{MODE_ENV}={environ[MODE_ENV]!r}: must be on (compile the kernels) or off (plain Python)")
    if mode == "off":
        return frozenset(GROUPS)
    names = [name.strip() for name in environ.get(PLAIN_ENV, "").split(",") if name.strip()]
    unknown = [name for name in names if name not in GROUPS]
    if unknown:
        raise ConfigError(f"{PLAIN_ENV}: unknown kernel group {unknown[0]!r}; groups are {', '.join(GROUPS)}")
    return frozenset(names)


try:  # numba compiles the kernels (plain Python runs the same code, slowly, without it)
    import numba
    from llvmlite import ir as llvm_ir
    from numba import types
    from numba.extending import intrinsic as _numba_intrinsic
except ImportError:  # pragma: no cover - numba is a dependency; this keeps the code importable without it
    numba = llvm_ir = types = None

PLAIN = frozenset(GROUPS) if numba is None else _plain_groups(os.environ)
"""The groups whose kernels run as plain Python in this process."""


def group_of(function) -> str:
    """The group of a kernel (or intrinsic) defined in `function`'s module."""
    try:
        return _GROUP_OF_MODULE[function.__module__]
    except KeyError:
        raise ValueError(f"{function.__module__}.{function.__qualname__}: its module is in no group of "
                         "core.jit.GROUPS; add it there") from None


def jit(function):
    """Compiles a numeric kernel once (cached on disk), unless its group runs as plain Python."""
    group = group_of(function)
    if group in PLAIN:
        function.py_func = function
        kernel = function
    else:
        kernel = numba.njit(cache=True, nogil=True, error_model="numpy")(function)
    KERNELS[group].append(kernel)
    return kernel


def intrinsic(plain):
    """numba's `intrinsic` (a function that emits LLVM IR into the compiled kernels that call it) with its
    plain Python version: the decorated typing function serves compiled groups, `plain` (the same result,
    bit for bit) the plain ones.

    Args:
        plain: the Python function the intrinsic stands for, called with the intrinsic's arguments.
    """

    def decorate(typer):
        return plain if group_of(typer) in PLAIN else _numba_intrinsic(typer)

    return decorate


def cold_cache() -> bool:
    """Whether some compiled group's kernels have no index in numba's on-disk cache (a first run, a fresh clone):
    the command that calls them then compiles them first, about a minute. Looked up where numba keeps them: the
    `__pycache__` beside each module, or under $NUMBA_CACHE_DIR (`<module>.<kernel>-<line>.pyXY.nbi`). A changed
    kernel of an older cache is not seen."""
    if numba is None:
        return False
    root = Path(__file__).resolve().parents[1]
    tag = f"py{sys.version_info.major}{sys.version_info.minor}.nbi"
    custom = os.environ.get("NUMBA_CACHE_DIR")
    for group, modules in GROUPS.items():
        if group in PLAIN:
            continue
        for module in modules:
            source = root.joinpath(*module.split("."))
            pattern = f"{source.name}.*.{tag}"
            found = any(source.parent.joinpath("__pycache__").glob(pattern)) or bool(
                custom and any(Path(custom).rglob(pattern)))
            if not found:
                return True
    return False


@contextlib.contextmanager
def saying_when_compiling(say: Callable[[], None]):
    """Within the block, `say()` is called once, as numba starts its first compile (never when every kernel loads
    from its cache), in this process or a worker forked from it within the block (the flag saying whether it was
    said is shared memory, so the line comes once). Through numba's event API ("numba:compile")."""
    if numba is None:
        yield
        return
    from numba.core import event

    said = mmap.mmap(-1, 1)  # (anonymous and shared: a forked worker sees and sets the same byte)

    class _Listener(event.Listener):
        def on_start(self, ev):
            if said[0] == 0:
                said[0] = 1
                say()

        def on_end(self, ev):
            pass

    listener = _Listener()
    event.register("numba:compile", listener)
    try:
        yield
    finally:
        event.unregister("numba:compile", listener)
        said.close()


def prepare() -> None:
    """Does numba's one-time set-up of its compiler now (the first kernel called would do it): before a
    fork, so that the processes share it instead of each doing it.

    The set-up makes about a hundred thousand objects that live as long as the process and no garbage:
    it runs with Python's cyclic collector off, and then every object alive is frozen out of the
    collector's sight (`gc.freeze`), Python's own recipe before a fork: a collection in the child would
    write to their pages. (Without either, a whole `crossview generate store_layout2` takes about 8 %
    longer.) Nothing to do when every group is plain."""
    if numba is None or PLAIN == frozenset(GROUPS):
        return
    from numba.core.registry import cpu_target

    enabled = gc.isenabled()
    gc.disable()
    try:
        cpu_target.target_context.refresh()
        gc.freeze()
    finally:
        if enabled:
            gc.enable()


@jit
def sort_prefix(values, n):
    """Sorts values[:n] in place (insertion sort: the kernels sort a few dozen numbers, and numba compiles
    this in a fraction of the time np.sort takes)."""
    for i in range(1, n):
        v = values[i]
        k = i - 1
        while k >= 0 and values[k] > v:
            values[k + 1] = values[k]
            k -= 1
        values[k + 1] = v
