"""
The serial link: the port opened raw at 9600 8N1, one reader thread, reopened when it fails.

The reconnect loop has the nmea_navsat_driver TCP node's shape: an outer
loop (re)opens the port around an inner read loop that breaks out on a port
error. When the port fails the link closes it, tells its owner (who fails
every waiter at once) and reopens it after ``reconnect_initial_s``; while
the port cannot be opened (unplugged) the attempts back off, doubling up to
``reconnect_max_s``. Why an open failed is said in one line
(:func:`open_error`) and kept in ``last_error``. A second thread runs
callbacks (``call_soon``) so they may use the link's owner: they never run
on the reader.
"""

import errno
import logging
import queue
import threading
from typing import Callable, Optional

import serial

from .exceptions import ViscaConnectionError
from .protocol import hex_bytes
from .stats import Counters

logger = logging.getLogger(__name__)


def open_error(port: str, exc: BaseException) -> str:
    """Return why ``port`` could not be opened, in one line a user can act on."""
    code = getattr(exc, 'errno', None)
    text = str(exc)
    if code == errno.ENOENT:
        return f'VISCA port {port} does not exist'
    if code in (errno.EACCES, errno.EPERM):
        return f'no permission to open VISCA port {port} (is the user in the dialout group?)'
    if 'exclusively lock' in text or code == errno.EBUSY:
        return f'VISCA port {port} is in use by another program'
    if code == errno.EISDIR:
        return f'VISCA port {port} is a directory, not a serial port'
    if 'configure port' in text or code == errno.ENOTTY:
        return f'VISCA port {port} is not a serial port ({text})'
    return f'cannot open VISCA port {port}: {text}'


