"""On-disk cache of costly, pure model builds, shared by every process on the machine.

The motion estimator's catenary tension table takes about a second to solve (and its solver
kernels about half a second more to load) at every start of ``buoymon replay``, ``demo`` or
``run``; loading the finished build from this cache takes milliseconds.

An entry is a pickle named by a SHA-256 of the build's kind and inputs, of the source of the
``models`` package (subpackages included) and of the module that defines the build function,
and of the Python and numpy versions: a change to any of them never reuses a stale build. The directory is ``$BUOYMON_CACHE_DIR``, else ``$XDG_CACHE_HOME/buoymon``,
else ``~/.cache/buoymon`` (created private to the user; ``BUOYMON_CACHE_DIR=""`` turns the
cache off). Like numba's own cache it loads pickles, so it must not be writable by others.
An entry that cannot be read is rebuilt and rewritten; a directory that cannot be written
only costs the build time (logged once at debug level).
"""

from __future__ import annotations

import functools
import hashlib
import logging
import os
import pickle
import sys
from pathlib import Path
from typing import Callable, TypeVar

import numpy as np

from models._jit import compiled
from monitor.atomic_file import atomic_write_bytes

log = logging.getLogger(__name__)
T = TypeVar("T")
_MODELS = Path(__file__).resolve().parents[1] / "models"


def cache_dir() -> Path | None:
    """Where entries live, from the environment at call time; None when turned off."""
    env = os.environ.get("BUOYMON_CACHE_DIR")
    if env is not None:
        return Path(env) if env else None
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "buoymon"


@functools.lru_cache(maxsize=8)
def _code_version(builder_file: str) -> str:
    h = hashlib.sha256(f"{sys.version}|numpy {np.__version__}".encode())
    # every module of the package, subpackages (models/catenary/, models/fatigue/) included
    for f in [*sorted(_MODELS.rglob("*.py")), Path(builder_file)]:
        h.update(str(f.relative_to(_MODELS) if f.is_relative_to(_MODELS) else f.name).encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def cached(kind: str, inputs: object, build: Callable[[], T]) -> T:
    """``build()``, or its result saved by an earlier call with the same ``kind`` and
    ``inputs`` (whose ``repr`` must determine the result: dataclasses of numbers and strings)."""
    folder = cache_dir()
    builder_file = getattr(sys.modules.get(build.__module__), "__file__", None)
    # a model build is long work (a catenary table: 1e5 solves) however small the log whose
    # replay asked for it: its kernels run compiled (models._jit.uncompiled says why not)
    build = compiled()(build)
    if folder is None or builder_file is None:  # off, or a build whose source is unknown
        return build()
    code = _code_version(builder_file)
    key = hashlib.sha256(f"{kind}|{inputs!r}|{code}".encode()).hexdigest()
    path = folder / f"{kind}-{key[:32]}.pickle"
    try:
        with open(path, "rb") as f:
            return pickle.load(f)
    except FileNotFoundError:
        pass
    except Exception as e:  # a damaged or foreign entry: rebuild it
        log.warning("model cache entry %s unreadable (%s): rebuilding it", path, e)
    value = build()
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        atomic_write_bytes(path, pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL))
    except OSError as e:
        log.debug("model cache %s not writable (%s): not caching %s", folder, e, kind)
    return value
