"""Emulated EVI-D31 on a pty, driven through real pyserial like the camera."""

import collections
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from pattern_locator.sim.sim_clock import ScaledClock
from pattern_locator.visca import protocol as visca
from pattern_locator.visca.emulator import EmulatedEviD31
from pattern_locator.visca.protocol import hex_bytes, PacketFramer
import pytest
import serial

ROOT = Path(__file__).resolve().parents[2]
FIELD_S = 0.02
# Slack for a loaded test machine on top of the modelled delays (upper
# bounds only; 0.06 s was exceeded with make test beside a benchmark).
SLACK_S = 0.2


class Link:
    """The host side: pyserial on the emulator's port plus a packet framer."""

    def __init__(self, path):
        self.serial = serial.Serial(path, 9600, timeout=0.05)
        self.framer = PacketFramer()
        self.packets = collections.deque()

    def close(self):
        self.serial.close()

    def send(self, packet):
        # Stamped before the write: the camera cannot act on a command before
        # it is written, so times measured from here are never short (stamped
        # after, a test thread descheduled for a millisecond on a busy
        # machine saw a zoom end 1 ms before its travel time).
        sent = time.monotonic()
        self.serial.write(packet)
        return sent

    def read(self, timeout=0.5):
        """Return the next packet, or None after ``timeout`` seconds of silence."""
        deadline = time.monotonic() + timeout
        while not self.packets and time.monotonic() < deadline:
            data = self.serial.read(max(1, self.serial.in_waiting))
            self.packets.extend(self.framer.feed(data))
        return self.packets.popleft() if self.packets else None

    def read_raw(self, duration):
        """Return every byte received during ``duration`` seconds."""
        data = bytearray()
        deadline = time.monotonic() + duration
        while time.monotonic() < deadline:
            data += self.serial.read(max(1, self.serial.in_waiting))
        return bytes(data)

    def expect(self, packet, timeout=0.5):
        got = self.read(timeout)
        assert got == packet, f'expected {hex_bytes(packet)}, got {got and hex_bytes(got)}'
        return time.monotonic()

    def quiet(self, duration=0.15):
        got = self.read(duration)
        assert got is None, f'unexpected {hex_bytes(got)}'

    def ask(self, packet, timeout=0.5):
        self.send(packet)
        got = self.read(timeout)
        assert got is not None, f'no answer to {hex_bytes(packet)}'
        return got

    def setup(self):
        self.send(visca.address_set())
        self.expect(bytes.fromhex('88 30 02 FF'))
        self.send(visca.if_clear())
        self.expect(bytes.fromhex('88 01 00 01 FF'))


def wait_for(condition, timeout, what):
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f'timed out waiting for {what}'
        time.sleep(0.005)


def ready(camera):
    wait_for(lambda: not camera.state().initialising, 2.0, 'the initialisation')


def position(link):
    return visca.parse_pan_tilt_position(
        visca.parse_reply(link.ask(visca.inquiry_pan_tilt_position(1))).payload)


def zoom(link):
    return visca.parse_zoom_position(
        visca.parse_reply(link.ask(visca.inquiry_zoom_position(1))).payload)


def h(text):
    return bytes.fromhex(text)


@pytest.fixture
def camera(tmp_path):
    with EmulatedEviD31(init_s=0.03, reset_s=0.3, link_path=str(tmp_path / 'ttyVISCA')) as cam:
        ready(cam)
        yield cam


@pytest.fixture
def link(camera):
    port = Link(camera.port)
    port.setup()
    yield port
    port.close()


# Start-up ------------------------------------------------------------------------------


