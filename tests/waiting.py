"""Polling helpers for tests that wait on another thread or process (an event they can
observe), never a fixed sleep."""

from __future__ import annotations

import time
from typing import Callable, TypeVar

T = TypeVar("T")


def _poll(pred: Callable[[], T], timeout: float, interval: float) -> T | None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = pred()
        if value:
            return value
        time.sleep(interval)
    return None


def wait_for(pred: Callable[[], object], timeout: float = 10.0) -> bool:
    """True as soon as ``pred()`` holds, False if it still does not after ``timeout`` s."""
    return bool(_poll(pred, timeout, 0.02))


def wait_until(pred: Callable[[], T], timeout: float = 30.0, what: str = "condition",
               interval: float = 0.02) -> T:
    """``pred()``'s first truthy value, polled every ``interval`` s; AssertionError naming
    ``what`` if there is none within ``timeout`` s."""
    value = _poll(pred, timeout, interval)
    if not value:
        raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
    return value
