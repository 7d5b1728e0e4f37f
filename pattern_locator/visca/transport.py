"""
VISCA serial transport: one reader thread, replies matched to requests, reconnects.

ROS-free. The layers follow ``design/style.md``: ``protocol.py`` turns packets into
values, this module moves packets over a serial port, ``camera.py`` gives
them meaning.

Threading model:

* The caller's thread writes (writes are serialised by a lock) and then waits
  on an event for its reply.
* One I/O thread owns every read. It frames the byte stream with
  :class:`~pattern_locator.visca.protocol.PacketFramer`, parses each packet and hands it
  to whoever waits for it. Around the read loop sits the reconnect loop (the
  nmea_navsat_driver TCP node's shape): when the port fails, it closes it,
  fails every waiter at once with :class:`ViscaConnectionError` and reopens
  with a backoff of 0.1 s doubling to 2 s.
* One callback thread runs ``on_network_change`` and ``on_reconnect``, so
  those callbacks may call the transport (they never run on the reader).

Matching replies: VISCA replies carry no sequence number. Only one request
waits for its *first* reply at a time (ACK or error for a command, the answer
for an inquiry, the echo for a broadcast, 04/05 for a cancel), so socket-0
errors and answers are unambiguous. After its ACK a command's completion is
matched by socket number, so ACK1, ACK2, C2, C1 and answers between an ACK and
its completion are all fine. At most two commands hold a camera socket at any
time: the transport waits for a completion before sending a third, so the
camera's buffer never overflows because of us.
"""

import collections
from dataclasses import dataclass, field
import logging
import queue
import threading
import time
from typing import Callable, Dict, List, Optional

import serial

from .protocol import (BROADCAST, cancel as cancel_packet, ERROR_BUFFER_FULL, ERROR_CANCELLED,
                       ERROR_MESSAGE_LENGTH, ERROR_NO_SOCKET, ERROR_NOT_EXECUTABLE, ERROR_SYNTAX,
                       hex_bytes, PacketFramer, parse_reply, Reply, reply_header, ViscaError)

logger = logging.getLogger(__name__)

SOCKETS = 2


class ViscaConnectionError(ViscaError):
    """The serial port is closed, vanished or stopped answering."""


class ViscaTimeout(ViscaError):
    """The camera did not answer (or complete) in time."""


class ViscaCommandError(ViscaError):
    """
    The camera answered a request with an error reply.

    ``reply`` is the parsed error reply and ``packet`` the request it answered;
    the message holds the bytes of both.
    """

    def __init__(self, message: str, reply: Reply, packet: bytes = b'') -> None:
        super().__init__(message)
        self.reply = reply
        self.packet = packet


class ViscaMessageLengthError(ViscaCommandError):
    """The camera says a packet was too long or too short (a bug of ours)."""


class ViscaSyntaxError(ViscaCommandError):
    """The camera does not know the command (a bug of ours or a model difference)."""


class ViscaBufferFull(ViscaCommandError):
    """Both command sockets of the camera are busy."""


class ViscaCancelled(ViscaCommandError):
    """The command was cancelled (Cancel or IF_Clear); no completion follows."""


class ViscaNoSocket(ViscaCommandError):
    """A Cancel hit an empty socket (the command had already finished)."""


class ViscaNotExecutable(ViscaCommandError):
    """The command cannot run in the camera's current state (moving, initialising, limit)."""


_ERROR_CLASSES = {
    ERROR_MESSAGE_LENGTH: ViscaMessageLengthError,
    ERROR_SYNTAX: ViscaSyntaxError,
    ERROR_BUFFER_FULL: ViscaBufferFull,
    ERROR_CANCELLED: ViscaCancelled,
    ERROR_NO_SOCKET: ViscaNoSocket,
    ERROR_NOT_EXECUTABLE: ViscaNotExecutable,
}


