"""The one compiler switch of the project's numeric kernels (numba's njit, or plain Python without numba), and
the small compiled helpers the kernels share.

Kernels decorated with `jit` are written in the subset of Python and numpy that numba compiles (scalar loops
over preallocated arrays), so they run unchanged as plain Python; `kernel.py_func` is that plain version.
"""

from __future__ import annotations

import contextlib
import gc


@contextlib.contextmanager
def _collector_paused():
    """Python's cyclic garbage collector off for the block, and what the block made frozen out of its sight
    (`gc.freeze`) at the end. For numba's set-up: it makes a hundred thousand objects that live as long as
    the process and no garbage, and the collections its allocations trigger found nothing (70 ms of it), and
    would find nothing in them later either. Frozen before a fork, they also stay shared with the child
    (Python's recipe: a collection there would write to their pages)."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
        gc.freeze()
    finally:
        if enabled:
            gc.enable()


try:  # numba compiles the kernels (plain Python runs the same code, slowly, without it)
    from numba import njit as _njit

    def jit(function):
        """Compiles a numeric kernel once (cached on disk); the kernels are written for plain Python too."""
        return _njit(cache=True, nogil=True, error_model="numpy")(function)

    def prepare() -> None:
        """Does numba's one-time set-up of its compiler now (about a third of a second: the first kernel
        called would do it): before a fork, so that the processes share it instead of each doing it."""
        from numba.core.registry import cpu_target

        with _collector_paused():
            cpu_target.target_context.refresh()
except ImportError:  # pragma: no cover - numba is a dependency; this keeps the code importable without it
    def jit(function):
        function.py_func = function
        return function

    def prepare() -> None:
        pass


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
