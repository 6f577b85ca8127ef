"""A WebRTC peer that sends past the answer's bounds: refused below aiortc (D39, docs/webrtc.md).

First a real aiortc client whose own SCTP is bent as an attacker's would be: it
ignores the server's ``a=max-message-size`` and withholds the last fragment of a
message, so the message never ends; the server's SCTP (webrtc/sctp.py) abandons it
as it arrives. Then the bounds one by one, on a real aiortc SCTP transport bounded
as the server's are and fed the DATA chunks of a hostile peer in process (aiortc's
SCTP takes a second to carry the thousands of packets a bound needs).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from struct import pack
from typing import Any

import pytest

from tests.webrtc.conftest import NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

from aiortc import (
    RTCCertificate,
    RTCDataChannel,
    RTCDtlsTransport,
    RTCIceGatherer,
    RTCIceTransport,
    RTCSctpTransport,
)
from aiortc.rtcsctptransport import SCTP_DATA_LAST_FRAG, DataChunk

from rwt_transports.server import ServerConfig
from rwt_transports.webrtc.channel import INBOX_LIMIT_BYTES
from rwt_transports.webrtc.sctp import MAX_HELD_CHUNKS, SctpBound, bound_sctp
from rwt_transports.webrtc.signalling import WebRtcOptions
from tests.support.clients import HAS_AIORTC
from tests.webrtc.peer import RtcClient, Served, peers_of, rtc_client, serving

pytestmark = [
    pytest.mark.anyio,
    pytest.mark.skipif(not HAS_AIORTC, reason="WebRTC needs an address besides loopback"),
]

MAX_MESSAGE = 64 * 1024


def withhold_last_fragment(client: RtcClient, size: int) -> None:
    """Make ``client``'s SCTP never send the last fragment of its messages of ``size``
    bytes, and send past the server's ``a=max-message-size``, as a hostile stack would."""
    sctp = client.pc.sctp
    assert sctp is not None
    transport = sctp
    transport._remote_max_message_size = 0  # no bound: aiortc's own refuses to send more
    send: Callable[..., Awaitable[None]] = transport._send

    async def send_all_but_last(
        stream_id: int, pp_id: int, data: bytes, *args: Any, **kw: Any
    ) -> None:
        await send(stream_id, pp_id, data, *args, **kw)
        if len(data) == size:  # its fragments are queued: the last one goes nowhere
            queue = transport._outbound_queue
            last = next(c for c in reversed(queue) if c.flags & SCTP_DATA_LAST_FRAG)
            queue.remove(last)

    transport._send = send_all_but_last  # type: ignore[method-assign,assignment]


def sctp_of(served: Served) -> RTCSctpTransport:
    (peer,) = peers_of(served.server).peers.values()
    assert peer.pc.sctp is not None
    return peer.pc.sctp


def held_bytes(served: Served) -> int:
    """Bytes of fragments the server's SCTP holds (aiortc's reassembly, all streams)."""
    streams = sctp_of(served)._inbound_streams.values()
    return sum(len(c.user_data) for s in streams for c in s.reassembly)


async def test_a_message_over_the_size_is_abandoned_as_it_arrives_and_never_held_whole() -> None:
    # it used to be held until its end, which never comes: no answer, and its bytes
    # held past every bound (17 MB for one of 17 MB)
    options = WebRtcOptions(stack="aiortc")  # the bound below aiortc's SCTP (D39)
    config = ServerConfig(port=0, max_message_size=MAX_MESSAGE, webrtc=options)
    size = 4 * MAX_MESSAGE
    async with serving(config) as served, rtc_client(served.base) as client:
        withhold_last_fragment(client, size)
        client.channel.send(b"\x00" * size)  # binary: CBOR's frame, never ending
        status = await client.next_op("status")
        assert status["level"] == "error"
        assert f"message larger than {MAX_MESSAGE} bytes skipped" in str(status["msg"])
        assert held_bytes(served) <= MAX_MESSAGE  # abandoned: what came of it is freed
        client.send({"op": "call_service", "service": "/rosapi/nodes", "id": "after"})
        reply = await client.next_op("service_response")  # the channel goes on past it
        assert reply["id"] == "after" and reply["result"] is True
        assert held_bytes(served) <= MAX_MESSAGE


@dataclass
class Fed:
    """A real aiortc SCTP transport, bounded as the server's are, fed DATA chunks in process.

    Its DTLS transport never starts: the chunks are what a hostile peer's packets
    would carry, handed to aiortc's own ``_receive_chunk``.
    """

    sctp: RTCSctpTransport
    bound: SctpBound
    messages: list[tuple[int, bytes]] = field(default_factory=list)
    oversized: list[int] = field(default_factory=list)
    overflows: int = 0
    tsn: int = 1000

    async def open(self, stream: int, *, ordered: bool = True) -> None:
        """Open a data channel on ``stream`` as a peer does (a DCEP OPEN message)."""
        kind = 0x00 if ordered else 0x80
        await self.chunk(stream, 0, pack("!BBHLHH", 3, kind, 0, 0, 1, 0) + b"x", pp_id=50)

    async def chunk(
        self,
        stream: int,
        seq: int,
        data: bytes,
        *,
        flags: int = 3,
        pp_id: int = 53,
        tsn: int | None = None,
    ) -> None:
        """One DATA chunk: ``flags`` 3 is a whole message (first and last fragment).

        Its TSN is the next one, or ``tsn`` (one skipped before, arriving late).
        """
        chunk = DataChunk(flags=flags)
        chunk.tsn, chunk.stream_id, chunk.stream_seq = tsn or self.tsn, stream, seq
        chunk.protocol, chunk.user_data = pp_id, data
        if tsn is None:
            self.tsn += 1
        await self.sctp._receive_chunk(chunk)


