"""aiortc's SCTP receive path, bounded below aiortc (docs/webrtc.md, "Limits"; D39).

aiortc hands a data channel's message over only once SCTP has reassembled it
whole, and until then holds its fragments (DATA chunks) however many come: a
peer that ignores the ``a=max-message-size`` of the answer could make the
server hold an 8 MB message (9 s of CPU: aiortc scans every held fragment for
each new one), or the start of one that never ends, past every bound of the
session. ``bound_sctp`` puts rwt's bounds below that, on the server's own SCTP
transports only (the peers of tests and of ``rwt_client`` keep aiortc's):

- a message is abandoned as it arrives once its fragments pass the largest
  message the server takes (``--max-message-size``, and never more than the
  256 KiB its answer states, aiortc's ``LOCAL_MAX_MESSAGE_SIZE``): the
  fragments held are freed, the rest of it is dropped as it comes, and
  ``on_oversized`` tells the session (which answers an error status, as for a
  message over the size that came whole). An ordered channel's later messages
  are delivered as if it had been.
- the fragments held over the association (messages incomplete, or complete
  behind a lost fragment) count at ``len(data) + CHUNK_OVERHEAD_BYTES`` each
  toward the session's inbox bound (``webrtc.INBOX_LIMIT_BYTES``, with what the
  session has not read), and at most ``MAX_HELD_CHUNKS`` of them (and as many
  TSNs received past a gap) may wait, on at most ``MAX_INBOUND_STREAMS`` streams;
  past any, ``on_overflow``: the peer is disconnected, as for an inbox overrun.
- aiortc reassembles only when a held fragment ends a message (it scanned
  them all for every fragment before), and ``_mark_received`` consolidates the
  cumulative TSN without sorting the received TSNs for each chunk.

The aiortc 1.16 internals this relies on (pyproject.toml pins the range; the
tests in ``tests/hardening/test_webrtc_sctp.py`` drive them with a real aiortc
peer): ``RTCPeerConnection.sctp`` is the transport, made by
``setRemoteDescription`` and started after the answer, so its class can be
swapped for ``BoundedSctpTransport`` (which adds attributes of its own only)
in between; ``RTCSctpTransport._get_inbound_stream`` makes each stream's
``InboundStream``, of which the transport uses ``add_chunk``,
``pop_messages``, ``prune_chunks`` and ``sequence_number`` only;
``_receive_data_chunk`` takes away ``len(chunk.user_data)`` from
``_advertised_rwnd`` for each new chunk and gives it back as messages are
delivered or pruned; ``_mark_received`` keeps ``_last_received_tsn``,
``_sack_misordered`` and ``_sack_duplicates``.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from aiortc.rtcsctptransport import (
    LOCAL_MAX_MESSAGE_SIZE,
    SCTP_DATA_FIRST_FRAG,
    SCTP_DATA_LAST_FRAG,
    SCTP_DATA_UNORDERED,
    InboundStream,
    RTCSctpTransport,
    tsn_plus_one,
)
from aiortc.utils import uint16_add, uint16_gt, uint32_gt, uint32_gte

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

    from aiortc.rtcsctptransport import DataChunk

__all__ = [
    "ANSWER_MAX_MESSAGE_SIZE",
    "CHUNK_OVERHEAD_BYTES",
    "MAX_HELD_CHUNKS",
    "MAX_INBOUND_STREAMS",
    "BoundedSctpTransport",
    "SctpBound",
    "bound_sctp",
    "incoming_message_limit",
]

logger = logging.getLogger("rwt.webrtc")

MAX_HELD_CHUNKS = 4096
"""SCTP fragments (DATA chunks) a peer connection holds before the session gets them, and
TSNs it keeps past a gap (for its SACKs), each; past either the peer is disconnected. A
peer that respects the answer's receive window (1 MiB) holds about 900 full ones."""

