"""
The reply demultiplexer: the camera's byte stream in, each reply to whoever waits for it.

VISCA replies carry no sequence number. Only one request waits for its
*first* reply at a time (:class:`Exchange`: the ACK or error of a command,
the answer of an inquiry, the echo of a broadcast, 04/05 of a cancel), so
socket-0 errors and answers are unambiguous. After its ACK a command's
completion is matched by socket number in the
:class:`~pattern_locator.visca.sockets.SocketTable`, so ACK1, ACK2, C2, C1
and answers between an ACK and its completion all work out. ACKs,
completions and errors naming a socket the camera does not have (0, 3..F)
are counted and never book a socket; when one comes as the first reply to a
command, that command fails at once (:class:`ViscaReplyError`) instead of
waiting out its timeout. Runs on the transport's reader thread; no I/O here,
so it can be fed any bytes.
"""

import logging
import threading
import time
from typing import Callable, Optional

from .exceptions import command_error, ViscaCancelled
from .protocol import (BROADCAST, COMMAND_SOCKETS, ERROR_CANCELLED, ERROR_NO_SOCKET, hex_bytes,
                       PacketFramer, parse_reply, Reply, reply_header, ViscaError,
                       ViscaReplyError)
from .sockets import CommandResult, SocketTable
from .stats import Counters

logger = logging.getLogger(__name__)


class Exchange:
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

    def deliver(self, reply: Optional[Reply], error: Optional[ViscaError] = None,
                result: Optional[CommandResult] = None) -> None:
        """Hand the first reply (or an error) to the waiting caller."""
        self.reply, self.error, self.result = reply, error, result
        self.event.set()


