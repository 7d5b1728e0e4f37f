"""
The VISCA driver's exceptions, all :class:`~pattern_locator.visca.protocol.ViscaError`.

Connection and timing problems, and one class per error reply of visca.md
(``z0 6y ee FF``), so a caller can tell "our bug, do not retry" (syntax,
message length) from "wait and resend" (buffer full) or "already stopped"
(cancelled, no socket).
"""

from .protocol import (ERROR_BUFFER_FULL, ERROR_CANCELLED, ERROR_MESSAGE_LENGTH, ERROR_NO_SOCKET,
                       ERROR_NOT_EXECUTABLE, ERROR_SYNTAX, hex_bytes, Reply, ViscaError)


class ViscaConnectionError(ViscaError):
    """The serial port is closed, vanished or stopped answering."""


class ViscaTimeout(ViscaError):
    """The camera did not answer (or complete) in time."""


class ViscaSocketsBusy(ViscaTimeout):
    """Both command sockets hold one of our commands: the new one was not sent."""


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
