"""
The Sony EVI-D30/D31 pan/tilt/zoom head in ROS units, over VISCA.

ROS-free. Angles are radians and speeds radians per second with ROS REP 103
signs: **positive pan = turn left** (counter-clockwise seen from above,
about +z up), positive tilt = look up. VISCA counts pan positive to the
*right*, so this layer negates pan both ways; tilt has the same sign in both.

:class:`EviD31` adds the camera's start-up (:mod:`~pattern_locator.visca.startup`:
Address Set, IF_Clear, power and initialisation), speed quantisation, motion
bookkeeping (a Drive cancels a running absolute/relative move first, since
the camera refuses it otherwise) and checked answers (a position or zoom
outside the camera's range is rejected, counted, never returned) to
:class:`~pattern_locator.visca.transport.ViscaTransport`. It is thread-safe:
a ROS node may poll :meth:`EviD31.position` / :meth:`EviD31.zoom` from one
timer and call :meth:`EviD31.drive` from another, and :meth:`EviD31.close`
from any thread ends every wait at once.
"""

import collections
from dataclasses import dataclass
import logging
import math
import threading
import time
from typing import Callable, Dict, Optional, Tuple, TypeVar

import serial

from . import protocol as visca
from .exposure import ExposureReport, ShutterRequest
from .startup import StartUp
from .transport import (CommandResult, ViscaCommandError, ViscaConnectionError,
                        ViscaSocketsBusy, ViscaTimeout, ViscaTransport)

logger = logging.getLogger(__name__)
_T = TypeVar('_T')

PAN_LIMIT_DEG = visca.PAN_LIMIT_UNITS / visca.PAN_UNITS_PER_DEG
TILT_LIMIT_DEG = visca.TILT_LIMIT_UNITS / visca.TILT_UNITS_PER_DEG
# Worst-case motion times bound the waits for completions (plus a margin).
_MOTION_MARGIN_S = 3.0
# Reset and power-on run the initialisation: "several seconds" (visca.md).
_RESET_TIMEOUT_S = 20.0
# Zoom Direct end to end takes about 2.2 s.
_ZOOM_TIMEOUT_S = 10.0
# Closing sends Cancel/Stop; each waits this long for its reply at most.
_CLOSE_REPLY_S = 0.15


@dataclass(frozen=True)
class ViscaVersion:
    """The version inquiry's answer: model 0402h is the EVI-D30/D31."""

    vendor: int
    model: int
    rom: int
    sockets: int


def pan_step(pan_rad_s: float) -> Tuple[int, int]:
    """
    Return (speed step 0..18h, VISCA direction) for a REP 103 pan speed.

    Positive = left (VISCA ``PAN_LEFT``). The step is the nearest of the
    camera's linear steps (``visca.pan_speed_deg_s``); 0 means stop.
    """
    step = _nearest_step(math.degrees(abs(pan_rad_s)), visca.pan_speed_deg_s(1),
                         visca.PAN_SPEED_MAX)
    if step == 0:
        return 0, visca.PAN_STOP
    return step, visca.PAN_LEFT if pan_rad_s > 0 else visca.PAN_RIGHT


def tilt_step(tilt_rad_s: float) -> Tuple[int, int]:
    """Return (speed step 0..14h, VISCA direction) for a tilt speed (positive = up)."""
    step = _nearest_step(math.degrees(abs(tilt_rad_s)), visca.tilt_speed_deg_s(1),
                         visca.TILT_SPEED_MAX)
    if step == 0:
        return 0, visca.TILT_STOP
    return step, visca.TILT_UP if tilt_rad_s > 0 else visca.TILT_DOWN


def _nearest_step(speed_deg_s: float, per_step: float, max_step: int) -> int:
    if not math.isfinite(speed_deg_s):
        raise visca.ViscaError(f'speed {speed_deg_s} is not finite')
    return min(max_step, int(round(speed_deg_s / per_step)))


