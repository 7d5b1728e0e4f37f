"""Shared survey fixtures: one small survey bag per test session, made by the command line."""

from pathlib import Path

from pattern_locator.cli import main
import pytest

# The first four seconds of ``bag record-sim --survey``'s walk (the paper's room),
# 24 frames at 6 Hz, 1280x720.
BAG_FRAMES = 24
BAG_RATE_HZ = 6.0
BAG_SEED = 3


@pytest.fixture(scope='session')
def room_bag(tmp_path_factory) -> Path:
    """Return a survey bag written by ``bag record-sim --survey`` (MCAP, odometry, truth)."""
    out = tmp_path_factory.mktemp('survey') / 'walk'
    assert main(['bag', 'record-sim', '--survey', str(out), '--frames', str(BAG_FRAMES),
                 '--rate', str(BAG_RATE_HZ), '--seed', str(BAG_SEED)]) == 0
    return out
