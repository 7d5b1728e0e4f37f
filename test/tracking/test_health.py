"""The driver's health from positions and failures, on a clock the test moves."""

import math

from pattern_locator.tracking.health import (CONNECTION, ERROR, ERROR_REPLY, HealthMonitor,
                                             MALFORMED, OK, SILENCE, SOCKETS_BUSY, WARN)
import pytest


class Clock:
    """A clock that moves only when the test says."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def monitor(**kwargs):
    clock = Clock()
    return HealthMonitor(clock=clock, **kwargs), clock


def feed(health, clock, seconds, hz=10.0):
    for _ in range(int(round(seconds * hz))):
        clock.now += 1.0 / hz
        health.position()


def test_ok_only_while_fresh_positions_flow():
    health, clock = monitor(stale_after_s=0.5, expected_rate_hz=10.0)
    assert health.assess(True, True).level == ERROR
    assert health.assess(True, True).message == 'no position yet'
    feed(health, clock, 2.0)
    h = health.assess(True, True, reply_age_s=0.05)
    assert (h.level, h.message) == (OK, 'positions fresh (10.0 Hz)') and h.ok
    assert h.position_rate_hz == pytest.approx(10.0, rel=0.06) and h.position_age_s == 0.0
    clock.now += 0.6
    assert health.assess(True, True).level == ERROR
    assert health.assess(True, True).message == 'no position for 0.6 s'


def test_a_low_rate_is_a_warning():
    health, clock = monitor(stale_after_s=1.0, expected_rate_hz=10.0)
    feed(health, clock, 2.0, hz=3.0)
    h = health.assess(True, True)
    assert h.level == WARN and h.message == 'positions at 3.0 Hz, expected 10 Hz'


def test_stale_positions_say_why():
    health, clock = monitor(stale_after_s=0.5)
    feed(health, clock, 1.0)
    for kind, message, words in (
            (ERROR_REPLY, 'camera answered syntax error on socket 0 (90 60 02 FF)',
             'the camera answers only error replies (camera answered syntax error'),
            (MALFORMED, 'pan-tilt position answer 08 00 00 00 00 00 00 00 is outside',
             'the position replies are malformed (pan-tilt position answer 08'),
            (SILENCE, 'no reply to 81 09 06 12 FF within 0.30 s', 'the camera is silent')):
        clock.now += 1.0
        health.failure(kind, message)
        h = health.assess(True, True, reply_age_s=5.0)
        assert h.level == ERROR and words in h.message, h
        assert h.message.startswith('no position for ')


def test_failures_or_refused_commands_while_positions_flow_are_warnings():
    health, clock = monitor(stale_after_s=0.5, window_s=2.0)
    feed(health, clock, 1.0)
    health.command_failure(SOCKETS_BUSY, 'both camera sockets busy ([1, 2])')
    h = health.assess(True, True)
    assert h.level == WARN and 'sockets busy: both camera sockets busy' in h.message
    health.failure(MALFORMED, 'x' * 500)
    feed(health, clock, 0.5)
    h = health.assess(True, True)
    assert h.level == WARN and '1 failed in the last 2 s' in h.message
    assert len(h.message) < 250  # foreign text is quoted short
    feed(health, clock, 2.1)      # the window forgets them
    assert health.assess(True, True).level == OK


def test_link_states():
    health, clock = monitor(stale_after_s=0.5)
    feed(health, clock, 1.0)
    h = health.assess(False, False, 'VISCA port /dev/ttyUSB0 does not exist')
    assert h.level == ERROR
    assert h.message == ('camera link down: VISCA port /dev/ttyUSB0 does not exist; '
                         'reconnecting')
    assert health.assess(True, False, reply_age_s=0.1).level == WARN
    h = health.assess(True, False, reply_age_s=math.inf)
    assert h.level == ERROR and 'silent (no reply yet)' in h.message
    health.failure(CONNECTION, 'closing')
    assert health.stopped('camera driver stopped').message == 'camera driver stopped'