def test_startup_address_set_if_clear_and_network_change(tmp_path):
    path = str(tmp_path / 'ttyVISCA')
    # Initialising long enough for the asks below on a loaded machine.
    with EmulatedEviD31(init_s=1.0, link_path=path) as cam:
        assert os.path.islink(path) and os.readlink(path).startswith('/dev/pts/')
        port = Link(cam.port)
        # Nothing addressed is answered before Address Set.
        # The power-up Network Change went out before the open, which flushed it.
        port.send(visca.inquiry_power(1))
        port.quiet(0.1)
        assert cam.address is None
        port.setup()
        assert cam.address == 1
        # Initialising: inquiries answered (power on), commands not executable.
        assert cam.state().initialising
        assert port.ask(visca.inquiry_power(1)) == h('90 50 02 FF')
        assert port.ask(visca.inquiry_pan_tilt_mode(1))[2] >> 4 == 0x1
        assert port.ask(visca.pan_tilt_home(1)) == h('90 61 41 FF')
        ready(cam)
        assert cam.state().pan_deg == 0.0 and cam.state().zoom_units == 0.0
        assert port.ask(visca.pan_tilt_home(1)) == h('90 41 FF')
        port.expect(h('90 51 FF'))
        # Another camera's packets are not for us.
        port.send(bytes((0x82, 0x09, 0x04, 0x00, 0xFF)))
        port.quiet(0.1)
        # Power-up again: Network Change, address forgotten until Address Set.
        cam.power_cycle()
        port.expect(h('90 38 FF'))
        assert cam.address is None
        port.send(visca.inquiry_power(1))
        port.quiet(0.1)
        port.setup()
        assert port.ask(visca.inquiry_power(1)) == h('90 50 02 FF')
        port.close()
    assert not os.path.lexists(path)


def test_inquiry_answers_byte_exact(link):
    assert link.ask(visca.inquiry_pan_tilt_position(1)) == h('90 50 00 00 00 00 00 00 00 00 FF')
    assert link.ask(visca.inquiry_zoom_position(1)) == h('90 50 00 00 00 00 FF')
    assert link.ask(visca.inquiry_power(1)) == h('90 50 02 FF')
    assert link.ask(visca.inquiry_pan_tilt_max_speed(1)) == h('90 50 18 14 FF')
    assert link.ask(visca.inquiry_pan_tilt_mode(1)) == h('90 50 20 00 FF')
    assert link.ask(visca.inquiry_version(1)) == h('90 50 00 01 04 02 02 01 02 FF')
    assert link.ask(h('81 09 04 38 FF')) == h('90 50 02 FF')
    assert visca.parse_version(visca.parse_reply(
        link.ask(visca.inquiry_version(1))).payload) == (0x0001, 0x0402, 0x0201, 2)
    # Addressed IF_Clear answers on socket 0.
    assert link.ask(h('81 01 00 01 FF')) == h('90 50 FF')


# Sockets, completions, errors ----------------------------------------------------------


def test_absolute_move_ack_then_completion_after_travel_time(link, camera):
    # 50 deg at 80 deg/s and 10 deg at 50 deg/s: pan decides, 0.625 s.
    sent = link.send(visca.pan_tilt_absolute(1, 0x18, 0x14, 440, -120))
    acked = link.expect(h('90 41 FF'))
    assert acked - sent < 15 * 1.04e-3 + FIELD_S + 3 * 1.04e-3 + SLACK_S
    assert camera.state().sockets_busy == (1,)
    done = link.expect(h('90 51 FF'), timeout=1.5)
    assert 0.625 < done - sent < 0.625 + 2 * FIELD_S + 0.02 + SLACK_S
    assert link.ask(visca.inquiry_pan_tilt_position(1)) == h('90 50 00 01 0B 08 0F 0F 08 08 FF')
    assert link.ask(visca.inquiry_pan_tilt_mode(1)) == h('90 50 28 00 FF')
    # Relative from there, then Home at full speed.
    link.send(visca.pan_tilt_relative(1, 0x18, 0x14, -40, 20))
    link.expect(h('90 41 FF'))
    link.expect(h('90 51 FF'), timeout=1.0)
    assert position(link) == (400, -100)
    sent = link.send(visca.pan_tilt_home(1))
    link.expect(h('90 41 FF'))
    done = link.expect(h('90 51 FF'), timeout=1.5)
    assert 400 / 704 < done - sent < 400 / 704 + 2 * FIELD_S + 0.02 + SLACK_S
    assert position(link) == (0, 0)