def command_error(reply: Reply, packet: bytes = b'') -> ViscaCommandError:
    """Return the exception for an error reply, its message naming both packets' bytes."""
    cls = _ERROR_CLASSES.get(reply.code, ViscaCommandError)
    sent = f' to {hex_bytes(packet)}' if packet else ''
    return cls(f'camera answered {reply.describe()}{sent}', reply, packet)


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

    def _finish(self, completion: Optional[Reply] = None,
                error: Optional[ViscaError] = None) -> None:
        if self._event.is_set():
            return
        self.completion, self.error = completion, error
        self.completed_at = time.monotonic()
        self._event.set()
        if error is not None and self.detached and not isinstance(
                error, (ViscaCancelled, ViscaConnectionError)):
            logger.warning('VISCA command %s failed after its ACK: %s',
                           hex_bytes(self.packet), error)

    def __repr__(self) -> str:
        state = 'ok' if self.ok else ('error' if self.error else 'running')
        return f'CommandResult({hex_bytes(self.packet)}, socket={self.socket}, {state})'


@dataclass(frozen=True)
class TransportStats:
    """A snapshot of the transport's counters."""

    sent: int = 0
    replies: int = 0
    acks: int = 0
    completions: int = 0
    answers: int = 0
    errors: Dict[str, int] = field(default_factory=dict)
    timeouts: int = 0
    junk_bytes: int = 0
    bad_packets: int = 0
    unmatched: int = 0
    lost_completions: int = 0
    network_changes: int = 0
    buffer_full_resends: int = 0
    connection_losses: int = 0
    reconnects: int = 0


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


class _Exchange:
    """One request waiting for its first reply."""

    def __init__(self, kind: str, packet: bytes, answer_length: Optional[int] = None,
                 cancel_socket: int = 0, expires_s: float = 0.0) -> None:
        self.kind = kind  # 'command', 'inquiry', 'broadcast' or 'cancel'
        self.packet = packet
        self.answer_length = answer_length
        self.cancel_socket = cancel_socket
        self.expires_s = expires_s
        self.reply: Optional[Reply] = None
        self.result: Optional[CommandResult] = None
        self.error: Optional[ViscaError] = None
        self.event = threading.Event()

    def deliver(self, reply: Reply, error: Optional[ViscaError] = None,
                result: Optional[CommandResult] = None) -> None:
        self.reply, self.error, self.result = reply, error, result
        self.event.set()


