"""VISCA codec: every packet byte-exact against the tables of design/visca.md."""

import random

from pattern_locator.visca import protocol as v
import pytest


def h(text: str) -> bytes:
    return bytes.fromhex(text)


@pytest.mark.parametrize('packet, expected', [
    (v.address_set(), '88 30 01 FF'),
    (v.if_clear(), '88 01 00 01 FF'),
    (v.cancel(1, 1), '81 21 FF'),
    (v.cancel(3, 2), '83 22 FF'),
    (v.pan_tilt_drive(1, 0x18, 0x14, v.PAN_LEFT, v.TILT_UP), '81 01 06 01 18 14 01 01 FF'),
    (v.pan_tilt_drive(1, 1, 1, v.PAN_RIGHT, v.TILT_DOWN), '81 01 06 01 01 01 02 02 FF'),
    (v.pan_tilt_stop(1), '81 01 06 01 01 01 03 03 FF'),
    (v.pan_tilt_absolute(1, 0x18, 0x14, -880, 300),
     '81 01 06 02 18 14 0F 0C 09 00 00 01 02 0C FF'),
    (v.pan_tilt_absolute(1, 1, 1, 880, -300),
     '81 01 06 02 01 01 00 03 07 00 0F 0E 0D 04 FF'),
    (v.pan_tilt_relative(2, 5, 6, -1, 1), '82 01 06 03 05 06 0F 0F 0F 0F 00 00 00 01 FF'),
    (v.pan_tilt_home(1), '81 01 06 04 FF'),
    (v.pan_tilt_reset(1), '81 01 06 05 FF'),
    (v.pan_tilt_limit_set(1, True, 880, 300), '81 01 06 07 00 01 00 03 07 00 00 01 02 0C FF'),
    (v.pan_tilt_limit_set(1, False, -880, -300),
     '81 01 06 07 00 00 0F 0C 09 00 0F 0E 0D 04 FF'),
    (v.pan_tilt_limit_clear(1, True), '81 01 06 07 01 01 07 0F 0F 0F 07 0F 0F 0F FF'),
    (v.pan_tilt_limit_clear(1, False), '81 01 06 07 01 00 07 0F 0F 0F 07 0F 0F 0F FF'),
    (v.zoom_stop(1), '81 01 04 07 00 FF'),
    (v.zoom_tele(1), '81 01 04 07 02 FF'),
    (v.zoom_wide(1), '81 01 04 07 03 FF'),
    (v.zoom_tele(1, 2), '81 01 04 07 22 FF'),
    (v.zoom_wide(1, 7), '81 01 04 07 37 FF'),
    (v.zoom_direct(1, 0x3FF), '81 01 04 47 00 03 0F 0F FF'),
    (v.zoom_direct(1, 0), '81 01 04 47 00 00 00 00 FF'),
    (v.focus_auto(1), '81 01 04 38 02 FF'),
    (v.focus_manual(1), '81 01 04 38 03 FF'),
    (v.power(1, True), '81 01 04 00 02 FF'),
    (v.power(1, False), '81 01 04 00 03 FF'),
    (v.inquiry_pan_tilt_position(1), '81 09 06 12 FF'),
    (v.inquiry_zoom_position(1), '81 09 04 47 FF'),
    (v.inquiry_power(1), '81 09 04 00 FF'),
    (v.inquiry_pan_tilt_max_speed(1), '81 09 06 11 FF'),
    (v.inquiry_pan_tilt_mode(1), '81 09 06 10 FF'),
    (v.inquiry_version(1), '81 09 00 02 FF'),
])
def test_commands_byte_exact(packet, expected):
    assert packet == h(expected)
    assert v.hex_bytes(packet) == expected


