"""
VISCA protocol codec for the Sony EVI-D30/D31: packets as bytes, no I/O.

Everything here follows ``design/visca.md``: commands ``8x ... FF`` from the
controller, replies ``z0 ... FF`` from the camera (z = 8 + address), 16-bit
values as four nibbles in two's complement. Both sides use it: the camera
driver builds commands and parses replies, the emulated camera parses
commands and builds replies. Angles here are in the camera's own sign
convention (positive pan = right, positive tilt = up) and in degrees; the
conversion to ROS radians (REP 103, positive pan = left) is the camera
layer's job.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Tuple

from ..errors import PatternLocatorError


class ViscaError(PatternLocatorError):
    """A VISCA packet that is malformed, or a value out of the protocol's range."""


class ViscaReplyError(ViscaError):
    """
    A reply that is framed but impossible: a value outside the camera's range, a bad socket.

    The driver drops it (and counts it) instead of reporting what it says.
    """


TERMINATOR = 0xFF
BROADCAST = 0x88
MAX_PACKET = 16

# Travel and units of the EVI-D30/D31 (visca.md, "Travel and angles").
PAN_UNITS_PER_DEG = 8.8
TILT_UNITS_PER_DEG = 12.0
PAN_LIMIT_UNITS = 880
TILT_LIMIT_UNITS = 300
# Speed steps (visca.md, "Commands used by a tracking loop").
PAN_SPEED_MAX = 0x18
TILT_SPEED_MAX = 0x14
PAN_MAX_DEG_S = 80.0
TILT_MAX_DEG_S = 50.0
ZOOM_WIDE = 0x0000
ZOOM_TELE = 0x03FF
# A position answer further out than the travel plus this margin is malformed: the head
# can overshoot its nominal end by a unit or two, never by a degree.
TRAVEL_MARGIN_DEG = 1.0
PAN_ANSWER_LIMIT_UNITS = PAN_LIMIT_UNITS + int(math.ceil(TRAVEL_MARGIN_DEG * PAN_UNITS_PER_DEG))
TILT_ANSWER_LIMIT_UNITS = TILT_LIMIT_UNITS + int(math.ceil(TRAVEL_MARGIN_DEG
                                                           * TILT_UNITS_PER_DEG))
# The command sockets of the EVI-D30/D31 (the version answer says 2).
COMMAND_SOCKETS = (1, 2)
# The camera takes one packet per video field (ACK within ~17/20 ms) and completes an
# instant command (Drive, Stop, zoom tele/wide/stop, focus, LimitSet) in the next field.
# A completion that has not come after this is lost: 50 fields, the low end of the
# 1-3 s that public drivers wait (visca.md, "Replies").
INSTANT_COMMAND_S = 1.0
ZOOM_SPEED_MIN = 2
ZOOM_SPEED_MAX = 7

# Pan-tilt drive directions.
PAN_LEFT, PAN_RIGHT, PAN_STOP = 0x01, 0x02, 0x03
TILT_UP, TILT_DOWN, TILT_STOP = 0x01, 0x02, 0x03

# Error codes (third byte of ``z0 6y ee FF``).
ERROR_MESSAGE_LENGTH = 0x01
ERROR_SYNTAX = 0x02
ERROR_BUFFER_FULL = 0x03
ERROR_CANCELLED = 0x04
ERROR_NO_SOCKET = 0x05
ERROR_NOT_EXECUTABLE = 0x41
ERROR_NAMES = {
    ERROR_MESSAGE_LENGTH: 'message length error',
    ERROR_SYNTAX: 'syntax error',
    ERROR_BUFFER_FULL: 'command buffer full',
    ERROR_CANCELLED: 'command cancelled',
    ERROR_NO_SOCKET: 'no socket',
    ERROR_NOT_EXECUTABLE: 'command not executable',
}

POWER_ON, POWER_STANDBY = 0x02, 0x03

