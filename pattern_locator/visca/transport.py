"""
VISCA serial transport: requests sent, replies matched to them, over a port that reconnects.

ROS-free. The layers follow ``design/style.md``: ``protocol.py`` turns packets
into values, the transport moves packets over a serial port, ``camera.py``
gives them meaning. The transport is three parts behind one facade:

* :mod:`~pattern_locator.visca.link`: the port and its reader thread, the
  reconnect loop (close, fail every waiter at once with
  :class:`ViscaConnectionError`, reopen with a backoff), and a callback
  thread that runs ``on_network_change`` and ``on_reconnect`` (so they may
  call the transport; they never run on the reader);
* :mod:`~pattern_locator.visca.demux`: the reader/demultiplexer, which frames
  the byte stream, parses each packet and hands it to whoever waits for it;
* :mod:`~pattern_locator.visca.sockets`: the socket bookkeeping, which
  matches completions to commands by socket number.

Threading model: the caller's thread writes (writes are serialised) and
then waits on an event for its reply; requests take turns in the order they
came (a polling loop cannot starve a drive command). At most two commands
hold a camera socket at any time: the transport waits for a completion
before sending a third, so the camera's buffer never overflows because of
us.
"""

import collections
import logging
import math
import threading
import time
from typing import Callable, Dict, List, Optional, Sequence

import serial

from .demux import Exchange, ReplyDemux
from .exceptions import (command_error, ViscaBufferFull, ViscaCancelled, ViscaCommandError,
                         ViscaConnectionError, ViscaMessageLengthError, ViscaNoSocket,
                         ViscaNotExecutable, ViscaSocketsBusy, ViscaSyntaxError, ViscaTimeout)
from .link import SerialLink
from .protocol import (BROADCAST, cancel as cancel_packet, ERROR_CANCELLED, hex_bytes,
                       INSTANT_COMMAND_S, Reply, reply_header, ViscaError, ViscaReplyError)
from .sockets import CommandResult, SocketTable
from .stats import Counters, TransportStats

__all__ = ['command_error', 'CommandResult', 'TransportStats', 'ViscaBufferFull',
           'ViscaCancelled', 'ViscaCommandError', 'ViscaConnectionError', 'ViscaError',
           'ViscaMessageLengthError', 'ViscaNoSocket', 'ViscaNotExecutable', 'ViscaReplyError',
           'ViscaSocketsBusy', 'ViscaSyntaxError', 'ViscaTimeout', 'ViscaTransport']

logger = logging.getLogger(__name__)


class _FairLock:
    """A lock granted in request order, so a polling loop cannot starve a drive command."""

    def __init__(self) -> None:
        self._cond = threading.Condition(threading.Lock())
        self._queue: 'collections.deque[object]' = collections.deque()
        self._held = False

    def acquire(self, timeout: float) -> bool:
        ticket = object()
        with self._cond:
            self._queue.append(ticket)
            if self._cond.wait_for(lambda: not self._held and self._queue[0] is ticket,
                                   timeout):
                self._queue.popleft()
                self._held = True
                return True
            self._queue.remove(ticket)
            self._cond.notify_all()
            return False

    def release(self) -> None:
        with self._cond:
            self._held = False
            self._cond.notify_all()


