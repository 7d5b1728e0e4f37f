"""
The EVI-D30/D31's shutter as the driver sets it: request, apply, read back (ROS-free).

A fixed short shutter keeps a card sharp while the head slews (issue 12):
at the camera's auto exposure (1/50 s) a card moving 20-80 deg/s smears by
5-25 px. :class:`ShutterRequest` is what the user asked for (``shutter_s``
seconds, rounded to the table's nearest speed in log scale);
:func:`apply_shutter` puts the camera in shutter priority (CAM_AE 0A) at that
position (CAM_Shutter direct), reads both back with their inquiries and
returns an :class:`ExposureReport`: what the camera now does, or why it
would not. The commands and the table (``protocol.SHUTTER_DENOMINATORS``)
are not in visca.md: Sony's EVI-D100 technical manual, "Command List, D30/31
mode" (the shutter table, p. 43), and the standard VISCA camera commands of
Sony's EVI/FCB manuals. The D30/D31's version inquiry does not tell NTSC
from PAL, so the video standard is the user's to say.
"""

from dataclasses import dataclass
from typing import Optional, TYPE_CHECKING

from . import protocol as visca
from .exceptions import ViscaCommandError, ViscaConnectionError, ViscaNotExecutable

if TYPE_CHECKING:  # pragma: no cover - typing only
    from .camera import EviD31


@dataclass(frozen=True)
class ShutterRequest:
    """
    A shutter to set: ``seconds`` as asked, ``position`` the table's nearest (log scale).

    Build it with :meth:`from_seconds`, which checks both values.
    """

    seconds: float
    video_standard: str
    position: int

    @classmethod
    def from_seconds(cls, seconds: float,
                     video_standard: str = 'pal') -> Optional['ShutterRequest']:
        """Return the request for ``seconds`` (0: None, leave the auto exposure); ViscaError."""
        if seconds == 0.0:
            visca.shutter_denominator(0, video_standard)  # checks the standard
            return None
        return cls(float(seconds), video_standard,
                   visca.nearest_shutter_position(seconds, video_standard))

    @property
    def speed_s(self) -> float:
        """Return the exposure time of the position set (s)."""
        return visca.shutter_seconds(self.position, self.video_standard)

    def describe(self) -> str:
        """Return the speed set: ``1/250 s``."""
        return visca.describe_shutter(self.position, self.video_standard)


@dataclass(frozen=True)
class ExposureReport:
    """
    The outcome of one :func:`apply_shutter` on the camera.

    ``applied``: the camera accepted both commands and its answers say
    shutter priority at the requested position. ``mode`` and ``position``
    are what the inquiries answered (None when they did not). ``message``
    is one line for the log: ``shutter 1/250 s (shutter priority)`` or what
    went wrong. ``retryable``: a reply got lost (worth asking again).
    ``not_executable``: the camera refused a command as not executable now
    (it does so while it initialises after a power-up).
    """

    request: ShutterRequest
    applied: bool
    mode: Optional[int]
    position: Optional[int]
    message: str
    retryable: bool = False
    not_executable: bool = False

    @property
    def shutter_s(self) -> Optional[float]:
        """Return the exposure time the camera says it applies (None: it picks it, or unknown)."""
        if self.mode in visca.AE_FIXED_SHUTTER_MODES and self.position is not None:
            return visca.shutter_seconds(self.position, self.request.video_standard)
        return None


def describe_exposure(mode: int, position: int, video_standard: str) -> str:
    """Return what the camera's exposure answers mean: ``shutter 1/250 s (shutter priority)``."""
    name = visca.AE_MODE_NAMES.get(mode, f'mode {mode:02X}h')
    if mode in visca.AE_FIXED_SHUTTER_MODES:
        return f'shutter {visca.describe_shutter(position, video_standard)} ({name})'
    return f'shutter chosen by the camera ({name})'


def apply_shutter(camera: 'EviD31', request: ShutterRequest) -> ExposureReport:
    """
    Put the camera in shutter priority at ``request.position``; read it back.

    An error reply (a model without these commands: syntax error; not
    executable) or a lost answer gives a report saying so (never raises for
    them); ViscaConnectionError (the port went away) is raised.
    """
    refused = None
    try:
        camera.set_ae_mode(visca.AE_SHUTTER_PRIORITY)
        camera.set_shutter_position(request.position)
    except ViscaConnectionError:
        raise
    except ViscaCommandError as exc:
        refused = exc
    except visca.ViscaError as exc:
        return ExposureReport(request, False, None, None,
                              f'shutter {request.describe()} not set: no answer ({exc})',
                              retryable=True)
    if refused is not None:
        return ExposureReport(
            request, False, None, None,
            f'the camera refused the shutter {request.describe()} ({exc_text(refused)}): '
            'it keeps its own exposure; tracking goes on',
            not_executable=isinstance(refused, ViscaNotExecutable))
    try:
        mode, position = camera.ae_mode(), camera.shutter_position()
    except ViscaConnectionError:
        raise
    except ViscaCommandError as exc:
        return ExposureReport(request, False, None, None,
                              f'shutter {request.describe()} sent, but the camera does not '
                              f'answer its inquiries ({exc_text(exc)})')
    except visca.ViscaError as exc:
        return ExposureReport(request, False, None, None,
                              f'shutter {request.describe()} sent, no answer to read it back '
                              f'({exc})', retryable=True)
    text = describe_exposure(mode, position, request.video_standard)
    if mode != visca.AE_SHUTTER_PRIORITY or position != request.position:
        return ExposureReport(request, False, mode, position,
                              f'asked for shutter {request.describe()} (shutter priority), '
                              f'the camera says {text}')
    return ExposureReport(request, True, mode, position, text)


def exc_text(exc: ViscaCommandError) -> str:
    """Return an error reply's name and the bytes it answered."""
    sent = f' to {visca.hex_bytes(exc.packet)}' if exc.packet else ''
    return f'{exc.reply.error_name}{sent}'