# Exposure (CAM_AE, CAM_Shutter): not in visca.md. From Sony's EVI-D100 technical manual,
# "Command List, D30/31 mode" (the shutter-speed table, p. 43; e.g.
# https://www.manualsdir.com/manuals/144564/sony-evi-d100.html?page=43) and the standard
# VISCA camera commands of Sony's EVI/FCB manuals.
AE_FULL_AUTO, AE_MANUAL, AE_SHUTTER_PRIORITY, AE_IRIS_PRIORITY, AE_BRIGHT = (
    0x00, 0x03, 0x0A, 0x0B, 0x0D)
AE_MODE_NAMES = {
    AE_FULL_AUTO: 'full auto',
    AE_MANUAL: 'manual',
    AE_SHUTTER_PRIORITY: 'shutter priority',
    AE_IRIS_PRIORITY: 'iris priority',
    AE_BRIGHT: 'bright',
}
# The modes in which the camera uses the commanded shutter position; in the others it
# picks the shutter itself.
AE_FIXED_SHUTTER_MODES = (AE_MANUAL, AE_SHUTTER_PRIORITY)
# Shutter position (CAM_Shutter direct, 00..1Bh) -> 1/speed in seconds, EVI-D31 (PAL).
# The EVI-D30 (NTSC) has the same table except that 00 is 1/60 as well. The one copy of
# the table: the emulated camera and the driver both read it through shutter_seconds().
SHUTTER_DENOMINATORS = {
    'pal': (50, 60, 75, 90, 100, 120, 150, 180, 215, 250, 300, 350, 425, 500, 600, 725,
            850, 1000, 1250, 1500, 1750, 2000, 2500, 3000, 3500, 4000, 6000, 10000),
}
SHUTTER_DENOMINATORS['ntsc'] = (60,) + SHUTTER_DENOMINATORS['pal'][1:]
VIDEO_STANDARDS = ('pal', 'ntsc')
SHUTTER_POSITION_MAX = len(SHUTTER_DENOMINATORS['pal']) - 1
# CAM_Shutter reset / up / down (8x 01 04 0A pp FF).
SHUTTER_RESET, SHUTTER_UP, SHUTTER_DOWN = 0x00, 0x02, 0x03
# A requested exposure further than this factor outside the table is refused, not rounded.
SHUTTER_REQUEST_FACTOR = 2.0


def hex_bytes(data: bytes) -> str:
    """Return bytes the way visca.md writes them: ``81 01 06 04 FF``."""
    return ' '.join(f'{b:02X}' for b in data)


# Values --------------------------------------------------------------------------------


def encode_nibbles(value: int, count: int = 4, signed: bool = True) -> bytes:
    """
    Return ``value`` as ``count`` bytes of one nibble each, most significant first.

    Signed values are two's complement on ``4 * count`` bits.
    """
    bits = 4 * count
    low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
    if not low <= int(value) <= high:
        raise ViscaError(f'value {value} does not fit {count} nibbles '
                         f'({"signed" if signed else "unsigned"})')
    word = int(value) & ((1 << bits) - 1)
    return bytes((word >> (4 * (count - 1 - i))) & 0x0F for i in range(count))


def decode_nibbles(data: bytes, signed: bool = True) -> int:
    """Return the value of bytes holding one nibble each (inverse of encode_nibbles)."""
    word = 0
    for byte in data:
        if byte > 0x0F:
            raise ViscaError(f'nibble byte {byte:02X} has its high nibble set in '
                             f'{hex_bytes(data)}')
        word = (word << 4) | byte
    bits = 4 * len(data)
    if signed and word >= 1 << (bits - 1):
        word -= 1 << bits
    return word


def pan_units(degrees: float) -> int:
    """Return the pan position in camera units for an angle (positive = right)."""
    return int(round(degrees * PAN_UNITS_PER_DEG))


def tilt_units(degrees: float) -> int:
    """Return the tilt position in camera units for an angle (positive = up)."""
    return int(round(degrees * TILT_UNITS_PER_DEG))


def pan_degrees(units: int) -> float:
    """Return the pan angle in degrees (positive = right) for camera units."""
    return units / PAN_UNITS_PER_DEG