MAX_INBOUND_STREAMS = 256
"""SCTP streams (data channels) a peer connection receives on at once; past it the peer is
disconnected. The server keeps two channels and closes the others (their streams go)."""

CHUNK_OVERHEAD_BYTES = 256
"""What a held fragment costs beyond its data (aiortc's chunk object, its bytes' header,
its TSN in the SACK set), counted toward ``webrtc.INBOX_LIMIT_BYTES``."""


ANSWER_MAX_MESSAGE_SIZE: int = LOCAL_MAX_MESSAGE_SIZE
"""The ``a=max-message-size`` an answer states, bytes (256 KiB, aiortc's; the native stack's
answer states the same, native.py)."""


def incoming_message_limit(max_message_size: int) -> int:
    """The largest message the server's SCTP takes, bytes.

    ``--max-message-size``, at most the 256 KiB aiortc's answer states
    (``a=max-message-size``, RFC 8841).
    """
    return min(max_message_size, LOCAL_MAX_MESSAGE_SIZE)


class SctpBound:
    """What one peer connection's SCTP may hold, and whom it tells.

    Args:
        max_message_bytes: the largest message (``incoming_message_limit``).
        limit_bytes: bytes the fragments may hold together with ``inbox()``.
        inbox: bytes the session has not read yet (the data channel's inbox).
        on_oversized: called with the stream id of a message abandoned as too large.
        on_overflow: called once when the bounds are passed: disconnect the peer.
    """

    def __init__(
        self,
        max_message_bytes: int,
        limit_bytes: int,
        inbox: Callable[[], int],
        on_oversized: Callable[[int], None],
        on_overflow: Callable[[], None],
    ) -> None:
        self.max_message_bytes = max_message_bytes
        self.limit_bytes = limit_bytes
        self.inbox = inbox
        self.on_oversized = on_oversized
        self.on_overflow = on_overflow
        self.held_bytes = 0
        """Bytes the reassembly holds, each fragment's data and ``CHUNK_OVERHEAD_BYTES``."""
        self.held_chunks = 0
        self.cut = False
        """The bounds were passed: nothing more is held."""

    def over(self, misordered: int) -> bool:
        """Whether the fragments held (and ``misordered`` TSNs) pass the bounds."""
        if max(self.held_chunks, misordered) > MAX_HELD_CHUNKS:
            return True
        return self.held_bytes + self.inbox() > self.limit_bytes


