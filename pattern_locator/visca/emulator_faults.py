"""
The emulated EVI-D31's faults: what a broken camera or line does to the replies (tests).

:class:`Faults` holds the knobs; :class:`FaultInjector` applies them to each
reply the camera is about to send (and to the packets it receives, for
``error_only``). Seeded, so a run is repeatable.
"""

import collections
import random
from typing import Optional, Tuple

from .protocol import (BROADCAST, COMMAND_SOCKETS, encode_nibbles, error, ERROR_NOT_EXECUTABLE,
                       TERMINATOR)
from ..errors import ConfigError

# Position answers a broken camera was seen to send (issue 10): pan -8000h (-65 rad),
# pan 1000 units (113.6 deg), tilt 396 units (33 deg), and a nibble byte above 0F.
BAD_POSITIONS = (
    encode_nibbles(-0x8000) + encode_nibbles(0),
    encode_nibbles(1000) + encode_nibbles(0),
    encode_nibbles(0) + encode_nibbles(396),
    encode_nibbles(-2000) + encode_nibbles(-1000),
    bytes((0x00, 0x13, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00)),
)
# The third byte of the exposure commands and inquiries: CAM_AE, CAM_Shutter direct and
# reset/up/down.
EXPOSURE_OPS = (0x39, 0x4A, 0x0A)
# Sockets the EVI-D31 does not have.
ABSENT_SOCKETS = (0, 3, 4, 5, 6, 7, 8, 9)


class Faults:
    """
    Fault injection knobs, read by the emulator at every packet and reply.

    * ``drop_probability``, ``garble_probability`` (flip one bit or insert
      1-3 random bytes), ``delay_s``: every reply;
    * ``bad_position_probability``: a position answer says an impossible
      position instead (beyond the travel, -8000h, a nibble byte above 0F);
    * ``lose_completions``: completions are never sent (the camera's socket
      is free all the same);
    * ``bad_ack_socket_probability``: an ACK names a socket the camera does
      not have (0, 3..9);
    * ``error_only``: an error code (e.g. ``ERROR_SYNTAX``): every packet
      addressed to the camera is answered with that error only and does
      nothing (broadcasts still come back);
    * ``phantom_ack_interval_s``: every so often, ACKs on sockets 1 and 2
      that no command caused and no completion follows;
    * ``deaf_to_commands``: commands get no reply and do nothing
      (inquiries and broadcasts are still answered);
    * ``refuse_exposure``: an error code: the exposure commands and
      inquiries (CAM_AE, CAM_Shutter) are answered with that error only and
      do nothing (a model or firmware without them).

    Assigning an attribute is atomic, so tests may change them while the
    emulator runs.
    """

    def __init__(self) -> None:
        self.clear()

    def apply(self, spec: str) -> 'Faults':
        """
        Set knobs from ``name=value,...`` (e.g. ``bad_position_probability=0.3,error_only=2``).

        Error codes (``error_only``, ``refuse_exposure``) are hex;
        ``lose_completions`` and ``deaf_to_commands`` take 0/1. ConfigError, in
        one line, for an unknown name or a bad value.
        """
        for item in filter(None, (part.strip() for part in spec.split(','))):
            name, _, text = item.partition('=')
            name = name.strip().replace('-', '_')
            if name.startswith('_') or not hasattr(self, name) or name in ('apply', 'clear'):
                known = ', '.join(sorted(k for k in vars(self) if not k.startswith('_')))
                raise ConfigError(f'unknown fault {name!r} (known: {known})')
            try:
                if name in ('error_only', 'refuse_exposure'):
                    value = int(text, 16)
                elif name in ('lose_completions', 'deaf_to_commands'):
                    value = bool(int(text))
                else:
                    value = float(text)
                    if not 0.0 <= value <= (1.0 if name.endswith('probability') else 60.0):
                        raise ValueError(value)
            except ValueError:
                raise ConfigError(f'fault {name}: bad value {text!r}') from None
            setattr(self, name, value)
        return self

    def clear(self) -> None:
        """Switch every fault off."""
        self.drop_probability = 0.0
        self.garble_probability = 0.0
        self.delay_s = 0.0
        self.bad_position_probability = 0.0
        self.lose_completions = False
        self.bad_ack_socket_probability = 0.0
        self.error_only: Optional[int] = None
        self.phantom_ack_interval_s = 0.0
        self.deaf_to_commands = False
        self.refuse_exposure: Optional[int] = None


