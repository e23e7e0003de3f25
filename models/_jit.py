"""Optional numba compilation for the fatigue hot loops (numba is a declared dependency;
every compiled loop also runs as plain Python/numpy so the models work without it)."""

from __future__ import annotations

try:
    import numba
except ImportError:  # pragma: no cover - exercised only where numba is missing
    numba = None


def compile_loop(func):
    """``func`` compiled with numba (cached on disk), or None when numba is unavailable."""
    if numba is None:  # pragma: no cover
        return None
    return numba.njit(cache=True, nogil=True)(func)
