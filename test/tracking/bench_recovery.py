"""
Measure the camera driver's recovery from each fault of issue 10 (a benchmark, not a test).

Run: ``.venv/bin/python test/tracking/bench_recovery.py [--runs N] [--rate HZ]``

The driver's real parts (EviD31, HeadLoop, TrackingController) run the
camera_driver node's own thread loop (start with backoff, then cycles at
``--rate``) against the emulated EVI-D31 on a pseudo-terminal. Each fault is
switched on for ``--fault-s`` seconds and off again; printed per fault kind:
the joint-state rate during the fault, the time from the camera answering
normally again to the first of ten readings at full rate (see
:func:`recovery_s`), the health during the fault, and readings outside the
travel (a row without a fault gives the noise floor). Then the time to
report a missing port, and the time ``HeadLoop.stop()`` takes (and the loop
thread to end) while the thread waits on a silent camera, on a start-up,
and on a missing port. Mean, p99 and max over the runs.
"""

import argparse
import logging
import math
from pathlib import Path
import statistics
import sys
import tempfile
import threading
import time
from typing import Callable, Dict, List, Optional, Tuple

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from pattern_locator.tracking.controller import TrackingController, TrackingParams  # noqa: E402
from pattern_locator.tracking.head_loop import HeadLoop  # noqa: E402
from pattern_locator.visca import protocol as visca  # noqa: E402
from pattern_locator.visca.camera import EviD31  # noqa: E402
from pattern_locator.visca.emulator import EmulatedEviD31  # noqa: E402

FULL_RATE_RUN = 10


class DriverThread:
    """The camera_driver node's thread: start (retrying with backoff), then cycles at a rate."""

    def __init__(self, loop: HeadLoop, rate_hz: float, startup_timeout_s: float = 15.0,
                 feed: Optional[Callable[[HeadLoop], None]] = None) -> None:
        self.loop = loop
        self.period = 1.0 / rate_hz
        self.startup_timeout_s = startup_timeout_s
        self.feed = feed
        self.readings: List[Tuple[float, float, float]] = []
        self.start_errors: List[Tuple[float, str]] = []
        self.stopping = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def start(self) -> 'DriverThread':
        self.thread.start()
        return self

    def _run(self) -> None:
        camera, backoff = self.loop.camera, 0.5
        while not self.stopping.is_set():
            try:
                camera.start(timeout_s=self.startup_timeout_s)
                backoff = 0.5
            except visca.ViscaError as exc:
                self.start_errors.append((time.monotonic(), str(exc)))
                self.stopping.wait(backoff)
                backoff = min(2 * backoff, 5.0)
                continue
            self._cycles()
        camera.close()

    def _cycles(self) -> None:
        due = time.monotonic()
        while not self.stopping.is_set():
            due += self.period
            if self.loop.camera.ready:
                if self.feed is not None:
                    self.feed(self.loop)
                reading = self.loop.cycle()
                if reading is not None:
                    self.readings.append((time.monotonic(), reading.pan, reading.tilt))
            due = max(due, time.monotonic())
            self.stopping.wait(max(0.0, due - time.monotonic()))

    def stop(self) -> Tuple[float, float]:
        """Stop as the node will (event, loop.stop, join); return the seconds each took."""
        start = time.monotonic()
        self.stopping.set()
        self.loop.stop()
        stopped = time.monotonic() - start
        self.thread.join(5.0)
        return stopped, time.monotonic() - start


def wandering_target(loop: HeadLoop) -> None:
    """Keep the controller tracking a card that swings left and right (drives every cycle)."""
    now = loop.clock()
    loop.on_target(now, 0.15 * math.sin(3.0 * now), 0.05 * math.cos(2.0 * now), 100.0)


def recovery_s(readings, since: float, period: float) -> float:
    """
    Return the time from ``since`` to the first of a run of readings at full rate.

    Full rate: the next FULL_RATE_RUN readings come within FULL_RATE_RUN periods
    plus 25 % (jitter of a loaded machine), none later than two periods.
    """
    times = [t for t, _, _ in readings if t >= since]
    for i in range(len(times) - FULL_RATE_RUN):
        run = times[i:i + FULL_RATE_RUN + 1]
        if run[-1] - run[0] <= 1.25 * FULL_RATE_RUN * period \
                and all(b - a < 2.0 * period for a, b in zip(run, run[1:])):
            return times[i] - since
    return math.inf


FAULTS: Dict[str, Tuple[Callable[[EmulatedEviD31], None], Callable[[EmulatedEviD31], None]]] = {
    'none (the noise floor)': (lambda cam: None, lambda cam: None),
    'malformed position replies': (
        lambda cam: setattr(cam.faults, 'bad_position_probability', 1.0),
        lambda cam: cam.faults.clear()),
    'completions never sent': (
        lambda cam: setattr(cam.faults, 'lose_completions', True),
        lambda cam: cam.faults.clear()),
    'ACKs never completed': (
        lambda cam: setattr(cam.faults, 'phantom_ack_interval_s', 0.3),
        lambda cam: cam.faults.clear()),
    'ACKs on absent sockets': (
        lambda cam: setattr(cam.faults, 'bad_ack_socket_probability', 1.0),
        lambda cam: cam.faults.clear()),
    'error-only replies': (
        lambda cam: setattr(cam.faults, 'error_only', visca.ERROR_SYNTAX),
        lambda cam: cam.faults.clear()),
    'silence': (lambda cam: cam.stop_answering(True), lambda cam: cam.stop_answering(False)),
    'port gone': (lambda cam: cam.vanish(), lambda cam: cam.restore()),
}


