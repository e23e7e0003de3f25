"""Optional numba compilation for the fatigue hot loops (numba is a declared dependency;
every compiled loop also runs as plain Python/numpy so the models work without it).

- ``HAVE_NUMBA``: numba is installed (found without importing it).
- ``compile_loop(func)``: ``func`` compiled (cached on disk), or None without numba.
- ``jitable(func)``: ``func`` unchanged for Python callers; compiled in place where a
  compiled loop calls it (so shared building blocks need no compiled twin).
- ``numba_module()``: numba, with the ``jitable`` functions and the overloads below
  registered (for code that compiles its own loops over them: tests, benchmarks).
- ``float_bits(x)`` / ``bits_float(i)``: reinterpret float64 <-> int64 bits;
  ``select(cond, a, b)``: ``a`` where ``cond`` else ``b``. In Python they take numpy
  arrays or scalars (numpy ``view`` / ``where``); compiled they are scalar bit casts and
  branch-free selects, which keep loops vectorisable.

numba is imported on the first compilation, not with this module: importing it costs
0.22 s of CPU (measured 2026-11-25, 2-core Xeon: ``python -X importtime``), more than half
of ``buoymon check-config``, which builds the cable and S-N curves but runs no loop.

numba's disk cache only tracks the source file of the compiled function, so a ``jitable``
building block must live in the same file as the loops that call it (else editing it
would leave their cached machine code stale). The three scalar overloads below are the
exception: they are compiled into callers elsewhere, so change them only together with a
change to those files (or clear the ``__pycache__`` caches).
"""

from __future__ import annotations

import functools
import importlib.util
from types import ModuleType
from typing import Callable

import numpy as np

HAVE_NUMBA = importlib.util.find_spec("numba") is not None

# building blocks to register with numba when it is first imported (numba_module())
_JITABLES: list[Callable] = []


def compile_loop(func: Callable) -> Callable | None:
    """``func`` compiled with numba (cached on disk), or None when numba is unavailable."""
    if not HAVE_NUMBA:  # pragma: no cover
        return None
    # error_model="numpy": x / 0 is inf, not a raised ZeroDivisionError; the check it
    # saves would be a branch in every loop with a division, blocking vectorisation
    return numba_module().njit(cache=True, nogil=True, error_model="numpy")(func)


def jitable(func: Callable) -> Callable:
    """``func`` itself; compiled code calling it compiles it inline."""
    _JITABLES.append(func)
    if numba_module.cache_info().currsize:  # numba already set up: register now
        _register(numba_module(), func)
    return func


def float_bits(x):
    """IEEE-754 bits of float64 ``x`` as int64 (same shape)."""
    return np.asarray(x, dtype=np.float64).view(np.int64)


def bits_float(i):
    """float64 whose IEEE-754 bits are the int64 ``i`` (same shape)."""
    return np.asarray(i, dtype=np.int64).view(np.float64)


def select(cond, a, b):
    """``a`` where ``cond`` holds, else ``b``."""
    return np.where(cond, a, b)


def _register(numba: ModuleType, func: Callable) -> None:
    numba.extending.register_jitable(error_model="numpy")(func)


@functools.cache
def numba_module() -> ModuleType:
    """numba, imported once, with the scalar overloads and the ``jitable`` functions
    registered (ImportError without numba)."""
    import numba
    import numba.extending
    from llvmlite import ir
    from numba.core import types
    from numba.extending import intrinsic, overload

    @intrinsic
    def _f64_as_i64(typingctx, x):
        def codegen(context, builder, signature, args):
            return builder.bitcast(args[0], ir.IntType(64))
        return types.int64(types.float64), codegen

    @intrinsic
    def _i64_as_f64(typingctx, i):
        def codegen(context, builder, signature, args):
            return builder.bitcast(args[0], ir.DoubleType())
        return types.float64(types.int64), codegen

    @overload(float_bits)
    def _float_bits_scalar(x):
        if isinstance(x, types.Float):
            return lambda x: _f64_as_i64(np.float64(x))

    @overload(bits_float)
    def _bits_float_scalar(i):
        if isinstance(i, types.Integer):
            return lambda i: _i64_as_f64(np.int64(i))

    @overload(select)
    def _select_scalar(cond, a, b):
        if isinstance(cond, types.Boolean):
            return lambda cond, a, b: a if cond else b

    for func in _JITABLES:
        _register(numba, func)
    return numba
