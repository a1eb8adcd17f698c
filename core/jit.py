"""The one compiler switch of the project's numeric kernels (numba's njit, or plain Python without numba), and
the small compiled helpers the kernels share.

Kernels decorated with `jit` are written in the subset of Python and numpy that numba compiles (scalar loops
over preallocated arrays), so they run unchanged as plain Python; `kernel.py_func` is that plain version.
"""

from __future__ import annotations

import gc

try:  # numba compiles the kernels (plain Python runs the same code, slowly, without it)
    from numba import njit as _njit

    def jit(function):
        """Compiles a numeric kernel once (cached on disk); the kernels are written for plain Python too."""
        return _njit(cache=True, nogil=True, error_model="numpy")(function)

    def prepare() -> None:
        """Does numba's one-time set-up of its compiler now (the first kernel called would do it): before a
        fork, so that the processes share it instead of each doing it.

        The set-up makes about a hundred thousand objects that live as long as the process and no garbage:
        it runs with Python's cyclic collector off, and then every object alive is frozen out of the
        collector's sight (`gc.freeze`), Python's own recipe before a fork: a collection in the child would
        write to their pages. (Without either, a whole `crossview generate store_layout2` takes about 8 %
        longer.)"""
        from numba.core.registry import cpu_target

        enabled = gc.isenabled()
        gc.disable()
        try:
            cpu_target.target_context.refresh()
            gc.freeze()
        finally:
            if enabled:
                gc.enable()
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