def tilt_degrees(units: int) -> float:
    """Return the tilt angle in degrees (positive = up) for camera units."""
    return units / TILT_UNITS_PER_DEG


def pan_speed_deg_s(step: int) -> float:
    """Return the pan speed of a speed step (1..18h); linear up to 80 deg/s."""
    return PAN_MAX_DEG_S * step / PAN_SPEED_MAX


def tilt_speed_deg_s(step: int) -> float:
    """Return the tilt speed of a speed step (1..14h); linear up to 50 deg/s."""
    return TILT_MAX_DEG_S * step / TILT_SPEED_MAX


def _standard(video_standard: str) -> Tuple[int, ...]:
    try:
        return SHUTTER_DENOMINATORS[video_standard]
    except KeyError:
        raise ViscaError(f'video standard {video_standard!r} is not one of '
                         f'{", ".join(VIDEO_STANDARDS)}') from None


def shutter_denominator(position: int, video_standard: str = 'pal') -> int:
    """Return the shutter speed's denominator N (1/N s) of a shutter position 00..1Bh."""
    table = _standard(video_standard)
    if not 0 <= position <= SHUTTER_POSITION_MAX:
        raise ViscaError(f'shutter position {position} is not in 0..{SHUTTER_POSITION_MAX:X}h')
    return table[position]


def shutter_seconds(position: int, video_standard: str = 'pal') -> float:
    """Return the exposure time (s) of a shutter position 00..1Bh (the EVI-D30/D31 table)."""
    return 1.0 / shutter_denominator(position, video_standard)


def nearest_shutter_position(seconds: float, video_standard: str = 'pal') -> int:
    """
    Return the shutter position whose speed is nearest to ``seconds`` in log scale.

    ViscaError for a time that is not finite and positive, or more than
    :data:`SHUTTER_REQUEST_FACTOR` beyond the table's ends (1/10000 s ..
    1/50 s PAL, 1/60 s NTSC): rounding it would not give what was asked.
    Of two positions with the same speed (NTSC 00 and 01) the lower one.
    """
    table = _standard(video_standard)
    fastest, slowest = 1.0 / table[-1], 1.0 / table[0]
    if not (math.isfinite(seconds) and fastest / SHUTTER_REQUEST_FACTOR <= seconds
            <= slowest * SHUTTER_REQUEST_FACTOR):
        raise ViscaError(f'shutter time {seconds} s is outside what the camera can do '
                         f'(1/{table[-1]} .. 1/{table[0]} s, {video_standard.upper()})')
    target = math.log(seconds)
    return min(range(len(table)), key=lambda i: (abs(math.log(1.0 / table[i]) - target), i))


def describe_shutter(position: int, video_standard: str = 'pal') -> str:
    """Return a shutter position as a speed: ``1/250 s``."""
    return f'1/{shutter_denominator(position, video_standard)} s'


def _address(address: int) -> int:
    if not 1 <= address <= 7:
        raise ViscaError(f'camera address {address} is not in 1..7')
    return 0x80 | address


def _speeds(pan_speed: int, tilt_speed: int) -> bytes:
    # Always 01..max: some models answer a 00 speed with a syntax error.
    if not 1 <= pan_speed <= PAN_SPEED_MAX:
        raise ViscaError(f'pan speed {pan_speed} is not in 1..{PAN_SPEED_MAX}')
    if not 1 <= tilt_speed <= TILT_SPEED_MAX:
        raise ViscaError(f'tilt speed {tilt_speed} is not in 1..{TILT_SPEED_MAX}')
    return bytes((pan_speed, tilt_speed))


def _position(pan: int, tilt: int, relative: bool) -> bytes:
    if not relative:
        if not -PAN_LIMIT_UNITS <= pan <= PAN_LIMIT_UNITS:
            raise ViscaError(f'pan position {pan} is outside +-{PAN_LIMIT_UNITS} units')
        if not -TILT_LIMIT_UNITS <= tilt <= TILT_LIMIT_UNITS:
            raise ViscaError(f'tilt position {tilt} is outside +-{TILT_LIMIT_UNITS} units')
    return encode_nibbles(pan) + encode_nibbles(tilt)