class ReplyDemux:
    """
    Frame bytes into packets, parse them, and route each reply (thread-safe).

    ``address`` is the camera's; ``unknown_ack_hold_s`` how long an ACK no
    command waited for keeps its socket booked; ``on_network_change`` is
    called (outside the lock) for Network Change.
    """

    def __init__(self, address: int, sockets: SocketTable, counters: Counters,
                 unknown_ack_hold_s: float, on_network_change: Callable[[], None]) -> None:
        self.address = address
        self.unknown_ack_hold_s = unknown_ack_hold_s
        self._header = reply_header(address)
        self._sockets = sockets
        self._counters = counters
        self._on_network_change = on_network_change
        self._lock = threading.Lock()
        self._pending: Optional[Exchange] = None
        self._framer = PacketFramer(resync=True)
        self._extra_junk = 0
        self._last_reply_at: Optional[float] = None

    @property
    def last_reply_at(self) -> Optional[float]:
        """Return the ``time.monotonic()`` of the last reply parsed (None: none yet)."""
        return self._last_reply_at

    @property
    def junk_bytes(self) -> int:
        """Return the bytes dropped as junk (before a header, unparseable, overlong)."""
        with self._lock:
            return self._framer.junk_bytes + self._extra_junk

    # Requests (caller threads) ------------------------------------------------------------------

    def begin(self, ex: Exchange) -> None:
        """Make ``ex`` the request that waits for the next first reply."""
        with self._lock:
            self._pending = ex

    def end(self, ex: Exchange) -> None:
        """``ex`` stopped waiting (answered, timed out, failed)."""
        with self._lock:
            if self._pending is ex:
                self._pending = None

    def fail_pending(self, error: ViscaError) -> None:
        """Fail the waiting request at once (connection lost, closing)."""
        with self._lock:
            ex = self._pending
            if ex is not None and not ex.event.is_set():
                ex.deliver(None, error)

    def reset(self) -> None:
        """Drop a partial packet (after a reconnect)."""
        with self._lock:
            self._framer.reset()

    # Replies (reader thread) ------------------------------------------------------------------

    def feed(self, data: bytes) -> int:
        """Route every reply ``data`` completes; return how many there were."""
        with self._lock:
            packets = self._framer.feed(data)
        count = 0
        for packet in packets:
            reply = self._parse(packet)
            if reply is not None:
                logger.debug('VISCA <- %s', hex_bytes(reply.raw))
                count += 1
                self._dispatch(reply)
        return count

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
                with self._lock:
                    self._extra_junk += start
            return reply
        with self._lock:
            self._extra_junk += len(packet)
        self._counters.add('bad_packets')
        logger.debug('VISCA dropped unparseable bytes %s', hex_bytes(packet))
        return None

    def _dispatch(self, reply: Reply) -> None:
        network_change = False
        with self._lock:
            self._counters.add('replies')
            self._last_reply_at = time.monotonic()
            ex = self._pending
            if ex is not None and ex.event.is_set():
                ex = None
            kind = reply.kind
            if kind not in ('address_set', 'if_clear') and reply.address != self.address:
                self._unmatched(reply, 'from another address')
            elif kind in ('ack', 'completion', 'error') and reply.socket not in COMMAND_SOCKETS \
                    and not (kind == 'error' and reply.socket == 0):
                self._bad_socket(reply, ex)
            elif kind == 'network_change':
                self._counters.add('network_changes')
                network_change = True
                logger.info('VISCA network change (%s)', hex_bytes(reply.raw))
            elif kind == 'ack':
                self._on_ack(reply, ex)
            elif kind == 'completion':
                self._counters.add('completions')
                if not self._sockets.complete(reply.socket, reply):
                    self._unmatched(reply, 'no command in that socket')
            elif kind == 'answer':
                if (ex is not None and ex.kind == 'inquiry'
                        and ex.answer_length in (None, len(reply.payload))):
                    self._counters.add('answers')
                    ex.deliver(reply)
                else:
                    self._unmatched(reply, 'no inquiry waits for it')
            elif kind in ('address_set', 'if_clear'):
                if kind == 'if_clear':
                    self._sockets.clear(lambda record: ViscaCancelled(
                        f'IF_Clear ({hex_bytes(reply.raw)}) emptied socket {record.socket} '
                        f'holding {hex_bytes(record.packet)}', reply, record.packet))
                if (ex is not None and ex.kind == 'broadcast'
                        and ex.packet[1] == reply.raw[1]):
                    ex.deliver(reply)
                else:
                    self._unmatched(reply, 'no broadcast waits for it')
            elif kind == 'error':
                self._on_error(reply, ex)
        if network_change:
            self._on_network_change()

    def _on_ack(self, reply: Reply, ex: Optional[Exchange]) -> None:
        self._counters.add('acks')
        now = time.monotonic()
        if ex is not None and ex.kind == 'command':
            record = CommandResult(ex.packet, reply.socket, reply, now + ex.expires_s)
            self._sockets.book(reply.socket, record)
            ex.deliver(reply, result=record)
        else:
            # An ACK for a command whose wait timed out: keep the socket booked.
            self._sockets.book(reply.socket, CommandResult(
                b'', reply.socket, reply, now + self.unknown_ack_hold_s))
            self._unmatched(reply, 'no command waits for an ACK')

    def _on_error(self, reply: Reply, ex: Optional[Exchange]) -> None:
        self._counters.add_error(reply.error_name)
        code, socket = reply.code, reply.socket

        def error(record: CommandResult) -> ViscaError:
            return command_error(reply, record.packet)

        if code in (ERROR_CANCELLED, ERROR_NO_SOCKET) and socket:
            record = self._sockets.fail(socket, error)
            if ex is not None and ex.kind == 'cancel' and ex.cancel_socket == socket:
                ex.deliver(reply)
            elif record is None:
                self._unmatched(reply, 'no command in that socket')
            return
        if ex is not None and (socket == 0 or ex.kind == 'command'):
            # Refused before an ACK: the request that waits for its first reply.
            ex.deliver(reply, command_error(reply, ex.packet))
        elif socket == 0 or self._sockets.fail(socket, error) is None:
            self._unmatched(reply, 'nothing waits for it')

    def _bad_socket(self, reply: Reply, ex: Optional[Exchange]) -> None:
        self._counters.add('bad_socket_replies')
        if reply.kind in ('ack', 'error') and ex is not None and ex.kind == 'command':
            # The first reply to our command, and nonsense: what the camera did is unknown.
            ex.deliver(reply, ViscaReplyError(
                f'camera answered {hex_bytes(ex.packet)} with {reply.describe()}, a socket '
                f'it does not have (only {", ".join(map(str, COMMAND_SOCKETS))})'))
        logger.debug('VISCA ignored %s: no such socket', reply.describe())

    def _unmatched(self, reply: Reply, why: str) -> None:
        self._counters.add('unmatched')
        logger.debug('VISCA unmatched reply %s: %s', hex_bytes(reply.raw), why)