@pytest.mark.parametrize('packet, expected', [
    (v.ack(1, 1), '90 41 FF'),
    (v.ack(1, 2), '90 42 FF'),
    (v.completion(1, 2), '90 52 FF'),
    (v.answer(1, v.pan_tilt_position_payload(-880, 300)),
     '90 50 0F 0C 09 00 00 01 02 0C FF'),
    (v.answer(1, v.zoom_position_payload(0x3FF)), '90 50 00 03 0F 0F FF'),
    (v.answer(1, bytes((v.POWER_ON,))), '90 50 02 FF'),
    (v.error(1, 0, v.ERROR_MESSAGE_LENGTH), '90 60 01 FF'),
    (v.error(1, 0, v.ERROR_SYNTAX), '90 60 02 FF'),
    (v.error(1, 0, v.ERROR_BUFFER_FULL), '90 60 03 FF'),
    (v.error(1, 2, v.ERROR_CANCELLED), '90 62 04 FF'),
    (v.error(1, 1, v.ERROR_NO_SOCKET), '90 61 05 FF'),
    (v.error(1, 1, v.ERROR_NOT_EXECUTABLE), '90 61 41 FF'),
    (v.network_change(1), '90 38 FF'),
    (v.network_change(2), 'A0 38 FF'),
    (v.address_set_reply(2), '88 30 02 FF'),
])
def test_replies_byte_exact(packet, expected):
    assert packet == h(expected)


@pytest.mark.parametrize('text, kind, socket, extra', [
    ('90 41 FF', 'ack', 1, None),
    ('90 42 FF', 'ack', 2, None),
    ('90 51 FF', 'completion', 1, None),
    ('90 52 FF', 'completion', 2, None),
    ('90 50 02 FF', 'answer', 0, b'\x02'),
    ('90 60 02 FF', 'error', 0, 0x02),
    ('90 60 03 FF', 'error', 0, 0x03),
    ('90 61 04 FF', 'error', 1, 0x04),
    ('90 62 05 FF', 'error', 2, 0x05),
    ('90 61 41 FF', 'error', 1, 0x41),
    ('90 60 01 FF', 'error', 0, 0x01),
    ('90 38 FF', 'network_change', 0, None),
    ('88 30 02 FF', 'address_set', 0, b'\x02'),
    ('88 01 00 01 FF', 'if_clear', 0, None),
    ('A0 42 FF', 'ack', 2, None),
])
def test_parse_reply(text, kind, socket, extra):
    reply = v.parse_reply(h(text))
    assert (reply.kind, reply.socket) == (kind, socket)
    assert reply.raw == h(text)
    if kind == 'error':
        assert reply.code == extra
        assert v.ERROR_NAMES[extra] in reply.describe()
        assert text in reply.describe()
    elif extra is not None:
        assert reply.payload == extra
    assert reply.address == (2 if text.startswith('A0') else (0 if text[0] == '8' else 1))


@pytest.mark.parametrize('text', ['90 FF', '90 41', '10 41 FF', '90 70 FF', '88 31 FF',
                                  '90 41 00 00 00 00 00 00 00 00 00 00 00 00 00 00 FF'])
def test_malformed_replies_raise_naming_the_bytes(text):
    with pytest.raises(v.ViscaError, match=text.split()[0]):
        v.parse_reply(h(text))


def test_sign_handling_at_the_travel_limits():
    # FC90h is -880 and FED4h is -300: 0x10000 is subtracted, not 0xFFFF.
    assert v.parse_pan_tilt_position(h('0F 0C 09 00 0F 0E 0D 04')) == (-880, -300)
    assert v.parse_pan_tilt_position(h('00 03 07 00 00 01 02 0C')) == (880, 300)
    assert v.parse_pan_tilt_position(h('0F 0F 0F 0F 00 00 00 00')) == (-1, 0)
    assert v.decode_nibbles(h('07 0F 0F 0F')) == 0x7FFF
    assert v.decode_nibbles(h('08 00 00 00')) == -0x8000
    for value in range(-0x8000, 0x8000, 97):
        assert v.decode_nibbles(v.encode_nibbles(value)) == value
    assert v.decode_nibbles(h('0F 0F 0F 0F'), signed=False) == 0xFFFF