# Commands (controller -> camera) --------------------------------------------------------


def address_set() -> bytes:
    """Return the Address Set broadcast (the first camera takes address 1)."""
    return bytes((BROADCAST, 0x30, 0x01, TERMINATOR))


def if_clear() -> bytes:
    """Return the IF_Clear broadcast (empties both sockets of every camera)."""
    return bytes((BROADCAST, 0x01, 0x00, 0x01, TERMINATOR))


def cancel(address: int, socket: int) -> bytes:
    """Return Cancel for the command held in ``socket`` (1 or 2)."""
    if socket not in (1, 2):
        raise ViscaError(f'socket {socket} is not 1 or 2')
    return bytes((_address(address), 0x20 | socket, TERMINATOR))


def pan_tilt_drive(address: int, pan_speed: int, tilt_speed: int,
                   pan_direction: int, tilt_direction: int) -> bytes:
    """Return Pan-tilt Drive: directions PAN_LEFT/RIGHT/STOP and TILT_UP/DOWN/STOP."""
    if pan_direction not in (PAN_LEFT, PAN_RIGHT, PAN_STOP):
        raise ViscaError(f'pan direction {pan_direction} is not 1, 2 or 3')
    if tilt_direction not in (TILT_UP, TILT_DOWN, TILT_STOP):
        raise ViscaError(f'tilt direction {tilt_direction} is not 1, 2 or 3')
    return (bytes((_address(address), 0x01, 0x06, 0x01)) + _speeds(pan_speed, tilt_speed)
            + bytes((pan_direction, tilt_direction, TERMINATOR)))


def pan_tilt_stop(address: int, pan_speed: int = 1, tilt_speed: int = 1) -> bytes:
    """Return the Pan-tilt Drive that stops both axes (speeds stay non-zero)."""
    return pan_tilt_drive(address, pan_speed, tilt_speed, PAN_STOP, TILT_STOP)


def pan_tilt_absolute(address: int, pan_speed: int, tilt_speed: int,
                      pan: int, tilt: int) -> bytes:
    """Return AbsolutePosition to (pan, tilt) in camera units."""
    return (bytes((_address(address), 0x01, 0x06, 0x02)) + _speeds(pan_speed, tilt_speed)
            + _position(pan, tilt, False) + bytes((TERMINATOR,)))


def pan_tilt_relative(address: int, pan_speed: int, tilt_speed: int,
                      pan: int, tilt: int) -> bytes:
    """Return RelativePosition by (pan, tilt) camera units."""
    return (bytes((_address(address), 0x01, 0x06, 0x03)) + _speeds(pan_speed, tilt_speed)
            + _position(pan, tilt, True) + bytes((TERMINATOR,)))


def pan_tilt_home(address: int) -> bytes:
    """Return Home (pan and tilt to 0)."""
    return bytes((_address(address), 0x01, 0x06, 0x04, TERMINATOR))


def pan_tilt_reset(address: int) -> bytes:
    """Return Reset (the head re-initialises through both ends of travel)."""
    return bytes((_address(address), 0x01, 0x06, 0x05, TERMINATOR))


def pan_tilt_limit_set(address: int, up_right: bool, pan: int, tilt: int) -> bytes:
    """Return LimitSet of the up-right (True) or down-left (False) corner."""
    return (bytes((_address(address), 0x01, 0x06, 0x07, 0x00, 0x01 if up_right else 0x00))
            + _position(pan, tilt, False) + bytes((TERMINATOR,)))


def pan_tilt_limit_clear(address: int, up_right: bool) -> bytes:
    """Return LimitClear of the up-right (True) or down-left (False) corner."""
    return bytes((_address(address), 0x01, 0x06, 0x07, 0x01, 0x01 if up_right else 0x00,
                  0x07, 0x0F, 0x0F, 0x0F, 0x07, 0x0F, 0x0F, 0x0F, TERMINATOR))


