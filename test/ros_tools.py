"""Shared plumbing of the tests that run nodes as real processes over DDS."""

from contextlib import contextmanager
import os
from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Iterator, Sequence


def spin_until(executor, condition, timeout: float) -> bool:
    """Spin ``executor`` until ``condition()`` holds or ``timeout`` seconds pass."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        if condition():
            return True
    return False


@contextmanager
def locator_process(log: Path, parameters: Sequence[str]) -> Iterator[subprocess.Popen]:
    """
    Run the locator node as a process (its output in ``log``); Ctrl-C it at the end.

    ``parameters`` are ``name:=value`` strings. The process gets this process's
    environment: its ROS domain, localhost discovery and Fast DDS profile.
    """
    args = [sys.executable, '-m', 'pattern_locator.locator_node', '--ros-args']
    for parameter in parameters:
        args += ['-p', parameter]
    with open(log, 'w') as out:
        proc = subprocess.Popen(args, env=dict(os.environ), stdout=out,
                                stderr=subprocess.STDOUT, text=True)
    proc.log = log
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
