"""
Socket bookkeeping: which of the camera's two command sockets holds which of our commands.

VISCA matches a completion to its command by socket number only (visca.md,
"Replies"), so the transport books a :class:`CommandResult` on the socket
its ACK names and finishes it on that socket's completion or error. The
table also keeps the count of commands on their way (sent, not yet ACKed),
so at most two commands ever hold a camera socket and the camera's buffer
never overflows because of us.
"""

import logging
import threading
import time
from typing import Callable, Dict, List, Optional

from .exceptions import ViscaCancelled, ViscaConnectionError, ViscaSocketsBusy, ViscaTimeout
from .protocol import hex_bytes, Reply, ViscaError
from .stats import Counters

logger = logging.getLogger(__name__)

SOCKETS = 2


class CommandResult:
    """
    A command the camera accepted (ACK) into ``socket``.

    ``completion`` is set when it completes; ``error`` when it failed after
    its ACK (cancelled, not executable, connection lost). :meth:`wait` blocks
    until one of the two.
    """

    def __init__(self, packet: bytes, socket: int, ack: Reply, expires_at: float) -> None:
        self.packet = packet
        self.socket = socket
        self.ack = ack
        self.sent_at = time.monotonic()
        self.acked_at = self.sent_at
        self.expires_at = expires_at
        self.completion: Optional[Reply] = None
        self.error: Optional[ViscaError] = None
        self.completed_at: Optional[float] = None
        self.detached = False
        self._event = threading.Event()

    @property
    def done(self) -> bool:
        """Return True once the command completed or failed."""
        return self._event.is_set()

    @property
    def ok(self) -> bool:
        """Return True when the command completed without error."""
        return self.completion is not None

    def wait(self, timeout: Optional[float] = None) -> 'CommandResult':
        """Wait for the completion; raise the command's error or ViscaTimeout."""
        if not self._event.wait(timeout):
            raise ViscaTimeout(f'no completion for {hex_bytes(self.packet)} on socket '
                               f'{self.socket} within {timeout:.2f} s')
        if self.error is not None:
            raise self.error
        return self

    def finish(self, completion: Optional[Reply] = None,
               error: Optional[ViscaError] = None) -> None:
        """Record the completion or the error (the first one counts) and wake the waiters."""
        if self._event.is_set():
            return
        self.completion, self.error = completion, error
        self.completed_at = time.monotonic()
        self._event.set()
        if error is not None and self.detached:
            # A refusal after the ACK is news; cancelled, lost and expired ones are counted.
            quiet = isinstance(error, (ViscaCancelled, ViscaConnectionError, ViscaTimeout))
            logger.log(logging.DEBUG if quiet else logging.WARNING,
                       'VISCA command %s failed after its ACK: %s', hex_bytes(self.packet), error)

    def __repr__(self) -> str:
        state = 'ok' if self.ok else ('error' if self.error else 'running')
        return f'CommandResult({hex_bytes(self.packet)}, socket={self.socket}, {state})'