def zoom_stop(address: int) -> bytes:
    """Return Zoom Stop."""
    return bytes((_address(address), 0x01, 0x04, 0x07, 0x00, TERMINATOR))


def zoom_tele(address: int, speed: Optional[int] = None) -> bytes:
    """Return Zoom Tele, at the standard speed or a variable speed 2..7."""
    return bytes((_address(address), 0x01, 0x04, 0x07, _zoom_byte(0x02, 0x20, speed),
                  TERMINATOR))


def zoom_wide(address: int, speed: Optional[int] = None) -> bytes:
    """Return Zoom Wide, at the standard speed or a variable speed 2..7."""
    return bytes((_address(address), 0x01, 0x04, 0x07, _zoom_byte(0x03, 0x30, speed),
                  TERMINATOR))


def _zoom_byte(standard: int, variable: int, speed: Optional[int]) -> int:
    if speed is None:
        return standard
    if not ZOOM_SPEED_MIN <= speed <= ZOOM_SPEED_MAX:
        raise ViscaError(f'zoom speed {speed} is not in {ZOOM_SPEED_MIN}..{ZOOM_SPEED_MAX}')
    return variable | speed


def zoom_direct(address: int, position: int) -> bytes:
    """Return Zoom Direct to ``position`` (0 wide .. 3FFh tele)."""
    if not ZOOM_WIDE <= position <= ZOOM_TELE:
        raise ViscaError(f'zoom position {position} is not in 0..{ZOOM_TELE}')
    return (bytes((_address(address), 0x01, 0x04, 0x47))
            + encode_nibbles(position, signed=False) + bytes((TERMINATOR,)))


def focus_auto(address: int) -> bytes:
    """Return Focus Auto."""
    return bytes((_address(address), 0x01, 0x04, 0x38, 0x02, TERMINATOR))


def focus_manual(address: int) -> bytes:
    """Return Focus Manual."""
    return bytes((_address(address), 0x01, 0x04, 0x38, 0x03, TERMINATOR))


def power(address: int, on: bool) -> bytes:
    """Return Power On or Power Off (standby)."""
    return bytes((_address(address), 0x01, 0x04, 0x00, POWER_ON if on else POWER_STANDBY,
                  TERMINATOR))


def ae_mode(address: int, mode: int) -> bytes:
    """Return CAM_AE: the exposure mode (AE_FULL_AUTO, AE_SHUTTER_PRIORITY, ...)."""
    if mode not in AE_MODE_NAMES:
        raise ViscaError(f'exposure mode {mode:02X}h is not one of '
                         f'{", ".join(f"{m:02X}" for m in AE_MODE_NAMES)}')
    return bytes((_address(address), 0x01, 0x04, 0x39, mode, TERMINATOR))


def shutter_direct(address: int, position: int) -> bytes:
    """Return CAM_Shutter direct to ``position`` (00 1/50 s .. 1Bh 1/10000 s, PAL)."""
    if not 0 <= position <= SHUTTER_POSITION_MAX:
        raise ViscaError(f'shutter position {position} is not in 0..{SHUTTER_POSITION_MAX:X}h')
    return (bytes((_address(address), 0x01, 0x04, 0x4A))
            + encode_nibbles(position, signed=False) + bytes((TERMINATOR,)))


# Inquiries (controller -> camera; answered on socket 0 without an ACK).
def inquiry_pan_tilt_position(address: int) -> bytes:
    """Return the pan-tilt position inquiry."""
    return bytes((_address(address), 0x09, 0x06, 0x12, TERMINATOR))


def inquiry_zoom_position(address: int) -> bytes:
    """Return the zoom position inquiry."""
    return bytes((_address(address), 0x09, 0x04, 0x47, TERMINATOR))


def inquiry_power(address: int) -> bytes:
    """Return the power inquiry."""
    return bytes((_address(address), 0x09, 0x04, 0x00, TERMINATOR))


