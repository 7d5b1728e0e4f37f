"""
Emulated Sony EVI-D31 pan/tilt/zoom camera on a pseudo-terminal (ROS-free).

:class:`EmulatedEviD31` opens a pty whose slave end pyserial opens like the
real RS-232 port (the slave is set raw, so 0x0D/0x11/0x13 pass unchanged) and
answers VISCA the way ``design/visca.md`` describes, with a continuous-time
model of the head so :meth:`EmulatedEviD31.state` is right at any instant
(for rendering a simulated camera image). Packets are built and parsed with
:mod:`pattern_locator.visca.protocol`.

Where to look: :mod:`~pattern_locator.visca.emulator_motion` is the motion
model (axes in continuous time, limits), :mod:`~pattern_locator.visca.emulator_device`
the device state (power, address, sockets, initialisation) and what each
command does, :mod:`~pattern_locator.visca.emulator_protocol` the protocol
handling (packets in, replies out, in the order below),
:mod:`~pattern_locator.visca.emulator_line` the pty paced at 9600 baud and
:mod:`~pattern_locator.visca.emulator_faults` the fault injection; this
module runs them on one thread, one packet per video field.

Timing
    One received packet (command, inquiry, cancel or broadcast) is processed
    per video field (50 Hz for the PAL D31; ``field_rate_hz``), so an ACK
    or an answer comes within one field of the packet's last byte. Socket
    completions are checked at each field before the packet, so a motion's
    completion comes at the first field after the motion ends. With
    ``pace_output`` the line runs at 9600 baud both ways: reply bytes are
    written one at a time, ~1.04 ms apart, and a received packet counts as
    arrived only once its bytes would have crossed the wire. Received
    packets wait in a queue of 32 (more are dropped and counted).

Addressing
    Address Set ``88 30 0w FF`` (w 1..7) gives the camera address w and
    comes back as ``88 30 0(w+1) FF``. Until then every addressed packet is
    ignored (``require_address_set=True``; with False the camera answers at
    address 1 from power-up); power-up forgets the address. Packets for
    another address, other broadcasts and camera replies are ignored.
    IF_Clear (broadcast ``88 01 00 01 FF``, echoed unchanged; or addressed
    ``8x 01 00 01 FF``, answered ``z0 50 FF``) empties both sockets with no
    reply for the held commands, and stops every pan-tilt and zoom motion
    (also a Drive that already completed), so the head is still after a
    driver's start-up. A power-up initialisation continues.

Sockets and errors
    Timed commands (AbsolutePosition, RelativePosition, Home, Reset, Zoom
    Direct) hold their socket (ACK ``z0 4y FF``) until the motion ends
    (``z0 5y FF``); instant commands (Drive, Zoom stop/tele/wide, focus,
    power, LimitSet/Clear) are ACKed and completed in the next field. The
    checks run in this order: syntax (``z0 60 02 FF``: unknown command or
    inquiry, wrong length, speed 00 or above max, direction outside 1..3,
    zoom speed outside 2..7, a nibble byte above 0F, an absolute position or
    limit outside travel, zoom outside 0..3FF), then a free socket
    (``z0 60 03 FF``), then ``z0 6y 41 FF`` (y = the free socket it would
    have used) for: anything but Power in standby; anything during
    initialisation; a pan-tilt command (Drive too) while a pan-tilt
    Absolute/Relative/Home/Reset is held, or a zoom command while a Zoom
    Direct is held (cancel that socket first); focus far/near in auto focus;
    a LimitSet that would cross the other corner. Cancel ``8x 2y FF`` stops
    the held command's motion and answers ``z0 6y 04 FF`` (no completion
    follows; cancelling Reset leaves the head where it is and ends the
    initialisation), or ``z0 6y 05 FF`` for an empty socket. A packet
    without FF within 16 bytes gets ``z0 60 01 FF`` (also a 2-byte packet).

Motion
    Positions in camera units (pan +-880 = +-100 deg, positive right; tilt
    +-300 = +-25 deg, positive up), speed steps by ``pan_speed_deg_s`` /
    ``tilt_speed_deg_s``, velocity changes are instant (no ramps). Drive runs
    until stop or the current limits (LimitSet corners, else travel); a
    LimitSet/Clear re-plans a running drive. Absolute targets must be within
    travel and are clamped into the LimitSet box; relative targets are
    clamped into it. Each axis moves at its own speed; completion when both
    arrive. Home = absolute (0, 0) at 18h/14h. Reset sweeps both axes to the
    positive end, the negative end and back to 0 in ``reset_s``. Zoom Direct
    and standard tele/wide move 0..3FFh in ``zoom_full_s`` (2.2 s); variable
    speed p (2..7) takes ``zoom_full_s * 7 / p`` end to end (?), so p = 7
    equals standard.

Power
    At power-up (:meth:`start`, :meth:`power_cycle`) the camera sends
    Network Change ``z0 38 FF`` (address 1's header, ``90 38 FF``, as the
    address is not set yet) and initialises for ``init_s``: both axes sweep
    through their ends back to 0, zoom goes wide, limits are cleared, focus
    is auto. Power inquiry says on throughout; commands are not executable
    until the end (``z0 6y 41 FF``). :meth:`start` writes that Network
    Change before it returns, and pyserial flushes the input when it opens
    the port, so a driver opening the port after :meth:`start` never sees
    it (as with a real camera powered before the driver): always send
    Address Set at start. :meth:`power_cycle` sends it to an open port.
    Power Off (standby) stops every motion and frees the other socket
    silently, the head stays where it is; Power On from standby re-runs
    the initialisation (without Network Change).

Inquiries (socket 0, no ACK; answered in standby and during initialisation)
    position ``z0 50 0p 0p 0p 0p 0t 0t 0t 0t FF`` (rounded units), zoom
    ``z0 50 0p 0q 0r 0s FF``, power ``02``/``03``, max speed ``18 14``,
    focus mode ``09 04 38`` -> ``02``/``03``, version
    ``00 01 04 02 02 01 02`` (vendor 0001, model 0402, ROM 0201, 2 sockets),
    pan-tilt mode ``pq rs`` laid out as the EVI-D80's status code list:
    bits 13-12 initialisation (01 running, 10 done), bits 11-10 pan-tilt
    motion (00 none commanded since power-up, 01 moving, 10 done), bits 9-8
    and 5-4 tilt/pan position detection (00 fine), bits 3..0 at the
    down/up/right/left end of travel. E.g. ``20 00`` idle, ``28 00`` after
    a move, ``14 00`` initialising, ``28 06`` at the up-right end.

Exposure (not in visca.md: Sony's EVI-D100 technical manual, "Command List,
D30/31 mode", the shutter table on p. 43, and the standard VISCA camera
commands of Sony's EVI/FCB manuals)
    CAM_AE ``8x 01 04 39 pp FF`` sets the exposure mode (pp 00 full auto, 03
    manual, 0A shutter priority, 0B iris priority, 0D bright; other values a
    syntax error), CAM_Shutter direct ``8x 01 04 4A 00 00 0p 0q FF`` the
    shutter position 00..1Bh (above 1Bh, or a nibble byte above 0F: syntax
    error), ``8x 01 04 0A 00/02/03 FF`` resets it to 00 or steps it up
    (faster) / down, stopping at the ends (?). All are instant commands (ACK,
    completion in the next field) and refused like the others in standby and
    during initialisation. Inquiries ``8x 09 04 39 FF`` -> ``z0 50 pp FF``
    and ``8x 09 04 4A FF`` -> ``z0 50 00 00 0p 0q FF`` answer what was
    commanded. :attr:`HeadState.shutter_s` is the exposure time the camera
    applies: in shutter priority and manual the position's speed from the
    PAL table (``protocol.SHUTTER_DENOMINATORS``: 00 1/50 s .. 1Bh 1/10000
    s), in the other modes ``auto_shutter_s`` (the camera picks it; 1/50 s
    by default); the position is kept while the camera picks. A change
    reaches :meth:`state` at the next field, when its completion goes out.
    A power-up (:meth:`start`, :meth:`power_cycle`) returns to full auto,
    position 00; standby and pan-tilt Reset keep the exposure (?).

Faults (for tests, thread-safe)
    ``faults.drop_probability`` / ``garble_probability`` (flip one bit or
    insert 1-3 random bytes) / ``delay_s`` apply to each reply;
    ``faults.bad_position_probability`` (impossible position answers),
    ``lose_completions``, ``bad_ack_socket_probability`` (ACKs on sockets
    0, 3..9), ``error_only`` (every addressed packet answered with one
    error code, nothing done), ``refuse_exposure`` (the exposure commands
    and inquiries answered with one error code: a model without them),
    ``phantom_ack_interval_s`` (ACKs never
    completed) and ``deaf_to_commands`` are the broken camera of issue 10
    (see :class:`Faults`);
    :meth:`reply_to_wrong_socket_once` swaps sockets 1 and 2 in the next
    ACK, completion or socket error; :meth:`send_garbage` and
    :meth:`send_network_change` write at once; :meth:`vanish` closes the pty
    (the driver's port errors out) and removes the ``link_path`` symlink,
    :meth:`restore` opens a new pty behind the same symlink (the camera kept
    its state, address included); :meth:`stop_answering` makes the camera
    read and discard every packet and send nothing (motions still run; their
    completions are lost).
"""