def test_angles_and_speeds():
    assert v.pan_units(100.0) == 880 and v.pan_units(-100.0) == -880
    assert v.tilt_units(25.0) == 300 and v.tilt_units(-25.0) == -300
    assert v.pan_degrees(-880) == pytest.approx(-100.0)
    assert v.tilt_degrees(12) == pytest.approx(1.0)
    assert v.pan_speed_deg_s(0x18) == pytest.approx(80.0)
    assert v.tilt_speed_deg_s(0x14) == pytest.approx(50.0)
    assert v.tilt_speed_deg_s(1) == pytest.approx(2.5)


@pytest.mark.parametrize('build, match', [
    (lambda: v.pan_tilt_drive(1, 0, 1, v.PAN_LEFT, v.TILT_UP), 'pan speed 0'),
    (lambda: v.pan_tilt_drive(1, 1, 0x15, v.PAN_LEFT, v.TILT_UP), 'tilt speed 21'),
    (lambda: v.pan_tilt_drive(1, 1, 1, 4, v.TILT_UP), 'pan direction 4'),
    (lambda: v.pan_tilt_absolute(1, 1, 1, 881, 0), 'pan position 881'),
    (lambda: v.pan_tilt_absolute(1, 1, 1, 0, -301), 'tilt position -301'),
    (lambda: v.zoom_direct(1, 0x400), 'zoom position 1024'),
    (lambda: v.zoom_tele(1, 8), 'zoom speed 8'),
    (lambda: v.cancel(1, 3), 'socket 3'),
    (lambda: v.pan_tilt_home(0), 'address 0'),
    (lambda: v.encode_nibbles(0x8000), 'does not fit'),
])
def test_out_of_range_values_raise(build, match):
    with pytest.raises(v.ViscaError, match=match):
        build()


def test_answer_parsers():
    assert v.parse_zoom_position(h('00 03 0F 0F')) == 0x3FF
    assert v.parse_power(b'\x02') is True and v.parse_power(b'\x03') is False
    assert v.parse_max_speed(h('18 14')) == (0x18, 0x14)
    assert v.parse_version(h('00 01 04 02 01 00 02')) == (0x0001, 0x0402, 0x0100, 2)
    for parse, payload in ((v.parse_zoom_position, b'\x00'), (v.parse_power, b'\x05'),
                           (v.parse_pan_tilt_position, b'\x00' * 7)):
        with pytest.raises(v.ViscaError):
            parse(payload)
    with pytest.raises(v.ViscaError, match='high nibble'):
        v.parse_pan_tilt_position(h('10 00 00 00 00 00 00 00'))
    assert v.is_inquiry(v.inquiry_power(1)) and not v.is_inquiry(v.pan_tilt_home(1))


STREAM = [v.ack(1, 1), v.ack(1, 2), v.answer(1, v.pan_tilt_position_payload(-880, 300)),
          v.completion(1, 2), v.error(1, 1, v.ERROR_CANCELLED), v.network_change(1),
          v.address_set_reply(2), v.completion(1, 1)]


def test_framer_byte_by_byte_and_in_random_chunks():
    data = b''.join(STREAM)
    framer = v.PacketFramer()
    packets = [p for byte in data for p in framer.feed(bytes((byte,)))]
    assert packets == STREAM
    rng = random.Random(3)
    for _ in range(50):
        framer = v.PacketFramer()
        packets, i = [], 0
        while i < len(data):
            n = rng.randint(1, 9)
            packets += framer.feed(data[i:i + n])
            i += n
        assert packets == STREAM


def test_framer_drops_junk_before_a_header_and_overlong_packets():
    framer = v.PacketFramer()
    junk = h('00 13 0D FF 11')
    assert framer.feed(junk + v.ack(1, 1)) == [v.ack(1, 1)]
    assert framer.junk_bytes == len(junk)
    assert framer.feed(h('90 50') + bytes(20)) == []
    assert framer.overlong_packets == 1
    assert framer.feed(bytes(3) + v.completion(1, 1)) == [v.completion(1, 1)]