def inquiry_pan_tilt_max_speed(address: int) -> bytes:
    """Return the pan-tilt maximum speed inquiry."""
    return bytes((_address(address), 0x09, 0x06, 0x11, TERMINATOR))


def inquiry_pan_tilt_mode(address: int) -> bytes:
    """Return the pan-tilt mode (status) inquiry."""
    return bytes((_address(address), 0x09, 0x06, 0x10, TERMINATOR))


def inquiry_version(address: int) -> bytes:
    """Return the version inquiry."""
    return bytes((_address(address), 0x09, 0x00, 0x02, TERMINATOR))


def inquiry_ae_mode(address: int) -> bytes:
    """Return the exposure mode (CAM_AE) inquiry."""
    return bytes((_address(address), 0x09, 0x04, 0x39, TERMINATOR))


def inquiry_shutter(address: int) -> bytes:
    """Return the shutter position (CAM_Shutter) inquiry."""
    return bytes((_address(address), 0x09, 0x04, 0x4A, TERMINATOR))


def is_inquiry(packet: bytes) -> bool:
    """Return True for an inquiry packet (``8x 09 ...``)."""
    return len(packet) >= 3 and packet[1] == 0x09


# Replies (camera -> controller) ----------------------------------------------------------


def reply_header(address: int) -> int:
    """Return the first byte of the camera's replies: ``z0``, z = 8 + address."""
    if not 1 <= address <= 7:
        raise ViscaError(f'camera address {address} is not in 1..7')
    return (8 + address) << 4


def ack(address: int, socket: int) -> bytes:
    """Return ACK: the command is held in ``socket``."""
    return bytes((reply_header(address), 0x40 | socket, TERMINATOR))


def completion(address: int, socket: int) -> bytes:
    """Return Completion of the command in ``socket``."""
    return bytes((reply_header(address), 0x50 | socket, TERMINATOR))


def answer(address: int, payload: bytes) -> bytes:
    """Return an inquiry answer ``z0 50 <payload> FF``."""
    return bytes((reply_header(address), 0x50)) + bytes(payload) + bytes((TERMINATOR,))


def error(address: int, socket: int, code: int) -> bytes:
    """Return an error reply ``z0 6y ee FF``."""
    return bytes((reply_header(address), 0x60 | socket, code, TERMINATOR))


def network_change(address: int) -> bytes:
    """Return Network Change ``z0 38 FF``."""
    return bytes((reply_header(address), 0x38, TERMINATOR))


def address_set_reply(next_address: int) -> bytes:
    """Return the Address Set broadcast as it comes back round the chain."""
    return bytes((BROADCAST, 0x30, next_address, TERMINATOR))


def pan_tilt_position_payload(pan: int, tilt: int) -> bytes:
    """Return the payload of the pan-tilt position answer."""
    return encode_nibbles(pan) + encode_nibbles(tilt)


def zoom_position_payload(position: int) -> bytes:
    """Return the payload of the zoom position answer."""
    return encode_nibbles(position, signed=False)


def shutter_position_payload(position: int) -> bytes:
    """Return the payload of the shutter answer: ``00 00 0p 0q``."""
    return encode_nibbles(position, signed=False)


@dataclass(frozen=True)
class Reply:
    """
    One parsed reply from the camera.

    ``kind`` is 'ack', 'completion', 'answer', 'error', 'network_change',
    'address_set' or 'if_clear'. ``socket`` is 0 for answers and broadcasts;
    ``payload`` holds an answer's bytes between ``50`` and ``FF``; ``code``
    an error's code; ``raw`` the whole packet.
    """

    kind: str
    address: int
    socket: int
    raw: bytes
    payload: bytes = b''
    code: int = 0

    @property
    def error_name(self) -> str:
        """Return the error's name from visca.md (empty for non-errors)."""
        if self.kind != 'error':
            return ''
        return ERROR_NAMES.get(self.code, f'unknown error {self.code:02X}')

    def describe(self) -> str:
        """Return a one-line description with the reply bytes."""
        what = self.error_name if self.kind == 'error' else self.kind
        return f'{what} on socket {self.socket} ({hex_bytes(self.raw)})'


