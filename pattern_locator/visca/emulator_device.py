"""
The emulated EVI-D31's device state and what its commands do (ROS-free, no bytes).

:class:`EmulatedDevice` holds what the camera remembers: power, address,
the two command sockets, focus mode, the power-up initialisation, and the
head (:class:`~pattern_locator.visca.emulator_motion.HeadMotion`). It runs
parsed :class:`Command` values; turning packets into commands and outcomes
into reply packets is :mod:`~pattern_locator.visca.emulator_protocol`'s job,
the pty and the timing are :mod:`~pattern_locator.visca.emulator`'s.
"""

from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

from .emulator_motion import HeadMotion
from .protocol import (AE_FIXED_SHUTTER_MODES, AE_FULL_AUTO, pan_speed_deg_s, PAN_SPEED_MAX,
                       PAN_UNITS_PER_DEG, SHUTTER_DOWN, SHUTTER_POSITION_MAX, SHUTTER_RESET,
                       shutter_seconds, tilt_speed_deg_s, TILT_SPEED_MAX, TILT_UNITS_PER_DEG,
                       ZOOM_TELE)

SOCKETS = (1, 2)

# Pan-tilt mode answer (EVI-D80 status code list layout, see the emulator's docstring).
_INIT_RUNNING, _INIT_DONE = 0x1000, 0x2000
_MOTION_RUNNING, _MOTION_DONE = 0x0400, 0x0800


@dataclass(frozen=True)
class HeadState:
    """
    The emulated head at one instant, in the camera's own conventions.

    Pan is positive to the right and tilt positive up (degrees, as the
    camera counts them; a ROS joint state negates pan). ``zoom_units`` is
    0 (wide) .. 1023 (tele), not rounded. ``sockets_busy`` lists the sockets
    holding a command; ``stamp`` is the ``time.monotonic()`` of the state.
    ``shutter_s`` is the exposure time the camera applies now: the shutter
    position's speed (PAL table) in shutter priority or manual, else the
    emulator's ``auto_shutter_s``.
    """

    pan_deg: float
    tilt_deg: float
    zoom_units: float
    powered: bool
    initialising: bool
    sockets_busy: Tuple[int, ...]
    stamp: float
    shutter_s: float

    @property
    def pan_units(self) -> float:
        """Return the pan position in camera units (not rounded)."""
        return self.pan_deg * PAN_UNITS_PER_DEG

    @property
    def tilt_units(self) -> float:
        """Return the tilt position in camera units (not rounded)."""
        return self.tilt_deg * TILT_UNITS_PER_DEG


@dataclass(frozen=True)
class Command:
    """
    A syntactically valid command.

    ``kind`` is 'instant' (completes in the next field), 'move' (completes
    when its motion ends) or 'reset'; ``motion`` the part of the head it
    moves ('pt', 'zoom' or None); ``args`` its decoded values.
    """

    name: str
    kind: str
    motion: Optional[str]
    args: tuple = ()


@dataclass
class Held:
    """A command held in a socket."""

    name: str
    kind: str               # 'instant', 'move' or 'reset'
    motion: Optional[str]   # 'pt', 'zoom' or None
    done_tick: int = 0


