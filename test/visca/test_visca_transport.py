"""VISCA transport against a scripted peer on a pseudo-terminal: framing, matching, errors."""

import os
import random
import select
import threading
import time
import tty

from pattern_locator.visca import protocol as v
from pattern_locator.visca.transport import (CommandResult, ViscaBufferFull, ViscaCancelled,
                                             ViscaCommandError, ViscaConnectionError,
                                             ViscaMessageLengthError, ViscaNotExecutable,
                                             ViscaSyntaxError, ViscaTimeout, ViscaTransport)
import pytest
from ros_tools import wait_until
import serial

ADDR = 1
POSITION_ANSWER = v.answer(ADDR, v.pan_tilt_position_payload(-880, 300))
DRIVE = v.pan_tilt_drive(ADDR, 5, 5, v.PAN_LEFT, v.TILT_STOP)
HOME = v.pan_tilt_home(ADDR)
POSITION_INQ = v.inquiry_pan_tilt_position(ADDR)


def camera_reply(packet):
    """Return what a well-behaved idle camera answers to ``packet`` (socket 1)."""
    if packet == v.address_set():
        return v.address_set_reply(2)
    if packet == v.if_clear():
        return packet
    if packet == POSITION_INQ:
        return POSITION_ANSWER
    if packet == v.inquiry_zoom_position(ADDR):
        return v.answer(ADDR, v.zoom_position_payload(0x123))
    if v.is_inquiry(packet):
        return v.answer(ADDR, b'\x02')
    if packet[1] & 0xF0 == 0x20:
        return v.error(ADDR, packet[1] & 0x0F, v.ERROR_NO_SOCKET)
    return v.ack(ADDR, 1) + v.completion(ADDR, 1)


