"""Optional numba compilation for the fatigue hot loops (numba is a declared dependency;
every compiled loop also runs as plain Python/numpy so the models work without it).

- ``compile_loop(func)``: ``func`` compiled (cached on disk), or None without numba.
- ``jitable(func)``: ``func`` unchanged for Python callers; compiled in place where a
  compiled loop calls it (so shared building blocks need no compiled twin).
- ``float_bits(x)`` / ``bits_float(i)``: reinterpret float64 <-> int64 bits;
  ``select(cond, a, b)``: ``a`` where ``cond`` else ``b``. In Python they take numpy
  arrays or scalars (numpy ``view`` / ``where``); compiled they are scalar bit casts and
  branch-free selects, which keep loops vectorisable.

numba's disk cache only tracks the source file of the compiled function, so a ``jitable``
building block must live in the same file as the loops that call it (else editing it
would leave their cached machine code stale). The three scalar overloads below are the
exception: they are compiled into callers elsewhere, so change them only together with a
change to those files (or clear the ``__pycache__`` caches).
"""

from __future__ import annotations

import numpy as np

try:
    import numba
except ImportError:  # pragma: no cover - exercised only where numba is missing
    numba = None  # type: ignore[assignment]  # the compiled loops are then None


def compile_loop(func):
    """``func`` compiled with numba (cached on disk), or None when numba is unavailable."""
    if numba is None:  # pragma: no cover
        return None
    # error_model="numpy": x / 0 is inf, not a raised ZeroDivisionError; the check it
    # saves would be a branch in every loop with a division, blocking vectorisation
    return numba.njit(cache=True, nogil=True, error_model="numpy")(func)


def jitable(func):
    """``func`` itself; compiled code calling it compiles it inline."""
    if numba is not None:
        numba.extending.register_jitable(error_model="numpy")(func)
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


if numba is not None:
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