def test_two_sockets_buffer_full_cancel_and_no_socket(link, camera):
    link.send(visca.pan_tilt_absolute(1, 1, 1, 800, 200))
    link.expect(h('90 41 FF'))
    link.send(visca.zoom_direct(1, 0x3FF))
    link.expect(h('90 42 FF'))
    assert camera.state().sockets_busy == (1, 2)
    assert link.ask(visca.focus_auto(1)) == h('90 60 03 FF')
    assert link.ask(visca.inquiry_power(1)) == h('90 50 02 FF')
    # Cancel stops the motion; no completion follows.
    assert link.ask(visca.cancel(1, 1)) == h('90 61 04 FF')
    pan = camera.state().pan_deg
    assert 0.0 < pan < 5.0
    assert link.ask(visca.cancel(1, 1)) == h('90 61 05 FF')
    assert link.ask(visca.cancel(1, 2)) == h('90 62 04 FF')
    link.quiet(0.1)
    assert camera.state().pan_deg == pan and camera.state().sockets_busy == ()
    # Instant commands: ACK, then completion in the next field.
    sent = link.send(visca.focus_manual(1))
    link.expect(h('90 41 FF'))
    assert link.expect(h('90 51 FF')) - sent < 0.1 + SLACK_S
    assert link.ask(h('81 09 04 38 FF')) == h('90 50 03 FF')


def test_if_clear_empties_sockets_and_stops_motion(link, camera):
    link.send(visca.pan_tilt_absolute(1, 1, 1, 800, 200))
    link.expect(h('90 41 FF'))
    link.send(visca.zoom_tele(1))
    link.expect(h('90 42 FF'))
    link.expect(h('90 52 FF'))
    link.send(visca.if_clear())
    link.expect(h('88 01 00 01 FF'))
    link.quiet(0.1)
    first = camera.state()
    time.sleep(0.05)
    second = camera.state()
    assert first.sockets_busy == ()
    assert (first.pan_deg, first.zoom_units) == (second.pan_deg, second.zoom_units)
    assert first.zoom_units > 0


def test_drive_during_absolute_move_is_not_executable(link, camera):
    link.send(visca.pan_tilt_absolute(1, 2, 2, -500, 0))
    link.expect(h('90 41 FF'))
    assert link.ask(visca.pan_tilt_drive(1, 5, 5, visca.PAN_RIGHT, visca.TILT_STOP)) \
        == h('90 62 41 FF')
    assert link.ask(visca.pan_tilt_stop(1)) == h('90 62 41 FF')
    assert link.ask(visca.pan_tilt_home(1)) == h('90 62 41 FF')
    # Zoom is independent of the pan-tilt socket.
    assert link.ask(visca.zoom_direct(1, 0x100)) == h('90 42 FF')
    assert link.ask(visca.zoom_tele(1)) == h('90 60 03 FF')
    link.expect(h('90 52 FF'), timeout=1.0)
    assert link.ask(visca.zoom_tele(1)) == h('90 42 FF')
    link.expect(h('90 52 FF'))
    assert link.ask(visca.cancel(1, 1)) == h('90 61 04 FF')
    assert link.ask(visca.pan_tilt_stop(1)) == h('90 41 FF')
    link.expect(h('90 51 FF'))


def test_syntax_errors(link, camera):
    bad = [
        h('81 01 06 01 00 01 03 03 FF'),        # pan speed 00, even with stop
        h('81 01 06 01 01 00 03 03 FF'),        # tilt speed 00
        h('81 01 06 01 19 01 02 03 FF'),        # pan speed above 18h
        h('81 01 06 01 18 15 03 01 FF'),        # tilt speed above 14h
        h('81 01 06 01 01 01 04 03 FF'),        # pan direction 04
        h('81 01 06 01 01 01 03 00 FF'),        # tilt direction 00
        h('81 01 06 02 18 14 00 03 07 01 00 00 00 00 FF'),  # pan 881: outside travel
        h('81 01 06 02 18 14 00 00 00 00 00 01 02 0D FF'),  # tilt 301
        h('81 01 06 02 18 14 00 10 00 00 00 00 00 00 FF'),  # nibble byte above 0F
        h('81 01 06 02 18 14 00 00 00 FF'),     # too short
        h('81 01 04 47 00 04 00 00 FF'),        # zoom 400h
        h('81 01 04 07 21 FF'),                 # zoom speed 1
        h('81 01 04 07 28 FF'),                 # zoom speed 8
        h('81 01 7E 01 FF'),                    # unknown command
        h('81 09 7E 01 FF'),                    # unknown inquiry
        h('81 27 FF'),                          # cancel of socket 7
    ]
    for packet in bad:
        assert link.ask(packet) == h('90 60 02 FF'), hex_bytes(packet)
    assert camera.state().sockets_busy == () and camera.state().pan_deg == 0.0
    assert camera.stats.errors_by_code[visca.ERROR_SYNTAX] == len(bad)


