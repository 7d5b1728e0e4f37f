"""
Give big image buffers back to the system (glibc's allocator), for the long-running nodes.

A burst of large frames (each message a few MB, its decoded copy, OpenCV's
work images) leaves the heap grown: glibc raises its mmap threshold after
freeing a large mmapped block, so the next large blocks come from the heap
and stay mapped after they are freed. :class:`HeapTrimmer` fixes the
threshold (large blocks are always mmapped, so freeing one unmaps it) and
trims the heap when the node goes idle after big frames. Elsewhere than
glibc it does nothing.
"""

import ctypes
import ctypes.util
import logging
from typing import Optional

logger = logging.getLogger(__name__)

# mallopt parameters (malloc.h).
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
# Blocks from this size on are mmapped: an image row block, not a small object.
MMAP_THRESHOLD_BYTES = 1024 * 1024
TRIM_THRESHOLD_BYTES = 4 * 1024 * 1024


def _libc() -> Optional[ctypes.CDLL]:
    name = ctypes.util.find_library('c')
    if not name:
        return None
    try:
        libc = ctypes.CDLL(name)
        libc.malloc_trim, libc.mallopt   # glibc only
    except (OSError, AttributeError):
        return None
    return libc


class HeapTrimmer:
    """Bound the heap's growth after big frames (glibc); a no-op elsewhere."""

    def __init__(self) -> None:
        self._libc = _libc()
        if self._libc is not None:
            self._libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)
            self._libc.mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)
        self.trims = 0

    @property
    def active(self) -> bool:
        """Return whether the allocator is glibc's (trimming does something)."""
        return self._libc is not None

    def trim(self) -> None:
        """Return the free memory at the top of every heap to the system."""
        if self._libc is not None:
            self._libc.malloc_trim(0)
            self.trims += 1
