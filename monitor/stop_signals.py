"""Stop signals as an exception, so that ``finally`` blocks and handlers run: SIGTERM (a
service manager, ``kill``), SIGHUP (the terminal went away) and, where wanted, SIGINT (which
Python otherwise raises as KeyboardInterrupt)."""

from __future__ import annotations

import contextlib
import signal
from typing import Iterator, Sequence

STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)


class Stopped(BaseException):
    """A stop signal arrived (raised from the signal handler). A BaseException, as
    KeyboardInterrupt is: code that turns an Exception into a warning (Rerun's logging calls
    do) must not swallow it. Pickles (a forked child hands it to its parent) as its number."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum

    def __str__(self) -> str:
        return signal.Signals(self.signum).name

    @property
    def exit_status(self) -> int:
        """The shell's status for a command ended by this signal: 128 + its number."""
        return 128 + self.signum


@contextlib.contextmanager
def stop_signals_raise(signals: Sequence[signal.Signals] = STOP_SIGNALS) -> Iterator[None]:
    """Within the block, ``signals`` raise :class:`Stopped`; after the first, they are ignored
    until the block ends (a second signal must not cut the clean-up short)."""

    def handler(signum: int, frame: object) -> None:
        for s in signals:
            signal.signal(s, signal.SIG_IGN)
        raise Stopped(signum)

    previous = {s: signal.signal(s, handler) for s in signals}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
