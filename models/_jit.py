"""numba compilation of the numerical kernels, or none: every kernel also runs as plain
Python/numpy with the same bits (numba is a declared dependency; the models work without it,
and a small job runs uncompiled rather than pay for loading numba).

- ``HAVE_NUMBA``: numba is installed (found without importing it).
- ``kernel(**options)``: decorator making a loop a :class:`Kernel`, numba's ``njit`` with
  ``options`` (cached on disk) when compiled, the function itself when not; callable from
  Python and from other kernels alike.
- ``uncompiled()``: context in which every kernel runs as plain Python and numba is never
  imported (the one switch: for work too small to repay numba's start-up, see below);
  ``compiled()`` turns it off again inside (for a long model build a small job starts).
- ``compile_loop(func)``: ``func`` as a kernel with the fatigue loops' options.
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

Compiled or not, a kernel is the same function, so it gives the same bits: the loops use
IEEE-754 arithmetic without fast-math (no contraction, no reassociation), integer steps on
int64 (buffers are read as ``np.int64(buf[p])``), and elementary functions that are libm's
both ways: compiled, numba calls libm; as plain Python, ``math`` does too except for
``math.hypot`` (Python's own: use ``np.hypot``), and numpy's scalar ``arcsin`` is numpy's
own (use ``math.asin``); ``np.sin``/``np.cos``/``np.sqrt`` agree (tests/test_plain_kernels.py).
Loading numba and its CPU target for a cached kernel costs about 0.55 s of CPU (measured
2026-11-25, 2-core Xeon), more than a replay of a log of a few minutes spends in all its
loops as plain Python; ``replay.runner.plain_python_pays`` chooses per process from the
logs' inflated size (:func:`uncompiled` around the whole run, read-ahead thread included:
the choice is process-wide because loading numba is).

numba's disk cache only tracks the source file of the compiled function, so a ``jitable``
building block must live in the same file as the loops that call it (else editing it
would leave their cached machine code stale). The three scalar overloads below are the
exception: they are compiled into callers elsewhere, so change them only together with a
change to those files (or clear the ``__pycache__`` caches). The same holds for a kernel
called from a kernel of another file (numba inlines or links it into the caller's cached
code): ``models.dynamics.jerk_step`` in ``models.estimator``'s loops, ``monitor.qartod``'s
kernels in ``monitor.validate``'s. Editing the callee alone leaves the caller's cached code
stale until the caller's file changes: touch it (or clear the caches). An install or a fresh
checkout is never affected (every file is new to the cache).
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
from types import ModuleType
from typing import Any, Callable, Iterator

import numpy as np

HAVE_NUMBA = importlib.util.find_spec("numba") is not None

# building blocks to register with numba when it is first imported (numba_module())
_JITABLES: list[Callable] = []


class _Dispatch:
    """How kernels run in this process: compiled unless inside :func:`uncompiled`."""

    depth = 0  # nesting of uncompiled(); a class attribute: the choice is process-wide


class Kernel:
    """A loop run compiled by numba (``njit(**options)``, compiled or loaded from the disk
    cache on first use) or, inside :func:`uncompiled` or without numba, as the plain Python
    function ``py_func``. Compiled code calling a kernel calls its compiled form (numba
    types it as its dispatcher; ``targetoptions`` is where numba's inliner looks for
    ``inline``)."""

    def __init__(self, func: Callable, options: dict[str, Any]):
        functools.update_wrapper(self, func)
        self.py_func = func
        self.targetoptions = options
        self._compiled: Callable | None = None

    @property
    def compiled(self) -> Callable:
        """numba's dispatcher of ``py_func`` (created on first use: imports numba)."""
        if self._compiled is None:
            self._compiled = numba_module().njit(**self.targetoptions)(self.py_func)
        return self._compiled

    def __call__(self, *args: Any) -> Any:
        if _Dispatch.depth or not HAVE_NUMBA:
            # compiled code raises no floating-point warnings (x / 0 is inf, int64 wraps):
            # neither do numpy's scalars here
            with np.errstate(all="ignore"):
                return self.py_func(*args)
        return (self._compiled or self.compiled)(*args)


def kernel(**options: Any) -> Callable[[Callable], Kernel]:
    """Decorator: the function as a :class:`Kernel` compiled with numba's ``njit(cache=True,
    **options)``."""
    return lambda func: Kernel(func, {"cache": True, **options})


@contextlib.contextmanager
def uncompiled() -> Iterator[None]:
    """Every kernel runs as plain Python inside (in every thread): the same bits, and numba
    is not imported by them."""
    _Dispatch.depth += 1
    try:
        yield
    finally:
        _Dispatch.depth -= 1


@contextlib.contextmanager
def compiled() -> Iterator[None]:
    """Kernels run compiled inside, even within :func:`uncompiled`: for long work (a model
    build) that a small job may start."""
    depth, _Dispatch.depth = _Dispatch.depth, 0
    try:
        yield
    finally:
        _Dispatch.depth = depth


def compile_loop(func: Callable) -> Kernel:
    """``func`` as a kernel with the fatigue loops' options."""
    # error_model="numpy": x / 0 is inf, not a raised ZeroDivisionError; the check it
    # saves would be a branch in every loop with a division, blocking vectorisation
    return Kernel(func, {"cache": True, "nogil": True, "error_model": "numpy"})


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
    from numba.extending import intrinsic, overload, typeof_impl

    @typeof_impl.register(Kernel)
    def _typeof_kernel(val, c):  # a kernel called from compiled code: its dispatcher
        return types.Dispatcher(val.compiled)

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
