"""A compiled kernel as plain Python all the way down: the reference the "compiled equals plain" tests run.

`kernel.py_func` alone is the kernel's own body uncompiled, but the kernels it calls are still the compiled
dispatchers it finds among its module's globals. `plain_python` rebuilds the body over a copy of those globals
in which every compiled callee is itself replaced by its plain version, recursively, so that the comparison
sets numba's whole output against the interpreter's.
"""

from __future__ import annotations

import types


def _is_kernel(value) -> bool:
    """A numba dispatcher (or the plain stand-in `core.jit` makes without numba): callable, with `py_func`."""
    return callable(value) and callable(getattr(value, "py_func", None))


def plain_python(kernel, _made: dict | None = None) -> types.FunctionType:
    """`kernel` and every kernel it reaches through its module's globals, uncompiled."""
    made = {} if _made is None else _made
    if kernel in made:
        return made[kernel]
    body = kernel.py_func
    namespace = dict(body.__globals__)
    function = types.FunctionType(body.__code__, namespace, body.__name__, body.__defaults__, body.__closure__)
    made[kernel] = function
    for name in body.__code__.co_names:
        value = namespace.get(name)
        if _is_kernel(value):
            namespace[name] = plain_python(value, made)
    return function


def reaches_compiled_code(function: types.FunctionType, _seen: set | None = None) -> bool:
    """Whether `function`, or a plain function it calls through its globals, would still call a compiled kernel."""
    seen = set() if _seen is None else _seen
    if function in seen:
        return False
    seen.add(function)
    for name in function.__code__.co_names:
        value = function.__globals__.get(name)
        if _is_kernel(value):
            return True
        if isinstance(value, types.FunctionType) and reaches_compiled_code(value, seen):
            return True
    return False
