"""
The camera driver's control cycle, ROS-free: read the head, decide, command.

One :class:`HeadLoop` owns all talk to the camera, from one thread: each
:meth:`HeadLoop.cycle` asks the pan/tilt position first (and every few
cycles the zoom), feeds the reading to the tracking controller, and sends a
Drive or zoom command only when the controller's decision changed (or to
refresh it now and then), so the camera's two sockets and 9600-baud line
are never the bottleneck. Commands never wait for a camera socket: when
both are busy (completions lost) the command is skipped and sent next
cycle, and a command whose ACK did not come pauses the commands for
``refresh_s``, so a busy or deaf camera cannot slow the positions down. Requests from other
threads (home, reset) start between cycles and run while the cycles go on.
:meth:`HeadLoop.health` says whether fresh positions flow
(:class:`~pattern_locator.tracking.health.HeadHealth`); :meth:`HeadLoop.stop`
ends every wait on the camera at once. The ROS node is a thin shell that
runs the cycles and publishes.
"""

from collections import Counter
from dataclasses import dataclass
import logging
import queue
import threading
import time
from typing import Callable, Dict, Optional, Tuple

from .controller import HeadCommand, MODE_IDLE, TrackingController
from .health import (CONNECTION, ERROR_REPLY, HeadHealth, HealthMonitor, MALFORMED, OTHER,
                     SILENCE, SOCKETS_BUSY)
from ..errors import PatternLocatorError
from ..visca.camera import EviD31
from ..visca.exceptions import (ViscaCommandError, ViscaConnectionError, ViscaSocketsBusy,
                                ViscaTimeout)
from ..visca.protocol import ViscaError, ViscaReplyError
from ..visca.sockets import CommandResult

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

    def finish(self, error: str = '') -> None:
        """Mark it done (``error`` empty: it succeeded)."""
        self.error = error
        self.done.set()


def failure_kind(exc: BaseException) -> str:
    """Return the :mod:`~pattern_locator.tracking.health` kind of a camera exception."""
    if isinstance(exc, ViscaSocketsBusy):
        return SOCKETS_BUSY
    if isinstance(exc, ViscaCommandError):
        return ERROR_REPLY
    if isinstance(exc, ViscaReplyError):
        return MALFORMED
    if isinstance(exc, ViscaConnectionError):
        return CONNECTION
    if isinstance(exc, ViscaTimeout):
        return SILENCE
    return OTHER


