"""
The package's own exception types.

Every error a user can cause (a bad file, a bad id, a bad image) is one of
these, with a message that names the bad part, so nodes can log it and the
command line can print it as one line.
"""


class PatternLocatorError(Exception):
    """Base class of every error raised on purpose by this package."""


class ConfigError(PatternLocatorError):
    """A configuration file (pattern, building, camera) is missing or invalid."""


class CodeError(PatternLocatorError):
    """A colour code or a (floor, room, pattern) triple is invalid."""


class CameraError(ConfigError):
    """Camera intrinsics are missing or invalid."""


class ImageError(PatternLocatorError):
    """An image cannot be read or has an unusable format."""


class EstimationError(PatternLocatorError):
    """A pose cannot be estimated from the detected points."""


class PrintError(PatternLocatorError):
    """A card file cannot be written (unknown format, unwritable path)."""
