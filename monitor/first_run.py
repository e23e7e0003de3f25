"""Say so when numba compiles: the first run after an install or an update compiles the
numerical kernels; later runs load them from numba's disk cache and never see this message.

numba fires its ``numba:compile`` event only on a cache miss, so the message appears exactly
when a compile is about to take time, once per process.
"""

from __future__ import annotations

import functools
import sys
from typing import TextIO

MESSAGE = ("buoymon: compiling the numerical kernels, once after an install or update "
           "(about {seconds:.0f} s on an idle 2-core machine, longer on a busy one; later "
           "runs reuse them) ...")
# issue 19: about 25 s on first run after install; a cold `buoymon demo --hours 0.1` took
# 101 s here (2026-11-25, 2 cores shared by 8 busy workers) against a few s warm
COMPILE_SECONDS = 30.0


def announce_compiles(stream: TextIO | None = None, seconds: float = COMPILE_SECONDS) -> None:
    """Print :data:`MESSAGE` to ``stream`` (stderr) when numba first compiles in this
    process; installed once per process (and arguments), when numba is first imported (a
    command whose kernels all run as plain Python never imports it: models._jit). Without
    numba (the models then run as plain Python) nothing is installed."""
    from monitor.numba_setup import after_numba_import

    after_numba_import(lambda: _install(stream, seconds))


# numba's listener registry is per process, so is this: a command run inside another
# (the demo runs simulate) must not add a second listener and a second message
@functools.cache
def _install(stream: TextIO | None, seconds: float) -> None:
    try:
        from numba.core import event
    except ImportError:  # pragma: no cover - numba is a declared dependency
        return

    class _Once(event.Listener):
        said = False

        def on_start(self, ev: event.Event) -> None:
            if not self.said:
                self.said = True
                print(MESSAGE.format(seconds=seconds), file=stream or sys.stderr, flush=True)

        def on_end(self, ev: event.Event) -> None:
            """Nothing to say when one kernel is done: others may follow."""

    event.register("numba:compile", _Once())
