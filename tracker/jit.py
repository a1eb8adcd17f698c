"""The one compiler switch of the project's numeric kernels: numba's njit, or plain Python without numba.

Kernels decorated with `jit` are written in the subset of Python and numpy that numba compiles (scalar loops
over preallocated arrays), so they run unchanged as plain Python; `kernel.py_func` is that plain version.
"""

from __future__ import annotations

try:  # numba compiles the kernels (plain Python runs the same code, slowly, without it)
    from numba import njit as _njit

    def jit(function):
        """Compiles a numeric kernel once (cached on disk); the kernels are written for plain Python too."""
        return _njit(cache=True, nogil=True, error_model="numpy")(function)
except ImportError:  # pragma: no cover - numba is a dependency; this keeps the code importable without it
    def jit(function):
        function.py_func = function
        return function