class ViscaTransport:
    """
    Send VISCA packets over a serial port and match the camera's replies to them.

    ``port`` is a device path (``/dev/ttyUSB0``); the line is 9600 8N1, raw, no
    flow control, DTR on, opened exclusively. ``reply_timeout_s`` bounds the
    wait for a first reply (ACK, answer), ``completion_timeout_s`` the default
    wait for a completion. ``max_timeouts`` consecutive reply timeouts count as
    a dead link: the port is closed and reopened. ``unknown_ack_hold_s``: how
    long an ACK that no command waited for keeps its socket booked (a wrong
    guess costs one buffer-full reply, which :meth:`command` handles).
    ``on_network_change`` and ``on_reconnect`` run on the transport's callback
    thread and may call it.
    """

    def __init__(self, port: str, baud: int = 9600, address: int = 1,
                 reply_timeout_s: float = 1.0, completion_timeout_s: float = 30.0,
                 serial_factory: Callable[..., serial.Serial] = serial.Serial,
                 max_timeouts: int = 3, max_resends: int = 3,
                 reconnect_initial_s: float = 0.1, reconnect_max_s: float = 0.5,
                 on_reconnect: Optional[Callable[[], None]] = None,
                 on_network_change: Optional[Callable[[], None]] = None,
                 read_timeout_s: float = 0.05,
                 unknown_ack_hold_s: float = INSTANT_COMMAND_S) -> None:
        reply_header(address)  # validates 1..7
        self.port = port
        self.baud = baud
        self.address = address
        self.reply_timeout_s = reply_timeout_s
        self.completion_timeout_s = completion_timeout_s
        self.max_timeouts = max_timeouts
        self.max_resends = max_resends
        self.on_reconnect = on_reconnect
        self.on_network_change = on_network_change
        self._counters = Counters()
        self._sockets = SocketTable(self._counters)
        self._demux = ReplyDemux(address, self._sockets, self._counters, unknown_ack_hold_s,
                                 self._network_changed)
        self._link = SerialLink(port, baud, serial_factory, read_timeout_s,
                                max(1.0, reply_timeout_s), reconnect_initial_s, reconnect_max_s,
                                self._counters, self._on_data, self._on_lost, self._on_reopen)
        self._exchange_lock = _FairLock()
        self._timeouts_lock = threading.Lock()
        self._consecutive_timeouts = 0
        self._closing = False

    # Life cycle ---------------------------------------------------------------------------

    def open(self) -> None:  # noqa: A003 - the transport's natural verb
        """Open the port and start the reader; ViscaConnectionError if it cannot be opened."""
        if self._link.is_open:
            return
        self._demux.reset()
        with self._timeouts_lock:
            self._consecutive_timeouts = 0
        self._closing = False
        if self._link.open():
            logger.info('VISCA port %s open (%d baud, camera %d)', self.port, self.baud,
                        self.address)

    def close(self, final: Sequence[bytes] = (), final_timeout_s: float = 0.2) -> None:
        """
        Fail every waiter, send the ``final`` packets, stop the threads, close the port.

        Any thread may call it, while others wait on replies: their requests
        fail at once with ViscaConnectionError and new ones are refused.
        ``final`` (a Stop, a Cancel) go out in order, each waiting at most
        ``final_timeout_s`` for its first reply, so closing takes about
        ``len(final) * final_timeout_s`` at worst. Idempotent.
        """
        if not self._link.is_open:
            return
        self._closing = True
        closing = ViscaConnectionError(f'VISCA port {self.port}: closing')
        self._demux.fail_pending(closing)
        self._sockets.clear(lambda record: closing)
        for packet in final if self._link.connected else ():
            try:
                self._final_exchange(bytes(packet), final_timeout_s)
            except ViscaError as exc:
                logger.info('VISCA port %s: %s not answered while closing: %s', self.port,
                            hex_bytes(packet), exc)
        if self._link.close():
            logger.info('VISCA port %s closed', self.port)

    def __enter__(self) -> 'ViscaTransport':
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def connected(self) -> bool:
        """Return True while the port is open (not while reconnecting)."""
        return self._link.connected

    @property
    def is_open(self) -> bool:
        """Return True between open() and close(), reconnecting or not."""
        return self._link.is_open

    @property
    def reconnect_count(self) -> int:
        """Return how many times the port was reopened since open()."""
        return self._counters.get('reconnects')

    @property
    def last_error(self) -> str:
        """Return why the connection was last lost ('' if never)."""
        return self._link.last_error

    @property
    def last_reply_age_s(self) -> float:
        """Return the seconds since the camera's last reply of any kind (inf: none yet)."""
        at = self._demux.last_reply_at
        return math.inf if at is None else time.monotonic() - at

    @property
    def sockets_in_use(self) -> List[int]:
        """Return the camera sockets that hold one of our commands, by our bookkeeping."""
        return self._sockets.in_use()

    def running(self) -> Dict[int, CommandResult]:
        """Return socket -> command for the commands not yet completed."""
        return self._sockets.running()

    @property
    def stats(self) -> TransportStats:
        """Return a snapshot of the counters."""
        return self._counters.snapshot(self._demux.junk_bytes)

    # Requests -----------------------------------------------------------------------------

    def broadcast(self, packet: bytes, timeout: Optional[float] = None) -> Reply:
        """Send Address Set or IF_Clear to every camera; return the packet that comes back."""
        if packet[:1] != bytes((BROADCAST,)):
            raise ViscaError(f'not a broadcast packet: {hex_bytes(packet)}')
        ex = self._exchange(Exchange('broadcast', bytes(packet)), timeout)
        return ex.reply

    def inquiry(self, packet: bytes, timeout: Optional[float] = None,
                answer_length: Optional[int] = None) -> Reply:
        """
        Send an inquiry and return its answer (socket 0).

        ``answer_length`` (payload bytes) lets a late answer to an earlier,
        timed-out inquiry of another kind be told apart and dropped.
        """
        ex = self._exchange(Exchange('inquiry', bytes(packet), answer_length), timeout)
        return ex.reply

    def command(self, packet: bytes, wait: bool = True, timeout: Optional[float] = None,
                duration_s: Optional[float] = None,
                socket_wait_s: Optional[float] = None) -> CommandResult:
        """
        Send a command; return once it is ACKed, or completed when ``wait``.

        ``timeout`` (default ``completion_timeout_s``) bounds the wait for a
        free socket and for the completion; the ACK itself must come within
        ``reply_timeout_s``. ``duration_s`` (default ``timeout``) is the
        longest the camera can take for this command: a completion that has
        not come by then is lost, and its socket is taken as free.
        ``socket_wait_s`` (default ``timeout``) bounds the wait for a free
        socket alone: 0 raises :class:`ViscaSocketsBusy` at once when both are
        busy (a control loop that sends again next cycle). A buffer-full
        reply is retried after the next completion (at most ``max_resends``
        times). Error replies raise the matching :class:`ViscaCommandError`
        subclass; an ACK naming a socket the camera does not have raises
        :class:`ViscaReplyError`.
        """
        packet = bytes(packet)
        timeout = self.completion_timeout_s if timeout is None else timeout
        duration_s = timeout if duration_s is None else duration_s
        start = time.monotonic()
        deadline = start + timeout
        socket_deadline = deadline if socket_wait_s is None else start + socket_wait_s
        resends = 0
        while True:
            self._sockets.reserve(packet, min(deadline, socket_deadline), self._check)
            completions_before = self._sockets.completions_seen()
            try:
                ex = self._exchange(Exchange('command', packet, expires_s=duration_s), None)
            except ViscaBufferFull:
                if resends >= self.max_resends:
                    raise
                resends += 1
                self._counters.add('buffer_full_resends')
                self._sockets.wait_for_completion(
                    completions_before,
                    min(self.reply_timeout_s, max(0.0, deadline - time.monotonic())),
                    lambda: self._link.connected and not self._closing)
                continue
            finally:
                self._sockets.release()
            result = ex.result
            if wait:
                result.wait(max(0.0, deadline - time.monotonic()))
            else:
                result.detached = True
            return result

    def cancel(self, socket: int, timeout: Optional[float] = None) -> bool:
        """Cancel the command in ``socket``: True if cancelled, False if it had finished."""
        ex = self._exchange(Exchange('cancel', cancel_packet(self.address, socket),
                                     cancel_socket=socket), timeout)
        return ex.reply.code == ERROR_CANCELLED

    def write_raw(self, data: bytes) -> None:
        """Write bytes without waiting for anything (tests, diagnostics)."""
        self._link.write(bytes(data))

    # Internals ----------------------------------------------------------------------------

    def _check(self) -> None:
        if self._closing:
            raise ViscaConnectionError(f'VISCA port {self.port}: closing')
        self._link.check()

    def _exchange(self, ex: Exchange, timeout: Optional[float]) -> Exchange:
        timeout = self.reply_timeout_s if timeout is None else timeout
        self._check()
        # The holder keeps the line for one reply timeout at most.
        if not self._exchange_lock.acquire(timeout=4 * self.reply_timeout_s + timeout):
            self._check()
            raise ViscaTimeout(f'VISCA line busy: could not send {hex_bytes(ex.packet)}')
        try:
            return self._exchange_locked(ex, timeout)
        finally:
            self._exchange_lock.release()

    def _final_exchange(self, packet: bytes, timeout: float) -> None:
        """Send one packet while closing (others are refused) and wait for its first reply."""
        if not self._exchange_lock.acquire(timeout=timeout):
            raise ViscaTimeout(f'VISCA line busy: could not send {hex_bytes(packet)}')
        try:
            kind = 'cancel' if len(packet) == 3 and packet[1] >> 4 == 0x2 else 'command'
            ex = Exchange(kind, packet, cancel_socket=packet[1] & 0x0F, expires_s=timeout)
            self._link.check()
            self._exchange_locked(ex, timeout, final=True)
        finally:
            self._exchange_lock.release()

    def _exchange_locked(self, ex: Exchange, timeout: float, final: bool = False) -> Exchange:
        self._demux.begin(ex)
        try:
            # Lost (or closing) between check and begin: that did not see ex, so look again.
            if not final:
                self._check()
            self._link.write(ex.packet)
            ex.event.wait(timeout)
        finally:
            self._demux.end(ex)
        if not ex.event.is_set():
            self._note_timeout(ex, timeout)
        if ex.error is not None:
            raise ex.error
        return ex

    def _note_timeout(self, ex: Exchange, timeout: float) -> None:
        self._counters.add('timeouts')
        with self._timeouts_lock:
            self._consecutive_timeouts += 1
            dead = self._consecutive_timeouts >= self.max_timeouts
        message = f'no reply to {hex_bytes(ex.packet)} within {timeout:.2f} s'
        if dead:
            self._link.lose(f'the camera did not answer {self.max_timeouts} requests in a row',
                            None)
        raise ViscaTimeout(message)

    # Link callbacks -----------------------------------------------------------------------

    def _on_data(self, data: bytes) -> None:
        """Reader thread: route the replies; any reply means the camera is alive."""
        if self._demux.feed(data):
            with self._timeouts_lock:
                self._consecutive_timeouts = 0
            self._link.reset_backoff()

    def _on_lost(self, message: str) -> None:
        """Fail every waiter at once: the port failed or closed."""
        self._demux.fail_pending(ViscaConnectionError(message))
        self._sockets.clear(lambda record: ViscaConnectionError(message))

    def _on_reopen(self) -> None:
        """Reader thread, after a reopen: a clean framer, and the owner's on_reconnect."""
        self._demux.reset()
        with self._timeouts_lock:
            self._consecutive_timeouts = 0
        if self.on_reconnect is not None:
            self._link.call_soon(self.on_reconnect)

    def _network_changed(self) -> None:
        if self.on_network_change is not None:
            self._link.call_soon(self.on_network_change)
