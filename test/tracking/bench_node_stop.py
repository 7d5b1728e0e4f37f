"""
Time Ctrl-C of the real camera_driver process, and its report of a missing port (a benchmark).

Run: ``.venv/bin/python test/tracking/bench_node_stop.py [--runs N]`` (with
``ROS_DOMAIN_ID`` etc. exported as for ``make test``).

Starts ``python -m pattern_locator.nodes.camera_driver_node`` on the
emulated EVI-D31 (healthy, then gone silent 0.45 s before the Ctrl-C, so a
position inquiry is waiting on a reply) and on a missing port, sends SIGINT
and times the process's exit, ROS shut-down included. For the missing port
also the time from the node's configuration line to its line saying the
port does not exist. Mean, p99 and max over the runs.
"""

import argparse
from pathlib import Path
import re
import signal
import subprocess
import sys
import tempfile
import time
from typing import Optional

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_recovery import summary  # noqa: E402
from pattern_locator.visca.emulator import EmulatedEviD31  # noqa: E402


def start_node(port: Path, log: Path) -> subprocess.Popen:
    args = [sys.executable, '-m', 'pattern_locator.nodes.camera_driver_node', '--ros-args',
            '-p', f'port:={port}', '-p', 'search:=false']
    with open(log, 'w') as out:
        return subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT, text=True)


def wait_log(log: Path, pattern: str, timeout_s: float) -> Optional[float]:
    """Return when ``pattern`` showed up in the log (None: it did not)."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if re.search(pattern, log.read_text()):
            return time.monotonic()
        time.sleep(0.005)
    return None


def ctrl_c(proc: subprocess.Popen) -> float:
    start = time.monotonic()
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(20.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    return time.monotonic() - start


def run(kind: str, tmp: Path) -> dict:
    log = tmp / f'{kind}.log'
    if kind == 'missing port':
        proc = start_node(tmp / 'nothing', log)
        configured = wait_log(log, 'camera_driver configuration', 30.0)
        reported = wait_log(log, 'does not exist', 30.0)
        time.sleep(1.5)  # retrying with its backoff
        return {'stop': ctrl_c(proc), 'report': (reported or float('inf')) - configured}
    with EmulatedEviD31(init_s=0.1, link_path=str(tmp / 'evi')) as emu:
        proc = start_node(tmp / 'evi', log)
        wait_log(log, 'ready', 30.0)
        time.sleep(1.0)
        if kind == 'silent camera':
            emu.stop_answering(True)
            time.sleep(0.45)
        return {'stop': ctrl_c(proc)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', type=int, default=3, help='runs per figure (default 3)')
    args = parser.parse_args(argv)
    print(f'camera_driver process, {args.runs} runs; times in s')
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ('healthy camera', 'silent camera', 'missing port'):
            results = [run(kind, Path(tmp)) for _ in range(args.runs)]
            print(f'Ctrl-C to exit, {kind:15s} {summary([r["stop"] for r in results])}')
            if kind == 'missing port':
                print(f'missing port reported after the configuration line '
                      f'{summary([r["report"] for r in results])}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