class SocketTable:
    """
    The camera's command sockets as far as our replies tell (thread-safe).

    Reservations count commands sent and not yet answered; booked records
    the commands the camera ACKed. A socket is busy until its command
    completes or fails; a command still booked at its ``expires_at`` (the
    longest the camera can take for it) lost its completion: it fails with
    ViscaTimeout and the socket is free again (counted as
    ``expired_sockets``).
    """

    def __init__(self, counters: Counters) -> None:
        self._cond = threading.Condition(threading.Lock())
        self._counters = counters
        self._records: Dict[int, CommandResult] = {}
        self._reserved = 0
        self._completions = 0

    # Reservations (caller threads) ----------------------------------------------------------

    def reserve(self, packet: bytes, deadline: float, check: Callable[[], None]) -> None:
        """
        Wait until fewer than two sockets are busy, then count one more on its way.

        ``check`` raises when waiting makes no sense any more (link lost);
        ViscaTimeout at ``deadline``.
        """
        with self._cond:
            while True:
                check()
                now = time.monotonic()
                self._expire(now)
                busy = self._reserved + len(self._records)
                if busy < SOCKETS:
                    self._reserved += 1
                    return
                if now >= deadline:
                    raise ViscaSocketsBusy(
                        f'both camera sockets busy ({sorted(self._records)}): could not '
                        f'send {hex_bytes(packet)}')
                # Short waits: a socket may also free itself by expiring.
                self._cond.wait(min(deadline - now, 0.05))

    def release(self) -> None:
        """Count one fewer command on its way (it got its first reply, or none)."""
        with self._cond:
            self._reserved -= 1
            self._cond.notify_all()

    def completions_seen(self) -> int:
        """Return how many completions arrived so far (for :meth:`wait_for_completion`)."""
        with self._cond:
            return self._completions

    def wait_for_completion(self, count: int, timeout: float,
                            alive: Callable[[], bool]) -> None:
        """Wait until a completion arrives after ``count`` was read, or ``alive()`` is False."""
        with self._cond:
            self._cond.wait_for(lambda: self._completions != count or not alive(), timeout)

    # Replies (reader thread) ------------------------------------------------------------------

    def book(self, socket: int, record: CommandResult) -> None:
        """Book ``record`` on ``socket`` (its ACK came); one still there lost its completion."""
        with self._cond:
            stale = self._records.pop(socket, None)
            if stale is not None and not stale.done:
                # A new ACK on the socket: the old command's completion got lost.
                self._counters.add('lost_completions')
                stale.finish(error=ViscaTimeout(
                    f'completion of {hex_bytes(stale.packet)} on socket {socket} lost'))
            self._records[socket] = record
            self._cond.notify_all()

    def complete(self, socket: int, reply: Reply) -> bool:
        """Finish the command on ``socket`` with its completion; False if none was booked."""
        with self._cond:
            record = self._records.pop(socket, None)
            self._completions += 1
            if record is not None:
                record.finish(completion=reply)
            self._cond.notify_all()
            return record is not None

    def get(self, socket: int) -> Optional[CommandResult]:
        """Return the command booked on ``socket``."""
        with self._cond:
            return self._records.get(socket)

    def fail(self, socket: int, error: Callable[[CommandResult], ViscaError]
             ) -> Optional[CommandResult]:
        """Finish the command on ``socket`` with ``error(record)``; return it (None if none)."""
        with self._cond:
            record = self._records.pop(socket, None)
            if record is not None:
                record.finish(error=error(record))
                self._cond.notify_all()
            return record

    def clear(self, error: Callable[[CommandResult], ViscaError]) -> None:
        """Finish every booked command with ``error(record)`` (IF_Clear, connection lost)."""
        with self._cond:
            for record in self._records.values():
                record.finish(error=error(record))
            self._records.clear()
            self._cond.notify_all()

    def wake(self) -> None:
        """Wake every waiter so it re-checks its condition (the link changed)."""
        with self._cond:
            self._cond.notify_all()

    # Views --------------------------------------------------------------------------------------

    def in_use(self) -> List[int]:
        """Return the sockets that hold one of our commands."""
        with self._cond:
            self._expire(time.monotonic())
            return sorted(s for s, r in self._records.items() if not r.done)

    def running(self) -> Dict[int, CommandResult]:
        """Return socket -> command for the commands not yet completed."""
        with self._cond:
            self._expire(time.monotonic())
            return {s: r for s, r in self._records.items() if not r.done}

    def _expire(self, now: float) -> None:
        """Free the sockets whose command is past its longest time (lock held)."""
        for socket, record in list(self._records.items()):
            if record.done:
                del self._records[socket]
            elif record.expires_at <= now:
                del self._records[socket]
                self._counters.add('expired_sockets')
                what = hex_bytes(record.packet) if record.packet else 'an unknown command'
                record.finish(error=ViscaTimeout(
                    f'no completion for {what} on socket {socket} within '
                    f'{record.expires_at - record.acked_at:.2f} s of its ACK: socket freed'))
                self._cond.notify_all()
