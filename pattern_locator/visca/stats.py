"""Counters of the VISCA transport: one thread-safe tally, snapshots as a frozen dataclass."""

import collections
from dataclasses import dataclass, field
import threading
from typing import Dict


@dataclass(frozen=True)
class TransportStats:
    """
    A snapshot of the transport's counters.

    ``bad_socket_replies``: ACKs, completions and errors naming a socket the
    camera does not have (ignored). ``expired_sockets``: commands whose
    completion never came, their socket taken as free after the command's
    longest time.
    """

    sent: int = 0
    replies: int = 0
    acks: int = 0
    completions: int = 0
    answers: int = 0
    errors: Dict[str, int] = field(default_factory=dict)
    timeouts: int = 0
    junk_bytes: int = 0
    bad_packets: int = 0
    unmatched: int = 0
    lost_completions: int = 0
    network_changes: int = 0
    buffer_full_resends: int = 0
    connection_losses: int = 0
    reconnects: int = 0
    bad_socket_replies: int = 0
    expired_sockets: int = 0


class Counters:
    """Named counts and error reply counts, shared by the transport's parts (thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts: 'collections.Counter[str]' = collections.Counter()
        self._errors: 'collections.Counter[str]' = collections.Counter()

    def add(self, name: str, amount: int = 1) -> None:
        """Count ``amount`` more of ``name``."""
        with self._lock:
            self._counts[name] += amount

    def add_error(self, name: str) -> None:
        """Count one more error reply of that name."""
        with self._lock:
            self._errors[name] += 1

    def get(self, name: str) -> int:
        """Return the count of ``name``."""
        with self._lock:
            return self._counts[name]

    def snapshot(self, junk_bytes: int) -> TransportStats:
        """Return the counts as :class:`TransportStats`."""
        with self._lock:
            c = self._counts
            return TransportStats(
                sent=c['sent'], replies=c['replies'], acks=c['acks'],
                completions=c['completions'], answers=c['answers'], errors=dict(self._errors),
                timeouts=c['timeouts'], junk_bytes=junk_bytes, bad_packets=c['bad_packets'],
                unmatched=c['unmatched'], lost_completions=c['lost_completions'],
                network_changes=c['network_changes'],
                buffer_full_resends=c['buffer_full_resends'],
                connection_losses=c['connection_losses'], reconnects=c['reconnects'],
                bad_socket_replies=c['bad_socket_replies'], expired_sockets=c['expired_sockets'])