def test_message_length_error(link, camera):
    link.send(bytes((0x81,)) + bytes(16) + bytes((0xFF,)))
    link.expect(h('90 60 01 FF'))
    link.quiet(0.1)
    assert link.ask(visca.inquiry_power(1)) == h('90 50 02 FF')
    assert camera.stats.errors_by_code == {visca.ERROR_MESSAGE_LENGTH: 1}


# Motion --------------------------------------------------------------------------------


def test_travel_limits_and_signs(link, camera):
    link.send(visca.pan_tilt_drive(1, 0x18, 0x14, visca.PAN_RIGHT, visca.TILT_UP))
    link.expect(h('90 41 FF'))
    link.expect(h('90 51 FF'))
    wait_for(lambda: camera.state().pan_units >= 880 - 1e-6, 1.25 + 0.5, 'the right end')
    time.sleep(0.05)
    state = camera.state()
    assert (state.pan_units, state.tilt_units) == pytest.approx((880, 300))
    assert (state.pan_deg, state.tilt_deg) == pytest.approx((100.0, 25.0))
    assert link.ask(visca.inquiry_pan_tilt_position(1)) == h('90 50 00 03 07 00 00 01 02 0C FF')
    assert link.ask(visca.inquiry_pan_tilt_mode(1)) == h('90 50 28 06 FF')
    # Back to 0 by a power cycle (quicker than driving across).
    camera.power_cycle()
    link.expect(h('90 38 FF'))
    ready(camera)
    link.setup()
    assert position(link) == (0, 0)
    link.send(visca.pan_tilt_drive(1, 0x18, 0x14, visca.PAN_LEFT, visca.TILT_DOWN))
    link.expect(h('90 41 FF'))
    link.expect(h('90 51 FF'))
    wait_for(lambda: camera.state().pan_units <= -880 + 1e-6, 1.25 + 0.5, 'the left end')
    assert link.ask(visca.inquiry_pan_tilt_position(1)) == h('90 50 0F 0C 09 00 0F 0E 0D 04 FF')
    assert position(link) == (-880, -300)
    assert link.ask(visca.inquiry_pan_tilt_mode(1)) == h('90 50 28 09 FF')


def test_limit_set_stops_drive_and_clamps_moves(link, camera):
    link.send(visca.pan_tilt_limit_set(1, True, 88, 24))
    link.expect(h('90 41 FF'))
    link.expect(h('90 51 FF'))
    link.send(visca.pan_tilt_drive(1, 0x18, 0x14, visca.PAN_RIGHT, visca.TILT_UP))
    link.expect(h('90 41 FF'))
    link.expect(h('90 51 FF'))
    wait_for(lambda: camera.state().pan_units >= 88 - 1e-9, 0.5, 'the pan limit')
    time.sleep(0.05)
    assert position(link) == (88, 24)
    # Clearing the limit lets the running drive go on to the end of travel.
    link.send(visca.pan_tilt_limit_clear(1, True))
    link.expect(h('90 41 FF'))
    link.expect(h('90 51 FF'))
    wait_for(lambda: camera.state().tilt_units >= 300 - 1e-9, 1.0, 'the tilt end')
    assert link.ask(visca.pan_tilt_stop(1)) == h('90 41 FF')
    link.expect(h('90 51 FF'))
    link.send(visca.pan_tilt_limit_set(1, False, -44, -12))
    link.expect(h('90 41 FF'))
    link.expect(h('90 51 FF'))
    link.send(visca.pan_tilt_absolute(1, 0x18, 0x14, -880, -300))
    link.expect(h('90 41 FF'))
    link.expect(h('90 51 FF'), timeout=2.0)
    assert position(link)[1] == -12
    assert position(link)[0] == -44


