"""How a ``buoymon`` command sets numba up when it first imports it (:func:`prepare_numba`).

1. A notice on stderr when the process compiles a kernel. numba compiles a kernel on its
   first call unless its on-disk cache (``__pycache__`` beside the source, or
   ``NUMBA_CACHE_DIR``) holds the machine code; compiling all of buoymon's takes about
   35 s of CPU on the 2-core machine, which must never pass in silence inside a command
   (issue 22). ``buoymon warmup`` fills the cache at install and service start; when a
   command still has to compile (cache cleared or not writable, numba upgraded, a kernel
   edited), one line says so, naming the first kernel.
2. numba's CPU target loads without scipy. Loading the first (cached) kernel imports all
   of ``scipy.linalg`` to offer BLAS to ``np.dot`` in compiled code, which no kernel here
   calls: 0.16 s of the 0.9 s of CPU a replay of a tiny log took (measured 2026-11-25 with
   cProfile, 2-core Xeon). scipy is hidden (``None`` in ``sys.modules``: numba takes the
   ImportError as "no scipy") while numba imports and its target loads, then given back,
   so a command that uses scipy itself still imports it. (The daemon keeps scipy out for
   good, for its memory: monitor.cmd_run.keep_scipy_out.)

numba is imported late (``buoymon check-config`` never imports it: 0.22 s saved), so this
happens when numba is first imported, through a finder on ``sys.meta_path`` that wraps
numba's loader; nothing is imported before then.
"""

from __future__ import annotations

import contextlib
import functools
import sys
from typing import Any, Callable, Iterator, TextIO

NOTICE = ("buoymon: compiling numerical kernels ({name}); a one-time cost of up to a "
          "minute, kept in numba's cache (`buoymon warmup` does it ahead of time)")


def prepare_numba(stream: TextIO | None = None) -> None:
    """From now on (or as soon as numba is imported), print :data:`NOTICE` to ``stream``
    (default stderr) the first time this process compiles a kernel; numba's first import
    and target load without scipy. Idempotent."""
    after_numba_import(lambda: _register(stream))


def after_numba_import(then: Callable[[], None]) -> None:
    """Run ``then()`` now if numba is imported, else right after its first import (which
    loads numba's CPU target without scipy, see above); nothing is imported here."""
    if "numba" in sys.modules:
        then()
        return
    finder = next((f for f in sys.meta_path if isinstance(f, _AfterImport)), None)
    if finder is None:
        sys.meta_path.insert(0, _AfterImport("numba", then))
    else:
        finder.thens.append(then)


@contextlib.contextmanager
def _scipy_hidden() -> Iterator[None]:
    """``import scipy`` raises ImportError inside (unless scipy is already imported)."""
    if "scipy" in sys.modules:
        yield
        return
    sys.modules["scipy"] = None  # type: ignore[assignment]
    try:
        yield
    finally:
        if "scipy" in sys.modules and sys.modules["scipy"] is None:
            del sys.modules["scipy"]


@functools.cache  # one listener per process, however often a command is run in it
def _register(stream: TextIO | None) -> None:
    from numba.core import event

    class _Notice(event.Listener):
        def __init__(self) -> None:
            self.said = False

        def on_start(self, ev: event.Event) -> None:
            if not self.said:
                self.said = True
                func = ev.data["dispatcher"].py_func
                print(NOTICE.format(name=f"{func.__module__}.{func.__qualname__}"),
                      file=stream or sys.stderr, flush=True)

        def on_end(self, ev: event.Event) -> None:
            pass

    event.register("numba:compile", _Notice())


class _AfterImport:
    """A ``sys.meta_path`` finder that runs each of ``thens`` right after module ``name`` is
    first imported (then steps aside). Duck-typed: importlib.abc costs 5 ms of a 40 ms --help."""

    def __init__(self, name: str, then: Callable[[], None]):
        self.name, self.thens = name, [then]

    def find_spec(self, fullname, path, target=None):
        if fullname != self.name:
            return None
        # the other finders' spec, its loader wrapped; a mere look-up (importlib.util.find_spec
        # in models._jit) runs no loader, so this finder stays until the module is loaded
        for finder in sys.meta_path:
            spec = None if finder is self else finder.find_spec(fullname, path, target)
            if spec is not None:
                if spec.loader is not None:
                    spec.loader = _ThenLoader(spec.loader, self._loaded)
                return spec
        return None

    def _loaded(self) -> None:
        if self in sys.meta_path:
            sys.meta_path.remove(self)
        for then in self.thens:
            then()


class _ThenLoader:
    """``loader``, running ``then()`` after it has executed the module."""

    def __init__(self, loader: Any, then: Callable[[], None]):
        self.loader, self.then = loader, then

    def create_module(self, spec: Any):
        return self.loader.create_module(spec)

    def exec_module(self, module) -> None:
        with _scipy_hidden():
            self.loader.exec_module(module)
            from numba.core.registry import cpu_target

            cpu_target.target_context.refresh()  # what loading the first cached kernel does
        self.then()

    def __getattr__(self, name: str):  # the rest of the loader API (resource readers...)
        return getattr(self.loader, name)
