"""
Run the locator node as a separate process (for the benchmark and the tests).

The process inherits this process's environment: its ROS domain, localhost
discovery and Fast DDS profile.
"""

from contextlib import contextmanager
import os
from pathlib import Path
import signal
import subprocess
import sys
from typing import Iterator, Sequence


@contextmanager
def locator_process(log: Path, parameters: Sequence[str]) -> Iterator[subprocess.Popen]:
    """
    Run the locator node as a process (its output in ``log``); Ctrl-C it at the end.

    ``parameters`` are ``name:=value`` strings.
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
