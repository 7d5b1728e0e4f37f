"""
Run the package's nodes as separate processes (the demo, the benchmarks, the tests).

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
def node_process(module: str, log: Path, parameters: Sequence[str] = ()
                 ) -> Iterator[subprocess.Popen]:
    """
    Run ``python -m pattern_locator.nodes.<module>`` (its output in ``log``); Ctrl-C it at the end.

    ``parameters`` are ``name:=value`` strings.
    """
    args = [sys.executable, '-m', f'pattern_locator.nodes.{module}', '--ros-args']
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


def locator_process(log: Path, parameters: Sequence[str]):
    """Run the locator node as a process; see :func:`node_process`."""
    return node_process('locator_node', log, parameters)