class HeadLoop:
    """
    Read the head, run the tracking controller, command the camera.

    ``clock`` returns the time in seconds on the clock the targets' stamps
    use (the ROS clock in the node). ``controller`` None: no tracking, only
    readings. ``zoom_every``: cycles between zoom inquiries.
    ``expected_rate_hz`` (the rate the caller runs cycles at) and
    ``stale_after_s`` tune :meth:`health`: a position older than
    ``stale_after_s`` (default three cycles at ``expected_rate_hz``, at
    least 0.3 s; 1 s without a rate) is not fresh. ``locator_present``
    tells whether a locator publishes targets (the controller's search
    waits for one); None: always. ``on_reading`` gets each reading as soon
    as it is read, before the cycle's commands (whose ACKs take 20-40 ms
    of the line): a node publishes its joint state from it, so that a
    locator waiting for the joint state after an image gets it that much
    sooner.
    """

    def __init__(self, camera: EviD31, controller: Optional[TrackingController],
                 clock: Callable[[], float] = time.time, zoom_every: int = 5,
                 refresh_s: float = 1.0, expected_rate_hz: Optional[float] = None,
                 stale_after_s: Optional[float] = None,
                 locator_present: Optional[Callable[[], bool]] = None,
                 on_reading: Optional[Callable[[HeadReading], None]] = None) -> None:
        self.camera = camera
        self.on_reading = on_reading
        self.controller = controller
        self.clock = clock
        self.locator_present = locator_present
        self.zoom_every = max(1, int(zoom_every))
        self.refresh_s = refresh_s
        self.zoom_units = 0
        self.last_command: Optional[HeadCommand] = None
        self.mode = MODE_IDLE
        self.errors: Counter = Counter()
        self.last_error = ''
        self.commands_sent = 0
        self.cycles = 0
        self.readings = 0
        if stale_after_s is None:
            stale_after_s = max(0.3, 3.0 / expected_rate_hz) if expected_rate_hz else 1.0
        self._health = HealthMonitor(stale_after_s, expected_rate_hz)
        self._sent_at = 0.0
        self._pause_commands_until = 0.0
        self._sent_key: Optional[Tuple[int, int, int]] = None
        self._requests: 'queue.Queue[HeadRequest]' = queue.Queue()
        self._running: Optional[Tuple[HeadRequest, CommandResult]] = None
        self._stopped = threading.Event()

    def request(self, action: str) -> HeadRequest:
        """Queue 'home' or 'reset' for the loop's thread; wait on the returned request."""
        if action not in ('home', 'reset'):
            raise PatternLocatorError(f'unknown head request {action!r}')
        item = HeadRequest(action)
        if self._stopped.is_set():
            item.finish(f'{action} refused: the camera driver is stopping')
            return item
        self._requests.put(item)
        return item

    def cycle(self) -> Optional[HeadReading]:
        """Run one cycle; return the new reading (None when the camera did not answer)."""
        if self._stopped.is_set():
            return None
        self.cycles += 1
        self._run_requests()
        try:
            reading = self._read()
        except ViscaError as exc:
            self._error('position', exc)
            self._health.failure(failure_kind(exc), str(exc))
            return None
        self.readings += 1
        self._health.position()
        if self.on_reading is not None:
            self.on_reading(reading)
        if self.controller is not None and self._running is None:
            self.controller.on_head_state(reading.stamp_s, reading.pan, reading.tilt,
                                          reading.zoom_units)
            # The graph is asked only until the first target: the answer matters only then.
            present = (self.locator_present is None or self.controller.has_target
                       or self.locator_present())
            command = self.controller.update(self.clock(), present)
            self.mode = command.mode
            try:
                self._command(command)
            except ViscaError as exc:
                self._error('command', exc)
                self._health.command_failure(failure_kind(exc), str(exc))
                self._sent_key = None            # resend next cycle
                if isinstance(exc, ViscaTimeout) and not isinstance(exc, ViscaSocketsBusy):
                    # No ACK cost a whole reply timeout: spare the positions for a while.
                    self._pause_commands_until = time.monotonic() + self.refresh_s
        return reading

    def on_target(self, stamp_s: float, pan_error: float, tilt_error: float,
                  size_px: Optional[float], distance_m: Optional[float] = None) -> bool:
        """Pass a target to the controller (from any thread); False if it was ignored."""
        controller = self.controller
        if controller is None:
            return False
        return controller.on_target(stamp_s, pan_error, tilt_error, size_px, distance_m)

    def on_target_point(self, stamp_s: float, point: Tuple[float, float, float],
                        size_px: Optional[float]) -> bool:
        """Pass a target point (the image's optical frame) to the controller; False if ignored."""
        controller = self.controller
        if controller is None:
            return False
        return controller.on_target_point(stamp_s, point, size_px)

    def reset_tracking(self) -> None:
        """Forget the controller's history (after a reconnect or a home/reset)."""
        if self.controller is not None:
            self.controller.reset()
        self._sent_key = None

    def set_expected_rate(self, rate_hz: float) -> None:
        """Change the cycle rate :meth:`health` expects (a run-time parameter change)."""
        self._health.expected_rate_hz = float(rate_hz)
        self._health.stale_after_s = max(0.3, 3.0 / float(rate_hz))

    def health(self) -> HeadHealth:
        """Return the driver's health for diagnostics: OK only while fresh positions flow."""
        camera = self.camera
        if self._stopped.is_set():
            return self._health.stopped('camera driver stopped')
        return self._health.assess(camera.connected, camera.ready, camera.transport.last_error,
                                   camera.transport.last_reply_age_s)

    def stop(self) -> None:
        """
        Stop from any thread: the head is stopped, the port closed, every wait ends now.

        :meth:`cycle` returns None from then on and queued requests fail.
        Returns within about 0.3 s plus joining the reader (a Stop that the
        camera does not answer is waited for 0.15 s at most).
        """
        self._stopped.set()
        self.camera.close()
        while True:
            try:
                self._requests.get_nowait().finish('stopped')
            except queue.Empty:
                break
        running, self._running = self._running, None
        if running is not None:
            running[0].finish('stopped')

    def stats(self) -> Dict[str, object]:
        """Return the loop's counters for diagnostics."""
        return {'cycles': self.cycles, 'readings': self.readings,
                'commands sent': self.commands_sent, 'mode': self.mode,
                'errors': dict(self.errors), 'last error': self.last_error,
                'rejected replies': sum(self.camera.rejected_replies.values())}

    # Internals ------------------------------------------------------------------------

    def _read(self) -> HeadReading:
        # The position first: a zoom inquiry that fails must not cost the reading.
        pan, tilt = self.camera.position()
        stamp = self.clock() - ANSWER_WIRE_S
        if self.cycles % self.zoom_every == 1 or self.zoom_every == 1:
            try:
                self.zoom_units = self.camera.zoom()
            except ViscaError as exc:
                self._error('zoom', exc)
        return HeadReading(stamp, pan, tilt, self.zoom_units)

    def _command(self, command: HeadCommand) -> None:
        key = (command.pan_steps, command.tilt_steps, command.zoom)
        now = time.monotonic()
        if now < self._pause_commands_until:
            return
        if key == self._sent_key and now - self._sent_at < self.refresh_s:
            return
        previous = self._sent_key
        if previous is None or key[:2] != previous[:2] or now - self._sent_at >= self.refresh_s:
            self.camera.drive(command.pan_speed, command.tilt_speed, blocking=False)
            self.commands_sent += 1
        if previous is None or key[2] != previous[2]:
            {1: self.camera.zoom_tele, -1: self.camera.zoom_wide,
             0: self.camera.zoom_stop}[command.zoom](blocking=False)
            self.commands_sent += 1
        self._sent_key, self._sent_at = key, now
        self.last_command = command

    def _run_requests(self) -> None:
        """Start a queued home/reset, or finish the running one; never wait for a move."""
        if self._running is not None:
            item, result = self._running
            expired = time.monotonic() >= result.expires_at
            if not (result.done or expired):
                return
            self._running = None
            if result.error is not None or not result.ok:
                why = result.error or 'no completion within the move time'
                item.error = f'{item.action} failed: {why}'
                self._error(item.action, result.error or ViscaTimeout(str(why)))
            self.reset_tracking()
            item.finish(item.error)
        try:
            item = self._requests.get_nowait()
        except queue.Empty:
            return
        try:
            move = self.camera.home if item.action == 'home' else self.camera.reset
            self._running = (item, move(wait=False))
            self.commands_sent += 1
        except ViscaError as exc:
            self._error(item.action, exc)
            self.reset_tracking()
            item.finish(f'{item.action} failed: {exc}')

    def _error(self, where: str, exc: Exception) -> None:
        self.errors[type(exc).__name__] += 1
        self.last_error = f'{where}: {exc}'
        logger.debug('head loop: %s', self.last_error)
