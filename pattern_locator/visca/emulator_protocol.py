"""
The emulated EVI-D31's protocol handling: received packets in, reply packets out (ROS-free).

:func:`parse_command` checks a command's syntax (``z0 60 02 FF`` when it
fails); :class:`ViscaResponder` applies visca.md's rules in the emulator's
documented order (addressing, syntax, a free socket, executable) to an
:class:`~pattern_locator.visca.emulator_device.EmulatedDevice` and returns
the replies, without timing or faults (those are the emulator's).
"""

import collections
from typing import List, Optional

from .emulator_device import Command, EmulatedDevice, SOCKETS
from .protocol import (ack, address_set_reply, AE_MODE_NAMES, answer, BROADCAST, completion,
                       decode_nibbles, error, ERROR_BUFFER_FULL, ERROR_CANCELLED,
                       ERROR_MESSAGE_LENGTH, ERROR_NO_SOCKET, ERROR_NOT_EXECUTABLE,
                       ERROR_SYNTAX, PAN_LIMIT_UNITS, PAN_SPEED_MAX, pan_tilt_position_payload,
                       POWER_ON, POWER_STANDBY, SHUTTER_DOWN, SHUTTER_POSITION_MAX,
                       shutter_position_payload, SHUTTER_RESET, SHUTTER_UP, TERMINATOR,
                       TILT_LIMIT_UNITS, TILT_SPEED_MAX, zoom_position_payload, ZOOM_SPEED_MAX,
                       ZOOM_SPEED_MIN, ZOOM_TELE, ZOOM_WIDE)

VENDOR_ID = 0x0001
MODEL_ID = 0x0402
ROM_VERSION = 0x0201


class CommandSyntaxError(Exception):
    """A command the camera answers with a syntax error."""


def _nibbles(data: bytes, signed: bool = True) -> int:
    if len(data) != 4 or any(b > 0x0F for b in data):
        raise CommandSyntaxError()
    return decode_nibbles(data, signed=signed)


def _speed(value: int, maximum: int) -> int:
    # Speed 00 is refused as well (visca.md: some models answer it with a syntax error).
    if not 1 <= value <= maximum:
        raise CommandSyntaxError()
    return value


def _pan_tilt_command(body: bytes) -> Command:
    n, op = len(body), body[2]
    if op == 0x01 and n == 7:
        pan_speed, tilt_speed = _speed(body[3], PAN_SPEED_MAX), _speed(body[4], TILT_SPEED_MAX)
        if body[5] not in (1, 2, 3) or body[6] not in (1, 2, 3):
            raise CommandSyntaxError()
        return Command('drive', 'instant', 'pt', (pan_speed, tilt_speed, body[5], body[6]))
    if op in (0x02, 0x03) and n == 13:
        pan_speed, tilt_speed = _speed(body[3], PAN_SPEED_MAX), _speed(body[4], TILT_SPEED_MAX)
        pan, tilt = _nibbles(body[5:9]), _nibbles(body[9:13])
        if op == 0x02 and (abs(pan) > PAN_LIMIT_UNITS or abs(tilt) > TILT_LIMIT_UNITS):
            raise CommandSyntaxError()
        name = 'absolute' if op == 0x02 else 'relative'
        return Command(name, 'move', 'pt', (pan_speed, tilt_speed, pan, tilt))
    if op == 0x04 and n == 3:
        return Command('home', 'move', 'pt')
    if op == 0x05 and n == 3:
        return Command('reset', 'reset', 'pt')
    if op == 0x07 and n == 13 and body[3] in (0, 1) and body[4] in (0, 1):
        if body[3] == 0x01:
            # LimitClear: the position bytes are fixed filler, only checked as nibbles.
            _nibbles(body[5:9], signed=False)
            _nibbles(body[9:13], signed=False)
            return Command('limit_clear', 'instant', None, (body[4] == 1,))
        pan, tilt = _nibbles(body[5:9]), _nibbles(body[9:13])
        if abs(pan) > PAN_LIMIT_UNITS or abs(tilt) > TILT_LIMIT_UNITS:
            raise CommandSyntaxError()
        return Command('limit_set', 'instant', None, (body[4] == 1, pan, tilt))
    raise CommandSyntaxError()


def _camera_command(body: bytes) -> Command:
    n, op = len(body), body[2]
    if op == 0x07 and n == 4:
        value = body[3]
        if value in (0x00, 0x02, 0x03):
            return Command('zoom', 'instant', 'zoom', ({0: 0, 2: 1, 3: -1}[value], None))
        if value >> 4 in (0x2, 0x3) and ZOOM_SPEED_MIN <= value & 0x0F <= ZOOM_SPEED_MAX:
            return Command('zoom', 'instant', 'zoom',
                           (1 if value >> 4 == 0x2 else -1, value & 0x0F))
        raise CommandSyntaxError()
    if op == 0x47 and n == 7:
        position = _nibbles(body[3:7], signed=False)
        if not ZOOM_WIDE <= position <= ZOOM_TELE:
            raise CommandSyntaxError()
        return Command('zoom_direct', 'move', 'zoom', (position,))
    if op == 0x38 and n == 4 and body[3] in (0x02, 0x03):
        return Command('focus_mode', 'instant', None, (body[3] == 0x02,))
    if op == 0x08 and n == 4 and body[3] in (0x00, 0x02, 0x03):
        return Command('focus_drive', 'instant', None, (body[3],))
    if op == 0x00 and n == 4 and body[3] in (POWER_ON, POWER_STANDBY):
        return Command('power', 'instant', None, (body[3] == POWER_ON,))
    if op == 0x39 and n == 4 and body[3] in AE_MODE_NAMES:
        return Command('ae_mode', 'instant', None, (body[3],))
    if op == 0x4A and n == 7:
        position = _nibbles(body[3:7], signed=False)
        if position > SHUTTER_POSITION_MAX:
            raise CommandSyntaxError()
        return Command('shutter', 'instant', None, (position,))
    if op == 0x0A and n == 4 and body[3] in (SHUTTER_RESET, SHUTTER_UP, SHUTTER_DOWN):
        return Command('shutter_step', 'instant', None, (body[3],))
    raise CommandSyntaxError()


