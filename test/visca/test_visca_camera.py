"""EVI-D31 camera layer against the emulated camera on a pseudo-terminal."""

import math
import threading
import time

from pattern_locator.visca import protocol as v
from pattern_locator.visca.camera import (EviD31, from_visca_units, pan_step, tilt_step,
                                          to_visca_units)
from pattern_locator.visca.emulator import EmulatedEviD31
from pattern_locator.visca.transport import (ViscaCancelled, ViscaConnectionError,
                                             ViscaNotExecutable, ViscaSyntaxError, ViscaTimeout)
import pytest
from ros_tools import wait_until

INIT_S = 0.15


@pytest.fixture
def emulator(tmp_path):
    emu = EmulatedEviD31(init_s=INIT_S, reset_s=0.5, link_path=str(tmp_path / 'evi-d31'))
    emu.start()
    yield emu
    emu.stop()


@pytest.fixture
def camera(emulator):
    cam = EviD31(emulator.port, reply_timeout_s=0.25, completion_timeout_s=5.0)
    cam.start(timeout_s=5.0)
    yield cam
    cam.close()


def test_speed_quantisation_and_signs():
    assert pan_step(0.0) == (0, v.PAN_STOP)
    assert pan_step(math.radians(1.0)) == (0, v.PAN_STOP)  # below half a step
    assert pan_step(math.radians(10.0)) == (3, v.PAN_LEFT)  # REP 103: positive = left
    assert pan_step(-math.radians(10.0)) == (3, v.PAN_RIGHT)
    assert pan_step(10.0) == (v.PAN_SPEED_MAX, v.PAN_LEFT)
    assert tilt_step(math.radians(5.0)) == (2, v.TILT_UP)
    assert tilt_step(-10.0) == (v.TILT_SPEED_MAX, v.TILT_DOWN)
    assert to_visca_units(math.radians(10.0), math.radians(-5.0)) == (-88, -60)
    assert from_visca_units(-88, -60) == pytest.approx((math.radians(10.0),
                                                        math.radians(-5.0)))
    with pytest.raises(v.ViscaError):
        pan_step(float('nan'))


def test_start_up(emulator, camera):
    assert camera.ready and camera.connected
    assert emulator.address == 1
    state = emulator.state()
    assert state.powered and not state.initialising and state.sockets_busy == ()
    assert camera.power_on() is True
    assert camera.version().model == 0x0402
    assert camera.position() == pytest.approx((0.0, 0.0), abs=1e-9)
    assert camera.zoom() == 0
    assert camera.pan_limits_rad == pytest.approx((-math.radians(100), math.radians(100)))
    assert camera.tilt_limits_rad == pytest.approx((-math.radians(25), math.radians(25)))


def test_start_switches_a_standby_camera_on(emulator, camera):
    camera.power(False)
    assert wait_until(lambda: not emulator.state().powered)
    assert camera.power_on() is False
    start = time.monotonic()
    camera.start(timeout_s=5.0)
    assert camera.ready and emulator.state().powered and not emulator.state().initialising
    assert time.monotonic() - start >= INIT_S * 0.9  # it waited for the initialisation


def test_start_gives_up_with_a_clear_error(emulator):
    emulator.stop_answering(True)
    cam = EviD31(emulator.port, reply_timeout_s=0.1)
    start = time.monotonic()
    try:
        with pytest.raises(ViscaTimeout, match='no Address Set within 0.8 s'):
            cam.start(timeout_s=0.8)
        assert time.monotonic() - start < 1.5
    finally:
        cam.close()


def test_start_fails_at_once_on_a_missing_port_with_one_clear_line(tmp_path):
    port = tmp_path / 'nothing'
    cam = EviD31(str(port))
    # One attempt, no retries inside start(): the caller (the node) retries with its backoff.
    with pytest.raises(ViscaConnectionError) as info:
        cam.start(timeout_s=30.0)
    assert str(info.value) == f'VISCA port {port} does not exist'
    assert not cam.transport.is_open
    assert not any(th.name.startswith('visca-') for th in threading.enumerate())
    cam.close()


def test_position_round_trip_in_rep103_signs(emulator, camera):
    camera.move_to(0.3, 0.1)
    state = emulator.state()
    # REP 103 pan +0.3 rad (left) is VISCA pan -17.2 deg.
    assert state.pan_deg == pytest.approx(-17.19, abs=0.1)
    assert state.tilt_deg == pytest.approx(5.73, abs=0.1)
    assert camera.position() == pytest.approx((0.3, 0.1), abs=0.002)
    camera.move_by(-0.1, -0.2, speed_fraction=0.5)
    assert camera.position() == pytest.approx((0.2, -0.1), abs=0.003)
    camera.home()
    assert camera.position() == pytest.approx((0.0, 0.0), abs=1e-9)
    with pytest.raises(v.ViscaError, match='outside the travel'):
        camera.move_to(0.0, math.radians(30.0))


