"""
The emulated EVI-D31's end of the RS-232 line: a raw pseudo-terminal paced at 9600 baud.

:class:`PtyLine` opens the pty (and a symlink to it, so a driver can be
pointed at a fixed path), frames what the driver writes into packets that
count as arrived only once their bytes would have crossed the wire, keeps
them in a queue of 32 (more are dropped and counted), and writes replies one
byte per 1.04 ms. Not thread-safe: the emulator calls it under its lock.
"""

import collections
import errno
import os
import termios
import tty
from typing import Deque, Optional, Tuple

from .protocol import MAX_PACKET, PacketFramer

INBOX_LIMIT = 32


class PtyLine:
    """One pty; ``byte_s`` is a byte's time on the wire, ``pace`` False sends at once."""

    def __init__(self, link_path: Optional[str], byte_s: float, pace: bool) -> None:
        self.link_path = link_path
        self.byte_s = byte_s
        self.pace = pace
        self.counts: 'collections.Counter[str]' = collections.Counter()
        self._master: Optional[int] = None
        self._slave: Optional[int] = None
        self._slave_name: Optional[str] = None
        # Input side: packets with the time they are complete (None: one that overflowed).
        self._framer = PacketFramer()
        self._inbox: Deque[Tuple[float, Optional[bytes]]] = collections.deque()
        self._in_line_free = 0.0
        # Output side: packets waiting (ready time, bytes), the packet on the wire.
        self._outbox: Deque[Tuple[float, bytes]] = collections.deque()
        self._wire: Deque[int] = collections.deque()
        self._wire_ready = 0.0
        self._line_free = 0.0

    @property
    def master(self) -> Optional[int]:
        """Return the master fd to read from (None while closed)."""
        return self._master

    @property
    def port(self) -> str:
        """Return the path to open: the symlink if ``link_path`` was given, else the pty."""
        if self.link_path:
            return self.link_path
        if self._slave_name is None:
            raise RuntimeError('the emulated camera has no pty (not started, or vanished)')
        return self._slave_name

    @property
    def junk_bytes(self) -> int:
        """Return the bytes received outside packets."""
        return self._framer.junk_bytes

    # Pty ------------------------------------------------------------------------------------

    def open(self) -> None:  # noqa: A003 - the line's natural verb
        """Open a new pty, raw at 9600 baud, and point the symlink at it."""
        master, slave = os.openpty()
        # Raw: no CR/LF or XON/XOFF translation and no echo (visca.md, "Serial line").
        tty.setraw(slave)
        attrs = termios.tcgetattr(slave)
        attrs[4] = attrs[5] = termios.B9600
        termios.tcsetattr(slave, termios.TCSANOW, attrs)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self._slave_name = os.ttyname(slave)
        if self.link_path:
            temporary = f'{self.link_path}.{os.getpid()}.tmp'
            if os.path.lexists(temporary):
                os.unlink(temporary)
            os.symlink(self._slave_name, temporary)
            os.replace(temporary, self.link_path)
        self._framer.reset()

    def close(self) -> None:
        """Close the pty (the driver's port errors out) and remove the symlink."""
        if self.link_path and os.path.islink(self.link_path) \
                and os.readlink(self.link_path) == self._slave_name:
            os.unlink(self.link_path)
        for fd in (self._master, self._slave):
            if fd is not None:
                os.close(fd)
        self._master = self._slave = self._slave_name = None
        self._inbox.clear()
        self._outbox.clear()
        self._wire.clear()
        self._framer.reset()

    # Input ----------------------------------------------------------------------------------

    def receive(self, data: bytes, now: float, discard: bool) -> None:
        """Frame ``data`` read at ``now``; ``discard``: count the packets, keep none."""
        for byte in data:
            overlong = self._framer.overlong_packets
            packets = self._framer.feed(bytes((byte,)))
            if self._framer.overlong_packets != overlong:
                self._enqueue(now, None, MAX_PACKET, discard)
            for packet in packets:
                self._enqueue(now, packet, len(packet), discard)

    def packet_due(self, now: float) -> bool:
        """Return True when a received packet has fully arrived by ``now``."""
        return bool(self._inbox) and self._inbox[0][0] <= now

    def next_packet(self) -> Optional[bytes]:
        """Return the oldest received packet (None: one that overflowed 16 bytes)."""
        return self._inbox.popleft()[1]

    def clear_inbox(self) -> None:
        """Forget the received packets (power-up, silence)."""
        self._inbox.clear()

    def _enqueue(self, now: float, packet: Optional[bytes], length: int, discard: bool) -> None:
        self.counts['packets'] += 1
        # The packet is complete once its bytes would have crossed the line at 9600 baud.
        self._in_line_free = max(self._in_line_free, now)
        if self.pace:
            self._in_line_free += length * self.byte_s
        if discard:
            self.counts['ignored'] += 1
        elif len(self._inbox) >= INBOX_LIMIT:
            self.counts['overflows'] += 1
        else:
            self._inbox.append((self._in_line_free, packet))

    # Output ---------------------------------------------------------------------------------

    def send(self, packet: bytes, ready_at: float) -> None:
        """Queue ``packet`` to go out from ``ready_at`` on (nowhere while closed)."""
        if self._master is not None:
            self._outbox.append((ready_at, packet))

    def next_output_time(self) -> Optional[float]:
        """Return when the next byte is due (None: nothing to send)."""
        if self._master is None:
            return None
        if self._wire:
            if not self.pace:
                return self._wire_ready
            return max(self._line_free, self._wire_ready) + self.byte_s
        if self._outbox:
            return self._outbox[0][0] + (self.byte_s if self.pace else 0.0)
        return None

    def pump(self, now: float) -> None:
        """Write the bytes whose time has come: one byte per 1.04 ms when paced."""
        if self._master is None:
            return
        chunk = bytearray()
        while True:
            if not self._wire:
                if not self._outbox or self._outbox[0][0] > now:
                    break
                self._wire_ready, packet = self._outbox.popleft()
                self._wire.extend(packet)
            if not self.pace:
                chunk.extend(self._wire)
                self._wire.clear()
                continue
            done = max(self._line_free, self._wire_ready) + self.byte_s
            if done > now:
                break
            chunk.append(self._wire.popleft())
            self._line_free = done
        if chunk:
            try:
                os.write(self._master, bytes(chunk))
            except OSError as exc:
                # A full pty buffer loses bytes, like an overrun UART.
                if exc.errno not in (errno.EAGAIN, errno.EIO):
                    raise