def parse_reply(packet: bytes) -> Reply:
    """Return the reply a complete packet (header .. FF) holds; ViscaError if malformed."""
    packet = bytes(packet)
    if len(packet) < 3 or packet[-1] != TERMINATOR:
        raise ViscaError(f'reply too short or not terminated by FF: {hex_bytes(packet)}')
    if len(packet) > MAX_PACKET:
        raise ViscaError(f'reply longer than {MAX_PACKET} bytes: {hex_bytes(packet)}')
    header, kind = packet[0], packet[1]
    if header == BROADCAST:
        if kind == 0x30 and len(packet) == 4:
            return Reply('address_set', 0, 0, packet, payload=packet[2:3])
        if packet[1:] == bytes((0x01, 0x00, 0x01, TERMINATOR)):
            return Reply('if_clear', 0, 0, packet)
        raise ViscaError(f'unknown broadcast reply: {hex_bytes(packet)}')
    if header & 0x8F != 0x80 or not 9 <= header >> 4 <= 15:
        raise ViscaError(f'bad reply header {header:02X}: {hex_bytes(packet)}')
    address = (header >> 4) - 8
    high, socket = kind >> 4, kind & 0x0F
    if kind == 0x38 and len(packet) == 3:
        return Reply('network_change', address, 0, packet)
    if high == 0x4 and len(packet) == 3:
        return Reply('ack', address, socket, packet)
    if high == 0x5:
        if len(packet) == 3 and socket != 0:
            return Reply('completion', address, socket, packet)
        if socket == 0:
            return Reply('answer', address, 0, packet, payload=packet[2:-1])
    if high == 0x6 and len(packet) == 4:
        return Reply('error', address, socket, packet, code=packet[2])
    raise ViscaError(f'unknown reply: {hex_bytes(packet)}')


def _answer_nibbles(payload: bytes, signed: bool) -> int:
    try:
        return decode_nibbles(payload, signed=signed)
    except ViscaError as exc:
        raise ViscaReplyError(str(exc)) from None


def parse_pan_tilt_position(payload: bytes) -> Tuple[int, int]:
    """
    Return (pan, tilt) in camera units from the position answer's payload.

    ViscaReplyError for a payload that is not 8 nibble bytes, or a position
    outside the travel plus :data:`TRAVEL_MARGIN_DEG` (never reported).
    """
    if len(payload) != 8:
        raise ViscaReplyError(f'pan-tilt position answer needs 8 bytes, got '
                              f'{hex_bytes(payload)}')
    pan, tilt = _answer_nibbles(payload[:4], True), _answer_nibbles(payload[4:], True)
    if abs(pan) > PAN_ANSWER_LIMIT_UNITS or abs(tilt) > TILT_ANSWER_LIMIT_UNITS:
        raise ViscaReplyError(
            f'pan-tilt position answer {hex_bytes(payload)} is outside the travel: pan {pan} '
            f'units ({pan_degrees(pan):.1f} deg), tilt {tilt} units '
            f'({tilt_degrees(tilt):.1f} deg); the camera reaches +-{PAN_LIMIT_UNITS} and '
            f'+-{TILT_LIMIT_UNITS}')
    return pan, tilt


def parse_zoom_position(payload: bytes) -> int:
    """Return the zoom position (0..3FFh) from the zoom answer's payload; ViscaReplyError."""
    if len(payload) != 4:
        raise ViscaReplyError(f'zoom position answer needs 4 bytes, got {hex_bytes(payload)}')
    position = _answer_nibbles(payload, False)
    if not ZOOM_WIDE <= position <= ZOOM_TELE:
        raise ViscaReplyError(f'zoom position answer {hex_bytes(payload)} is {position:04X}h, '
                              f'outside {ZOOM_WIDE:04X}h..{ZOOM_TELE:04X}h')
    return position