def test_drive_then_stop(emulator, camera):
    pan_speed, tilt_speed = camera.drive(0.5, -0.2)
    assert pan_speed == pytest.approx(math.radians(30.0))  # step 9 of 80/24 deg/s
    assert tilt_speed == pytest.approx(-math.radians(12.5))  # step 5 of 2.5 deg/s
    assert wait_until(lambda: emulator.state().pan_deg < -3.0)
    pan, tilt = camera.position()
    assert pan > math.radians(3.0) and tilt < 0.0
    camera.stop()
    settled = emulator.state()
    time.sleep(0.1)
    assert emulator.state().pan_deg == settled.pan_deg
    assert emulator.state().tilt_deg == settled.tilt_deg
    # One axis only: the other stays.
    camera.drive(0.0, 0.3)
    assert wait_until(lambda: emulator.state().tilt_deg > settled.tilt_deg + 1.0)
    camera.stop()
    assert emulator.state().pan_deg == settled.pan_deg


def test_drive_during_a_move_cancels_it_and_drives(emulator, camera):
    refused = emulator.stats.errors_by_code.get(v.ERROR_NOT_EXECUTABLE, 0)
    errors = []

    def blocked_move():
        try:
            camera.move_to(-1.5, 0.0, speed_fraction=0.2)
        except ViscaCancelled as exc:
            errors.append(exc)

    mover = threading.Thread(target=blocked_move)
    mover.start()
    assert wait_until(lambda: emulator.state().pan_deg > 2.0)  # moving right
    camera.drive(0.5, 0.0)
    mover.join(2.0)
    assert len(errors) == 1 and '04 FF' in str(errors[0])
    turned = emulator.state().pan_deg
    assert wait_until(lambda: emulator.state().pan_deg < turned - 3.0)  # now left
    camera.stop()
    # And with wait=False: the result says it was cancelled.
    move = camera.move_to(0.5, 0.0, wait=False)
    camera.drive(0.0, 0.2)
    assert wait_until(lambda: move.done)
    assert isinstance(move.error, ViscaCancelled)
    camera.stop()
    # The camera never had to refuse a drive.
    assert emulator.stats.errors_by_code.get(v.ERROR_NOT_EXECUTABLE, 0) == refused


def test_zoom(emulator, camera):
    camera.zoom_to(200, wait=True)
    assert camera.zoom() == 200
    camera.zoom_to(0)  # no wait: zoom_tele cancels it
    camera.zoom_tele(speed=7)
    assert wait_until(lambda: emulator.state().zoom_units > 300)
    camera.zoom_stop()
    held = camera.zoom()
    time.sleep(0.1)
    assert camera.zoom() == held
    camera.focus_auto()


def test_reset(emulator, camera):
    camera.move_to(0.2, 0.0)
    start = time.monotonic()
    camera.reset()
    assert time.monotonic() - start >= 0.45
    assert camera.position() == pytest.approx((0.0, 0.0), abs=1e-9)


def test_buffer_full_never_reached_by_normal_use(emulator, camera):
    errors = []
    stop = threading.Event()

    def poll():
        try:
            while not stop.is_set():
                camera.position()
                camera.zoom()
        except Exception as exc:  # noqa: B902 - reported below
            errors.append(exc)

    poller = threading.Thread(target=poll)
    poller.start()
    try:
        for i in range(6):
            camera.drive(0.3 * (-1) ** i, 0.1)
            camera.move_to(0.1 * i, 0.0, wait=False)
            camera.zoom_to(80 * i)
            camera.zoom_tele()
            camera.move_by(0.01, 0.0, wait=False)
            camera.zoom_to(40 * i)
        camera.stop()
        camera.zoom_stop()
    finally:
        stop.set()
        poller.join(5.0)
    assert errors == []
    assert v.ERROR_BUFFER_FULL not in emulator.stats.errors_by_code
    assert 'command buffer full' not in camera.transport.stats.errors
    # Every move was cancelled before the next motion command: nothing refused.
    assert camera.transport.stats.errors.get('command not executable', 0) == \
        emulator.stats.errors_by_code.get(v.ERROR_NOT_EXECUTABLE, 0)
    assert wait_until(lambda: camera.transport.sockets_in_use == [])