class Peer:
    """
    Play the camera on the master side of a pseudo-terminal.

    ``handler(peer, packet)`` runs for every complete packet received and
    answers through :meth:`send`; it returns bytes to send in one go, or None.
    """

    def __init__(self, handler=None, chunking='whole', seed=0):
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self.handler = handler or (lambda peer, packet: camera_reply(packet))
        self.chunking = chunking
        self.received = []
        self.rng = random.Random(seed)
        self._stop = threading.Event()
        self._closed = False
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        buffer = bytearray()
        while not self._stop.is_set():
            ready, _, _ = select.select([self.master], [], [], 0.02)
            if not ready:
                continue
            try:
                data = os.read(self.master, 256)
            except OSError:
                time.sleep(0.01)
                continue
            for byte in data:
                buffer.append(byte)
                if byte == 0xFF:
                    packet = bytes(buffer)
                    buffer.clear()
                    self.received.append(packet)
                    out = self.handler(self, packet)
                    if out:
                        self.send(out)

    def send(self, data, chunking=None):
        """Write ``data``: whole, byte by byte, or in random chunks."""
        chunking = chunking or self.chunking
        data = bytes(data)
        if chunking == 'whole':
            os.write(self.master, data)
            return
        i = 0
        while i < len(data):
            size = 1 if chunking == 'bytes' else self.rng.randint(1, 4)
            os.write(self.master, data[i:i + size])
            i += size
            time.sleep(0.001)

    def commands(self):
        """Return the received packets that are not inquiries or broadcasts."""
        return [p for p in self.received if p[0] != v.BROADCAST and not v.is_inquiry(p)]

    def vanish(self):
        """Close both ends: the device is gone."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        if not self._closed:
            self._closed = True
            for fd in (self.master, self.slave):
                try:
                    os.close(fd)
                except OSError:
                    pass

    close = vanish


class Rig:
    """Peers and transports made by a test, closed transports first."""

    def __init__(self):
        self.peers = []
        self.transports = []

    def peer(self, handler=None, chunking='whole'):
        p = Peer(handler, chunking)
        self.peers.append(p)
        return p

    def transport(self, port, **kwargs):
        kwargs.setdefault('reply_timeout_s', 0.3)
        kwargs.setdefault('completion_timeout_s', 2.0)
        t = ViscaTransport(port, **kwargs)
        self.transports.append(t)
        t.open()
        return t

    def close(self):
        for t in self.transports:
            t.close()
        for p in self.peers:
            p.close()


@pytest.fixture
def rig():
    r = Rig()
    yield r
    r.close()


def test_opens_the_line_raw_9600_8n1_without_flow_control(rig):
    peer = rig.peer()
    calls = []

    def factory(**kwargs):
        calls.append(kwargs)
        return serial.Serial(**kwargs)

    t = rig.transport(peer.path, serial_factory=factory)
    assert t.connected
    kw = calls[0]
    assert kw['baudrate'] == 9600 and kw['bytesize'] == 8 and kw['parity'] == 'N'
    assert kw['stopbits'] == 1
    assert not kw['xonxoff'] and not kw['rtscts'] and not kw['dsrdtr']
    assert kw['exclusive'] is True


def test_factory_without_exclusive_is_accepted(rig):
    peer = rig.peer()

    def factory(exclusive=None, **kwargs):
        if exclusive is not None:
            raise TypeError('no exclusive here')
        return serial.Serial(**kwargs)

    t = rig.transport(peer.path, serial_factory=factory)
    assert t.inquiry(POSITION_INQ).raw == POSITION_ANSWER


def test_open_failure_is_a_connection_error(tmp_path):
    t = ViscaTransport(str(tmp_path / 'no-such-port'))
    with pytest.raises(ViscaConnectionError, match='no-such-port'):
        t.open()
    assert not t.connected and not t.is_open
    with pytest.raises(ViscaConnectionError):
        t.inquiry(POSITION_INQ)


def test_broadcasts_come_back(rig):
    peer = rig.peer()
    t = rig.transport(peer.path)
    assert t.broadcast(v.address_set()).kind == 'address_set'
    assert t.broadcast(v.address_set()).payload == b'\x02'
    assert t.broadcast(v.if_clear()).kind == 'if_clear'
    assert peer.received == [v.address_set(), v.address_set(), v.if_clear()]


@pytest.mark.parametrize('chunking', ['whole', 'bytes', 'random'])
def test_inquiry_answer_in_any_chunking(rig, chunking):
    peer = rig.peer(chunking=chunking)
    t = rig.transport(peer.path)
    for _ in range(3):
        reply = t.inquiry(POSITION_INQ, answer_length=8)
        assert v.parse_pan_tilt_position(reply.payload) == (-880, 300)
    result = t.command(DRIVE)
    assert result.ok and result.socket == 1
    assert t.stats.junk_bytes == 0


def test_junk_before_a_header_is_dropped_and_counted(rig):
    def handler(peer, packet):
        # Low junk, a stray FF, and a high byte that looks like a header.
        return b'\x00\x13\x11\xff\x0d' + b'\xa5\xc3' + camera_reply(packet)

    peer = rig.peer(handler)
    t = rig.transport(peer.path)
    assert t.inquiry(POSITION_INQ).raw == POSITION_ANSWER
    assert t.stats.junk_bytes == 7
    assert t.command(DRIVE).ok


def test_ack_and_completion_concatenated_with_an_answer(rig):
    def handler(peer, packet):
        if packet == DRIVE:
            # ACK, a completion and an unrelated stray answer in one write.
            return v.ack(ADDR, 2) + v.completion(ADDR, 2) + POSITION_ANSWER
        return camera_reply(packet)

    peer = rig.peer(handler)
    t = rig.transport(peer.path)
    result = t.command(DRIVE)
    assert result.ok and result.socket == 2
    assert wait_until(lambda: t.stats.unmatched == 1)
    assert t.inquiry(POSITION_INQ).raw == POSITION_ANSWER


def test_completions_out_of_order_ack1_ack2_c2_c1(rig):
    first, second = HOME, DRIVE

    def handler(peer, packet):
        if packet == first:
            return v.ack(ADDR, 1)
        if packet == second:
            return v.ack(ADDR, 2) + v.completion(ADDR, 2)
        return camera_reply(packet)

    peer = rig.peer(handler, chunking='random')
    t = rig.transport(peer.path)
    r1 = t.command(first, wait=False)
    r2 = t.command(second, wait=False)
    assert (r1.socket, r2.socket) == (1, 2)
    r2.wait(1.0)
    assert not r1.done and t.sockets_in_use == [1]
    peer.send(v.completion(ADDR, 1))
    r1.wait(1.0)
    assert r1.ok and r2.ok and t.sockets_in_use == []
    assert r1.completion.raw == v.completion(ADDR, 1)


def test_inquiry_answered_between_ack_and_completion(rig):
    def handler(peer, packet):
        if packet == HOME:
            return v.ack(ADDR, 1)
        return camera_reply(packet)

    peer = rig.peer(handler)
    t = rig.transport(peer.path)
    move = t.command(HOME, wait=False)
    waiter = threading.Thread(target=move.wait, args=(2.0,), daemon=True)
    waiter.start()
    assert t.inquiry(POSITION_INQ).raw == POSITION_ANSWER
    assert t.inquiry(v.inquiry_zoom_position(ADDR), answer_length=4).payload == b'\x00\x01\x02\x03'
    assert not move.done
    peer.send(v.completion(ADDR, 1), chunking='bytes')
    waiter.join(2.0)
    assert move.ok


@pytest.mark.parametrize('reply, cls, text', [
    (v.error(ADDR, 0, v.ERROR_SYNTAX), ViscaSyntaxError, '90 60 02 FF'),
    (v.error(ADDR, 0, v.ERROR_MESSAGE_LENGTH), ViscaMessageLengthError, '90 60 01 FF'),
    (v.error(ADDR, 1, v.ERROR_NOT_EXECUTABLE), ViscaNotExecutable, '90 61 41 FF'),
    (v.ack(ADDR, 1) + v.error(ADDR, 1, v.ERROR_NOT_EXECUTABLE), ViscaNotExecutable,
     '90 61 41 FF'),
    (v.ack(ADDR, 2) + v.error(ADDR, 2, v.ERROR_CANCELLED), ViscaCancelled, '90 62 04 FF'),
])
def test_command_error_replies_raise_with_the_bytes(rig, reply, cls, text):
    peer = rig.peer(lambda peer, packet: reply if packet == HOME else camera_reply(packet))
    t = rig.transport(peer.path)
    with pytest.raises(cls) as info:
        t.command(HOME)
    assert isinstance(info.value, ViscaCommandError)
    assert text in str(info.value) and v.hex_bytes(HOME) in str(info.value)
    assert info.value.reply.raw in reply
    assert t.sockets_in_use == []
    # The line is still usable, and the error was not retried.
    assert t.command(DRIVE).ok
    assert peer.commands().count(HOME) == 1


def test_inquiry_error_reply_raises(rig):
    peer = rig.peer(lambda peer, packet: (v.error(ADDR, 0, v.ERROR_SYNTAX)
                                          if v.is_inquiry(packet) else None))
    t = rig.transport(peer.path)
    with pytest.raises(ViscaSyntaxError, match='90 60 02 FF'):
        t.inquiry(v.inquiry_version(ADDR))
    assert t.stats.errors == {'syntax error': 1}


def test_error_after_ack_of_a_detached_command_is_kept(rig):
    peer = rig.peer(lambda peer, packet: (v.ack(ADDR, 1) if packet == HOME
                                          else camera_reply(packet)))
    t = rig.transport(peer.path)
    move = t.command(HOME, wait=False)
    peer.send(v.error(ADDR, 1, v.ERROR_NOT_EXECUTABLE))
    assert wait_until(lambda: move.done)
    assert isinstance(move.error, ViscaNotExecutable) and not move.ok
    with pytest.raises(ViscaNotExecutable):
        move.wait(0.1)


def test_buffer_full_waits_for_a_completion_and_resends(rig):
    state = {'refused': False}

    def handler(peer, packet):
        if packet == HOME and not state['refused']:
            state['refused'] = True
            # Both sockets busy with commands we do not know of; one completes.
            peer.send(v.error(ADDR, 0, v.ERROR_BUFFER_FULL))
            time.sleep(0.05)
            return v.completion(ADDR, 2)
        return camera_reply(packet)

    peer = rig.peer(handler)
    t = rig.transport(peer.path)
    result = t.command(HOME)
    assert result.ok
    assert peer.commands() == [HOME, HOME]
    stats = t.stats
    assert stats.buffer_full_resends == 1 and stats.errors == {'command buffer full': 1}


def test_buffer_full_resends_are_bounded(rig):
    peer = rig.peer(lambda peer, packet: v.error(ADDR, 0, v.ERROR_BUFFER_FULL))
    t = rig.transport(peer.path, reply_timeout_s=0.1, max_resends=2)
    with pytest.raises(ViscaBufferFull, match='90 60 03 FF'):
        t.command(HOME)
    assert len(peer.commands()) == 3


def test_never_more_than_two_commands_outstanding(rig):
    acks = iter([1, 2, 1])
    peer = rig.peer(lambda peer, packet: (v.ack(ADDR, next(acks)) if packet == HOME
                                          else camera_reply(packet)))
    t = rig.transport(peer.path)
    r1 = t.command(HOME, wait=False)
    r2 = t.command(HOME, wait=False)
    assert t.sockets_in_use == [1, 2]
    with pytest.raises(ViscaTimeout, match='both camera sockets busy'):
        t.command(HOME, wait=False, timeout=0.2)
    assert len(peer.commands()) == 2
    # The third goes out as soon as a socket frees; inquiries are never held back.
    third = {}
    sender = threading.Thread(target=lambda: third.setdefault(
        'r', t.command(HOME, wait=False, timeout=2.0)), daemon=True)
    sender.start()
    assert t.inquiry(POSITION_INQ).raw == POSITION_ANSWER
    time.sleep(0.1)
    assert len(peer.commands()) == 2
    peer.send(v.completion(ADDR, 1))
    sender.join(2.0)
    assert isinstance(third['r'], CommandResult) and third['r'].socket == 1
    assert r1.ok and not r2.done and len(peer.commands()) == 3


def test_silence_times_out(rig):
    peer = rig.peer(lambda peer, packet: None)
    t = rig.transport(peer.path, reply_timeout_s=0.1, max_timeouts=5)
    start = time.monotonic()
    with pytest.raises(ViscaTimeout, match='no reply to 81 09 06 12 FF'):
        t.inquiry(POSITION_INQ)
    assert 0.09 < time.monotonic() - start < 0.5
    with pytest.raises(ViscaTimeout):
        t.command(HOME)
    assert t.stats.timeouts == 2 and t.connected and t.sockets_in_use == []


def test_completion_timeout(rig):
    peer = rig.peer(lambda peer, packet: v.ack(ADDR, 1) if packet == HOME else None)
    t = rig.transport(peer.path)
    with pytest.raises(ViscaTimeout, match='no completion for 81 01 06 04 FF on socket 1'):
        t.command(HOME, timeout=0.2)
    # A completion that shows up late is still booked against its socket.
    peer.send(v.completion(ADDR, 1))
    assert wait_until(lambda: t.sockets_in_use == [])
    assert t.stats.unmatched == 0


def test_cancel(rig):
    def handler(peer, packet):
        if packet == HOME:
            return v.ack(ADDR, 1)
        if packet == v.cancel(ADDR, 1):
            return v.error(ADDR, 1, v.ERROR_CANCELLED)
        return camera_reply(packet)

    peer = rig.peer(handler)
    t = rig.transport(peer.path)
    move = t.command(HOME, wait=False)
    assert t.cancel(1) is True
    assert isinstance(move.error, ViscaCancelled) and '90 61 04 FF' in str(move.error)
    assert t.sockets_in_use == []
    assert t.cancel(2) is False


def test_if_clear_empties_the_booked_sockets(rig):
    peer = rig.peer(lambda peer, packet: (v.ack(ADDR, 1) if packet == HOME
                                          else camera_reply(packet)))
    t = rig.transport(peer.path)
    move = t.command(HOME, wait=False)
    t.broadcast(v.if_clear())
    assert isinstance(move.error, ViscaCancelled) and t.sockets_in_use == []


def test_network_change_calls_back_on_a_thread_that_may_use_the_transport(rig):
    peer = rig.peer()
    replies = []
    box = {}

    def on_change():
        replies.append(box['t'].broadcast(v.address_set()))

    t = box['t'] = rig.transport(peer.path, on_network_change=on_change)
    peer.send(v.network_change(ADDR))
    assert wait_until(lambda: replies)
    assert replies[0].raw == v.address_set_reply(2)
    assert t.stats.network_changes == 1


def test_unsolicited_replies_are_counted_not_fatal(rig):
    peer = rig.peer()
    t = rig.transport(peer.path)
    peer.send(v.completion(ADDR, 2) + POSITION_ANSWER + v.error(ADDR, 1, v.ERROR_NO_SOCKET)
              + v.ack(3, 1) + v.completion(ADDR, 1))
    assert wait_until(lambda: t.stats.unmatched == 5)
    # An ACK nobody waited for books its socket until the completion frees it.
    peer.send(v.ack(ADDR, 2))
    assert wait_until(lambda: t.sockets_in_use == [2])
    peer.send(v.completion(ADDR, 2))
    assert wait_until(lambda: t.sockets_in_use == [])
    assert t.inquiry(POSITION_INQ).raw == POSITION_ANSWER
    assert t.command(DRIVE).ok and t.connected


def test_late_answer_of_another_kind_is_not_taken(rig):
    state = {'n': 0}

    def handler(peer, packet):
        state['n'] += 1
        if state['n'] == 1:
            return None  # the zoom inquiry gets no answer in time
        if state['n'] == 2:
            return v.answer(ADDR, v.zoom_position_payload(5)) + POSITION_ANSWER
        return camera_reply(packet)

    peer = rig.peer(handler)
    t = rig.transport(peer.path, reply_timeout_s=0.1)
    with pytest.raises(ViscaTimeout):
        t.inquiry(v.inquiry_zoom_position(ADDR), answer_length=4)
    assert t.inquiry(POSITION_INQ, answer_length=8).raw == POSITION_ANSWER


def test_concurrent_callers_are_serialised(rig):
    peer = rig.peer(chunking='random')
    t = rig.transport(peer.path)
    errors = []

    def work(kind):
        try:
            for _ in range(10):
                if kind == 'inquiry':
                    assert t.inquiry(POSITION_INQ, answer_length=8).raw == POSITION_ANSWER
                else:
                    assert t.command(DRIVE, wait=False).socket == 1
        except Exception as exc:  # noqa: B902 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(k,)) for k in ('inquiry', 'command') * 2]
    for th in threads:
        th.start()
    for th in threads:
        th.join(10.0)
    assert errors == []
    assert t.stats.sent == 40 and t.stats.unmatched == 0


def test_stops_answering_then_reconnects(rig):
    silent = threading.Event()
    silent.set()
    peer = rig.peer(lambda peer, packet: None if silent.is_set() else camera_reply(packet))
    reconnected = threading.Event()
    t = rig.transport(peer.path, reply_timeout_s=0.1, max_timeouts=2,
                      on_reconnect=reconnected.set)
    for _ in range(2):
        with pytest.raises(ViscaTimeout):
            t.inquiry(POSITION_INQ)
    assert not t.connected and 'did not answer 2 requests in a row' in t.last_error
    silent.clear()
    assert reconnected.wait(2.0)
    assert t.connected and t.inquiry(POSITION_INQ).raw == POSITION_ANSWER
    assert t.stats.reconnects == 1 and t.stats.connection_losses == 1


def test_vanish_fails_waiters_then_reconnects_at_the_same_path(rig, tmp_path):
    first = rig.peer(lambda peer, packet: (v.ack(ADDR, 1) if packet == HOME
                                           else camera_reply(packet)))
    link = tmp_path / 'camera'
    os.symlink(first.path, link)
    reconnects = []
    t = rig.transport(str(link), reconnect_max_s=0.4,
                      on_reconnect=lambda: reconnects.append(time.monotonic()))
    move = t.command(HOME, wait=False)
    blocked = {}

    def wait_move():
        try:
            move.wait(5.0)
        except v.ViscaError as exc:
            blocked['error'] = exc

    waiter = threading.Thread(target=wait_move, daemon=True)
    waiter.start()
    lost_at = time.monotonic()
    first.vanish()
    # As udev would: the link goes with the device (its pts number may be reused at once).
    os.remove(link)
    waiter.join(2.0)
    assert isinstance(blocked['error'], ViscaConnectionError)
    assert time.monotonic() - lost_at < 0.5
    assert wait_until(lambda: not t.connected, 1.0)
    start = time.monotonic()
    for call in (lambda: t.inquiry(POSITION_INQ), lambda: t.command(DRIVE),
                 lambda: t.broadcast(v.address_set()), lambda: t.cancel(1)):
        with pytest.raises(ViscaConnectionError, match='not connected'):
            call()
    # At once, not after a reply timeout (1 s) each: room for a test process
    # waiting its turn beside a loaded test run.
    assert time.monotonic() - start < 0.5
    time.sleep(0.5)  # a few failed attempts at the old path
    second = rig.peer()
    tmp_link = tmp_path / 'camera.new'
    os.symlink(second.path, tmp_link)
    os.replace(tmp_link, link)  # atomic re-pointing
    assert wait_until(lambda: t.connected and reconnects, 3.0)
    assert t.inquiry(POSITION_INQ).raw == POSITION_ANSWER
    assert t.command(DRIVE).ok
    assert t.stats.reconnects == 1 and t.stats.connection_losses == 1


def test_close_fails_waiters_and_joins_threads(rig):
    peer = rig.peer(lambda peer, packet: None)
    t = rig.transport(peer.path, reply_timeout_s=5.0)
    errors = []

    def ask():
        try:
            t.inquiry(POSITION_INQ)
        except ViscaConnectionError as exc:
            errors.append(exc)

    asker = threading.Thread(target=ask)
    asker.start()
    assert wait_until(lambda: peer.received)
    t.close()
    asker.join(1.0)
    assert len(errors) == 1 and not t.connected
    assert not any(th.name.startswith('visca-') and th.is_alive()
                   for th in threading.enumerate())
    t.close()  # idempotent
