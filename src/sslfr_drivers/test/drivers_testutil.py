"""Helpers shared by the sslfr_drivers unit tests (imported as a plain module: pytest
puts this directory on sys.path)."""
from __future__ import annotations

import time


def wait_for(pred, timeout: float, step: float = 0.01) -> bool:
    """Poll ``pred()`` every ``step`` [s] until it is true or ``timeout`` [s, monotonic]
    has passed; return its last value."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(step)
    return pred()