class FaultInjector:
    """
    Apply :class:`Faults` (and the one-shot wrong socket) to replies; count what it did.

    ``counts``: 'dropped', 'garbled', 'error_only'.
    """

    def __init__(self, faults: Faults, seed: int) -> None:
        self.faults = faults
        self.counts: 'collections.Counter[str]' = collections.Counter()
        self.wrong_socket_once = False
        self._rng = random.Random(seed)

    def refusal(self, packet: Optional[bytes],
                address: Optional[int]) -> Optional[Tuple[bytes, ...]]:
        """Return the replies that replace the camera's answer to ``packet``, or None."""
        if packet is None or address is None or len(packet) < 3 or packet[0] != 0x80 | address:
            return None
        code = self.faults.error_only
        if code is not None:
            self.counts['error_only'] += 1
            return (error(address, 1 if code == ERROR_NOT_EXECUTABLE else 0, code),)
        if self.faults.deaf_to_commands and packet[1] != 0x09:
            self.counts['ignored'] += 1
            return ()
        code = self.faults.refuse_exposure
        if code is not None and len(packet) >= 4 and packet[1] in (0x01, 0x09) \
                and packet[2] == 0x04 and packet[3] in EXPOSURE_OPS:
            self.counts['refused_exposure'] += 1
            socket = 1 if code == ERROR_NOT_EXECUTABLE and packet[1] == 0x01 else 0
            return (error(address, socket, code),)
        return None

    def reply(self, packet: bytes) -> Optional[Tuple[bytes, float]]:
        """Return (the reply as it goes out, its delay), or None when it is lost."""
        if self.wrong_socket_once and packet[0] != BROADCAST and packet[1] >> 4 in (4, 5, 6) \
                and packet[1] & 0x0F in COMMAND_SOCKETS:
            self.wrong_socket_once = False
            packet = bytes((packet[0], packet[1] ^ 0x03)) + packet[2:]
        packet = self._by_kind(packet)
        faults, rng = self.faults, self._rng
        if packet is None or (faults.drop_probability > 0.0
                              and rng.random() < faults.drop_probability):
            self.counts['dropped'] += 1
            return None
        if faults.garble_probability > 0.0 and rng.random() < faults.garble_probability:
            self.counts['garbled'] += 1
            packet = self._garble(packet)
        return packet, max(0.0, faults.delay_s)

    def _by_kind(self, packet: bytes) -> Optional[bytes]:
        """Apply the faults that depend on what the reply is (None: not sent)."""
        faults, rng = self.faults, self._rng
        if packet[0] == BROADCAST or len(packet) < 3:
            return packet
        kind, socket = packet[1] >> 4, packet[1] & 0x0F
        if kind == 0x5 and socket in COMMAND_SOCKETS and len(packet) == 3 \
                and faults.lose_completions:
            return None
        if kind == 0x4 and len(packet) == 3 and faults.bad_ack_socket_probability > 0.0 \
                and rng.random() < faults.bad_ack_socket_probability:
            return bytes((packet[0], 0x40 | rng.choice(ABSENT_SOCKETS), TERMINATOR))
        if packet[1] == 0x50 and len(packet) == 11 and faults.bad_position_probability > 0.0 \
                and rng.random() < faults.bad_position_probability:
            return packet[:2] + rng.choice(BAD_POSITIONS) + bytes((TERMINATOR,))
        return packet

    def _garble(self, packet: bytes) -> bytes:
        rng, data = self._rng, bytearray(packet)
        if rng.random() < 0.5:
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        else:
            at = rng.randrange(len(data) + 1)
            data[at:at] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 3)))
        return bytes(data)
