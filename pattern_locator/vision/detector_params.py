"""The detector's tuning, shared by its four stages (dots, cards, centres, code)."""

from dataclasses import dataclass

from ..errors import ConfigError

FIELDS = ('auto', 'frame', 'even', 'odd')


@dataclass(frozen=True)
class DetectorParams:
    """
    Tuning of the detector; the defaults suit 320x240 to 1920x1080 cameras.

    ``field`` says which rows to use: ``frame`` all of them, ``even`` or
    ``odd`` one field of an interlaced frame (the other rows interpolated),
    ``auto`` one field when the frame shows the comb of a camera that moved
    between its two fields, else all rows.
    """

    # Dots: segmentation on the image decimated by `decimate` (cards far
    # away are segmented again at full resolution around their centre).
    decimate: int = 2
    dark_ratio: float = 0.75        # dot pixel: darkest channel below this fraction of local white
    noise_factor: float = 10.0      # ...and darker than local white by this many noise sigmas
    min_white: int = 24             # ignore regions whose local white is darker than this
    white_window: int = 48          # local white: max filter over about this many pixels
    max_dot_area_fraction: float = 0.05   # of the image
    field: str = 'auto'
    # Cards: candidates ranked by evidence, at most this many examined per image.
    max_candidates: int = 12
    min_ellipse_fill: float = 0.5   # centre blob area / area of its moment ellipse
    max_homography_error: float = 0.25    # in units of the dot's image radius
    # Colours, compared in linear light.
    gamma: float = 2.2              # the camera's encoding
    min_darkness: float = 0.2       # a dot darker than the card by less than this is unreadable
    min_colour_margin: float = 0.35     # of the way from the bisector to the nearest ink
    min_window_darkness: float = 0.12   # a dot must be this much darker than the paper
    max_channel_shift_px: float = 2.0   # colour measured where this shift cannot change it
    # Occlusion: at most this many slots (both rings) hidden when the known
    # codes (a building map) can complete the code.
    max_hidden_slots: int = 3
    decisive_margin: float = 0.6    # a seen slot that alone tells two known codes apart
    # Hidden slots that several known codes fill: at most this many
    # hypotheses are handed on for the localizer to choose among; more, and
    # the card is dropped.
    max_code_candidates: int = 8
    # Where no card was read: this many blobs (far candidates not read, then
    # small blobs that faint spots ring, then the darkest ink) are looked at
    # again in a window zoomed twice and sharpened (a far card through a
    # soft lens; vision.zoom). 0: never.
    zoom_tries: int = 3

    def __post_init__(self) -> None:
        if self.field not in FIELDS:
            raise ConfigError(f'detector: field must be one of {", ".join(FIELDS)}, '
                              f'got {self.field!r}')
        if self.decimate not in (1, 2):
            raise ConfigError(f'detector: decimate must be 1 or 2, got {self.decimate!r}')
        if not 0 <= self.max_hidden_slots <= 3:
            raise ConfigError(f'detector: max_hidden_slots must be 0..3, got '
                              f'{self.max_hidden_slots!r}')
        if self.max_code_candidates < 0:
            raise ConfigError(f'detector: max_code_candidates must be >= 0, got '
                              f'{self.max_code_candidates!r}')
        if self.zoom_tries < 0:
            raise ConfigError(f'detector: zoom_tries must be >= 0, got {self.zoom_tries!r}')
        if self.max_candidates < 1:
            raise ConfigError(f'detector: max_candidates must be >= 1, got '
                              f'{self.max_candidates!r}')