def _fraction_steps(fraction: float) -> Tuple[int, int]:
    if not 0.0 < fraction <= 1.0:
        raise visca.ViscaError(f'speed fraction {fraction} is not in (0, 1]')
    return (max(1, int(round(fraction * visca.PAN_SPEED_MAX))),
            max(1, int(round(fraction * visca.TILT_SPEED_MAX))))


def to_visca_units(pan_rad: float, tilt_rad: float) -> Tuple[int, int]:
    """Return VISCA (pan, tilt) units (pan positive right) for REP 103 radians."""
    return (visca.pan_units(-math.degrees(pan_rad)), visca.tilt_units(math.degrees(tilt_rad)))


def from_visca_units(pan: int, tilt: int) -> Tuple[float, float]:
    """Return REP 103 (pan, tilt) radians (pan positive left) for VISCA units."""
    return (-math.radians(visca.pan_degrees(pan)), math.radians(visca.tilt_degrees(tilt)))


class EviD31:
    """
    A Sony EVI-D30/D31 on a serial port, in radians with REP 103 signs.

    Positive pan turns the head **left** (counter-clockwise seen from above);
    the camera's own VISCA pan is positive right and is negated here.
    Positive tilt looks up (as in VISCA). ``shutter_s`` > 0: the start-up
    (after every reconnect and Network Change too) sets shutter priority at
    the table's speed nearest to it (:mod:`~pattern_locator.visca.exposure`;
    ``video_standard`` 'pal' for the D31, 'ntsc' for the D30) and
    :attr:`exposure` says how that went; 0 leaves the camera's exposure
    alone. Call :meth:`start` before anything else. Errors are
    :class:`~pattern_locator.visca.protocol.ViscaError` subclasses from
    :mod:`pattern_locator.visca.transport`; while the port is gone every
    call raises ``ViscaConnectionError`` at once, and after it comes back the
    start-up runs again in the background (``ready`` tells when it is done;
    commands sent while its Address Set / IF_Clear run raise
    ``ViscaConnectionError`` too, since IF_Clear would cancel them).
    """

    def __init__(self, port: str, baud: int = 9600, address: int = 1,
                 reply_timeout_s: float = 0.3, completion_timeout_s: float = 30.0,
                 serial_factory: Callable[..., serial.Serial] = serial.Serial,
                 power_on_at_start: bool = True, restart_timeout_s: float = 15.0,
                 shutter_s: float = 0.0, video_standard: str = 'pal',
                 **transport_options) -> None:
        self.port = port
        self.address = address
        self.restart_timeout_s = restart_timeout_s
        # Checked before anything opens: ViscaError for a shutter the camera cannot do.
        self.shutter_request = ShutterRequest.from_seconds(shutter_s, video_standard)
        self._exposure: Optional[ExposureReport] = None
        self._exposure_count = 0
        self._startup = StartUp(self, power_on_at_start)
        self._transport = ViscaTransport(
            port, baud=baud, address=address, reply_timeout_s=reply_timeout_s,
            completion_timeout_s=completion_timeout_s, serial_factory=serial_factory,
            on_reconnect=self._startup.on_reconnect,
            on_network_change=self._startup.on_network_change, **transport_options)
        # Every command goes out under this lock, so the socket of a running
        # move cannot be reused by another of our commands between a check and
        # its Cancel.
        self.command_lock = threading.RLock()
        self._move: Optional[CommandResult] = None
        self._zoom_move: Optional[CommandResult] = None
        self._closing = threading.Event()
        self._rejected: 'collections.Counter[str]' = collections.Counter()
        self._last_rejected = ''

    # Life cycle ---------------------------------------------------------------------------

    @property
    def transport(self) -> ViscaTransport:
        """Return the serial transport underneath: stats, sockets, raw access."""
        return self._transport

    @property
    def connected(self) -> bool:
        """Return True while the serial port is open."""
        return self._transport.connected

    @property
    def ready(self) -> bool:
        """Return True when connected and the start-up has finished on this connection."""
        return self._startup.ready and not self._closing.is_set()

    @property
    def closing(self) -> bool:
        """Return True once :meth:`close` was called (until the next :meth:`start`)."""
        return self._closing.is_set()

    @property
    def power_on_at_start(self) -> bool:
        """Return whether the start-up switches a camera in standby on."""
        return self._startup.power_on_at_start

    @property
    def rejected_replies(self) -> Dict[str, int]:
        """Return the answers rejected as impossible (out of range, malformed), by inquiry."""
        return dict(self._rejected)

    @property
    def last_rejected(self) -> str:
        """Return why the last answer was rejected ('' if none was)."""
        return self._last_rejected

    @property
    def exposure(self) -> Optional[ExposureReport]:
        """Return how the last shutter setting went (None: none asked for, or not yet)."""
        return self._exposure

    @property
    def exposure_count(self) -> int:
        """Return how many times the shutter setting was applied (or tried) so far."""
        return self._exposure_count

    def note_exposure(self, report: ExposureReport) -> None:
        """Keep the outcome of a shutter setting (the start-up calls it)."""
        self._exposure = report
        self._exposure_count += 1

    @property
    def pan_limits_rad(self) -> Tuple[float, float]:
        """Return the pan travel (min, max) in radians, REP 103 (positive = left)."""
        return (-math.radians(PAN_LIMIT_DEG), math.radians(PAN_LIMIT_DEG))

    @property
    def tilt_limits_rad(self) -> Tuple[float, float]:
        """Return the tilt travel (min, max) in radians (positive = up)."""
        return (-math.radians(TILT_LIMIT_DEG), math.radians(TILT_LIMIT_DEG))

    def start(self, timeout_s: float = 15.0) -> None:
        """
        Open the port and bring the camera up; raise a ViscaError after ``timeout_s``.

        A port that cannot be opened (missing, busy, no permission) raises
        ViscaConnectionError at once, in one line that says why: the caller
        retries. Then sends Address Set and IF_Clear, turns the power on if
        it is in standby (``power_on_at_start``), and waits until the head
        finished its initialisation (a Stop is accepted and the position
        inquiry answers). :meth:`close` from another thread ends it at once.
        """
        deadline = time.monotonic() + timeout_s
        self._closing.clear()
        if not self._transport.is_open:
            self._transport.open()
        self._startup.run(deadline, timeout_s, wait_reconnect=True)

    def close(self, stop: bool = True) -> None:
        """
        Stop the head (best effort, when ``stop``) and close the port; from any thread.

        Every other call waiting on the camera fails at once with
        ViscaConnectionError; the Cancel of a running move and the Stop then
        wait at most 0.15 s each for their replies, so this returns within
        about 0.3 s plus joining the reader thread. Idempotent.
        """
        self._closing.set()
        self._startup.forget()
        final = []
        if stop and self._transport.connected:
            move = self._move
            if move is not None and not move.done:
                final.append(visca.cancel(self.address, move.socket))
            final.append(visca.pan_tilt_stop(self.address))
        self._transport.close(final=final, final_timeout_s=min(
            _CLOSE_REPLY_S, self._transport.reply_timeout_s))

    def wait_closing(self, seconds: float) -> bool:
        """Sleep ``seconds`` or until :meth:`close`; return True when closing."""
        return self._closing.wait(seconds)

    def forget_motions(self) -> None:
        """Forget the running moves (IF_Clear emptied the sockets)."""
        with self.command_lock:
            self._move = self._zoom_move = None

    def __enter__(self) -> 'EviD31':
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # Motion -------------------------------------------------------------------------------

    def drive(self, pan_rad_s: float, tilt_rad_s: float,
              blocking: bool = True) -> Tuple[float, float]:
        """
        Turn at the given speeds (REP 103: pan positive = left, tilt positive = up).

        Speeds are quantised to the nearest camera step (pan 1..18h of
        80/24 deg/s, tilt 1..14h of 2.5 deg/s, clamped to the maximum); a
        speed below half a step stops that axis. A running absolute/relative
        move, home or reset is cancelled first. Returns the speeds actually
        commanded, in rad/s with the same signs. ``blocking`` False (a
        control loop that sends again next cycle): raise ViscaSocketsBusy at
        once instead of waiting for a free socket, and do not resend after a
        lost ACK.
        """
        p_step, p_dir = pan_step(pan_rad_s)
        t_step, t_dir = tilt_step(tilt_rad_s)
        # Speed bytes stay 01.. even for a stopped axis (some models refuse 00).
        packet = visca.pan_tilt_drive(self.address, max(1, p_step), max(1, t_step),
                                      p_dir, t_dir)
        with self.command_lock:
            self._cancel_move()
            self._send(packet, self._short_timeout(), blocking=blocking)
        pan = math.radians(visca.pan_speed_deg_s(p_step)) if p_step else 0.0
        tilt = math.radians(visca.tilt_speed_deg_s(t_step)) if t_step else 0.0
        return (math.copysign(pan, pan_rad_s), math.copysign(tilt, tilt_rad_s))

    def stop(self, blocking: bool = True) -> None:
        """Stop pan and tilt (cancels a running move first); ``blocking`` as for drive()."""
        with self.command_lock:
            self._cancel_move()
            self._send(visca.pan_tilt_stop(self.address), self._short_timeout(),
                       blocking=blocking)

    def move_to(self, pan_rad: float, tilt_rad: float, speed_fraction: float = 1.0,
                wait: bool = True, timeout: Optional[float] = None) -> CommandResult:
        """
        Move to an absolute position (REP 103 radians: pan positive = left).

        ``speed_fraction`` (0, 1] scales the camera's maximum speeds. With
        ``wait`` returns after the completion (raising ``ViscaCancelled`` if a
        later drive/move cancelled it); without, returns once the camera
        accepted it. A position outside the travel (``pan_limits_rad``,
        ``tilt_limits_rad``) raises ViscaError before anything is sent.
        """
        pan, tilt = to_visca_units(pan_rad, tilt_rad)
        ps, ts = _fraction_steps(speed_fraction)
        try:
            packet = visca.pan_tilt_absolute(self.address, ps, ts, pan, tilt)
        except visca.ViscaError as exc:
            raise visca.ViscaError(
                f'move_to({pan_rad:.4f}, {tilt_rad:.4f}) rad is outside the travel '
                f'pan {self._fmt(self.pan_limits_rad)}, tilt {self._fmt(self.tilt_limits_rad)} '
                f'rad: {exc}') from exc
        return self._start_move(packet, self._motion_timeout(ps, ts, timeout), wait)

    def move_by(self, dpan_rad: float, dtilt_rad: float, speed_fraction: float = 1.0,
                wait: bool = True, timeout: Optional[float] = None) -> CommandResult:
        """Move by an offset (REP 103 radians: positive pan = left); like :meth:`move_to`."""
        dpan, dtilt = to_visca_units(dpan_rad, dtilt_rad)
        ps, ts = _fraction_steps(speed_fraction)
        packet = visca.pan_tilt_relative(self.address, ps, ts, dpan, dtilt)
        return self._start_move(packet, self._motion_timeout(ps, ts, timeout), wait)

    def home(self, wait: bool = True) -> CommandResult:
        """Move to pan 0, tilt 0."""
        return self._start_move(visca.pan_tilt_home(self.address),
                                self._motion_timeout(visca.PAN_SPEED_MAX,
                                                     visca.TILT_SPEED_MAX, None), wait)

    def reset(self, wait: bool = True) -> CommandResult:
        """Re-initialise pan/tilt (the head runs through its ends of travel)."""
        return self._start_move(visca.pan_tilt_reset(self.address), _RESET_TIMEOUT_S, wait)

    def zoom_to(self, units: int, wait: bool = False) -> CommandResult:
        """Zoom to ``units`` (0 wide .. 3FFh tele); cancels a running zoom_to first."""
        packet = visca.zoom_direct(self.address, int(units))
        with self.command_lock:
            self._cancel_zoom()
            result = self._send(packet, _ZOOM_TIMEOUT_S, duration_s=_ZOOM_TIMEOUT_S)
            self._zoom_move = result
        if wait:
            result.wait(_ZOOM_TIMEOUT_S)
        return result

    def zoom_tele(self, speed: Optional[int] = None, blocking: bool = True) -> None:
        """Zoom in until zoom_stop (standard speed, or variable 2..7)."""
        self._zoom_command(visca.zoom_tele(self.address, speed), blocking)

    def zoom_wide(self, speed: Optional[int] = None, blocking: bool = True) -> None:
        """Zoom out until zoom_stop (standard speed, or variable 2..7)."""
        self._zoom_command(visca.zoom_wide(self.address, speed), blocking)

    def zoom_stop(self, blocking: bool = True) -> None:
        """Stop zooming (also a running zoom_to)."""
        self._zoom_command(visca.zoom_stop(self.address), blocking)

    def focus_auto(self) -> None:
        """Switch to auto focus."""
        with self.command_lock:
            self._send(visca.focus_auto(self.address), self._short_timeout(), wait=True)

    def set_ae_mode(self, mode: int) -> None:
        """Set the exposure mode (``protocol.AE_SHUTTER_PRIORITY``, ...); waits for completion."""
        with self.command_lock:
            self._send(visca.ae_mode(self.address, mode), self._short_timeout(), wait=True)

    def set_shutter_position(self, position: int) -> None:
        """Set the shutter position (00..1Bh, ``protocol.shutter_seconds``); waits likewise."""
        with self.command_lock:
            self._send(visca.shutter_direct(self.address, position), self._short_timeout(),
                       wait=True)

    def power(self, on: bool, wait: bool = True) -> CommandResult:
        """Switch the camera on or to standby."""
        with self.command_lock:
            return self._send(visca.power(self.address, on), _RESET_TIMEOUT_S, wait=wait,
                              duration_s=_RESET_TIMEOUT_S)

    # Inquiries ----------------------------------------------------------------------------

    def position(self) -> Tuple[float, float]:
        """
        Return (pan, tilt) in radians, REP 103: pan positive = left, tilt positive = up.

        Never outside the travel plus ``protocol.TRAVEL_MARGIN_DEG``: such an
        answer is rejected (counted in :attr:`rejected_replies`) and asked
        once more; ViscaReplyError if that one is bad too.
        """
        pan, tilt = self._inquiry('position', visca.inquiry_pan_tilt_position(self.address), 8,
                                  visca.parse_pan_tilt_position)
        return from_visca_units(pan, tilt)

    def zoom(self) -> int:
        """Return the zoom position in camera units (0 wide .. 3FFh tele), checked likewise."""
        return self._inquiry('zoom', visca.inquiry_zoom_position(self.address), 4,
                             visca.parse_zoom_position)

    def power_on(self) -> bool:
        """Return True when the camera is on, False in standby."""
        return self._inquiry('power', visca.inquiry_power(self.address), 1, visca.parse_power)

    def ae_mode(self) -> int:
        """Return the exposure mode (``protocol.AE_MODE_NAMES``); an unknown one is rejected."""
        return self._inquiry('exposure mode', visca.inquiry_ae_mode(self.address), 1,
                             visca.parse_ae_mode)

    def shutter_position(self) -> int:
        """Return the shutter position (00..1Bh); one beyond the table is rejected."""
        return self._inquiry('shutter', visca.inquiry_shutter(self.address), 4,
                             visca.parse_shutter_position)

    def version(self) -> ViscaVersion:
        """Return the camera's vendor, model, ROM version and socket count."""
        return ViscaVersion(*self._inquiry('version', visca.inquiry_version(self.address), 7,
                                           visca.parse_version))

    # Internals ----------------------------------------------------------------------------

    def _short_timeout(self) -> float:
        return self._transport.reply_timeout_s

    @staticmethod
    def _fmt(limits: Tuple[float, float]) -> str:
        return f'[{limits[0]:.4f}, {limits[1]:.4f}]'

    @staticmethod
    def _motion_timeout(ps: int, ts: int, timeout: Optional[float]) -> float:
        if timeout is not None:
            return timeout
        return max(2 * PAN_LIMIT_DEG / visca.pan_speed_deg_s(ps),
                   2 * TILT_LIMIT_DEG / visca.tilt_speed_deg_s(ts)) + _MOTION_MARGIN_S

    def _inquiry(self, name: str, packet: bytes, length: int, parse: Callable[[bytes], _T],
                 retries: int = 1) -> _T:
        """Ask, parse the answer; once more if it got lost or garbled (VISCA has no checksum)."""
        for attempt in range(retries + 1):
            try:
                return parse(self._transport.inquiry(packet, answer_length=length).payload)
            except ViscaCommandError:
                raise
            except visca.ViscaReplyError as exc:
                self._rejected[name] += 1
                self._last_rejected = f'{name}: {exc}'
                logger.debug('EVI-D31 on %s: rejected %s', self.port, self._last_rejected)
                if attempt == retries or not self._transport.connected:
                    raise
            except (ViscaTimeout, visca.ViscaError):
                if attempt == retries or not self._transport.connected:
                    raise

    def _send(self, packet: bytes, timeout: float, wait: bool = False, retries: int = 1,
              duration_s: float = visca.INSTANT_COMMAND_S,
              blocking: bool = True) -> CommandResult:
        """Send a command; retry an idempotent one whose ACK did not come (when blocking)."""
        if self._startup.clearing:
            raise ViscaConnectionError(f'EVI-D31 on {self.port}: start-up in progress '
                                       '(Address Set, IF_Clear)')
        attempts = retries + 1 if blocking else 1
        for attempt in range(attempts):
            try:
                return self._transport.command(packet, wait=wait, timeout=timeout,
                                               duration_s=duration_s,
                                               socket_wait_s=None if blocking else 0.0)
            except ViscaSocketsBusy:
                raise
            except ViscaTimeout:
                if attempt == attempts - 1 or wait:
                    raise
        raise AssertionError('unreachable')  # pragma: no cover

    def _start_move(self, packet: bytes, timeout: float, wait: bool) -> CommandResult:
        with self.command_lock:
            self._cancel_move()
            # No resend: a move whose ACK got lost may already be running.
            result = self._send(packet, timeout, retries=0, duration_s=timeout)
            self._move = result
        if wait:
            result.wait(timeout)
        return result

    def _zoom_command(self, packet: bytes, blocking: bool = True) -> None:
        with self.command_lock:
            self._cancel_zoom()
            self._send(packet, self._short_timeout(), blocking=blocking)

    def _cancel_move(self) -> None:
        self._move = self._cancel(self._move)

    def _cancel_zoom(self) -> None:
        self._zoom_move = self._cancel(self._zoom_move)

    def _cancel(self, running: Optional[CommandResult]) -> Optional[CommandResult]:
        if running is None or running.done:
            return None
        try:
            self._transport.cancel(running.socket)
        except ViscaTimeout as exc:
            # The next command then meets a busy socket: the transport waits for it.
            logger.warning('EVI-D31 on %s: cancel of socket %d unanswered: %s', self.port,
                           running.socket, exc)
        return None