class _BoundedStream(InboundStream):
    """One stream's reassembly (aiortc's), with the bounds of ``SctpBound``."""

    def __init__(self, bound: SctpBound, stream_id: int) -> None:
        super().__init__()
        self.bound = bound
        self.stream_id = stream_id
        self.released = 0
        """Bytes of chunks dropped or freed here that aiortc counted in its receive window."""
        self._lasts = 0  # held chunks that end a message: only they let one be popped
        self._ordered_sizes: dict[int, int] = {}  # stream sequence number -> bytes held
        self._runs: dict[int, tuple[int, int]] = {}  # unordered: next TSN -> (first, bytes)
        self._skipped: set[int] = set()  # ordered: abandoned messages not passed yet
        self._skipping: set[int] = set()  # unordered: the next TSN of an abandoned message

    def add_chunk(self, chunk: DataChunk) -> None:
        """Hold ``chunk`` for its message, unless that message was abandoned."""
        size = len(chunk.user_data)
        if self.bound.cut or self._abandoned(chunk):
            self.released += size
            return
        super().add_chunk(chunk)
        self._hold(1, size)
        if chunk.flags & SCTP_DATA_LAST_FRAG:
            self._lasts += 1
        first, total = self._message_bytes(chunk, size)
        if total > self.bound.max_message_bytes:
            self._abandon(chunk, first)

    def _abandoned(self, chunk: DataChunk) -> bool:
        """Whether ``chunk`` is dropped: of an abandoned message, or of one delivered.

        An ordered chunk whose stream sequence number is behind the stream's
        belongs to a message passed already (aiortc would deliver it again).
        """
        if not chunk.flags & SCTP_DATA_UNORDERED:
            seq = chunk.stream_seq
            return seq in self._skipped or uint16_gt(self.sequence_number, seq)
        if chunk.tsn not in self._skipping:
            return False
        self._skipping.discard(chunk.tsn)
        if not chunk.flags & SCTP_DATA_LAST_FRAG:
            self._skipping.add(tsn_plus_one(chunk.tsn))
        return True

    def _message_bytes(self, chunk: DataChunk, size: int) -> tuple[int, int]:
        """The first TSN and the bytes held of ``chunk``'s message.

        Unordered, a message is followed through its fragments in order; one
        ahead of its predecessors counts alone (the byte bound covers it).
        """
        if not chunk.flags & SCTP_DATA_UNORDERED:
            total = self._ordered_sizes.get(chunk.stream_seq, 0) + size
            self._ordered_sizes[chunk.stream_seq] = total
            return chunk.tsn, total
        first, total = chunk.tsn, size
        if not chunk.flags & SCTP_DATA_FIRST_FRAG and chunk.tsn in self._runs:
            first, held = self._runs.pop(chunk.tsn)
            total += held
        if not chunk.flags & SCTP_DATA_LAST_FRAG:
            self._runs[tsn_plus_one(chunk.tsn)] = (first, total)
        return first, total

    def _abandon(self, chunk: DataChunk, first: int) -> None:
        """Free the held fragments of ``chunk``'s message and drop the rest as it comes."""
        ended = bool(chunk.flags & SCTP_DATA_LAST_FRAG)
        if chunk.flags & SCTP_DATA_UNORDERED:
            self._runs.pop(tsn_plus_one(chunk.tsn), None)
            if not ended:
                self._skipping.add(tsn_plus_one(chunk.tsn))
            last = chunk.tsn

            def mine(c: DataChunk) -> bool:
                unordered = bool(c.flags & SCTP_DATA_UNORDERED)
                return unordered and uint32_gte(c.tsn, first) and uint32_gte(last, c.tsn)

        else:
            seq = chunk.stream_seq
            del self._ordered_sizes[seq]
            self._skipped.add(seq)  # passed once the messages before it are (pop_messages)

            def mine(c: DataChunk) -> bool:
                return not c.flags & SCTP_DATA_UNORDERED and c.stream_seq == seq

        freed = [c for c in self.reassembly if mine(c)]
        self.reassembly = [c for c in self.reassembly if not mine(c)]
        size = sum(len(c.user_data) for c in freed)
        self._lasts -= sum(1 for c in freed if c.flags & SCTP_DATA_LAST_FRAG)
        self._hold(-len(freed), -size)
        self.released += size
        self.bound.on_oversized(self.stream_id)

    def _hold(self, chunks: int, size: int) -> None:
        self.bound.held_chunks += chunks
        self.bound.held_bytes += size + chunks * CHUNK_OVERHEAD_BYTES

    def pop_messages(self) -> Iterator[tuple[int, int, bytes]]:
        """The messages now complete, in aiortc's order; past abandoned ordered ones."""
        while True:
            self._pass_abandoned()
            if not self._lasts:
                return  # no held chunk ends a message: none can be complete
            start, before, popped = self.sequence_number, len(self.reassembly), 0
            for message in super().pop_messages():
                popped += 1
                self.bound.held_bytes -= len(message[2])
                yield message
            self._lasts -= popped
            self._hold(len(self.reassembly) - before, 0)
            while start != self.sequence_number:  # ordered messages delivered
                self._ordered_sizes.pop(start, None)
                start = uint16_add(start, 1)
            if not popped or self.sequence_number not in self._skipped:
                return

    def _pass_abandoned(self) -> None:
        """Step the stream's sequence number past abandoned messages now due."""
        while self.sequence_number in self._skipped:
            self._skipped.discard(self.sequence_number)
            self.sequence_number = uint16_add(self.sequence_number, 1)

    def prune_chunks(self, tsn: int) -> int:
        """Prune as aiortc does (a FORWARD TSN), keeping the counts right."""
        before = self.reassembly
        size = super().prune_chunks(tsn)
        gone = before[: len(before) - len(self.reassembly)]
        self._lasts -= sum(1 for c in gone if c.flags & SCTP_DATA_LAST_FRAG)
        self._hold(-len(gone), -size)
        self._runs = {k: v for k, v in self._runs.items() if uint32_gt(k, tsn)}
        behind = self.sequence_number  # a FORWARD TSN moved it past the messages pruned
        self._ordered_sizes = {
            k: v for k, v in self._ordered_sizes.items() if not uint16_gt(behind, k)
        }
        self._skipping = {k for k in self._skipping if uint32_gt(k, tsn)}
        return size

    def drop_all(self) -> None:
        """Hold nothing more (the bounds were passed: the peer is being cut)."""
        self.reassembly = []
        self._lasts = 0
        self._ordered_sizes.clear()
        self._runs.clear()