def test_pan_and_tilt_speeds_match_the_tables(link, camera):
    for pan_step, tilt_step in ((1, 1), (6, 5), (0x0C, 0x0A), (0x18, 0x14)):
        direction = visca.PAN_RIGHT if pan_step % 2 else visca.PAN_LEFT
        link.send(visca.pan_tilt_drive(1, pan_step, tilt_step, direction, visca.TILT_DOWN))
        link.expect(h('90 41 FF'))
        link.expect(h('90 51 FF'))
        first = camera.state()
        time.sleep(0.05)
        second = camera.state()
        dt = second.stamp - first.stamp
        pan_speed = abs(second.pan_deg - first.pan_deg) / dt
        tilt_speed = abs(second.tilt_deg - first.tilt_deg) / dt
        assert pan_speed == pytest.approx(visca.pan_speed_deg_s(pan_step), rel=1e-6)
        assert tilt_speed == pytest.approx(visca.tilt_speed_deg_s(tilt_step), rel=1e-6)
        # visca.md: about 3.3 deg/s per pan step and 2.5 deg/s per tilt step.
        assert pan_speed == pytest.approx(80.0 * pan_step / 24)
        assert tilt_speed == pytest.approx(2.5 * tilt_step)
        assert (second.pan_deg > first.pan_deg) == (direction == visca.PAN_RIGHT)
        assert second.tilt_deg < first.tilt_deg
    link.send(visca.pan_tilt_stop(1))
    link.expect(h('90 41 FF'))


def test_state_matches_inquiries_while_moving(link, camera):
    link.send(visca.pan_tilt_absolute(1, 0x0C, 0x0A, 600, 250))
    link.expect(h('90 41 FF'))
    link.send(visca.zoom_direct(1, 0x3FF))
    link.expect(h('90 42 FF'))
    for _ in range(3):
        before = camera.state()
        pan, tilt = position(link)
        after = camera.state()
        assert round(before.pan_units) <= pan <= round(after.pan_units)
        assert round(before.tilt_units) <= tilt <= round(after.tilt_units)
        before = camera.state()
        value = zoom(link)
        after = camera.state()
        assert round(before.zoom_units) <= value <= round(after.zoom_units)
        assert before.sockets_busy == (1, 2)
    assert after.pan_units > 0 and after.zoom_units > 0


def test_zoom_direct_timing_continuous_zoom_and_inquiry(link, camera):
    sent = link.send(visca.zoom_direct(1, 0x200))
    link.expect(h('90 41 FF'))
    done = link.expect(h('90 51 FF'), timeout=2.0)
    expected = 2.2 * 0x200 / 0x3FF
    assert expected < done - sent < expected + 2 * FIELD_S + 0.02 + SLACK_S
    assert link.ask(visca.inquiry_zoom_position(1)) == h('90 50 00 02 00 00 FF')
    assert camera.state().zoom_units == 0x200
    # Variable wide at p = 4: the full range in 2.2 * 7 / 4 s.
    link.send(visca.zoom_wide(1, 4))
    link.expect(h('90 41 FF'))
    link.expect(h('90 51 FF'))
    first = camera.state()
    time.sleep(0.1)
    second = camera.state()
    speed = (first.zoom_units - second.zoom_units) / (second.stamp - first.stamp)
    assert speed == pytest.approx(0x3FF / (2.2 * 7 / 4))
    assert link.ask(visca.zoom_stop(1)) == h('90 41 FF')
    link.expect(h('90 51 FF'))
    value = zoom(link)
    assert value == round(camera.state().zoom_units) and 0 < value < 0x200
    # Standard tele: the full range in 2.2 s; it stops at the end.
    link.send(visca.zoom_tele(1))
    link.expect(h('90 41 FF'))
    link.expect(h('90 51 FF'))
    first = camera.state()
    time.sleep(0.1)
    second = camera.state()
    speed = (second.zoom_units - first.zoom_units) / (second.stamp - first.stamp)
    assert speed == pytest.approx(0x3FF / 2.2)
    link.send(visca.zoom_direct(1, 0x3F0))
    link.expect(h('90 41 FF'))
    link.expect(h('90 51 FF'), timeout=1.5)
    link.send(visca.zoom_tele(1, 7))
    link.expect(h('90 41 FF'))
    link.expect(h('90 51 FF'))
    wait_for(lambda: camera.state().zoom_units >= 0x3FF, 0.5, 'full tele')
    time.sleep(0.03)
    assert link.ask(visca.inquiry_zoom_position(1)) == h('90 50 00 03 0F 0F FF')
    assert camera.state().zoom_units == 0x3FF