def run_fault(name: str, rate_hz: float, fault_s: float, tmp: Path) -> Dict[str, object]:
    on, off = FAULTS[name]
    period = 1.0 / rate_hz
    with EmulatedEviD31(init_s=0.05, link_path=str(tmp / 'evi')) as emu:
        camera = EviD31(emu.port)
        loop = HeadLoop(camera, TrackingController(TrackingParams(control_period_s=period)),
                        expected_rate_hz=rate_hz)
        driver = DriverThread(loop, rate_hz, feed=wandering_target).start()
        deadline = time.monotonic() + 10.0
        while len(driver.readings) < 15 and time.monotonic() < deadline:
            time.sleep(0.05)
        on(emu)
        began = time.monotonic()
        healths = []
        while time.monotonic() - began < fault_s:
            time.sleep(0.25)
            healths.append(loop.health())
        off(emu)
        cleared = time.monotonic()
        time.sleep(3.0)
        during = [r for r in driver.readings if began <= r[0] < cleared]
        worst = healths[len(healths) // 2:]
        result = {
            'rate during': len(during) / (cleared - began),
            'recovery': recovery_s(driver.readings, cleared, period),
            'health during': max(h.level for h in worst),
            'message': worst[-1].message,
            'health after': loop.health().level_name,
            'outside travel': sum(1 for _, pan, tilt in driver.readings
                                  if abs(pan) > math.radians(101) or abs(tilt)
                                  > math.radians(26)),
        }
        driver.stop()
        return result


def stop_while(kind: str, tmp: Path) -> Tuple[float, float]:
    """Return (stop() s, thread ended s) with the loop thread in the given wait."""
    if kind == 'missing port':
        camera = EviD31(str(tmp / 'no-such-port'))
        driver = DriverThread(HeadLoop(camera, None), 10.0).start()
        time.sleep(1.2)
        return driver.stop()
    with EmulatedEviD31(init_s=0.05, link_path=str(tmp / 'evi')) as emu:
        camera = EviD31(emu.port)
        if kind == 'start-up, silent camera':
            emu.stop_answering(True)
            driver = DriverThread(HeadLoop(camera, None), 10.0).start()
            time.sleep(1.0)
            return driver.stop()
        driver = DriverThread(HeadLoop(camera, None), 10.0).start()
        deadline = time.monotonic() + 10.0
        while len(driver.readings) < 5 and time.monotonic() < deadline:
            time.sleep(0.05)
        emu.stop_answering(True)
        time.sleep(0.45)   # inside a position inquiry's wait
        return driver.stop()


def missing_port_report_s(tmp: Path) -> Tuple[float, str]:
    camera = EviD31(str(tmp / 'no-such-port'))
    start = time.monotonic()
    try:
        camera.start(timeout_s=15.0)
    except visca.ViscaError as exc:
        return time.monotonic() - start, str(exc)
    finally:
        camera.close()
    return math.inf, 'no error'


def summary(values: List[float]) -> str:
    finite = [v for v in values if math.isfinite(v)]
    if not finite:
        return 'never'
    ordered = sorted(finite)
    p99 = ordered[min(len(ordered) - 1, int(math.ceil(0.99 * len(ordered))) - 1)]
    extra = f' ({len(values) - len(finite)} never)' if len(finite) < len(values) else ''
    return (f'mean {statistics.fmean(finite):6.3f}  p99 {p99:6.3f}  '
            f'max {ordered[-1]:6.3f}{extra}')


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', type=int, default=3, help='runs per figure (default 3)')
    parser.add_argument('--rate', type=float, default=10.0, help='cycles per second (10)')
    parser.add_argument('--fault-s', type=float, default=3.0, help='fault duration (3 s)')
    args = parser.parse_args(argv)
    # The driver's own warnings (lost port, silent camera) would break up the table.
    logging.disable(logging.WARNING)
    print(f'camera_driver recovery, {args.runs} runs, {args.rate:.0f} Hz cycles, faults '
          f'{args.fault_s:.0f} s; times in s')
    with tempfile.TemporaryDirectory() as tmp:
        tmp_path = Path(tmp)
        print(f'{"fault":28s} {"Hz during":>9s}  {"health during":13s} '
              f'{"out of travel":>13s}  time to full rate after the fault')
        for name in FAULTS:
            results = [run_fault(name, args.rate, args.fault_s, tmp_path)
                       for _ in range(args.runs)]
            rate = statistics.fmean(r['rate during'] for r in results)
            level = ('OK', 'WARN', 'ERROR')[max(r['health during'] for r in results)]
            outside = sum(r['outside travel'] for r in results)
            print(f'{name:28s} {rate:9.1f}  {level:13s} {outside:13d}  '
                  f'{summary([r["recovery"] for r in results])}')
            print(f'{"":28s} health: "{results[-1]["message"]}", after: '
                  f'{results[-1]["health after"]}')
        reports = [missing_port_report_s(tmp_path) for _ in range(args.runs)]
        print(f'{"missing port reported in":42s} {summary([r[0] for r in reports])}')
        print(f'{"":28s} "{reports[-1][1]}"')
        for kind in ('waiting on a reply', 'start-up, silent camera', 'missing port'):
            times = [stop_while(kind, tmp_path) for _ in range(args.runs)]
            print(f'stop() while {kind:29s} {summary([t[0] for t in times])}')
            print(f'  loop thread ended {"":23s} {summary([t[1] for t in times])}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