def parse_command(body: bytes) -> Command:
    """Return the command in ``body`` (the bytes between header and FF); CommandSyntaxError."""
    if len(body) >= 3 and body[:2] == b'\x01\x06':
        return _pan_tilt_command(body)
    if len(body) >= 3 and body[:2] == b'\x01\x04':
        return _camera_command(body)
    raise CommandSyntaxError()


class ViscaResponder:
    """
    Apply received packets to the device; return the camera's replies, in order.

    ``counts`` holds 'commands', 'inquiries' and 'ignored' (packets for
    another address, before Address Set, unknown broadcasts).
    """

    def __init__(self, device: EmulatedDevice) -> None:
        self.device = device
        self.counts = collections.Counter()

    def completions(self, now: float) -> List[bytes]:
        """Start a video field: the completions of the commands that finished."""
        address = self.device.reply_address()
        return [completion(address, socket) for socket in self.device.next_field(now)]

    def handle(self, packet: Optional[bytes], now: float) -> List[bytes]:
        """Return the replies to one packet (None: one that overflowed 16 bytes)."""
        device = self.device
        if packet is None:
            return [] if device.address is None else [
                error(device.address, 0, ERROR_MESSAGE_LENGTH)]
        header = packet[0]
        if header == BROADCAST:
            return self._broadcast(packet, now)
        if not 0x81 <= header <= 0x87 or device.address is None \
                or header & 0x0F != device.address:
            self.counts['ignored'] += 1
            return []
        address = device.address
        body = packet[1:-1]
        if len(body) < 1:
            return [error(address, 0, ERROR_MESSAGE_LENGTH)]
        if body[0] == 0x09:
            self.counts['inquiries'] += 1
            return [self._inquiry(body, now)]
        self.counts['commands'] += 1
        if len(body) == 1 and body[0] >> 4 == 0x2:
            return [self._cancel(body[0] & 0x0F, now)]
        if body == b'\x01\x00\x01':
            device.if_clear(now)
            return [answer(address, b'')]
        try:
            command = parse_command(body)
        except CommandSyntaxError:
            return [error(address, 0, ERROR_SYNTAX)]
        socket = device.free_socket()
        if socket is None:
            return [error(address, 0, ERROR_BUFFER_FULL)]
        if not device.executable(command, now):
            return [error(address, socket, ERROR_NOT_EXECUTABLE)]
        device.accept(command, socket, now)
        return [ack(address, socket)]

    def _broadcast(self, packet: bytes, now: float) -> List[bytes]:
        if len(packet) == 4 and packet[1] == 0x30 and 1 <= packet[2] <= 7:
            self.device.set_address(packet[2])
            return [address_set_reply(packet[2] + 1)]
        if packet == bytes((BROADCAST, 0x01, 0x00, 0x01, TERMINATOR)):
            self.device.if_clear(now)
            return [packet]
        self.counts['ignored'] += 1
        return []

    def _cancel(self, socket: int, now: float) -> bytes:
        address = self.device.address
        if socket not in SOCKETS:
            return error(address, 0, ERROR_SYNTAX)
        if not self.device.cancel(socket, now):
            return error(address, socket, ERROR_NO_SOCKET)
        return error(address, socket, ERROR_CANCELLED)

    def _inquiry(self, body: bytes, now: float) -> bytes:
        device, address = self.device, self.device.address
        if body == b'\x09\x06\x12':
            pan, tilt = device.head.position(now)
            payload = pan_tilt_position_payload(round(pan), round(tilt))
        elif body == b'\x09\x04\x47':
            payload = zoom_position_payload(round(device.head.zoom_at(now)))
        elif body == b'\x09\x04\x00':
            payload = bytes((POWER_ON if device.powered else POWER_STANDBY,))
        elif body == b'\x09\x06\x11':
            payload = bytes((PAN_SPEED_MAX, TILT_SPEED_MAX))
        elif body == b'\x09\x06\x10':
            status = device.pan_tilt_status(now)
            payload = bytes((status >> 8, status & 0xFF))
        elif body == b'\x09\x04\x38':
            payload = bytes((0x02 if device.focus_auto else 0x03,))
        elif body == b'\x09\x04\x39':
            payload = bytes((device.ae_mode,))
        elif body == b'\x09\x04\x4A':
            payload = shutter_position_payload(device.shutter_position)
        elif body == b'\x09\x00\x02':
            payload = bytes((VENDOR_ID >> 8, VENDOR_ID & 0xFF, MODEL_ID >> 8, MODEL_ID & 0xFF,
                             ROM_VERSION >> 8, ROM_VERSION & 0xFF, len(SOCKETS)))
        else:
            return error(address, 0, ERROR_SYNTAX)
        return answer(address, payload)