class EmulatedDevice:
    """
    What the camera remembers and how its commands change it (times in seconds).

    ``init_s``: the power-up initialisation, ``reset_s``: a pan-tilt Reset,
    ``zoom_full_s``: wide to tele at the standard speed. Not thread-safe:
    the emulator calls it under its lock.
    """

    def __init__(self, init_s: float, reset_s: float, zoom_full_s: float,
                 require_address_set: bool, auto_shutter_s: float = 0.02) -> None:
        self.init_s = init_s
        self.reset_s = reset_s
        self.zoom_full_s = zoom_full_s
        self.auto_shutter_s = auto_shutter_s
        self.require_address_set = require_address_set
        self.head = HeadMotion()
        self.tick = 0
        self.address: Optional[int] = None if require_address_set else 1
        self.powered = True
        self.init_end = 0.0
        self.focus_auto = True
        self.pt_commanded = False
        self.sockets: Dict[int, Optional[Held]] = dict.fromkeys(SOCKETS)
        # Exposure as commanded (what the inquiries answer) and as applied to the
        # fields: a change reaches the image at the next field.
        self.ae_mode = AE_FULL_AUTO
        self.shutter_position = 0
        self._exposure_applied = (AE_FULL_AUTO, 0)
        self._exposure_from_tick: Optional[int] = None

    # State ----------------------------------------------------------------------------------

    def initialising(self, now: float) -> bool:
        """Return True during the power-up initialisation or a Reset."""
        return now < self.init_end or any(
            held is not None and held.kind == 'reset' for held in self.sockets.values())

    def reply_address(self) -> int:
        """Return the address replies carry (1 until Address Set)."""
        return self.address or 1

    def busy_sockets(self) -> Tuple[int, ...]:
        """Return the sockets holding a command."""
        return tuple(s for s in SOCKETS if self.sockets[s] is not None)

    def free_socket(self) -> Optional[int]:
        """Return the socket a new command would take, None when both are busy."""
        free = [s for s in SOCKETS if self.sockets[s] is None]
        return free[0] if free else None

    def state(self, now: float) -> HeadState:
        """Return the head's state at ``now``."""
        pan, tilt = self.head.position(now)
        return HeadState(pan_deg=pan / PAN_UNITS_PER_DEG, tilt_deg=tilt / TILT_UNITS_PER_DEG,
                         zoom_units=self.head.zoom_at(now), powered=self.powered,
                         initialising=self.initialising(now),
                         sockets_busy=self.busy_sockets(), stamp=now,
                         shutter_s=self.shutter_s())

    def shutter_s(self) -> float:
        """Return the exposure time applied to the current field (s)."""
        mode, position = self._exposure_applied
        if mode in AE_FIXED_SHUTTER_MODES:
            return shutter_seconds(position, 'pal')
        return self.auto_shutter_s

    def pan_tilt_status(self, now: float) -> int:
        """Return the pan-tilt mode answer's 16 status bits."""
        status = _INIT_RUNNING if self.initialising(now) else _INIT_DONE
        if self.head.pan_tilt_moving(now):
            status |= _MOTION_RUNNING
        elif self.pt_commanded:
            status |= _MOTION_DONE
        return status | self.head.end_flags(now)

    # Life -----------------------------------------------------------------------------------

    def power_up(self, now: float) -> None:
        """Power on from nothing: address forgotten, limits cleared, initialisation runs."""
        self.head.stop_all(now)
        self.sockets = dict.fromkeys(SOCKETS)
        if self.require_address_set:
            self.address = None
        self.powered = True
        self.focus_auto = True
        self.pt_commanded = False
        # A real camera comes up in full auto exposure.
        self.ae_mode, self.shutter_position = AE_FULL_AUTO, 0
        self._exposure_applied = (AE_FULL_AUTO, 0)
        self._exposure_from_tick = None
        self.head.clear_limits()
        self._initialise(now, self.init_s, zoom=True)

    def next_field(self, now: float) -> List[int]:
        """Start a video field; free and return the sockets whose command finished."""
        self.tick += 1
        if self._exposure_from_tick is not None and self.tick >= self._exposure_from_tick:
            self._exposure_applied = (self.ae_mode, self.shutter_position)
            self._exposure_from_tick = None
        finished = []
        for socket in SOCKETS:
            held = self.sockets[socket]
            if held is not None and self._held_done(held, now):
                self.sockets[socket] = None
                finished.append(socket)
        return finished

    def set_address(self, address: int) -> None:
        """Take the address an Address Set gave."""
        self.address = address

    # Commands -------------------------------------------------------------------------------

    def executable(self, command: Command, now: float) -> bool:
        """Return False when the camera's state refuses ``command`` (``z0 6y 41 FF``)."""
        if not self.powered:
            return command.name == 'power'
        if self.initialising(now):
            return False
        for held in self.sockets.values():
            if held is not None and held.kind != 'instant' and command.motion is not None \
                    and held.motion == command.motion:
                return False
        if command.name == 'focus_drive' and command.args[0] != 0x00 and self.focus_auto:
            return False
        if command.name == 'limit_set':
            up_right, pan, tilt = command.args
            return self.head.limit_set_allowed(up_right, pan, tilt)
        return True

    def accept(self, command: Command, socket: int, now: float) -> None:
        """Hold ``command`` in ``socket`` and start it."""
        self.sockets[socket] = Held(command.name, command.kind, command.motion,
                                    done_tick=self.tick + 1)
        self._execute(command, socket, now)

    def cancel(self, socket: int, now: float) -> bool:
        """Cancel the command in ``socket`` and stop its motion; False for an empty socket."""
        held = self.sockets[socket]
        if held is None:
            return False
        self.sockets[socket] = None
        if held.motion == 'pt':
            self.head.stop_pan_tilt(now)
        elif held.motion == 'zoom':
            self.head.zoom.stop(now)
        return True

    def if_clear(self, now: float) -> None:
        """Empty both sockets (no replies) and stop every motion."""
        self.sockets = dict.fromkeys(SOCKETS)
        # The power-up initialisation is no command: it goes on (nothing else can move then).
        if now >= self.init_end:
            self.head.stop_all(now)

    # Internals ------------------------------------------------------------------------------

    def _initialise(self, now: float, duration: float, zoom: bool) -> None:
        self.head.sweep(now, duration, zoom)
        if zoom:
            self.init_end = now + duration

    def _held_done(self, held: Held, now: float) -> bool:
        if held.kind == 'instant':
            return self.tick >= held.done_tick
        if held.motion == 'zoom':
            return not self.head.zoom_moving(now)
        return not self.head.pan_tilt_moving(now)

    def _execute(self, command: Command, socket: int, now: float) -> None:
        name, args, head = command.name, command.args, self.head
        if command.motion == 'pt':
            self.pt_commanded = True
        if name == 'drive':
            pan_speed, tilt_speed, pan_dir, tilt_dir = args
            # Pan 01 = left = negative units; tilt 01 = up = positive units.
            head.drive(now, {1: -1, 2: 1, 3: 0}[pan_dir], _pan_units_s(pan_speed),
                       {1: 1, 2: -1, 3: 0}[tilt_dir], _tilt_units_s(tilt_speed))
        elif name in ('absolute', 'home'):
            pan_speed, tilt_speed, pan, tilt = (PAN_SPEED_MAX, TILT_SPEED_MAX, 0, 0) \
                if name == 'home' else args
            head.move_to(now, pan, tilt, _pan_units_s(pan_speed), _tilt_units_s(tilt_speed))
        elif name == 'relative':
            pan_speed, tilt_speed, pan, tilt = args
            head.move_by(now, pan, tilt, _pan_units_s(pan_speed), _tilt_units_s(tilt_speed))
        elif name == 'reset':
            self._initialise(now, self.reset_s, zoom=False)
        elif name == 'zoom':
            direction, speed = args
            full_s = self.zoom_full_s if speed is None else self.zoom_full_s * 7.0 / speed
            head.zoom_run(now, direction, ZOOM_TELE / full_s)
        elif name == 'zoom_direct':
            head.zoom_to(now, args[0], ZOOM_TELE / self.zoom_full_s)
        elif name == 'focus_mode':
            self.focus_auto = args[0]
        elif name == 'power':
            self._power(args[0], socket, now)
        elif name == 'limit_set':
            head.set_limit(now, *args)
        elif name == 'limit_clear':
            head.clear_limit(now, args[0])
        elif name in ('ae_mode', 'shutter', 'shutter_step'):
            self._exposure(name, args[0])

    def _exposure(self, name: str, value: int) -> None:
        if name == 'ae_mode':
            self.ae_mode = value
        elif name == 'shutter':
            self.shutter_position = value
        elif value == SHUTTER_RESET:
            self.shutter_position = 0
        else:
            # Up = a faster shutter; both stop at the table's ends.
            step = -1 if value == SHUTTER_DOWN else 1
            self.shutter_position = min(SHUTTER_POSITION_MAX, max(0, self.shutter_position + step))
        # The field being exposed keeps its exposure; the next one gets the new one.
        self._exposure_from_tick = self.tick + 1

    def _power(self, on: bool, socket: int, now: float) -> None:
        if on and not self.powered:
            self.powered = True
            self._initialise(now, self.init_s, zoom=True)
        elif not on and self.powered:
            self.powered = False
            self.head.stop_all(now)
            self.init_end = 0.0
            for other in SOCKETS:
                if other != socket:
                    self.sockets[other] = None


def _pan_units_s(step: int) -> float:
    return pan_speed_deg_s(step) * PAN_UNITS_PER_DEG


def _tilt_units_s(step: int) -> float:
    return tilt_speed_deg_s(step) * TILT_UNITS_PER_DEG