class ViscaTransport:
    """
    Send VISCA packets over a serial port and match the camera's replies to them.

    ``port`` is a device path (``/dev/ttyUSB0``); the line is 9600 8N1, raw, no
    flow control, DTR on, opened exclusively. ``reply_timeout_s`` bounds the
    wait for a first reply (ACK, answer), ``completion_timeout_s`` the default
    wait for a completion. ``max_timeouts`` consecutive reply timeouts count as
    a dead link: the port is closed and reopened. ``on_network_change`` and
    ``on_reconnect`` run on the transport's callback thread and may call it.
    """

    def __init__(self, port: str, baud: int = 9600, address: int = 1,
                 reply_timeout_s: float = 1.0, completion_timeout_s: float = 30.0,
                 serial_factory: Callable[..., serial.Serial] = serial.Serial,
                 max_timeouts: int = 3, max_resends: int = 3,
                 reconnect_initial_s: float = 0.1, reconnect_max_s: float = 2.0,
                 on_reconnect: Optional[Callable[[], None]] = None,
                 on_network_change: Optional[Callable[[], None]] = None,
                 read_timeout_s: float = 0.05) -> None:
        reply_header(address)  # validates 1..7
        self.port = port
        self.baud = baud
        self.address = address
        self.reply_timeout_s = reply_timeout_s
        self.completion_timeout_s = completion_timeout_s
        self.max_timeouts = max_timeouts
        self.max_resends = max_resends
        self.reconnect_initial_s = reconnect_initial_s
        self.reconnect_max_s = reconnect_max_s
        self.on_reconnect = on_reconnect
        self.on_network_change = on_network_change
        self._factory = serial_factory
        self._read_timeout_s = read_timeout_s
        self._header = reply_header(address)

        self._cond = threading.Condition(threading.Lock())
        self._write_lock = threading.Lock()
        self._exchange_lock = _FairLock()
        self._serial: Optional[serial.Serial] = None
        self._connected = False
        self._opened = False
        self._closing = threading.Event()
        self._pending: Optional[_Exchange] = None
        self._sockets: Dict[int, CommandResult] = {}
        self._reserved = 0
        self._completion_count = 0
        self._consecutive_timeouts = 0
        self._backoff_s = reconnect_initial_s
        self._framer = PacketFramer()
        self._extra_junk = 0
        self._counts: Dict[str, int] = {}
        self._errors: Dict[str, int] = {}
        self._last_error = ''
        self._io_thread: Optional[threading.Thread] = None
        self._callback_thread: Optional[threading.Thread] = None
        self._callbacks: 'queue.Queue[Optional[Callable[[], None]]]' = queue.Queue()

    # Life cycle ---------------------------------------------------------------------------

    def open(self) -> None:  # noqa: A003 - the transport's natural verb
        """Open the port and start the reader; ViscaConnectionError if it cannot be opened."""
        with self._cond:
            if self._opened:
                return
        ser = self._open_port()
        with self._cond:
            self._closing.clear()
            self._serial, self._connected, self._opened = ser, True, True
            self._framer.reset()
            self._consecutive_timeouts = 0
            self._backoff_s = self.reconnect_initial_s
        self._callbacks = queue.Queue()
        self._callback_thread = threading.Thread(target=self._run_callbacks, daemon=True,
                                                 name=f'visca-callbacks {self.port}')
        self._io_thread = threading.Thread(target=self._run_io, daemon=True,
                                           name=f'visca-io {self.port}')
        self._callback_thread.start()
        self._io_thread.start()
        logger.info('VISCA port %s open (%d baud, camera %d)', self.port, self.baud,
                    self.address)

    def close(self) -> None:
        """Fail every waiter, stop the threads and close the port (idempotent)."""
        with self._cond:
            if not self._opened:
                return
            self._opened = False
            self._closing.set()
        self._lose('transport closed', None)
        io_thread, cb_thread = self._io_thread, self._callback_thread
        if io_thread is not None and io_thread is not threading.current_thread():
            io_thread.join(timeout=2.0)
        self._callbacks.put(None)
        if cb_thread is not None and cb_thread is not threading.current_thread():
            cb_thread.join(timeout=2.0)
        with self._cond:
            ser, self._serial = self._serial, None
        self._close_port(ser)
        logger.info('VISCA port %s closed', self.port)

    def __enter__(self) -> 'ViscaTransport':
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def connected(self) -> bool:
        """Return True while the port is open (not while reconnecting)."""
        return self._connected

    @property
    def is_open(self) -> bool:
        """Return True between open() and close(), reconnecting or not."""
        return self._opened

    @property
    def reconnect_count(self) -> int:
        """Return how many times the port was reopened since open()."""
        return self._counts.get('reconnects', 0)

    @property
    def last_error(self) -> str:
        """Return why the connection was last lost ('' if never)."""
        return self._last_error

    @property
    def sockets_in_use(self) -> List[int]:
        """Return the camera sockets that hold one of our commands, by our bookkeeping."""
        with self._cond:
            return sorted(s for s, r in self._sockets.items() if not r.done)

    def running(self) -> Dict[int, CommandResult]:
        """Return socket -> command for the commands not yet completed."""
        with self._cond:
            return {s: r for s, r in self._sockets.items() if not r.done}

    @property
    def stats(self) -> TransportStats:
        """Return a snapshot of the counters."""
        with self._cond:
            c = dict(self._counts)
            return TransportStats(
                sent=c.get('sent', 0), replies=c.get('replies', 0), acks=c.get('acks', 0),
                completions=c.get('completions', 0), answers=c.get('answers', 0),
                errors=dict(self._errors), timeouts=c.get('timeouts', 0),
                junk_bytes=self._framer.junk_bytes + self._extra_junk,
                bad_packets=c.get('bad_packets', 0), unmatched=c.get('unmatched', 0),
                lost_completions=c.get('lost_completions', 0),
                network_changes=c.get('network_changes', 0),
                buffer_full_resends=c.get('buffer_full_resends', 0),
                connection_losses=c.get('connection_losses', 0),
                reconnects=c.get('reconnects', 0))

    # Requests -----------------------------------------------------------------------------

    def broadcast(self, packet: bytes, timeout: Optional[float] = None) -> Reply:
        """Send Address Set or IF_Clear to every camera; return the packet that comes back."""
        if packet[:1] != bytes((BROADCAST,)):
            raise ViscaError(f'not a broadcast packet: {hex_bytes(packet)}')
        ex = self._exchange(_Exchange('broadcast', bytes(packet)), timeout)
        return ex.reply

    def inquiry(self, packet: bytes, timeout: Optional[float] = None,
                answer_length: Optional[int] = None) -> Reply:
        """
        Send an inquiry and return its answer (socket 0).

        ``answer_length`` (payload bytes) lets a late answer to an earlier,
        timed-out inquiry of another kind be told apart and dropped.
        """
        ex = self._exchange(_Exchange('inquiry', bytes(packet), answer_length), timeout)
        return ex.reply

    def command(self, packet: bytes, wait: bool = True,
                timeout: Optional[float] = None) -> CommandResult:
        """
        Send a command; return once it is ACKed, or completed when ``wait``.

        ``timeout`` (default ``completion_timeout_s``) bounds the wait for a
        free socket and for the completion; the ACK itself must come within
        ``reply_timeout_s``. A buffer-full reply is retried after the next
        completion (at most ``max_resends`` times). Error replies raise the
        matching :class:`ViscaCommandError` subclass.
        """
        packet = bytes(packet)
        timeout = self.completion_timeout_s if timeout is None else timeout
        deadline = time.monotonic() + timeout
        resends = 0
        while True:
            self._reserve_socket(packet, deadline)
            with self._cond:
                completions_before = self._completion_count
            try:
                ex = self._exchange(_Exchange('command', packet, expires_s=timeout), None)
            except ViscaBufferFull:
                if resends >= self.max_resends:
                    raise
                resends += 1
                self._count('buffer_full_resends')
                self._wait_for_completion(completions_before,
                                          min(self.reply_timeout_s,
                                              max(0.0, deadline - time.monotonic())))
                continue
            finally:
                with self._cond:
                    self._reserved -= 1
                    self._cond.notify_all()
            result = ex.result
            if wait:
                result.wait(max(0.0, deadline - time.monotonic()))
            else:
                result.detached = True
            return result

    def cancel(self, socket: int, timeout: Optional[float] = None) -> bool:
        """Cancel the command in ``socket``: True if cancelled, False if it had finished."""
        ex = self._exchange(_Exchange('cancel', cancel_packet(self.address, socket),
                                      cancel_socket=socket), timeout)
        return ex.reply.code == ERROR_CANCELLED

    def write_raw(self, data: bytes) -> None:
        """Write bytes without waiting for anything (tests, diagnostics)."""
        self._write(bytes(data))

    # Internals: requests ------------------------------------------------------------------

    def _check_connected(self) -> None:
        if not self._connected:
            why = f': {self._last_error}' if self._last_error else ''
            raise ViscaConnectionError(f'VISCA port {self.port} is not connected{why}')

    def _exchange(self, ex: _Exchange, timeout: Optional[float]) -> _Exchange:
        timeout = self.reply_timeout_s if timeout is None else timeout
        self._check_connected()
        # The holder keeps the line for one reply timeout at most.
        if not self._exchange_lock.acquire(timeout=4 * self.reply_timeout_s + timeout):
            self._check_connected()
            raise ViscaTimeout(f'VISCA line busy: could not send {hex_bytes(ex.packet)}')
        try:
            with self._cond:
                self._check_connected()
                self._pending = ex
            try:
                self._write(ex.packet)
                ex.event.wait(timeout)
            finally:
                with self._cond:
                    if self._pending is ex:
                        self._pending = None
            if not ex.event.is_set():
                self._note_timeout(ex, timeout)
            if ex.error is not None:
                raise ex.error
            return ex
        finally:
            self._exchange_lock.release()

    def _note_timeout(self, ex: _Exchange, timeout: float) -> None:
        with self._cond:
            self._count('timeouts', locked=True)
            self._consecutive_timeouts += 1
            dead = self._consecutive_timeouts >= self.max_timeouts
            ser = self._serial
        message = f'no reply to {hex_bytes(ex.packet)} within {timeout:.2f} s'
        if dead:
            self._lose(f'{self.max_timeouts} requests in a row got no reply', ser)
        raise ViscaTimeout(message)

    def _reserve_socket(self, packet: bytes, deadline: float) -> None:
        with self._cond:
            while True:
                self._check_connected()
                now = time.monotonic()
                busy = self._reserved + sum(
                    1 for r in self._sockets.values() if not r.done and r.expires_at > now)
                if busy < SOCKETS:
                    self._reserved += 1
                    return
                if now >= deadline:
                    raise ViscaTimeout(
                        f'both camera sockets busy ({sorted(self._sockets)}): could not '
                        f'send {hex_bytes(packet)}')
                # Short waits: a socket may also free itself by expiring.
                self._cond.wait(min(deadline - now, 0.05))

    def _wait_for_completion(self, count: int, timeout: float) -> None:
        with self._cond:
            self._cond.wait_for(lambda: self._completion_count != count or not self._connected,
                                timeout)

    def _write(self, packet: bytes) -> None:
        with self._write_lock:
            with self._cond:
                self._check_connected()
                ser = self._serial
            try:
                ser.write(packet)
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                # TypeError/AttributeError: pyserial's write on a port closed under it.
                self._lose(f'write failed: {exc}', ser)
                raise ViscaConnectionError(
                    f'VISCA port {self.port}: write failed: {exc}') from exc
            self._count('sent')
            logger.debug('VISCA -> %s', hex_bytes(packet))

    def _count(self, name: str, amount: int = 1, locked: bool = False) -> None:
        if locked:
            self._counts[name] = self._counts.get(name, 0) + amount
            return
        with self._cond:
            self._counts[name] = self._counts.get(name, 0) + amount

    # Internals: connection ----------------------------------------------------------------

    def _open_port(self) -> serial.Serial:
        kwargs = {'port': self.port, 'baudrate': self.baud, 'bytesize': serial.EIGHTBITS,
                  'parity': serial.PARITY_NONE, 'stopbits': serial.STOPBITS_ONE,
                  'timeout': self._read_timeout_s,
                  'write_timeout': max(1.0, self.reply_timeout_s),
                  'xonxoff': False, 'rtscts': False, 'dsrdtr': False}
        try:
            try:
                ser = self._factory(exclusive=True, **kwargs)
            except TypeError:
                # A factory (or platform) without exclusive access.
                ser = self._factory(**kwargs)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise ViscaConnectionError(f'cannot open VISCA port {self.port}: {exc}') from exc
        try:
            ser.dtr = True
        except (serial.SerialException, OSError):
            pass  # pseudo-terminals have no modem lines
        return ser

    @staticmethod
    def _close_port(ser: Optional[serial.Serial]) -> None:
        if ser is None:
            return
        try:
            ser.close()
        except (serial.SerialException, OSError):
            pass

    def _lose(self, reason: str, ser: Optional[serial.Serial]) -> None:
        """Mark the link down and fail every waiter at once (any thread)."""
        with self._cond:
            if ser is not None and ser is not self._serial:
                return
            was_connected = self._connected
            self._connected = False
            if was_connected:
                self._last_error = reason
                if not self._closing.is_set():
                    self._count('connection_losses', locked=True)
            message = f'VISCA port {self.port}: {reason}'
            if self._pending is not None and not self._pending.event.is_set():
                self._pending.deliver(None, ViscaConnectionError(message))
            for record in self._sockets.values():
                record._finish(error=ViscaConnectionError(message))
            self._sockets.clear()
            self._cond.notify_all()
            current = self._serial
        if was_connected and not self._closing.is_set():
            logger.warning('VISCA port %s lost: %s', self.port, reason)
        if current is not None:
            try:
                current.cancel_read()
            except (AttributeError, serial.SerialException, OSError, ValueError):
                pass

    def _run_io(self) -> None:
        """Reconnect loop around the read loop; the only reader of the port."""
        while not self._closing.is_set():
            with self._cond:
                ser = self._serial
            if ser is None:
                try:
                    ser = self._open_port()
                except ViscaConnectionError as exc:
                    logger.debug('%s', exc)
                    self._back_off()
                    continue
                with self._cond:
                    if self._closing.is_set():
                        self._close_port(ser)
                        return
                    self._serial, self._connected = ser, True
                    self._framer.reset()
                    self._consecutive_timeouts = 0
                    self._count('reconnects', locked=True)
                logger.info('VISCA port %s reopened', self.port)
                if self.on_reconnect is not None:
                    self._callbacks.put(self.on_reconnect)
            self._read_loop(ser)
            with self._cond:
                if self._serial is ser:
                    self._serial = None
            # Not under a writer's feet: a write takes write_timeout at most.
            with self._write_lock:
                self._close_port(ser)
            if not self._closing.is_set():
                self._back_off()

    def _back_off(self) -> None:
        with self._cond:
            delay = self._backoff_s
            self._backoff_s = min(self.reconnect_max_s, 2 * delay)
        self._closing.wait(delay)

    def _read_loop(self, ser: serial.Serial) -> None:
        while not self._closing.is_set() and self._connected and self._serial is ser:
            try:
                data = ser.read(ser.in_waiting or 1)
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                # TypeError/AttributeError: pyserial's read on a port closed under it.
                self._lose(f'read failed: {exc}', ser)
                return
            if data:
                self._feed(data)

    def _run_callbacks(self) -> None:
        while True:
            callback = self._callbacks.get()
            if callback is None:
                return
            try:
                callback()
            except Exception:  # noqa: B902 - a callback must not kill the thread
                logger.exception('VISCA callback %r failed', callback)

    # Internals: replies (reader thread) ---------------------------------------------------

    def _feed(self, data: bytes) -> None:
        for packet in self._framer.feed(data):
            reply = self._parse(packet)
            if reply is not None:
                logger.debug('VISCA <- %s', hex_bytes(reply.raw))
                self._dispatch(reply)

    def _parse(self, packet: bytes) -> Optional[Reply]:
        """Parse a framed packet; on failure re-frame from a later plausible header."""
        for start in range(len(packet) - 2):
            if start and packet[start] not in (self._header, BROADCAST):
                continue
            try:
                reply = parse_reply(packet[start:])
            except ViscaError:
                continue
            if start:
                with self._cond:
                    self._extra_junk += start
            return reply
        with self._cond:
            self._extra_junk += len(packet)
            self._count('bad_packets', locked=True)
        logger.debug('VISCA dropped unparseable bytes %s', hex_bytes(packet))
        return None

    def _dispatch(self, reply: Reply) -> None:
        callback = None
        with self._cond:
            self._count('replies', locked=True)
            self._consecutive_timeouts = 0
            self._backoff_s = self.reconnect_initial_s
            ex = self._pending
            if ex is not None and ex.event.is_set():
                ex = None
            kind = reply.kind
            if kind not in ('address_set', 'if_clear') and reply.address != self.address:
                self._unmatched(reply, 'from another address')
            elif kind == 'network_change':
                self._count('network_changes', locked=True)
                callback = self.on_network_change
                logger.info('VISCA network change (%s)', hex_bytes(reply.raw))
            elif kind == 'ack':
                self._on_ack(reply, ex)
            elif kind == 'completion':
                self._count('completions', locked=True)
                record = self._sockets.pop(reply.socket, None)
                self._completion_count += 1
                if record is not None:
                    record._finish(completion=reply)
                else:
                    self._unmatched(reply, 'no command in that socket')
                self._cond.notify_all()
            elif kind == 'answer':
                if (ex is not None and ex.kind == 'inquiry'
                        and ex.answer_length in (None, len(reply.payload))):
                    self._count('answers', locked=True)
                    ex.deliver(reply)
                else:
                    self._unmatched(reply, 'no inquiry waits for it')
            elif kind in ('address_set', 'if_clear'):
                if kind == 'if_clear':
                    self._clear_sockets(reply)
                if (ex is not None and ex.kind == 'broadcast'
                        and ex.packet[1] == reply.raw[1]):
                    ex.deliver(reply)
                else:
                    self._unmatched(reply, 'no broadcast waits for it')
            elif kind == 'error':
                self._on_error(reply, ex)
        if callback is not None:
            self._callbacks.put(callback)

    def _on_ack(self, reply: Reply, ex: Optional[_Exchange]) -> None:
        self._count('acks', locked=True)
        stale = self._sockets.pop(reply.socket, None)
        if stale is not None and not stale.done:
            # A new ACK on the socket: the old command's completion got lost.
            self._count('lost_completions', locked=True)
            stale._finish(error=ViscaTimeout(
                f'completion of {hex_bytes(stale.packet)} on socket {reply.socket} lost'))
        now = time.monotonic()
        if ex is not None and ex.kind == 'command':
            record = CommandResult(ex.packet, reply.socket, reply, now + ex.expires_s)
            self._sockets[reply.socket] = record
            ex.deliver(reply, result=record)
        else:
            # An ACK for a command whose wait timed out: keep the socket booked.
            self._sockets[reply.socket] = CommandResult(
                b'', reply.socket, reply, now + self.completion_timeout_s)
            self._unmatched(reply, 'no command waits for an ACK')
        self._cond.notify_all()

    def _on_error(self, reply: Reply, ex: Optional[_Exchange]) -> None:
        name = reply.error_name
        self._errors[name] = self._errors.get(name, 0) + 1
        code, socket = reply.code, reply.socket
        record = self._sockets.get(socket) if socket else None
        if code in (ERROR_CANCELLED, ERROR_NO_SOCKET) and socket:
            if record is not None:
                del self._sockets[socket]
                record._finish(error=command_error(reply, record.packet))
                self._cond.notify_all()
            if ex is not None and ex.kind == 'cancel' and ex.cancel_socket == socket:
                ex.deliver(reply)
            elif record is None:
                self._unmatched(reply, 'no command in that socket')
            return
        if ex is not None and (socket == 0 or ex.kind == 'command'):
            # Refused before an ACK: the request that waits for its first reply.
            ex.deliver(reply, command_error(reply, ex.packet))
        elif record is not None:
            del self._sockets[socket]
            record._finish(error=command_error(reply, record.packet))
            self._cond.notify_all()
        else:
            self._unmatched(reply, 'nothing waits for it')

    def _clear_sockets(self, reply: Reply) -> None:
        for record in self._sockets.values():
            record._finish(error=ViscaCancelled(
                f'IF_Clear ({hex_bytes(reply.raw)}) emptied socket {record.socket} holding '
                f'{hex_bytes(record.packet)}', reply, record.packet))
        self._sockets.clear()
        self._cond.notify_all()

    def _unmatched(self, reply: Reply, why: str) -> None:
        self._count('unmatched', locked=True)
        logger.debug('VISCA unmatched reply %s: %s', hex_bytes(reply.raw), why)
