"""
Property-based tests of the VISCA framer, parser and demultiplexer (hypothesis).

Any byte stream: nothing raises but ViscaError, no position or zoom outside
the camera's range comes out, no socket but 1 and 2 is ever booked, and the
stream re-synchronises after garbage.
"""

from hypothesis import given, settings, strategies as st
from pattern_locator.visca import protocol as v
from pattern_locator.visca.demux import Exchange, ReplyDemux
from pattern_locator.visca.sockets import SocketTable
from pattern_locator.visca.stats import Counters

ADDR = 1
PROPERTY = settings(max_examples=60, deadline=None, database=None)

# Replies a camera at address 1 can send (sockets 0..15 on purpose), and packets
# that look like them.
valid_replies = st.one_of(
    st.integers(0, 15).map(lambda s: v.ack(ADDR, s)),
    st.integers(1, 15).map(lambda s: v.completion(ADDR, s)),
    st.tuples(st.integers(0, 15), st.sampled_from([1, 2, 3, 4, 5, 0x41])).map(
        lambda a: v.error(ADDR, *a)),
    st.tuples(st.integers(-0x8000, 0x7FFF), st.integers(-0x8000, 0x7FFF)).map(
        lambda pt: v.answer(ADDR, v.encode_nibbles(pt[0]) + v.encode_nibbles(pt[1]))),
    st.integers(0, 0xFFFF).map(lambda z: v.answer(ADDR, v.encode_nibbles(z, signed=False))),
    st.just(v.network_change(ADDR)),
    st.just(v.address_set_reply(2)),
    st.just(v.if_clear()),
)
# Garbage: any bytes, with header-like and terminator bytes more often than chance.
garbage = st.lists(st.one_of(st.integers(0, 255), st.sampled_from([0x90, 0xFF, 0x50, 0x88])),
                   max_size=60).map(bytes)
streams = st.lists(st.one_of(valid_replies, garbage), max_size=12).map(b''.join)


def chunks(data: bytes, cuts) -> list:
    """Split ``data`` at the sorted positions ``cuts``."""
    edges = [0] + sorted(c % (len(data) + 1) for c in cuts) + [len(data)]
    return [data[a:b] for a, b in zip(edges, edges[1:])]


def in_range(pan: int, tilt: int) -> bool:
    return abs(pan) <= v.PAN_ANSWER_LIMIT_UNITS and abs(tilt) <= v.TILT_ANSWER_LIMIT_UNITS


@PROPERTY
@given(streams, st.lists(st.integers(0, 10 ** 6), max_size=8), st.booleans())
def test_framer_cuts_any_stream_into_well_formed_packets(data, cuts, resync):
    framer = v.PacketFramer(resync=resync)
    packets = [p for piece in chunks(data, cuts) for p in framer.feed(piece)]
    for packet in packets:
        assert 2 <= len(packet) <= v.MAX_PACKET
        assert packet[0] & 0x80 and packet[-1] == 0xFF
        assert 0xFF not in packet[:-1]
    # Every byte is either in a packet, counted as junk, or still waiting for its FF.
    assert sum(map(len, packets)) + framer.junk_bytes <= len(data)


@PROPERTY
@given(st.binary(max_size=20))
def test_parse_reply_raises_only_visca_error(packet):
    try:
        reply = v.parse_reply(packet)
    except v.ViscaError:
        return
    assert reply.raw == packet and reply.kind in (
        'ack', 'completion', 'answer', 'error', 'network_change', 'address_set', 'if_clear')


# Payloads: any bytes, and mostly-nibble bytes of the answers' own lengths.
payloads = st.one_of(st.binary(max_size=10), *(
    st.lists(st.integers(0, 0x10), min_size=n, max_size=n).map(bytes) for n in (4, 8)))


@PROPERTY
@given(payloads)
def test_position_and_zoom_answers_are_in_range_or_rejected(payload):
    try:
        pan, tilt = v.parse_pan_tilt_position(payload)
        assert in_range(pan, tilt)
    except v.ViscaReplyError:
        pass
    try:
        assert v.ZOOM_WIDE <= v.parse_zoom_position(payload) <= v.ZOOM_TELE
    except v.ViscaReplyError:
        pass


@PROPERTY
@given(garbage, valid_replies, valid_replies, st.lists(st.integers(0, 10 ** 6), max_size=5))
def test_framer_resynchronises_after_garbage(junk, first, second, cuts):
    # Whatever the garbage left half-framed, the first reply's FF ends it: the
    # second reply comes out exactly (with resync, often the first one too).
    framer = v.PacketFramer(resync=True)
    packets = [p for piece in chunks(junk + first + second, cuts) for p in framer.feed(piece)]
    assert packets[-1] == second
    assert v.parse_reply(packets[-1]).raw == second


def demux():
    counters = Counters()
    sockets = SocketTable(counters)
    return ReplyDemux(ADDR, sockets, counters, 1.0, lambda: None), sockets, counters


@PROPERTY
@given(streams, st.lists(st.integers(0, 10 ** 6), max_size=8),
       st.sampled_from(['inquiry', 'command', 'broadcast', 'cancel', None]))
def test_demux_survives_any_stream(data, cuts, waiting):
    mux, sockets, counters = demux()
    ex = None
    if waiting == 'inquiry':
        ex = Exchange('inquiry', v.inquiry_pan_tilt_position(ADDR), answer_length=8)
    elif waiting is not None:
        ex = Exchange(waiting, b'\x81\x01\x06\x04\xff', cancel_socket=1, expires_s=1.0)
    if ex is not None:
        mux.begin(ex)
    for piece in chunks(data, cuts):
        mux.feed(piece)
    # Only the camera's own sockets are ever booked.
    assert set(sockets.running()) <= {1, 2}
    if ex is not None and ex.event.is_set():
        assert ex.error is None or isinstance(ex.error, v.ViscaError)
        if ex.kind == 'inquiry' and ex.reply is not None:
            try:
                assert in_range(*v.parse_pan_tilt_position(ex.reply.payload))
            except v.ViscaReplyError:
                pass
        if ex.kind == 'command' and ex.result is not None:
            assert ex.result.socket in (1, 2)


@PROPERTY
@given(streams, st.tuples(st.integers(-880, 880), st.integers(-300, 300)),
       st.lists(st.integers(0, 10 ** 6), max_size=5))
def test_demux_takes_the_next_answer_exactly_once_an_ff_passed(data, position, cuts):
    mux, sockets, counters = demux()
    for piece in chunks(data + b'\xff', cuts):
        mux.feed(piece)
    ex = Exchange('inquiry', v.inquiry_pan_tilt_position(ADDR), answer_length=8)
    mux.begin(ex)
    answer = v.answer(ADDR, v.pan_tilt_position_payload(*position))
    mux.feed(answer)
    assert ex.event.is_set() and ex.reply.raw == answer
    assert v.parse_pan_tilt_position(ex.reply.payload) == position
