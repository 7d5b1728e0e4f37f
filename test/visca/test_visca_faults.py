"""
The broken camera of issue 10, at the camera layer: EviD31 on the emulated EVI-D31 on a pty.

Malformed position replies, replies on sockets the camera does not have,
completions that never come, a missing port, and closing from another
thread while a call waits on the camera.
"""

import math
import threading
import time

from pattern_locator.visca import protocol as v
from pattern_locator.visca.camera import EviD31
from pattern_locator.visca.emulator import EmulatedEviD31
from pattern_locator.visca.transport import (ViscaConnectionError, ViscaReplyError,
                                             ViscaSocketsBusy)
import pytest
from ros_tools import wait_until

ADDR = 1
PAN_MAX = math.radians(100.0 + v.TRAVEL_MARGIN_DEG)
TILT_MAX = math.radians(25.0 + v.TRAVEL_MARGIN_DEG)


@pytest.fixture
def emulator(tmp_path):
    with EmulatedEviD31(init_s=0.05, link_path=str(tmp_path / 'evi-d31')) as emu:
        yield emu


@pytest.fixture
def camera(emulator):
    cam = EviD31(emulator.port, reply_timeout_s=0.2)
    cam.start(timeout_s=5.0)
    yield cam
    cam.close()


def test_malformed_position_replies_are_rejected_counted_and_never_returned(emulator, camera):
    camera.move_to(0.5, 0.2)
    emulator.faults.bad_position_probability = 0.6
    good, rejected = [], 0
    for _ in range(12):
        try:
            good.append(camera.position())
        except ViscaReplyError as exc:
            rejected += 1
            assert 'outside the travel' in str(exc) or 'high nibble' in str(exc)
    emulator.faults.clear()
    # Every value that came out is the head's true position; the rest was rejected.
    assert good and all(p == pytest.approx((0.5, 0.2), abs=0.002) for p in good)
    assert all(abs(pan) <= PAN_MAX and abs(tilt) <= TILT_MAX for pan, tilt in good)
    assert camera.rejected_replies['position'] >= rejected * 2 > 0  # each one asked twice
    assert 'position' in camera.last_rejected
    assert camera.position() == pytest.approx((0.5, 0.2), abs=0.002)
    # The seen ones, one by one: -8000h (-65 rad), 1000 units (113.6 deg), tilt 396 (33 deg).
    for payload in (v.encode_nibbles(-0x8000) + v.encode_nibbles(0),
                    v.encode_nibbles(1000) + v.encode_nibbles(0),
                    v.encode_nibbles(0) + v.encode_nibbles(396)):
        with pytest.raises(ViscaReplyError, match='outside the travel'):
            v.parse_pan_tilt_position(payload)


def test_replies_on_absent_sockets_are_ignored_counted_and_book_nothing(emulator, camera):
    before = camera.transport.stats
    strays = [v.ack(ADDR, s) for s in (0, 3, 4, 9)] + [v.completion(ADDR, s) for s in (3, 7)] \
        + [v.error(ADDR, 5, v.ERROR_NOT_EXECUTABLE)]
    emulator.send_garbage(b''.join(strays))
    assert wait_until(lambda: camera.transport.stats.bad_socket_replies
                      == before.bad_socket_replies + len(strays))
    assert camera.transport.sockets_in_use == []
    # The camera answering our own commands on such sockets: they fail at once, no timeout.
    emulator.faults.bad_ack_socket_probability = 1.0
    for _ in range(3):
        with pytest.raises(ViscaReplyError, match='a socket it does not have'):
            camera.drive(0.1, 0.0, blocking=False)
        assert camera.position() is not None
    emulator.faults.clear()
    stats = camera.transport.stats
    assert stats.timeouts == before.timeouts and camera.transport.sockets_in_use == []
    camera.drive(0.1, 0.0)
    camera.stop()


def test_a_socket_whose_completion_never_comes_is_freed_after_the_longest_command_time(
        emulator, camera):
    # Two ACKs nobody caused, never completed: both sockets look busy.
    emulator.send_garbage(v.ack(ADDR, 1) + v.ack(ADDR, 2))
    assert wait_until(lambda: camera.transport.sockets_in_use == [1, 2])
    booked = time.monotonic()
    with pytest.raises(ViscaSocketsBusy):
        camera.drive(0.2, 0.0, blocking=False)  # not sent, not waited for
    assert camera.position() is not None       # inquiries need no socket
    # Freed after INSTANT_COMMAND_S (1 s), not the 30 s completion timeout.
    assert wait_until(lambda: camera.transport.sockets_in_use == [], 3.0)
    assert time.monotonic() - booked >= v.INSTANT_COMMAND_S * 0.9
    assert camera.transport.stats.expired_sockets == 2
    # A command of ours whose completion is lost frees its socket the same way.
    emulator.faults.lose_completions = True
    result = camera.transport.command(v.focus_auto(ADDR), wait=False, timeout=0.5,
                                      duration_s=0.3)
    assert camera.transport.sockets_in_use == [result.socket]
    assert wait_until(lambda: camera.transport.sockets_in_use == [], 2.0)
    assert not result.ok and 'socket freed' in str(result.error)
    emulator.faults.clear()
    camera.drive(0.2, 0.0, blocking=False)
    camera.stop()


def test_close_from_another_thread_ends_a_wait_on_a_silent_camera(emulator, camera):
    emulator.stop_answering(True)
    errors = []

    def ask():
        try:
            camera.position()
        except v.ViscaError as exc:
            errors.append(exc)

    asker = threading.Thread(target=ask)
    asker.start()
    assert wait_until(lambda: emulator.stats.ignored_packets > 0)
    camera.close()
    asker.join(1.0)
    assert not asker.is_alive()
    assert len(errors) == 1 and isinstance(errors[0], ViscaConnectionError)
    assert not camera.transport.is_open and camera.closing


def test_close_ends_a_start_up_that_waits_for_a_silent_camera(emulator):
    emulator.stop_answering(True)
    camera = EviD31(emulator.port, reply_timeout_s=0.2)
    errors = []

    def start():
        try:
            camera.start(timeout_s=30.0)
        except v.ViscaError as exc:
            errors.append(exc)

    starter = threading.Thread(target=start)
    starter.start()
    assert wait_until(lambda: emulator.stats.ignored_packets >= 2)
    camera.close()
    starter.join(1.0)
    assert not starter.is_alive()
    assert len(errors) == 1 and isinstance(errors[0], ViscaConnectionError)


def test_close_stops_a_driving_head(emulator, camera):
    camera.drive(0.5, 0.0)
    assert wait_until(lambda: emulator.state().pan_deg < -2.0)
    camera.close()
    held = emulator.state().pan_deg
    time.sleep(0.1)
    assert emulator.state().pan_deg == held
