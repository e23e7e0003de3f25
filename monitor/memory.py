"""Resident memory the daemon no longer needs: the JIT compiler's library pages.

numba compiles (or loads from its cache) the kernels with LLVM when the pipeline is built.
Doing so touches tens of megabytes of ``libllvmlite``'s code, which then stay resident and
count in the process's RSS although a steady daemon never runs LLVM again: the compiled
kernels are plain machine code. :func:`release_compiler_pages` asks Linux to reclaim those
pages (``madvise(MADV_PAGEOUT)``, Linux >= 5.4). It is only a hint: the mapping's contents
do not change, and should LLVM run again (a kernel compiled for a new argument type) its
pages are read back from the page cache. Elsewhere it does nothing.
"""

from __future__ import annotations

import ctypes
import logging
import os
import sys

log = logging.getLogger("buoymon.memory")

_MADV_PAGEOUT = 21  # linux/mman.h
_LIBRARIES = ("libllvmlite",)  # the compiler; the kernels it produced live elsewhere


def _madvise():
    libc = ctypes.CDLL(None, use_errno=True)
    fn = libc.madvise
    fn.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
    fn.restype = ctypes.c_int
    return fn


def compiler_mappings(maps_path: str = "/proc/self/maps") -> list[tuple[int, int]]:
    """(start, end) addresses of this process's mappings of the compiler's library."""
    out = []
    try:
        with open(maps_path) as f:
            for line in f:
                fields = line.split()
                if len(fields) >= 6 and any(lib in fields[5] for lib in _LIBRARIES):
                    start, end = (int(x, 16) for x in fields[0].split("-"))
                    out.append((start, end))
    except OSError:  # no /proc (not Linux)
        return []
    return out


def release_compiler_pages() -> int:
    """Ask the kernel to reclaim the compiler library's resident pages; returns how many
    mappings it accepted the advice for (0 when unsupported: not Linux, or Linux < 5.4)."""
    if not sys.platform.startswith("linux"):
        return 0
    regions = compiler_mappings()
    if not regions:
        return 0
    madvise = _madvise()
    done = 0
    for start, end in regions:
        if madvise(start, end - start, _MADV_PAGEOUT) == 0:
            done += 1
        else:
            err = ctypes.get_errno()
            log.debug("madvise(MADV_PAGEOUT) refused", extra={"fields": {
                "error": os.strerror(err)}})
            break  # the same answer for the others
    return done
