"""
The camera's shutter over VISCA (issue 12): codec, emulated camera, driver.

The commands and the table are not in visca.md: Sony's EVI-D100 technical
manual, "Command List, D30/31 mode" (shutter table p. 43), and the standard
VISCA camera commands of Sony's EVI/FCB manuals.
"""

import math

from pattern_locator.errors import ConfigError
from pattern_locator.visca import protocol as v
from pattern_locator.visca.camera import EviD31
from pattern_locator.visca.emulator import EmulatedEviD31
from pattern_locator.visca.emulator_device import EmulatedDevice
from pattern_locator.visca.emulator_faults import FaultInjector, Faults
from pattern_locator.visca.emulator_protocol import (CommandSyntaxError, parse_command,
                                                     ViscaResponder)
from pattern_locator.visca.exposure import apply_shutter, ShutterRequest
import pytest
from ros_tools import wait_until
from test_visca_emulator import h, Link, ready

INIT_S = 0.15
PAL_1_250 = 0x09


def responder(auto_shutter_s=0.02):
    """Return a powered-up, addressed emulated camera without a pty (times in s)."""
    device = EmulatedDevice(init_s=0.0, reset_s=0.1, zoom_full_s=2.2, require_address_set=True,
                            auto_shutter_s=auto_shutter_s)
    device.power_up(0.0)
    r = ViscaResponder(device)
    assert r.handle(v.address_set(), 0.0) == [h('88 30 02 FF')]
    return r


def field(r, now=1.0):
    """Start the next video field; return the completions it sent."""
    return r.completions(now)


# Codec ---------------------------------------------------------------------------------


def test_table_is_the_d31s_and_the_d30s():
    assert v.SHUTTER_POSITION_MAX == 0x1B
    assert [v.shutter_denominator(p) for p in (0x00, 0x01, 0x09, 0x0F, 0x1A, 0x1B)] == \
        [50, 60, 250, 725, 6000, 10000]
    assert [v.shutter_denominator(p, 'ntsc') for p in (0x00, 0x01, 0x02, 0x1B)] == \
        [60, 60, 75, 10000]
    pal = [v.shutter_seconds(p) for p in range(0x1C)]
    assert all(a > b for a, b in zip(pal, pal[1:]))     # faster with each position
    assert v.describe_shutter(PAL_1_250) == '1/250 s'
    for bad in (-1, 0x1C):
        with pytest.raises(v.ViscaError, match='shutter position'):
            v.shutter_seconds(bad)
    with pytest.raises(v.ViscaError, match='video standard'):
        v.shutter_seconds(0, 'secam')


def test_nearest_position_in_log_scale():
    assert v.nearest_shutter_position(0.004) == PAL_1_250
    assert v.nearest_shutter_position(0.02) == 0x00
    assert v.nearest_shutter_position(0.008) == 0x05                   # 1/120, not 1/150
    # Between 1/4000 and 1/6000 the geometric mean decides.
    mean = math.sqrt(1 / 4000 * 1 / 6000)
    assert v.nearest_shutter_position(mean * 1.01) == 0x19
    assert v.nearest_shutter_position(mean / 1.01) == 0x1A
    assert v.nearest_shutter_position(0.02, 'ntsc') == 0x00           # 1/60: the lower one
    assert v.nearest_shutter_position(0.03) == 0x00                     # within 2x of 1/50
    for bad in (0.0, -0.004, 0.041, 1e-5, math.nan, math.inf):
        with pytest.raises(v.ViscaError, match='outside what the camera can do'):
            v.nearest_shutter_position(bad)