def test_errors_are_surfaced_with_the_bytes(emulator, camera):
    commands = emulator.stats.commands_received
    with pytest.raises(v.ViscaError, match='outside the travel'):
        camera.move_to(2.0, 0.0)
    assert emulator.stats.commands_received == commands  # refused before sending
    beyond = bytes((0x81, 0x01, 0x06, 0x02, 0x18, 0x14)) + v.encode_nibbles(0x400) \
        + v.encode_nibbles(0) + b'\xff'
    with pytest.raises(ViscaSyntaxError) as info:
        camera.transport.command(beyond)
    assert '90 60 02 FF' in str(info.value) and v.hex_bytes(beyond) in str(info.value)
    camera.power(False)
    with pytest.raises(ViscaNotExecutable, match='90 61 41 FF'):
        camera.drive(0.1, 0.0)
    camera.start(timeout_s=5.0)
    camera.drive(0.1, 0.0)
    camera.stop()


def test_garbage_and_garbled_replies_are_survived(emulator, camera):
    emulator.send_garbage(b'\x00\x13\x11\x0d\xa5\xff\x90')
    assert camera.position() == pytest.approx((0.0, 0.0), abs=1e-9)
    emulator.faults.garble_probability = 0.3
    failures = 0
    for i in range(15):
        try:
            camera.position()
            camera.drive(0.05 * (-1) ** i, 0.0)
        except v.ViscaError:
            failures += 1  # lost to garbling: VISCA has no checksum
    emulator.faults.clear()
    assert failures < 15
    assert wait_until(lambda: camera.ready, 3.0)
    camera.stop()
    camera.move_to(0.1, 0.0)
    assert camera.position() == pytest.approx((0.1, 0.0), abs=0.002)
    assert emulator.stats.replies_garbled > 0
    assert camera.transport.stats.junk_bytes > 0


def test_network_change_after_power_cycle_sets_the_address_again(emulator, camera):
    emulator.send_network_change()
    assert wait_until(lambda: camera.transport.stats.network_changes == 1)
    assert camera.position() == pytest.approx((0.0, 0.0), abs=1e-9)
    # A power cycle forgets the address: nothing answers until Address Set.
    emulator.power_cycle()
    assert wait_until(lambda: emulator.address == 1, 2.0)
    assert camera.transport.stats.network_changes == 2
    assert camera.position() is not None
    assert wait_until(lambda: not emulator.state().initialising, 2.0)
    camera.move_to(-0.1, 0.0)
    assert emulator.state().pan_deg == pytest.approx(5.73, abs=0.1)


def test_vanish_and_restore_recovers(emulator, camera):
    camera.move_to(0.2, 0.0)
    emulator.vanish()
    assert wait_until(lambda: not camera.connected, 1.0)
    assert not camera.ready
    start = time.monotonic()
    with pytest.raises(ViscaConnectionError):
        camera.position()
    with pytest.raises(ViscaConnectionError):
        camera.drive(0.1, 0.0)
    # At once, not after a reply timeout each (0.25 s here); the bound leaves
    # room for a test process waiting its turn beside a loaded test run.
    assert time.monotonic() - start < 0.2
    emulator.restore()
    assert wait_until(lambda: camera.ready, 5.0)
    assert camera.transport.stats.reconnects == 1
    assert camera.position() == pytest.approx((0.2, 0.0), abs=0.002)
    camera.drive(0.2, 0.0)
    camera.stop()


def test_silent_camera_is_reconnected_and_started_again(emulator, camera):
    emulator.stop_answering(True)
    for _ in range(2):
        with pytest.raises(ViscaTimeout):
            camera.position()  # each one retries once: 4 timeouts
    assert wait_until(lambda: camera.transport.stats.connection_losses >= 1, 2.0)
    emulator.stop_answering(False)
    assert wait_until(lambda: camera.ready, 5.0)
    assert camera.position() == pytest.approx((0.0, 0.0), abs=1e-9)


def test_position_and_drive_from_two_threads(emulator, camera):
    errors, polls, drives = [], [], []
    stop = threading.Event()

    def poll():
        while not stop.is_set():
            try:
                start = time.monotonic()
                camera.position()
                polls.append(time.monotonic() - start)
            except Exception as exc:  # noqa: B902 - reported below
                errors.append(exc)

    def drive():
        i = 0
        while not stop.is_set():
            try:
                camera.drive(0.2 * (-1) ** (i // 5), 0.0)
                drives.append(1)
            except Exception as exc:  # noqa: B902 - reported below
                errors.append(exc)
            i += 1
            time.sleep(0.02)

    threads = [threading.Thread(target=poll), threading.Thread(target=drive)]
    for th in threads:
        th.start()
    # Both threads make progress side by side (ten of each; about half a
    # second on an idle machine, longer beside a loaded test run).
    assert wait_until(lambda: len(polls) >= 10 and len(drives) >= 10, 10.0)
    stop.set()
    for th in threads:
        th.join(2.0)
    camera.stop()
    assert errors == []
    # One field (20 ms) per packet at 50 Hz plus the 9600 baud line: an
    # inquiry waits for a drive or two, never for a queue of them.
    assert sorted(polls)[len(polls) // 2] < 0.25