class SerialLink:
    """
    One serial port and its reader thread (thread-safe).

    ``on_data(bytes)`` runs on the reader thread for everything read;
    ``on_lost(message)`` when the port failed or closed (any thread);
    ``on_reopen()`` on the reader thread after the port was opened again.
    """

    def __init__(self, port: str, baud: int, serial_factory: Callable[..., serial.Serial],
                 read_timeout_s: float, write_timeout_s: float, reconnect_initial_s: float,
                 reconnect_max_s: float, counters: Counters,
                 on_data: Callable[[bytes], None], on_lost: Callable[[str], None],
                 on_reopen: Callable[[], None]) -> None:
        self.port = port
        self.baud = baud
        self.reconnect_initial_s = reconnect_initial_s
        self.reconnect_max_s = reconnect_max_s
        self._factory = serial_factory
        self._read_timeout_s = read_timeout_s
        self._write_timeout_s = write_timeout_s
        self._counters = counters
        self._on_data = on_data
        self._on_lost = on_lost
        self._on_reopen = on_reopen
        self._lock = threading.Lock()
        self._write_lock = threading.Lock()
        self._serial: Optional[serial.Serial] = None
        self._connected = False
        self._opened = False
        self._closing = threading.Event()
        self._backoff_s = reconnect_initial_s
        self._last_error = ''
        self._io_thread: Optional[threading.Thread] = None
        self._callback_thread: Optional[threading.Thread] = None
        self._callbacks: 'queue.Queue[Optional[Callable[[], None]]]' = queue.Queue()

    # Life cycle ---------------------------------------------------------------------------------

    def open(self) -> bool:  # noqa: A003 - the link's natural verb
        """Open the port and start the threads; False if already open, ViscaConnectionError."""
        with self._lock:
            if self._opened:
                return False
        ser = self._open_port()
        with self._lock:
            self._closing.clear()
            self._serial, self._connected, self._opened = ser, True, True
            self._backoff_s = self.reconnect_initial_s
        self._callbacks = queue.Queue()
        self._callback_thread = threading.Thread(target=self._run_callbacks, daemon=True,
                                                 name=f'visca-callbacks {self.port}')
        self._io_thread = threading.Thread(target=self._run_io, daemon=True,
                                           name=f'visca-io {self.port}')
        self._callback_thread.start()
        self._io_thread.start()
        return True

    def close(self) -> bool:
        """Stop the threads and close the port; False if it was not open (idempotent)."""
        with self._lock:
            if not self._opened:
                return False
            self._opened = False
            self._closing.set()
        self.lose('transport closed', None)
        io_thread, cb_thread = self._io_thread, self._callback_thread
        if io_thread is not None and io_thread is not threading.current_thread():
            io_thread.join(timeout=2.0)
        self._callbacks.put(None)
        if cb_thread is not None and cb_thread is not threading.current_thread():
            cb_thread.join(timeout=2.0)
        with self._lock:
            ser, self._serial = self._serial, None
        self._close_port(ser)
        return True

    @property
    def connected(self) -> bool:
        """Return True while the port is open (not while reconnecting)."""
        return self._connected

    @property
    def is_open(self) -> bool:
        """Return True between open() and close(), reconnecting or not."""
        return self._opened

    @property
    def closing(self) -> bool:
        """Return True once close() started."""
        return self._closing.is_set()

    @property
    def last_error(self) -> str:
        """Return why the connection was last lost ('' if never)."""
        return self._last_error

    def check(self) -> None:
        """Raise ViscaConnectionError unless the port is open."""
        if not self._connected:
            why = f': {self._last_error}' if self._last_error else ''
            raise ViscaConnectionError(f'VISCA port {self.port} is not connected{why}')

    def call_soon(self, callback: Callable[[], None]) -> None:
        """Run ``callback`` on the callback thread."""
        self._callbacks.put(callback)

    def reset_backoff(self) -> None:
        """Start the next reconnect with the shortest pause (the camera answered)."""
        with self._lock:
            self._backoff_s = self.reconnect_initial_s

    # Writing ------------------------------------------------------------------------------------

    def write(self, packet: bytes) -> None:
        """Write ``packet``; ViscaConnectionError (and the link is lost) when that fails."""
        with self._write_lock:
            with self._lock:
                self.check()
                ser = self._serial
            try:
                ser.write(packet)
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                # TypeError/AttributeError: pyserial's write on a port closed under it.
                self.lose(f'write failed: {exc}', ser)
                raise ViscaConnectionError(
                    f'VISCA port {self.port}: write failed: {exc}') from exc
            self._counters.add('sent')
            logger.debug('VISCA -> %s', hex_bytes(packet))

    # Losing and reopening -----------------------------------------------------------------------

    def lose(self, reason: str, ser: Optional[serial.Serial]) -> None:
        """Mark the link down and tell the owner (any thread); ``ser``: only if still current."""
        with self._lock:
            if ser is not None and ser is not self._serial:
                return
            was_connected = self._connected
            self._connected = False
            if was_connected:
                self._last_error = reason
                if not self._closing.is_set():
                    self._counters.add('connection_losses')
            current = self._serial
        self._on_lost(f'VISCA port {self.port}: {reason}')
        if was_connected and not self._closing.is_set():
            logger.warning('VISCA port %s lost: %s', self.port, reason)
        if current is not None:
            try:
                current.cancel_read()
            except (AttributeError, serial.SerialException, OSError, ValueError):
                pass

    def _open_port(self) -> serial.Serial:
        kwargs = {'port': self.port, 'baudrate': self.baud, 'bytesize': serial.EIGHTBITS,
                  'parity': serial.PARITY_NONE, 'stopbits': serial.STOPBITS_ONE,
                  'timeout': self._read_timeout_s, 'write_timeout': self._write_timeout_s,
                  'xonxoff': False, 'rtscts': False, 'dsrdtr': False}
        try:
            try:
                ser = self._factory(exclusive=True, **kwargs)
            except TypeError:
                # A factory (or platform) without exclusive access.
                ser = self._factory(**kwargs)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise ViscaConnectionError(open_error(self.port, exc)) from exc
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

    def _run_io(self) -> None:
        """Reconnect loop around the read loop; the only reader of the port."""
        while not self._closing.is_set():
            with self._lock:
                ser = self._serial
            if ser is None:
                try:
                    ser = self._open_port()
                except ViscaConnectionError as exc:
                    if str(exc) != self._last_error:
                        logger.warning('%s (retrying)', exc)
                    self._last_error = str(exc)
                    self._back_off()
                    continue
                with self._lock:
                    if self._closing.is_set():
                        self._close_port(ser)
                        return
                    self._serial, self._connected = ser, True
                    self._backoff_s = self.reconnect_initial_s
                self._counters.add('reconnects')
                logger.info('VISCA port %s reopened', self.port)
                self._on_reopen()
            self._read_loop(ser)
            with self._lock:
                if self._serial is ser:
                    self._serial = None
            # Not under a writer's feet: a write takes write_timeout at most.
            with self._write_lock:
                self._close_port(ser)
            # The port opened fine last time: try again soon (the backoff is for failed opens).
            self._closing.wait(self.reconnect_initial_s)

    def _back_off(self) -> None:
        with self._lock:
            delay = self._backoff_s
            self._backoff_s = min(self.reconnect_max_s, 2 * delay)
        self._closing.wait(delay)

    def _read_loop(self, ser: serial.Serial) -> None:
        while not self._closing.is_set() and self._connected and self._serial is ser:
            try:
                data = ser.read(ser.in_waiting or 1)
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                # TypeError/AttributeError: pyserial's read on a port closed under it.
                self.lose(f'read failed: {exc}', ser)
                return
            if data:
                self._on_data(data)

    def _run_callbacks(self) -> None:
        while True:
            callback = self._callbacks.get()
            if callback is None:
                return
            try:
                callback()
            except Exception:  # noqa: B902 - a callback must not kill the thread
                logger.exception('VISCA callback %r failed', callback)
