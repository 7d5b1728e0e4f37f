"""The emulator's units without a pty: motion model, device state, protocol handling, faults."""

from pattern_locator.errors import ConfigError
from pattern_locator.visca import protocol as v
from pattern_locator.visca.emulator_device import EmulatedDevice
from pattern_locator.visca.emulator_faults import BAD_POSITIONS, FaultInjector, Faults
from pattern_locator.visca.emulator_motion import HeadMotion
from pattern_locator.visca.emulator_protocol import (CommandSyntaxError, parse_command,
                                                     ViscaResponder)
import pytest


def h(text: str) -> bytes:
    return bytes.fromhex(text)


def test_motion_drive_stops_at_the_limit_and_replans_when_it_moves():
    head = HeadMotion()
    head.drive(0.0, 1, 704.0, 0, 0.0)          # right at 80 deg/s
    assert head.position(0.5) == (352.0, 0.0)
    head.set_limit(0.5, True, 400, 300)
    assert head.position(10.0)[0] == 400.0 and not head.pan_tilt_moving(10.0)
    head.clear_limit(10.0, True)                # the drive goes on to the end of travel
    assert head.position(20.0)[0] == v.PAN_LIMIT_UNITS
    assert head.end_flags(20.0) == 0x02
    head.move_to(20.0, -1000, 0, 704.0, 600.0)  # clamped into the travel
    assert head.position(30.0) == (-v.PAN_LIMIT_UNITS, 0.0)


def test_parse_command_checks_the_syntax():
    assert parse_command(h('01 06 01 18 14 01 02')).name == 'drive'
    assert parse_command(h('01 04 47 00 03 0F 0F')).args == (0x3FF,)
    for body in ('01 06 01 00 01 03 03', '01 06 02 18 14 00 03 07 01 00 00 00 00',
                 '01 04 07 28', '01 7E 01'):
        with pytest.raises(CommandSyntaxError):
            parse_command(h(body))


def test_responder_applies_the_rules_in_order():
    device = EmulatedDevice(init_s=0.0, reset_s=0.1, zoom_full_s=2.2, require_address_set=True)
    responder = ViscaResponder(device)
    device.power_up(0.0)
    assert responder.handle(v.inquiry_power(1), 0.0) == []        # no address yet
    assert responder.handle(v.address_set(), 0.0) == [h('88 30 02 FF')]
    assert responder.handle(v.pan_tilt_absolute(1, 1, 1, 800, 0), 0.0) == [h('90 41 FF')]
    assert responder.handle(v.zoom_direct(1, 0x3FF), 0.0) == [h('90 42 FF')]
    assert responder.handle(v.focus_auto(1), 0.0) == [h('90 60 03 FF')]   # buffer full
    assert responder.handle(v.cancel(1, 1), 0.1) == [h('90 61 04 FF')]
    assert responder.handle(v.pan_tilt_home(1), 0.1) == [h('90 41 FF')]
    assert responder.handle(v.cancel(1, 2), 0.1) == [h('90 62 04 FF')]
    # A socket is free, but a Drive while a pan-tilt move runs is not executable.
    assert responder.handle(v.pan_tilt_stop(1), 0.1) == [h('90 62 41 FF')]
    assert responder.completions(10.0) == [h('90 51 FF')]
    assert device.busy_sockets() == ()


def test_fault_injector_makes_the_broken_camera_of_issue_10():
    faults = Faults()
    injector = FaultInjector(faults, seed=1)
    assert injector.reply(v.completion(1, 1)) == (v.completion(1, 1), 0.0)
    faults.lose_completions = True
    assert injector.reply(v.completion(1, 1)) is None
    faults.bad_ack_socket_probability = 1.0
    sent, _ = injector.reply(v.ack(1, 2))
    assert sent[1] >> 4 == 0x4 and sent[1] & 0x0F not in (1, 2)
    faults.bad_position_probability = 1.0
    sent, _ = injector.reply(v.answer(1, v.pan_tilt_position_payload(10, 10)))
    assert sent[2:-1] in BAD_POSITIONS
    with pytest.raises(v.ViscaReplyError):
        v.parse_pan_tilt_position(sent[2:-1])
    faults.error_only = v.ERROR_SYNTAX
    assert injector.refusal(v.inquiry_power(1), 1) == (h('90 60 02 FF'),)
    assert injector.refusal(v.address_set(), 1) is None         # broadcasts pass
    faults.clear()
    assert injector.refusal(v.inquiry_power(1), 1) is None
    faults.deaf_to_commands = True
    assert injector.refusal(v.pan_tilt_home(1), 1) == ()
    assert injector.refusal(v.inquiry_power(1), 1) is None
    faults.clear()
    assert injector.counts['dropped'] == 1 and injector.counts['error_only'] == 1


def test_faults_from_a_command_line_spec():
    faults = Faults().apply('bad_position_probability=0.5, error-only=41,lose_completions=1')
    assert faults.bad_position_probability == 0.5 and faults.error_only == 0x41
    assert faults.lose_completions is True
    for spec, words in (('nonsense=1', "unknown fault 'nonsense'"),
                        ('drop_probability=2', "bad value '2'"),
                        ('error_only=zz', "bad value 'zz'"), ('clear=1', 'unknown fault')):
        with pytest.raises(ConfigError, match=words):
            Faults().apply(spec)