class BoundedSctpTransport(RTCSctpTransport):
    """aiortc's SCTP transport with ``SctpBound``'s bounds (made by ``bound_sctp``)."""

    _rwt_bound: SctpBound

    def _get_inbound_stream(self, stream_id: int) -> InboundStream:
        streams = self._inbound_streams
        if stream_id not in streams:
            streams[stream_id] = _BoundedStream(self._rwt_bound, stream_id)
        return streams[stream_id]

    async def _receive_data_chunk(self, chunk: DataChunk) -> None:
        bound = self._rwt_bound
        streams = self._inbound_streams
        if chunk.stream_id not in streams and len(streams) >= MAX_INBOUND_STREAMS:
            self._cut()
        if bound.cut:
            return  # the peer is being disconnected: nothing more is held
        stream = self._get_inbound_stream(chunk.stream_id)
        await super()._receive_data_chunk(chunk)
        if isinstance(stream, _BoundedStream) and stream.released:
            self._advertised_rwnd += stream.released  # aiortc counted what was dropped
            stream.released = 0
        if bound.over(len(self._sack_misordered)):
            self._cut()

    def _cut(self) -> None:
        """The bounds were passed: free what is held, hold nothing more, tell the peers'."""
        bound = self._rwt_bound
        if bound.cut:
            return
        bound.cut = True
        bound.on_overflow()  # (it logs what was held)
        for held in self._inbound_streams.values():
            if isinstance(held, _BoundedStream):
                held.drop_all()
        self._sack_misordered.clear()
        bound.held_bytes = bound.held_chunks = 0

    def _mark_received(self, tsn: int) -> bool:
        """Mark ``tsn`` received as aiortc does, in time independent of the TSNs past a gap."""
        last = self._last_received_tsn
        if last is None:  # before the association's INIT: aiortc's own
            return super()._mark_received(tsn)
        misordered = self._sack_misordered
        if uint32_gte(last, tsn) or tsn in misordered:
            self._sack_duplicates.append(tsn)
            return True
        misordered.add(tsn)
        following = tsn_plus_one(last)
        while following in misordered:
            misordered.discard(following)
            last = following
            following = tsn_plus_one(following)
        if last != self._last_received_tsn:
            self._last_received_tsn = last
            self._sack_duplicates = [x for x in self._sack_duplicates if uint32_gt(x, last)]
        return False


def bound_sctp(transport: RTCSctpTransport, bound: SctpBound) -> BoundedSctpTransport:
    """Give ``transport`` (a peer connection's, before it starts) ``bound``'s bounds.

    Raises:
        RuntimeError: it has started receiving already.
    """
    if transport._inbound_streams:
        raise RuntimeError("bound_sctp: the SCTP transport received data already")
    transport.__class__ = BoundedSctpTransport
    assert isinstance(transport, BoundedSctpTransport)
    transport._rwt_bound = bound
    return transport
