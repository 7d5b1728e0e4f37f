"""
The camera driver's control cycle, ROS-free: read the head, decide, command.

One :class:`HeadLoop` owns all talk to the camera, from one thread: each
:meth:`HeadLoop.cycle` asks the pan/tilt position (and every few cycles the
zoom), feeds the reading to the tracking controller, and sends a Drive or
zoom command only when the controller's decision changed (or to refresh it
now and then), so the camera's two sockets and 9600-baud line are never
the bottleneck. Requests from other threads (home, reset) run between
cycles. The ROS node is a thin shell that runs the cycles and publishes.
"""

from collections import Counter
from dataclasses import dataclass
import logging
import queue
import threading
import time
from typing import Callable, Dict, Optional, Tuple

from .controller import HeadCommand, MODE_IDLE, TrackingController
from ..errors import PatternLocatorError
from ..visca.camera import EviD31
from ..visca.protocol import ViscaError

logger = logging.getLogger(__name__)

# The 11-byte position answer spends this long on the 9600-baud wire after the
# camera latched the position: the reading is stamped that much earlier.
ANSWER_WIRE_S = 11 * 10 / 9600.0


@dataclass(frozen=True)
class HeadReading:
    """The head's angles (radians, REP 103) and zoom (camera units) at ``stamp_s``."""

    stamp_s: float
    pan: float
    tilt: float
    zoom_units: int


class HeadRequest:
    """A request (home, reset) to run between cycles; the caller waits on it."""

    def __init__(self, action: str) -> None:
        self.action = action
        self.done = threading.Event()
        self.error = ''

    def wait(self, timeout_s: float) -> Tuple[bool, str]:
        """Return (success, message) once done, or a timeout message."""
        if not self.done.wait(timeout_s):
            return False, f'{self.action} did not finish within {timeout_s:.0f} s'
        return (not self.error, self.error or f'{self.action} done')


class HeadLoop:
    """
    Read the head, run the tracking controller, command the camera.

    ``clock`` returns the time in seconds on the clock the targets' stamps
    use (the ROS clock in the node). ``controller`` None: no tracking, only
    readings. ``zoom_every``: cycles between zoom inquiries.
    """

    def __init__(self, camera: EviD31, controller: Optional[TrackingController],
                 clock: Callable[[], float] = time.time, zoom_every: int = 5,
                 refresh_s: float = 1.0) -> None:
        self.camera = camera
        self.controller = controller
        self.clock = clock
        self.zoom_every = max(1, int(zoom_every))
        self.refresh_s = refresh_s
        self.zoom_units = 0
        self.last_command: Optional[HeadCommand] = None
        self.mode = MODE_IDLE
        self.errors: Counter = Counter()
        self.last_error = ''
        self.commands_sent = 0
        self.cycles = 0
        self._sent_at = 0.0
        self._sent_key: Optional[Tuple[int, int, int]] = None
        self._requests: 'queue.Queue[HeadRequest]' = queue.Queue()

    def request(self, action: str) -> HeadRequest:
        """Queue 'home' or 'reset' for the loop's thread; wait on the returned request."""
        if action not in ('home', 'reset'):
            raise PatternLocatorError(f'unknown head request {action!r}')
        item = HeadRequest(action)
        self._requests.put(item)
        return item

    def cycle(self) -> Optional[HeadReading]:
        """Run one cycle; return the new reading (None when the camera did not answer)."""
        self.cycles += 1
        self._run_requests()
        try:
            reading = self._read()
        except ViscaError as exc:
            self._error('position', exc)
            return None
        if self.controller is not None:
            self.controller.on_head_state(reading.stamp_s, reading.pan, reading.tilt,
                                          reading.zoom_units)
            command = self.controller.update(self.clock())
            self.mode = command.mode
            try:
                self._command(command)
            except ViscaError as exc:
                self._error('command', exc)
                self._sent_key = None            # resend next cycle
        return reading

    def on_target(self, stamp_s: float, pan_error: float, tilt_error: float,
                  size_px: float) -> bool:
        """Pass a target to the controller (from any thread); False if it was ignored."""
        if self.controller is None:
            return False
        return self.controller.on_target(stamp_s, pan_error, tilt_error, size_px)

    def reset_tracking(self) -> None:
        """Forget the controller's history (after a reconnect or a home/reset)."""
        if self.controller is not None:
            self.controller.reset()
        self._sent_key = None

    def stats(self) -> Dict[str, object]:
        """Return the loop's counters for diagnostics."""
        return {'cycles': self.cycles, 'commands sent': self.commands_sent,
                'mode': self.mode, 'errors': dict(self.errors), 'last error': self.last_error}

    # Internals ------------------------------------------------------------------------

    def _read(self) -> HeadReading:
        if self.cycles % self.zoom_every == 1 or self.zoom_every == 1:
            self.zoom_units = self.camera.zoom()
        pan, tilt = self.camera.position()
        return HeadReading(self.clock() - ANSWER_WIRE_S, pan, tilt, self.zoom_units)

    def _command(self, command: HeadCommand) -> None:
        key = (command.pan_steps, command.tilt_steps, command.zoom)
        now = time.monotonic()
        if key == self._sent_key and now - self._sent_at < self.refresh_s:
            return
        previous = self._sent_key
        if previous is None or key[:2] != previous[:2] or now - self._sent_at >= self.refresh_s:
            self.camera.drive(command.pan_speed, command.tilt_speed)
            self.commands_sent += 1
        if previous is None or key[2] != previous[2]:
            {1: self.camera.zoom_tele, -1: self.camera.zoom_wide,
             0: self.camera.zoom_stop}[command.zoom]()
            self.commands_sent += 1
        self._sent_key, self._sent_at = key, now
        self.last_command = command

    def _run_requests(self) -> None:
        while True:
            try:
                item = self._requests.get_nowait()
            except queue.Empty:
                return
            try:
                if item.action == 'home':
                    self.camera.home(wait=True)
                else:
                    self.camera.reset(wait=True)
                self.commands_sent += 1
            except ViscaError as exc:
                item.error = f'{item.action} failed: {exc}'
                self._error(item.action, exc)
            self.reset_tracking()
            item.done.set()

    def _error(self, where: str, exc: Exception) -> None:
        self.errors[type(exc).__name__] += 1
        self.last_error = f'{where}: {exc}'
        logger.debug('head loop: %s', self.last_error)
