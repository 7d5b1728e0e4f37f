"""
The driver's cycle (HeadLoop) on the emulated EVI-D31: positions first, health, stop.

Each finding of issue 10 that the cycle owns: joint states keep coming
whenever the camera answers positions (busy sockets, lost completions),
health is OK only while fresh positions flow and says why not, and stop()
ends any wait on the camera at once.
"""

import math
import threading
import time

from pattern_locator.tracking.controller import TrackingController, TrackingParams
from pattern_locator.tracking.head_loop import HeadLoop
from pattern_locator.visca import protocol as v
from pattern_locator.visca.camera import EviD31
from pattern_locator.visca.emulator import EmulatedEviD31
import pytest
from ros_tools import wait_until


@pytest.fixture
def emulator(tmp_path):
    with EmulatedEviD31(init_s=0.05, reset_s=0.3, link_path=str(tmp_path / 'evi')) as emu:
        yield emu


@pytest.fixture
def camera(emulator):
    cam = EviD31(emulator.port, reply_timeout_s=0.15)
    cam.start(timeout_s=5.0)
    yield cam
    cam.close()


def tracking_loop(camera, **kwargs) -> HeadLoop:
    return HeadLoop(camera, TrackingController(TrackingParams(control_period_s=0.05)),
                    zoom_every=3, **kwargs)


def cycle_tracking(loop: HeadLoop, count: int) -> list:
    """Run ``count`` cycles with a card swinging left and right (a new Drive each cycle)."""
    readings = []
    for k in range(count):
        loop.on_target(loop.clock(), 0.2 * (-1) ** k, 0.0, 100.0)
        readings.append(loop.cycle())
    return readings


def test_positions_come_every_cycle_while_both_sockets_are_busy(emulator, camera):
    loop = tracking_loop(camera)
    cycle_tracking(loop, 3)
    sent = loop.commands_sent
    # ACKs on both sockets that never complete (the fuzzer's finding), again and again.
    emulator.faults.phantom_ack_interval_s = 0.1
    assert wait_until(lambda: camera.transport.sockets_in_use == [1, 2])
    readings = cycle_tracking(loop, 12)
    assert all(r is not None for r in readings)          # a reading every cycle
    assert loop.errors['ViscaSocketsBusy'] >= 6          # commands skipped, not waited for
    assert camera.transport.stats.timeouts == 0
    health = loop.health()
    assert health.level_name == 'WARN' and 'sockets busy' in health.message
    # (test_visca_faults: the sockets are freed after the longest command time.)
    assert loop.commands_sent >= sent


def test_the_reading_is_handed_on_before_the_cycles_commands(camera):
    # The node publishes its joint state from on_reading. Published after the
    # Drive's ACK it came ~45 ms after its stamp, and a locator waiting 50 ms
    # for the joint state after an image mostly held the one before, from
    # before the head's last change of speed: fixes centimetres and many
    # sigmas off while the head slewed to a new card.
    handed = []
    loop = tracking_loop(camera, on_reading=lambda r: handed.append((r, loop.commands_sent)))
    for k in range(4):
        sent = loop.commands_sent
        loop.on_target(loop.clock(), 0.2 * (-1) ** k, 0.0, 100.0)
        reading = loop.cycle()
        assert handed[-1] == (reading, sent)            # before this cycle's Drive
        assert loop.commands_sent > sent                 # which was sent after it
    assert len(handed) == 4


def test_a_camera_deaf_to_commands_costs_one_reply_timeout_not_the_rate(emulator, camera):
    loop = tracking_loop(camera)
    cycle_tracking(loop, 2)
    emulator.faults.deaf_to_commands = True
    readings = cycle_tracking(loop, 8)
    assert all(r is not None for r in readings)
    # One Drive waited for its ACK; the commands then pause for refresh_s (1 s).
    assert loop.errors['ViscaTimeout'] == 1, (loop.errors, loop.commands_sent, loop.last_error)
    assert 'no reply' in loop.health().message


def test_error_only_replies_are_an_error_and_positions_return_at_once(emulator, camera):
    loop = HeadLoop(camera, None, stale_after_s=0.3)
    assert loop.cycle() is not None and loop.health().ok
    emulator.faults.error_only = v.ERROR_SYNTAX
    start = time.monotonic()
    while time.monotonic() - start < 0.4:
        assert loop.cycle() is None
    health = loop.health()
    assert health.level_name == 'ERROR' and camera.ready
    assert 'answers only error replies' in health.message and 'syntax error' in health.message
    emulator.faults.clear()
    assert loop.cycle() is not None                      # the first cycle after
    assert loop.health().level_name == 'WARN'            # fresh again, recent failures said


def test_silence_is_an_error_and_the_camera_comes_back(emulator, tmp_path):
    camera = EviD31(emulator.port, reply_timeout_s=0.1)
    camera.start(timeout_s=5.0)
    loop = HeadLoop(camera, None, stale_after_s=0.3)
    try:
        assert loop.cycle() is not None
        emulator.stop_answering(True)
        assert wait_until(lambda: loop.cycle() is None and not camera.ready, 3.0)
        health = loop.health()
        assert health.level_name == 'ERROR', health
        assert 'silent' in health.message or 'did not answer' in health.message, health
        emulator.stop_answering(False)
        assert wait_until(lambda: camera.ready, 2.0)
        assert loop.cycle() is not None
    finally:
        camera.close()


def test_a_vanished_port_is_an_error_that_names_it_and_recovers(emulator, camera):
    loop = HeadLoop(camera, None)
    assert loop.cycle() is not None
    emulator.vanish()
    assert wait_until(lambda: 'does not exist' in loop.health().message, 2.0)
    health = loop.health()
    assert health.level_name == 'ERROR' and emulator.port in health.message
    emulator.restore()
    assert wait_until(lambda: camera.ready, 2.0)
    assert loop.cycle() is not None and loop.health().level_name != 'ERROR'


def test_stop_ends_a_cycle_waiting_on_a_silent_camera(emulator, camera):
    loop = tracking_loop(camera)
    assert loop.cycle() is not None
    emulator.stop_answering(True)
    cycles = []

    def run():
        while not camera.closing:
            cycles.append(loop.cycle())

    runner = threading.Thread(target=run)
    runner.start()
    assert wait_until(lambda: emulator.stats.ignored_packets > 0)
    loop.stop()
    runner.join(1.0)
    assert not runner.is_alive() and cycles and cycles[-1] is None
    assert loop.cycle() is None
    health = loop.health()
    assert health.level_name == 'ERROR' and health.message == 'camera driver stopped'
    assert loop.request('home').wait(0.1) == (False, 'home refused: the camera driver is '
                                                     'stopping')
    loop.stop()  # idempotent


def test_home_runs_while_the_positions_keep_coming(emulator, camera):
    camera.move_to(0.6, 0.2)
    loop = tracking_loop(camera)
    request = loop.request('home')
    readings = []
    deadline = time.monotonic() + 3.0
    while not request.done.is_set() and time.monotonic() < deadline:
        readings.append(loop.cycle())
    assert request.wait(0.0) == (True, 'home done')
    # The head moved 0.6 rad at 80 deg/s: the cycles went on meanwhile.
    moving = [r for r in readings if r is not None and 0.05 < r.pan < 0.55]
    assert len(moving) >= 3 and all(r is not None for r in readings)
    assert loop.cycle().pan == pytest.approx(0.0, abs=math.radians(0.2))