@pytest.fixture(name="fed")
async def fed_transport() -> Fed:
    dtls = RTCDtlsTransport(
        RTCIceTransport(RTCIceGatherer()), [RTCCertificate.generateCertificate()]
    )
    sctp = RTCSctpTransport(dtls)

    def oversized(stream: int) -> None:
        fed.oversized.append(stream)

    def overflow() -> None:
        fed.overflows += 1

    bound = SctpBound(SMALL_MESSAGE, INBOX_LIMIT_BYTES, lambda: 0, oversized, overflow)
    bound_sctp(sctp, bound)
    fed = Fed(sctp, bound)
    sctp._last_received_tsn = fed.tsn - 1  # as after the association's INIT

    @sctp.on("datachannel")
    def on_channel(channel: RTCDataChannel) -> None:
        assert channel.id is not None
        stream = channel.id
        channel.on("message", lambda data: fed.messages.append((stream, data)))

    return fed


SMALL_MESSAGE = 10_000
FIRST, MIDDLE, LAST = 2, 0, 1


async def test_abandoned_messages_are_passed_in_order_and_their_window_given_back(
    fed: Fed,
) -> None:
    await fed.open(1)
    await fed.chunk(1, 1, b"a" * 100, flags=FIRST)
    late = fed.tsn
    fed.tsn += 1  # the end of message 1 comes late
    await fed.chunk(1, 2, b"b" * 6000, flags=FIRST)
    await fed.chunk(1, 2, b"b" * 6000, flags=MIDDLE)  # over 10,000: abandoned
    await fed.chunk(1, 2, b"b" * 6000, flags=LAST)  # dropped as it comes
    await fed.chunk(1, 3, b"c", flags=FIRST | LAST)
    assert fed.oversized == [1] and not fed.messages  # 1 is not complete yet
    await fed.chunk(1, 1, b"a", flags=LAST, tsn=late)
    assert fed.messages == [(1, b"a" * 101), (1, b"c")]  # in order, past the abandoned one
    assert fed.bound.held_chunks == 0 and fed.bound.held_bytes == 0
    assert fed.sctp._advertised_rwnd == 1024 * 1024  # what was dropped is given back
    await fed.chunk(1, 2, b"late", flags=LAST)  # a straggler of a message passed
    await fed.chunk(1, 4, b"d")
    assert fed.messages[-1] == (1, b"d") and fed.bound.held_chunks == 0


async def test_an_unordered_message_over_the_size_is_abandoned(fed: Fed) -> None:
    await fed.open(3, ordered=False)
    unordered = 0x04
    await fed.chunk(3, 0, b"u" * 8000, flags=unordered | FIRST)
    await fed.chunk(3, 0, b"u" * 8000, flags=unordered | MIDDLE)
    await fed.chunk(3, 0, b"u" * 8000, flags=unordered | LAST)
    await fed.chunk(3, 0, b"small", flags=unordered | FIRST | LAST)
    assert fed.oversized == [3] and fed.messages == [(3, b"small")]
    assert fed.bound.held_chunks == 0


async def test_messages_held_behind_one_that_never_comes_cut_the_peer_at_the_count(
    fed: Fed,
) -> None:
    await fed.open(1)
    for seq in range(2, MAX_HELD_CHUNKS + 2):  # 1 never comes: all wait for it
        await fed.chunk(1, seq, b"m")
        assert fed.overflows == 0
    assert fed.bound.held_chunks == MAX_HELD_CHUNKS
    await fed.chunk(1, MAX_HELD_CHUNKS + 2, b"m")
    assert fed.overflows == 1 and fed.bound.cut
    assert not fed.sctp._inbound_streams[1].reassembly  # freed; nothing more is held
    await fed.chunk(1, 1, b"m")
    assert not fed.messages and fed.bound.held_chunks == 0


async def test_tsns_received_past_a_gap_count_toward_the_bound(fed: Fed) -> None:
    await fed.open(3, ordered=False)
    fed.tsn += 1  # one TSN never comes: every later one waits in the SACK's gap list
    for _ in range(MAX_HELD_CHUNKS):  # delivered at once (unordered), TSNs kept
        await fed.chunk(3, 0, b"u", flags=0x04 | FIRST | LAST)
    assert len(fed.messages) == MAX_HELD_CHUNKS and fed.overflows == 0
    await fed.chunk(3, 0, b"u", flags=0x04 | FIRST | LAST)
    assert fed.overflows == 1 and not fed.sctp._sack_misordered


async def test_never_ending_messages_on_many_streams_cut_the_peer_at_the_inbox_bound(
    fed: Fed,
) -> None:
    fed.bound.max_message_bytes = 256 * 1024  # the most any answer allows
    fragment = b"f" * 12_000  # a DTLS record holds up to 16 KiB
    per_message = fed.bound.max_message_bytes // len(fragment)
    streams = INBOX_LIMIT_BYTES // (per_message * len(fragment)) + 1
    for stream in range(streams):  # each message short of the size, and never ending
        for n in range(per_message):
            await fed.chunk(2 * stream, 0, fragment, flags=FIRST if n == 0 else MIDDLE)
            assert fed.bound.held_bytes <= INBOX_LIMIT_BYTES
    assert fed.overflows == 1 and not fed.oversized
