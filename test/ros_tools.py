"""Shared plumbing of the tests that run nodes as real processes over DDS."""

import time

from pattern_locator.node_process import locator_process

__all__ = ['locator_process', 'spin_until']


def spin_until(executor, condition, timeout: float) -> bool:
    """Spin ``executor`` until ``condition()`` holds or ``timeout`` seconds pass."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        if condition():
            return True
    return False