def test_builders_and_parsers_byte_exact():
    assert v.ae_mode(1, v.AE_SHUTTER_PRIORITY) == h('81 01 04 39 0A FF')
    assert v.ae_mode(2, v.AE_FULL_AUTO) == h('82 01 04 39 00 FF')
    assert v.shutter_direct(1, 0x1B) == h('81 01 04 4A 00 00 01 0B FF')
    assert v.shutter_direct(1, PAL_1_250) == h('81 01 04 4A 00 00 00 09 FF')
    assert v.inquiry_ae_mode(1) == h('81 09 04 39 FF')
    assert v.inquiry_shutter(1) == h('81 09 04 4A FF')
    assert v.shutter_position_payload(0x1A) == h('00 00 01 0A')
    assert v.parse_ae_mode(h('0A')) == v.AE_SHUTTER_PRIORITY
    assert v.parse_shutter_position(h('00 00 01 0B')) == 0x1B
    for bad in (0x01, 0x0C):
        with pytest.raises(v.ViscaError, match='exposure mode'):
            v.ae_mode(1, bad)
    with pytest.raises(v.ViscaError, match='shutter position'):
        v.shutter_direct(1, 0x1C)
    for payload in ('01', '0A 00', ''):
        with pytest.raises(v.ViscaReplyError):
            v.parse_ae_mode(h(payload))
    for payload in ('00 00 01 0C', '00 00 00', '00 00 10 00'):
        with pytest.raises(v.ViscaReplyError):
            v.parse_shutter_position(h(payload))


# The emulated camera without a pty -----------------------------------------------------


def test_emulator_parses_the_exposure_commands():
    assert parse_command(h('01 04 39 0A')).args == (v.AE_SHUTTER_PRIORITY,)
    assert parse_command(h('01 04 4A 00 00 01 0B')).args == (0x1B,)
    assert parse_command(h('01 04 0A 02')).name == 'shutter_step'
    for body in ('01 04 39 01', '01 04 39 0A 00', '01 04 4A 00 00 01 0C', '01 04 4A 00 00 00 10',
                 '01 04 4A 00 01 00 00', '01 04 4A 00 00 09', '01 04 0A 01'):
        with pytest.raises(CommandSyntaxError):
            parse_command(h(body))


def test_emulator_exposure_state_inquiries_and_fields():
    r = responder(auto_shutter_s=0.03)
    device = r.device
    assert device.state(0.0).shutter_s == 0.03                         # full auto
    assert r.handle(v.inquiry_ae_mode(1), 0.0) == [h('90 50 00 FF')]
    assert r.handle(v.inquiry_shutter(1), 0.0) == [h('90 50 00 00 00 00 FF')]
    # In full auto the position is kept, and the camera still picks the shutter.
    assert r.handle(v.shutter_direct(1, PAL_1_250), 0.0) == [h('90 41 FF')]
    assert field(r) == [h('90 51 FF')]
    assert device.state(1.0).shutter_s == 0.03
    # Shutter priority: the field being exposed keeps its shutter, the next one has it.
    assert r.handle(v.ae_mode(1, v.AE_SHUTTER_PRIORITY), 1.0) == [h('90 41 FF')]
    assert device.state(1.0).shutter_s == 0.03
    assert field(r) == [h('90 51 FF')]
    assert device.state(1.0).shutter_s == 1 / 250
    assert r.handle(v.inquiry_ae_mode(1), 1.0) == [h('90 50 0A FF')]
    assert r.handle(v.inquiry_shutter(1), 1.0) == [h('90 50 00 00 00 09 FF')]
    assert r.handle(v.shutter_direct(1, 0x1B), 1.0) == [h('90 41 FF')]
    assert device.state(1.0).shutter_s == 1 / 250
    field(r)
    assert device.state(1.0).shutter_s == 1 / 10000
    # Up stops at the fastest, down and reset go back.
    for command, expected in (('02', 0x1B), ('03', 0x1A), ('00', 0x00), ('03', 0x00),
                              ('02', 0x01)):
        assert r.handle(h(f'81 01 04 0A {command} FF'), 1.0) == [h('90 41 FF')]
        field(r)
        assert device.shutter_position == expected
        assert device.state(1.0).shutter_s == v.shutter_seconds(expected)
    # Manual uses the position too; iris priority and bright let the camera pick.
    for mode, expected in ((v.AE_MANUAL, 1 / 60), (v.AE_IRIS_PRIORITY, 0.03),
                           (v.AE_BRIGHT, 0.03), (v.AE_SHUTTER_PRIORITY, 1 / 60)):
        r.handle(v.ae_mode(1, mode), 1.0)
        field(r)
        assert device.state(1.0).shutter_s == expected, mode


