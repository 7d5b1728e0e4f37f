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
from typing import Iterator, List, Sequence


def node_command(module: str, parameters: Sequence[str] = (), namespace: str = '',
                 ros_args: Sequence[str] = ()) -> List[str]:
    """Return the command line of a node: ``parameters`` are ``name:=value`` strings."""
    args = [sys.executable, '-m', f'pattern_locator.nodes.{module}', '--ros-args']
    if namespace:
        args += ['-r', f'__ns:=/{namespace.strip("/")}']
    for parameter in parameters:
        args += ['-p', parameter]
    return args + list(ros_args)


@contextmanager
def node_process(module: str, log: Path, parameters: Sequence[str] = (), namespace: str = '',
                 ros_args: Sequence[str] = ()) -> Iterator[subprocess.Popen]:
    """
    Run ``python -m pattern_locator.nodes.<module>`` (its output in ``log``); Ctrl-C it at the end.

    ``parameters`` are ``name:=value`` strings; ``namespace`` moves the
    node and its relative topics; ``ros_args`` are more ``--ros-args``
    arguments (e.g. ``['-r', 'from:=to']``).
    """
    args = node_command(module, parameters, namespace, ros_args)
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


def locator_process(log: Path, parameters: Sequence[str], namespace: str = ''):
    """Run the locator node as a process; see :func:`node_process`."""
    return node_process('locator_node', log, parameters, namespace)