def parse_power(payload: bytes) -> bool:
    """Return True when the power answer says on, False for standby."""
    if len(payload) != 1 or payload[0] not in (POWER_ON, POWER_STANDBY):
        raise ViscaError(f'power answer is not 02 or 03: {hex_bytes(payload)}')
    return payload[0] == POWER_ON


def parse_ae_mode(payload: bytes) -> int:
    """Return the exposure mode from its answer's payload; ViscaReplyError if unknown."""
    if len(payload) != 1 or payload[0] not in AE_MODE_NAMES:
        raise ViscaReplyError(f'exposure mode answer is not one of '
                              f'{", ".join(f"{m:02X}" for m in AE_MODE_NAMES)}: '
                              f'{hex_bytes(payload)}')
    return payload[0]


def parse_shutter_position(payload: bytes) -> int:
    """Return the shutter position (00..1Bh) from its answer's payload; ViscaReplyError."""
    if len(payload) != 4:
        raise ViscaReplyError(f'shutter answer needs 4 bytes, got {hex_bytes(payload)}')
    position = _answer_nibbles(payload, False)
    if position > SHUTTER_POSITION_MAX:
        raise ViscaReplyError(f'shutter answer {hex_bytes(payload)} is {position:02X}h, '
                              f'outside 00..{SHUTTER_POSITION_MAX:02X}h')
    return position


def parse_max_speed(payload: bytes) -> Tuple[int, int]:
    """Return the (pan, tilt) maximum speed steps from their answer's payload."""
    if len(payload) != 2:
        raise ViscaError(f'max speed answer needs 2 bytes, got {hex_bytes(payload)}')
    return payload[0], payload[1]


def parse_version(payload: bytes) -> Tuple[int, int, int, int]:
    """Return (vendor, model, ROM version, sockets) from the version answer's payload."""
    if len(payload) != 7:
        raise ViscaError(f'version answer needs 7 bytes, got {hex_bytes(payload)}')
    return ((payload[0] << 8) | payload[1], (payload[2] << 8) | payload[3],
            (payload[4] << 8) | payload[5], payload[6])


# Framing ---------------------------------------------------------------------------------


class PacketFramer:
    """
    Cut a byte stream into packets: from a header byte (high bit set) to FF.

    Bytes before a header are junk and dropped (counted in ``junk_bytes``);
    a packet that grows past 16 bytes without FF is dropped as well (counted
    in ``overlong_packets``: the camera's message length error). With
    ``resync`` only the bytes before the next header byte in it are dropped,
    so a packet that follows a garbled one without its FF is still found.
    Feed it whatever the port returned: partial reads and several packets at
    once. Every packet it returns is 2..16 bytes, starts with a header byte
    and ends with FF; an FF always ends the packet being collected, so
    whatever garbage came before, the packet after the next FF is framed
    exactly.
    """

    def __init__(self, resync: bool = False) -> None:
        self._buffer = bytearray()
        self._resync = resync
        self.junk_bytes = 0
        self.overlong_packets = 0

    def feed(self, data: bytes) -> List[bytes]:
        """Return the complete packets that ``data`` finishes, in order."""
        packets = []
        for byte in data:
            if not self._buffer:
                if byte & 0x80 and byte != TERMINATOR:
                    self._buffer.append(byte)
                else:
                    self.junk_bytes += 1
                continue
            self._buffer.append(byte)
            if byte == TERMINATOR:
                packets.append(bytes(self._buffer))
                self._buffer.clear()
            elif len(self._buffer) >= MAX_PACKET:
                self.overlong_packets += 1
                drop = self._next_header() if self._resync else len(self._buffer)
                self.junk_bytes += drop
                del self._buffer[:drop]
        return packets

    def _next_header(self) -> int:
        """Return the index of the first header byte after the start (the length if none)."""
        for i in range(1, len(self._buffer)):
            if self._buffer[i] & 0x80:
                return i
        return len(self._buffer)

    def reset(self) -> None:
        """Drop a partial packet (after a reconnect)."""
        self._buffer.clear()
