"""Polling helper for tests that wait on another thread or process."""

from __future__ import annotations

import time
from typing import Callable


def wait_for(pred: Callable[[], bool], timeout: float = 10.0) -> bool:
    """True as soon as ``pred()`` holds, False if it still does not after ``timeout`` s."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.02)
    return False