import collections
from dataclasses import dataclass
import math
import os
import select
import signal
import sys
import threading
import time
from typing import Callable, Deque, Mapping, Optional, Tuple

from .emulator_device import EmulatedDevice, HeadState, SOCKETS
from .emulator_faults import FaultInjector, Faults
from .emulator_line import PtyLine
from .emulator_protocol import ViscaResponder
from .protocol import ack, BROADCAST, network_change

DEFAULT_BAUD = 9600

__all__ = ['EmulatedEviD31', 'EmulatorStats', 'Faults', 'HeadState', 'run_fake_camera']


@dataclass(frozen=True)
class EmulatorStats:
    """Counters of the emulated camera since :meth:`EmulatedEviD31.start`."""

    packets_received: int
    commands_received: int
    inquiries_received: int
    ignored_packets: int
    inbox_overflows: int
    junk_bytes: int
    replies_sent: int
    replies_dropped: int
    replies_garbled: int
    errors_by_code: Mapping[int, int]


class EmulatedEviD31:
    """
    A Sony EVI-D31 answering VISCA on a pseudo-terminal; see the module docstring.

    ``start()`` opens the pty and the emulator thread; open :attr:`port`
    with pyserial at 9600 baud. Times come from ``clock`` (``time.monotonic``;
    a sim's slowed clock runs the head's motion and the line's bytes at
    ``clock_rate`` of its seconds per wall second). The
    camera itself is :class:`~pattern_locator.visca.emulator_device.EmulatedDevice`
    behind a :class:`~pattern_locator.visca.emulator_protocol.ViscaResponder`,
    the line a :class:`~pattern_locator.visca.emulator_line.PtyLine`, the faults
    a :class:`~pattern_locator.visca.emulator_faults.FaultInjector`; this class
    runs them on one thread, one packet per video field.
    """

    def __init__(self, field_rate_hz: float = 50.0, init_s: float = 2.0, reset_s: float = 2.5,
                 pace_output: bool = True, link_path: Optional[str] = None, seed: int = 0,
                 require_address_set: bool = True, zoom_full_s: float = 2.2,
                 baud: int = DEFAULT_BAUD, auto_shutter_s: float = 0.02,
                 clock: Callable[[], float] = time.monotonic, clock_rate: float = 1.0) -> None:
        if field_rate_hz <= 0.0:
            raise ValueError(f'field rate {field_rate_hz} Hz is not positive')
        if not (math.isfinite(clock_rate) and clock_rate > 0.0):
            raise ValueError(f'clock rate {clock_rate} is not positive')
        self._clock = clock
        self._clock_rate = float(clock_rate)
        # 0: an idealised instant exposure (a sim without motion blur).
        if not (math.isfinite(auto_shutter_s) and 0.0 <= auto_shutter_s <= 1.0):
            raise ValueError(f'auto exposure time {auto_shutter_s} s is not in [0, 1]')
        self.field_rate_hz = float(field_rate_hz)
        self.link_path = os.fspath(link_path) if link_path is not None else None
        # 8N1: ten bit times per byte.
        self._line = PtyLine(self.link_path, 10.0 / float(baud), bool(pace_output))
        self.faults = Faults()
        self._injector = FaultInjector(self.faults, seed)
        self._device = EmulatedDevice(max(0.0, float(init_s)), max(0.0, float(reset_s)),
                                      float(zoom_full_s), bool(require_address_set),
                                      float(auto_shutter_s))
        self._responder = ViscaResponder(self._device)
        self._lock = threading.RLock()
        self._thread: Optional[threading.Thread] = None
        self._stopping = False
        self._requests: Deque[Tuple[Callable[[], None], threading.Event]] = collections.deque()
        self._wake_r: Optional[int] = None
        self._wake_w: Optional[int] = None
        self._silent = False
        self._phantom_at = 0.0
        self._counts: 'collections.Counter[str]' = collections.Counter()
        self._errors: 'collections.Counter[int]' = collections.Counter()

    # Life cycle ---------------------------------------------------------------------------

    def start(self) -> 'EmulatedEviD31':
        """Open the pty (and the symlink), power the camera up and start its thread."""
        with self._lock:
            if self._thread is not None:
                raise RuntimeError('the emulated camera is already started')
            if self.link_path and os.path.lexists(self.link_path) \
                    and not os.path.islink(self.link_path):
                raise FileExistsError(f'{self.link_path} exists and is not a symlink')
            self._wake_r, self._wake_w = os.pipe()
            os.set_blocking(self._wake_w, False)
            self._line.open()
            self._power_up(self._clock())
            self._thread = threading.Thread(target=self._run, name='fake-evi-d31', daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread, close every fd and remove the symlink (idempotent)."""
        with self._lock:
            thread, self._stopping = self._thread, True
        self._wake()
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=5.0)
        with self._lock:
            self._line.close()
            for fd in (self._wake_r, self._wake_w):
                if fd is not None:
                    os.close(fd)
            self._wake_r = self._wake_w = None

    def __enter__(self) -> 'EmulatedEviD31':
        """Start unless already started."""
        if self._thread is None:
            self.start()
        return self

    def __exit__(self, *exc_info) -> None:
        """Stop."""
        self.stop()

    @property
    def port(self) -> str:
        """Return the path to open: the symlink if ``link_path`` was given, else the pty."""
        return self._line.port

    @property
    def address(self) -> Optional[int]:
        """Return the camera's VISCA address, None until Address Set."""
        with self._lock:
            return self._device.address

    @property
    def init_s(self) -> float:
        """Return the power-up initialisation time (s); settable, for the next power-up."""
        return self._device.init_s

    @init_s.setter
    def init_s(self, seconds: float) -> None:
        with self._lock:
            self._device.init_s = max(0.0, float(seconds))

    def state(self) -> HeadState:
        """Return the head's state now (thread-safe)."""
        with self._lock:
            return self._device.state(self._clock())

    @property
    def stats(self) -> EmulatorStats:
        """Return a snapshot of the counters."""
        with self._lock:
            line, handled, faults = self._line.counts, self._responder.counts, \
                self._injector.counts
            return EmulatorStats(
                packets_received=line['packets'], commands_received=handled['commands'],
                inquiries_received=handled['inquiries'],
                ignored_packets=line['ignored'] + handled['ignored'],
                inbox_overflows=line['overflows'], junk_bytes=self._line.junk_bytes,
                replies_sent=self._counts['sent'], replies_dropped=faults['dropped'],
                replies_garbled=faults['garbled'], errors_by_code=dict(self._errors))

    # Fault injection ----------------------------------------------------------------------

    def reply_to_wrong_socket_once(self) -> None:
        """Swap sockets 1 and 2 in the next ACK, completion or socket error."""
        with self._lock:
            self._injector.wrong_socket_once = True

    def send_garbage(self, data: bytes) -> None:
        """Write ``data`` to the driver as they are (no faults applied)."""
        with self._lock:
            self._line.send(bytes(data), self._clock())
        self._wake()

    def send_network_change(self) -> None:
        """Send Network Change ``z0 38 FF`` now (no faults applied)."""
        with self._lock:
            self._line.send(network_change(self._device.reply_address()), self._clock())
        self._wake()

    def stop_answering(self, silent: bool = True) -> None:
        """Read and discard every packet and send nothing (True), or answer again (False)."""
        with self._lock:
            self._silent = bool(silent)
            if silent:
                self._line.clear_inbox()

    def vanish(self) -> None:
        """Close the pty so the driver's port errors out, and remove the symlink."""
        self._in_worker(self._line.close)

    def restore(self) -> None:
        """Open a new pty after :meth:`vanish` and point the symlink at it."""
        self._in_worker(self._restore)

    def power_cycle(self) -> None:
        """Switch the camera off and on: initialisation and Network Change again."""
        with self._lock:
            self._power_up(self._clock())
        self._wake()

    # Thread -------------------------------------------------------------------------------

    def _restore(self) -> None:
        if self._line.master is None:
            self._line.open()

    def _wake(self) -> None:
        fd = self._wake_w
        if fd is not None:
            try:
                os.write(fd, b'w')
            except OSError:
                pass  # A full pipe already wakes the thread.

    def _in_worker(self, function: Callable[[], None]) -> None:
        """Run ``function`` in the emulator thread, which owns the fds (or here if none runs)."""
        with self._lock:
            thread = self._thread
            if thread is None or not thread.is_alive() or self._stopping \
                    or thread is threading.current_thread():
                function()
                return
            done = threading.Event()
            self._requests.append((function, done))
        self._wake()
        if not done.wait(timeout=5.0):
            raise RuntimeError('the emulated camera thread did not answer')

    def _run(self) -> None:
        period = 1.0 / self.field_rate_hz
        next_field = self._clock()
        while True:
            with self._lock:
                if self._stopping:
                    return
                while self._requests:
                    function, done = self._requests.popleft()
                    try:
                        function()
                    finally:
                        done.set()
                now = self._clock()
                if now >= next_field:
                    self._field(now)
                    next_field += period
                    if next_field <= now:
                        # Fell behind (a stalled machine): resume the cadence from now.
                        next_field = now + period
                self._line.pump(now)
                wake_at = next_field
                output_at = self._line.next_output_time()
                if output_at is not None:
                    wake_at = min(wake_at, output_at)
                master = self._line.master
                fds = [self._wake_r] + ([master] if master is not None else [])
            try:
                wait_s = max(0.0, (wake_at - self._clock()) / self._clock_rate)
                readable, _, _ = select.select(fds, [], [], wait_s)
            except (OSError, ValueError):
                continue
            if self._wake_r in readable:
                try:
                    os.read(self._wake_r, 4096)
                except OSError:
                    pass
            if master is not None and master in readable:
                try:
                    data = os.read(master, 4096)
                except OSError:
                    data = b''  # EIO/EAGAIN: nothing to read this time.
                if data:
                    with self._lock:
                        self._line.receive(data, self._clock(), discard=self._silent)

    # Camera -------------------------------------------------------------------------------

    def _power_up(self, now: float) -> None:
        self._device.power_up(now)
        self._line.clear_inbox()
        if not self._silent:
            self._line.send(network_change(1), now)
        if self._thread is None and self._line.master is not None:
            # At start() it goes out before the port can be opened (so the driver's open
            # flushes it, as with a camera powered before the driver): deterministic.
            self._line.pump(float('inf'))

    def _field(self, now: float) -> None:
        """Run one video field: completions first, then at most one received packet."""
        for packet in self._responder.completions(now):
            self._reply(packet, now)
        interval = self.faults.phantom_ack_interval_s
        if interval > 0.0 and now >= self._phantom_at:
            self._phantom_at = now + interval
            address = self._device.reply_address()
            for socket in SOCKETS:
                self._line.send(ack(address, socket), now)
        if self._line.packet_due(now):
            packet = self._line.next_packet()
            refusal = self._injector.refusal(packet, self._device.address)
            replies = refusal if refusal is not None else self._responder.handle(packet, now)
            for reply in replies:
                self._reply(reply, now)

    def _reply(self, packet: bytes, now: float) -> None:
        if self._silent or self._line.master is None:
            return
        if packet[0] != BROADCAST and packet[1] >> 4 == 0x6:
            self._errors[packet[2]] += 1
        sent = self._injector.reply(packet)
        if sent is not None:
            self._counts['sent'] += 1
            self._line.send(sent[0], now + sent[1])


def run_fake_camera(link_path: Optional[str], init_s: float, faults: str = '') -> int:
    """
    Run an emulated EVI-D31 until Ctrl-C or SIGTERM and return 0.

    Prints one line ``fake EVI-D31 on <port>`` once the port can be opened.
    ``faults``: knobs of :class:`Faults` as ``name=value,...`` (a broken
    camera for trying the driver by hand); ConfigError for a bad one.
    """
    camera = EmulatedEviD31(init_s=init_s, link_path=link_path)
    camera.faults.apply(faults)
    stopped = threading.Event()
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, lambda signum, frame: stopped.set())
    try:
        camera.start()
        print(f'fake EVI-D31 on {camera.port}', flush=True)
        while not stopped.wait(0.2):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        camera.stop()
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    sys.stdout.flush()
    return 0
