"""
The camera driver's health: OK only while fresh positions flow, else why not (ROS-free).

:class:`HealthMonitor` hears of every position read and every failed read
(:meth:`HealthMonitor.position`, :meth:`HealthMonitor.failure`) and turns
them, with the link's state, into a :class:`HeadHealth`: a level with the
numbers of ``diagnostic_msgs/DiagnosticStatus`` (0 OK, 1 WARN, 2 ERROR) and a
short reason a person can act on, e.g. "no position for 3.2 s: the camera
answers only error replies (syntax error)".
"""

import collections
from dataclasses import dataclass
import math
import threading
import time
from typing import Callable, Deque, Optional, Tuple

OK, WARN, ERROR = 0, 1, 2
LEVEL_NAMES = ('OK', 'WARN', 'ERROR')

# Failure kinds (HeadLoop sorts the camera's exceptions into these).
ERROR_REPLY = 'error reply'
MALFORMED = 'malformed reply'
SILENCE = 'no reply'
CONNECTION = 'connection'
SOCKETS_BUSY = 'sockets busy'
OTHER = 'other'

_WHY = {
    ERROR_REPLY: 'the camera answers only error replies',
    MALFORMED: 'the position replies are malformed',
    SILENCE: 'the camera is silent',
    CONNECTION: 'the port is gone',
    SOCKETS_BUSY: 'both command sockets are busy',
    OTHER: 'the position inquiry fails',
}
# Reasons quote at most this much of an exception's message.
_QUOTE_CHARS = 160


def _quote(text: str) -> str:
    text = ' '.join(str(text).split())
    return text if len(text) <= _QUOTE_CHARS else text[:_QUOTE_CHARS - 3] + '...'


@dataclass(frozen=True)
class HeadHealth:
    """
    The driver's state for diagnostics.

    ``level``: 0 OK, 1 WARN, 2 ERROR (``DiagnosticStatus`` numbers); ``message``:
    a short reason. ``position_age_s``: since the last good position (inf:
    none yet); ``position_rate_hz``: good positions per second over the last
    ``window_s``; ``failures``: failed reads in that window.
    """

    level: int
    message: str
    position_age_s: float
    position_rate_hz: float
    failures: int = 0

    @property
    def level_name(self) -> str:
        """Return 'OK', 'WARN' or 'ERROR'."""
        return LEVEL_NAMES[self.level]

    @property
    def ok(self) -> bool:
        """Return True for level OK."""
        return self.level == OK


class HealthMonitor:
    """
    Keep the recent positions and failures; say how healthy the link is (thread-safe).

    ``stale_after_s``: a position older than this is not fresh (ERROR).
    ``expected_rate_hz``: when given, fresh positions at less than half of
    it are a WARN. ``window_s``: the span of the rate and of the failure
    count. ``clock``: ``time.monotonic`` (a test may pass its own).
    """

    def __init__(self, stale_after_s: float = 1.0, expected_rate_hz: Optional[float] = None,
                 window_s: float = 2.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.stale_after_s = float(stale_after_s)
        self.expected_rate_hz = expected_rate_hz
        self.window_s = float(window_s)
        self._clock = clock
        self._lock = threading.Lock()
        self._positions: Deque[float] = collections.deque()
        self._failures: Deque[Tuple[float, str, str]] = collections.deque()
        self._command_failures: Deque[Tuple[float, str, str]] = collections.deque()
        self._last_position: Optional[float] = None
        self._started = clock()

    def position(self) -> None:
        """Note a good position now."""
        now = self._clock()
        with self._lock:
            self._last_position = now
            self._positions.append(now)
            self._trim(now)

    def failure(self, kind: str, message: str) -> None:
        """Note a failed position read now: ``kind`` is one of this module's kinds."""
        now = self._clock()
        with self._lock:
            self._failures.append((now, kind, _quote(message)))
            self._trim(now)

    def command_failure(self, kind: str, message: str) -> None:
        """Note a command that did not go out or was refused (a WARN while positions flow)."""
        now = self._clock()
        with self._lock:
            self._command_failures.append((now, kind, _quote(message)))
            self._trim(now)

    def assess(self, connected: bool, ready: bool, link_error: str = '',
               reply_age_s: float = math.inf) -> HeadHealth:
        """
        Return the health now, given the link's state.

        ``connected``: the port is open; ``ready``: the camera's start-up is
        done on it; ``link_error``: why the port was last lost;
        ``reply_age_s``: since the camera's last reply of any kind.
        """
        now = self._clock()
        with self._lock:
            self._trim(now)
            age = math.inf if self._last_position is None else now - self._last_position
            span = min(self.window_s, max(now - self._started, 1e-3))
            rate = len(self._positions) / span
            failures = len(self._failures)
            last = self._failures[-1] if self._failures else None
            commands = len(self._command_failures)
            last_command = self._command_failures[-1] if self._command_failures else None

        def health(level: int, message: str) -> HeadHealth:
            return HeadHealth(level, message, age, rate, failures)

        if not connected:
            return health(ERROR, f'camera link down: {_quote(link_error) or "port not open"}; '
                                 'reconnecting')
        if not ready:
            if reply_age_s > self.stale_after_s:
                return health(ERROR, f'starting up, but the camera is silent '
                                     f'({_silence(reply_age_s)})')
            return health(WARN, 'starting up (Address Set, IF_Clear, initialisation)')
        if age <= self.stale_after_s:
            expected = self.expected_rate_hz
            if expected and rate < 0.5 * expected:
                return health(WARN, f'positions at {rate:.1f} Hz, expected {expected:.0f} Hz')
            if last is not None:
                return health(WARN, f'positions flow, but {failures} failed in the last '
                                    f'{self.window_s:.0f} s ({last[1]}: {last[2]})')
            if last_command is not None:
                return health(WARN, f'positions flow, but {commands} commands failed in the '
                                    f'last {self.window_s:.0f} s ({last_command[1]}: '
                                    f'{last_command[2]})')
            return health(OK, f'positions fresh ({rate:.1f} Hz)')
        since = 'no position yet' if age == math.inf else f'no position for {age:.1f} s'
        if last is None:
            return health(ERROR, since)
        kind, message = last[1], last[2]
        if kind == SILENCE and reply_age_s < self.stale_after_s:
            kind = OTHER  # replies come, just not to the position inquiry
        return health(ERROR, f'{since}: {_WHY.get(kind, _WHY[OTHER])} ({message})')

    def stopped(self, why: str) -> HeadHealth:
        """Return an ERROR saying ``why`` (the driver stopped: no positions will come)."""
        now = self._clock()
        with self._lock:
            self._trim(now)
            age = math.inf if self._last_position is None else now - self._last_position
            return HeadHealth(ERROR, why, age, 0.0, len(self._failures))

    def _trim(self, now: float) -> None:
        cut = now - self.window_s
        while self._positions and self._positions[0] < cut:
            self._positions.popleft()
        for events in (self._failures, self._command_failures):
            while events and events[0][0] < cut:
                events.popleft()


def _silence(seconds: float) -> str:
    return 'no reply yet' if seconds == math.inf else f'no reply for {seconds:.1f} s'