def test_emulator_refuses_bad_values_and_states():
    r = responder()
    device = r.device
    # Bad values: the syntax error the emulator gives any bad value; nothing changes.
    for packet in ('81 01 04 4A 00 00 01 0C FF', '81 01 04 39 05 FF', '81 01 04 0A 04 FF'):
        assert r.handle(h(packet), 0.0) == [h('90 60 02 FF')], packet
    field(r)
    assert (device.ae_mode, device.shutter_position) == (v.AE_FULL_AUTO, 0)
    # Standby and the initialisation refuse them like any other command.
    r.handle(v.power(1, False), 0.0)
    field(r)
    assert r.handle(v.ae_mode(1, v.AE_SHUTTER_PRIORITY), 0.0) == [h('90 61 41 FF')]
    assert r.handle(v.inquiry_ae_mode(1), 0.0) == [h('90 50 00 FF')]  # answered in standby
    device.init_s = 5.0
    r.handle(v.power(1, True), 0.0)
    field(r)
    assert r.handle(v.shutter_direct(1, 3), 1.0) == [h('90 61 41 FF')]
    assert device.state(1.0).shutter_s == 0.02


def test_standby_keeps_the_exposure_and_power_up_returns_to_full_auto():
    r = responder()
    device = r.device
    r.handle(v.ae_mode(1, v.AE_SHUTTER_PRIORITY), 0.0)
    field(r, 0.0)
    r.handle(v.shutter_direct(1, PAL_1_250), 0.0)
    field(r, 0.0)
    r.handle(v.power(1, False), 0.0)
    field(r, 0.0)
    r.handle(v.power(1, True), 0.0)
    field(r, 0.0)
    assert device.state(0.0).shutter_s == 1 / 250
    r.handle(v.pan_tilt_reset(1), 0.0)                                  # pan-tilt only
    assert device.state(0.0).shutter_s == 1 / 250
    device.power_up(1.0)
    assert device.state(1.0).shutter_s == 0.02
    assert (device.ae_mode, device.shutter_position) == (v.AE_FULL_AUTO, 0)


def test_fault_refuse_exposure_answers_only_the_exposure_packets():
    faults = Faults().apply('refuse_exposure=2')
    assert faults.refuse_exposure == v.ERROR_SYNTAX
    injector = FaultInjector(faults, seed=0)
    assert injector.refusal(v.ae_mode(1, v.AE_SHUTTER_PRIORITY), 1) == (h('90 60 02 FF'),)
    assert injector.refusal(v.inquiry_shutter(1), 1) == (h('90 60 02 FF'),)
    assert injector.refusal(h('81 01 04 0A 02 FF'), 1) == (h('90 60 02 FF'),)
    assert injector.refusal(v.zoom_direct(1, 0x10), 1) is None
    assert injector.refusal(v.inquiry_zoom_position(1), 1) is None
    faults.refuse_exposure = v.ERROR_NOT_EXECUTABLE
    assert injector.refusal(v.shutter_direct(1, 2), 1) == (h('90 61 41 FF'),)
    with pytest.raises(ConfigError, match='refuse_exposure'):
        Faults().apply('refuse_exposure=zz')


def test_auto_shutter_must_be_a_time():
    for bad in (-0.01, math.nan, 2.0):
        with pytest.raises(ValueError, match='auto exposure time'):
            EmulatedEviD31(auto_shutter_s=bad)
    # 0 is the sim's idealised instant exposure (sim_node exposure_s:=0).
    EmulatedEviD31(auto_shutter_s=0.0)


# The emulated camera over the pty ----------------------------------------------------------


@pytest.fixture
def emulator(tmp_path):
    with EmulatedEviD31(init_s=INIT_S, link_path=str(tmp_path / 'evi-d31'),
                        auto_shutter_s=0.025) as emu:
        yield emu


def test_emulator_over_the_pty_byte_exact(emulator):
    ready(emulator)
    link = Link(emulator.port)
    try:
        link.setup()
        assert emulator.state().shutter_s == 0.025
        assert link.ask(v.ae_mode(1, v.AE_SHUTTER_PRIORITY)) == h('90 41 FF')
        link.expect(h('90 51 FF'))
        assert link.ask(h('81 01 04 4A 00 00 01 03 FF')) == h('90 41 FF')
        link.expect(h('90 51 FF'))
        # The completion goes out in the field that applies the new shutter.
        assert emulator.state().shutter_s == 1 / 1500
        assert link.ask(v.inquiry_shutter(1)) == h('90 50 00 00 01 03 FF')
        assert link.ask(v.inquiry_ae_mode(1)) == h('90 50 0A FF')
        assert link.ask(h('81 01 04 4A 00 00 01 0C FF')) == h('90 60 02 FF')
        assert emulator.state().shutter_s == 1 / 1500
        emulator.power_cycle()
        assert emulator.state().shutter_s == 0.025
        assert link.read() == h('90 38 FF')
    finally:
        link.close()


