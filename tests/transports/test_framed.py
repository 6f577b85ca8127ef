"""The WebSocket writer's framing (``ws-frame-writer``) against the general write rule.

``websocket._framed`` is ``writes.coalesce``'s loop written out for frames, with
each header made once and a batch of small frames shared by the clients that
send it one after the other. It must give the writes ``coalesce`` gives for the
same frames, and those must be the RFC 6455 frames of each payload, in order.
"""

from __future__ import annotations

import struct

from hypothesis import given, settings
from hypothesis import strategies as st

from rwt_protocol.runtime.outbox import OutFrame
from rwt_transports import websocket
from rwt_transports.writes import WRITE_BATCH, coalesce

SIZES = st.one_of(
    st.integers(0, 200), st.sampled_from([125, 126, 65535, 65536]), st.integers(0, 3 * WRITE_BATCH)
)
FRAME = st.tuples(SIZES, st.booleans(), st.sampled_from([b"", b"\x01" * 13]))


def rfc6455(frame: OutFrame) -> bytes:
    """One whole unmasked server frame: FIN, opcode, the length's shortest form."""
    payload = frame.prefix + frame.data
    first = 0x82 if frame.binary else 0x81
    n = len(payload)
    if n < 126:
        return bytes((first, n)) + payload
    if n < 65536:
        return struct.pack("!BBH", first, 126, n) + payload
    return struct.pack("!BBQ", first, 127, n) + payload


def make(specs: list[tuple[int, bool, bytes]]) -> list[OutFrame]:
    return [
        OutFrame(bytes([i % 251]) * size, binary, prefix=prefix)
        for i, (size, binary, prefix) in enumerate(specs)
    ]


@settings(max_examples=150, deadline=None)
@given(st.lists(FRAME, max_size=12))
def test_framed_writes_are_coalesces_and_the_frames_themselves(
    specs: list[tuple[int, bool, bytes]],
) -> None:
    frames = make(specs)
    writes = websocket._framed(frames)
    expected = [rfc6455(frame) for frame in frames]
    assert b"".join(writes) == b"".join(expected)
    headed = [(rfc6455(f)[: -len(f.data)] if f.data else rfc6455(f), f.data, b"") for f in frames]
    assert writes == coalesce((head, data, tail) for head, data, tail in headed)
    # a second client sending the same frames (shared objects, headers kept) gets the same
    assert websocket._framed(frames) == writes
    assert websocket._framed(make(specs)) == writes  # equal frames made anew, too