def test_reset_sweeps_through_the_ends_and_refuses_commands(tmp_path):
    # A sweep of 1.2 s: its ends pass at some 3,000 units a second, so the
    # samples below (every 2 ms, but tens of ms apart on a loaded machine)
    # still see them; at 0.3 s a 16 ms gap missed the end by 200 units.
    reset_s = 1.2
    with EmulatedEviD31(init_s=0.03, reset_s=reset_s,
                        link_path=str(tmp_path / 'ttyVISCA')) as camera:
        ready(camera)
        link = Link(camera.port)
        link.setup()
        try:
            link.send(visca.pan_tilt_absolute(1, 0x18, 0x14, 100, 50))
            link.expect(h('90 41 FF'))
            link.expect(h('90 51 FF'))
            sent = link.send(visca.pan_tilt_reset(1))
            link.expect(h('90 41 FF'))
            assert camera.state().initialising
            assert link.ask(visca.pan_tilt_drive(1, 1, 1, visca.PAN_LEFT, visca.TILT_STOP)) \
                == h('90 62 41 FF')
            assert link.ask(visca.inquiry_pan_tilt_mode(1))[2] == 0x14
            highest = lowest = 0.0
            while 1 in camera.state().sockets_busy:
                highest = max(highest, camera.state().pan_units)
                lowest = min(lowest, camera.state().pan_units)
                time.sleep(0.002)
            done = link.expect(h('90 51 FF'))
            assert reset_s < done - sent < reset_s + 2 * FIELD_S + 0.02 + SLACK_S
            assert highest > 700 and lowest < -700
            assert position(link) == (0, 0)
            assert not camera.state().initialising
        finally:
            link.close()


def test_power_off_and_on(link, camera):
    assert link.ask(visca.power(1, False)) == h('90 41 FF')
    link.expect(h('90 51 FF'))
    assert link.ask(visca.inquiry_power(1)) == h('90 50 03 FF')
    assert not camera.state().powered
    assert link.ask(visca.pan_tilt_home(1)) == h('90 61 41 FF')
    camera.init_s = 0.3
    assert link.ask(visca.power(1, True)) == h('90 41 FF')
    link.expect(h('90 51 FF'))
    assert camera.state().powered and camera.state().initialising
    assert link.ask(visca.pan_tilt_home(1)) == h('90 61 41 FF')
    ready(camera)
    assert link.ask(visca.pan_tilt_home(1)) == h('90 41 FF')


def test_ntsc_field_rate_paces_commands(tmp_path):
    with EmulatedEviD31(field_rate_hz=59.94, init_s=0.0, pace_output=False,
                        require_address_set=False) as cam:
        port = Link(cam.port)
        # Five inquiries at once are answered one per field.
        port.send(visca.inquiry_power(1) * 5)
        start = time.monotonic()
        for _ in range(5):
            port.expect(h('90 50 02 FF'))
        assert 3 / 59.94 < time.monotonic() - start < 5 / 59.94 + SLACK_S
        port.close()


def test_output_paced_at_9600_baud(link, camera):
    link.serial.timeout = 1.0
    # Timed from the send: a reader woken late by a loaded machine can only
    # make it longer, never shorter than the wire allows.
    start = time.monotonic()
    camera.send_garbage(bytes(100))
    received = link.serial.read(100)
    elapsed = time.monotonic() - start
    assert received == bytes(100)
    assert 99 * 1.04e-3 * 0.95 < elapsed < 100 * 1.04e-3 + SLACK_S


# Fault injection -----------------------------------------------------------------------


def test_dropped_garbled_and_delayed_replies(link, camera):
    expected = h('90 50 00 00 00 00 00 00 00 00 FF')
    camera.faults.drop_probability = 1.0
    link.send(visca.inquiry_pan_tilt_position(1))
    link.quiet(0.15)
    camera.faults.drop_probability = 0.0
    camera.faults.garble_probability = 1.0
    for _ in range(3):
        link.send(visca.inquiry_pan_tilt_position(1))
        assert link.read_raw(0.1) != expected
    camera.faults.garble_probability = 0.0
    link.framer.reset()
    link.packets.clear()
    camera.faults.delay_s = 0.3
    sent = link.send(visca.inquiry_pan_tilt_position(1))
    assert link.read(1.0) == expected
    assert time.monotonic() - sent > 0.3
    camera.faults.clear()
    assert link.ask(visca.inquiry_pan_tilt_position(1)) == expected
    stats = camera.stats
    assert (stats.replies_dropped, stats.replies_garbled) == (1, 3)