# The driver (real pyserial on the emulator's pty) ----------------------------------------


def test_shutter_request_validation():
    assert ShutterRequest.from_seconds(0.0) is None
    request = ShutterRequest.from_seconds(0.0041)
    assert (request.position, request.describe()) == (PAL_1_250, '1/250 s')
    assert request.speed_s == 1 / 250
    assert ShutterRequest.from_seconds(0.018, 'ntsc').describe() == '1/60 s'
    with pytest.raises(v.ViscaError, match='outside'):
        ShutterRequest.from_seconds(1e-6)
    with pytest.raises(v.ViscaError, match='video standard'):
        ShutterRequest.from_seconds(0.0, 'secam')
    with pytest.raises(v.ViscaError, match='outside'):
        EviD31('/dev/null-never-opened', shutter_s=-1.0)


def test_driver_sets_the_shutter_and_sets_it_again_after_a_power_cycle(emulator):
    camera = EviD31(emulator.port, reply_timeout_s=0.25, completion_timeout_s=5.0,
                    shutter_s=0.004)
    try:
        camera.start(timeout_s=5.0)
        assert emulator.state().shutter_s == 1 / 250
        report = camera.exposure
        assert report.applied and camera.exposure_count == 1
        assert (report.mode, report.position, report.shutter_s) == (
            v.AE_SHUTTER_PRIORITY, PAL_1_250, 1 / 250)
        assert report.message == 'shutter 1/250 s (shutter priority)'
        assert camera.ae_mode() == v.AE_SHUTTER_PRIORITY
        assert camera.shutter_position() == PAL_1_250
        # A power cycle: the camera comes up in full auto; the driver sets the shutter
        # again once the initialisation lets it.
        emulator.power_cycle()
        assert emulator.state().shutter_s == 0.025
        assert wait_until(lambda: camera.exposure_count == 2, 5.0)
        assert camera.exposure.applied
        assert emulator.state().shutter_s == 1 / 250
        assert not emulator.state().initialising
        # A reconnect runs the start-up, shutter included.
        emulator.vanish()
        assert wait_until(lambda: not camera.connected, 2.0)
        emulator.restore()
        assert wait_until(lambda: camera.ready and camera.exposure_count == 3, 5.0)
        assert camera.exposure.applied
    finally:
        camera.close()


def test_a_camera_that_refuses_the_shutter_is_tracked_all_the_same(emulator):
    emulator.faults.refuse_exposure = v.ERROR_SYNTAX
    camera = EviD31(emulator.port, reply_timeout_s=0.25, completion_timeout_s=5.0,
                    shutter_s=0.001)
    try:
        camera.start(timeout_s=5.0)
        assert camera.ready
        report = camera.exposure
        assert not report.applied and report.shutter_s is None
        assert report.message.startswith('the camera refused the shutter 1/1000 s (syntax '
                                         'error to 81 01 04 39 0A FF)'), report.message
        assert emulator.state().shutter_s == 0.025
        camera.move_to(0.1, 0.0)
        assert camera.position() == pytest.approx((0.1, 0.0), abs=0.002)
        # The same camera without the fault: the shutter is set and read back.
        emulator.faults.refuse_exposure = None
        assert apply_shutter(camera, camera.shutter_request).applied
        assert emulator.state().shutter_s == 1 / 1000
    finally:
        camera.close()


def test_shutter_zero_leaves_the_camera_alone(emulator):
    camera = EviD31(emulator.port, reply_timeout_s=0.25)
    try:
        camera.start(timeout_s=5.0)
        emulator.power_cycle()
        assert wait_until(lambda: emulator.address == 1, 2.0)
        assert camera.shutter_request is None and camera.exposure is None
        assert camera.exposure_count == 0
        assert camera.ae_mode() == v.AE_FULL_AUTO
        assert emulator.state().shutter_s == 0.025
    finally:
        camera.close()