def test_wrong_socket_garbage_and_network_change(link, camera):
    camera.reply_to_wrong_socket_once()
    link.send(visca.pan_tilt_absolute(1, 0x18, 0x14, 88, 0))
    link.expect(h('90 42 FF'))
    link.expect(h('90 51 FF'))
    # The line is raw: every byte value arrives unchanged (0D, 11, 13 included).
    camera.send_garbage(bytes(range(256)))
    assert link.read_raw(0.6) == bytes(range(256))
    camera.send_network_change()
    link.expect(h('90 38 FF'))
    # Junk before a command does not hurt the camera's framing.
    link.send(h('00 11 13 0D FF') + visca.inquiry_power(1))
    link.expect(h('90 50 02 FF'))
    assert camera.stats.junk_bytes == 5


def test_vanish_and_restore_at_the_same_path(link, camera):
    path = camera.port
    link.send(visca.pan_tilt_drive(1, 0x0C, 0x0A, visca.PAN_RIGHT, visca.TILT_UP))
    link.expect(h('90 41 FF'))
    camera.vanish()
    assert not os.path.lexists(path)
    with pytest.raises(serial.SerialException):
        for _ in range(10):
            link.serial.write(visca.inquiry_power(1))
            link.serial.read(1)
    link.close()
    with pytest.raises(serial.SerialException):
        serial.Serial(path, 9600, timeout=0.1)
    # The head goes on moving while the adapter is away.
    moving = camera.state().pan_deg
    time.sleep(0.05)
    assert camera.state().pan_deg > moving
    camera.restore()
    assert os.path.islink(path)
    again = Link(path)
    # The camera kept its address: no Address Set needed (a driver sends it anyway).
    assert again.ask(visca.pan_tilt_stop(1)) == h('90 41 FF')
    again.expect(h('90 51 FF'))
    again.setup()
    assert position(again)[0] > 0
    again.close()


def test_stop_answering(link, camera):
    camera.stop_answering(True)
    link.send(visca.pan_tilt_drive(1, 0x18, 0x14, visca.PAN_RIGHT, visca.TILT_STOP))
    link.send(visca.inquiry_power(1))
    link.quiet(0.15)
    assert camera.state().pan_deg == 0.0
    camera.stop_answering(False)
    assert link.ask(visca.inquiry_power(1)) == h('90 50 02 FF')


# Command line --------------------------------------------------------------------------


def test_run_fake_camera_prints_its_port_and_stops_on_sigterm(tmp_path):
    path = tmp_path / 'ttyFAKE'
    code = ('import sys; from pattern_locator.visca.emulator import run_fake_camera; '
            "assert 'rclpy' not in sys.modules; "
            f'sys.exit(run_fake_camera({str(path)!r}, 0.05))')
    process = subprocess.Popen([sys.executable, '-c', code], cwd=ROOT, stdout=subprocess.PIPE,
                               text=True)
    try:
        line = process.stdout.readline()
        assert line == f'fake EVI-D31 on {path}\n'
        port = Link(str(path))
        port.setup()
        assert port.ask(visca.inquiry_power(1)) == h('90 50 02 FF')
        port.close()
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=5) == 0
        assert process.stdout.read() == ''
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert not path.exists()


def test_a_slowed_clock_slows_the_head_and_the_line(tmp_path):
    # A sim at half the wall's pace: the move's 0.625 s are 0.625 s of its
    # clock, 1.25 s of the wall; the camera's state is on its clock too.
    clock = ScaledClock(0.5)
    with EmulatedEviD31(init_s=0.03, link_path=str(tmp_path / 'ttyVISCA'), clock=clock,
                        clock_rate=clock.rate) as cam:
        ready(cam)
        port = Link(cam.port)
        port.setup()
        sent, sent_sim = port.send(visca.pan_tilt_absolute(1, 0x18, 0x14, 440, -120)), clock()
        port.expect(h('90 41 FF'), timeout=1.0)
        done = port.expect(h('90 51 FF'), timeout=3.0)
        assert 1.25 < done - sent < 1.25 + 2 * (2 * FIELD_S + 0.02) + SLACK_S
        state = cam.state()
        assert state.stamp > sent_sim + 0.625 and state.pan_deg == pytest.approx(50.0, abs=0.1)
        # 11 bytes of answer at 9600 baud: 11.5 ms of its clock, 23 ms of the wall.
        began = time.monotonic()
        port.ask(visca.inquiry_pan_tilt_position(1), timeout=1.0)
        assert time.monotonic() - began > 2 * 11 * 1.04e-3
        port.close()
    with pytest.raises(ValueError, match='clock rate'):
        EmulatedEviD31(clock_rate=0.0)
