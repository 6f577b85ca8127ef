"""The stream framers (D22, D24): any chunking gives the same frames; bounded; never raise."""

from __future__ import annotations

import itertools
import json
import re

import cbor2
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rwt_protocol.framing import streams as framing
from rwt_protocol.framing.datagrams import fragment_datagrams
from rwt_protocol.framing.streams import (
    FramerEvent,
    FramingError,
    InFrame,
    JsonStreamFramer,
    LineFramer,
)

LIMIT = 1 << 20


def feed(framer: JsonStreamFramer | LineFramer, chunks: list[bytes]) -> list[FramerEvent]:
    events: list[FramerEvent] = []
    for chunk in chunks:
        events += framer.receive_data(chunk)
    return events + framer.receive_eof()


def split(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts})
    edges = [0, *points, len(data)]
    return [data[a:b] for a, b in itertools.pairwise(edges)]


tricky_strings = st.text(
    alphabet=st.sampled_from(list('{}[]"\\ \n\t:,abcé€😀\x00\x1f')), max_size=30
)
json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | tricky_strings,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(tricky_strings, inner, max_size=4),
    max_leaves=12,
)
ops = st.dictionaries(tricky_strings, json_values, max_size=5).map(lambda d: {"op": "x", **d})
separators = st.sampled_from([b"", b" ", b"\n", b"\r\n", b"\t \n "])


@settings(max_examples=150, deadline=None)
@given(
    messages=st.lists(ops, min_size=1, max_size=6),
    seps=st.lists(separators, min_size=6, max_size=6),
    cuts=st.lists(st.integers(min_value=0), max_size=12),
)
def test_any_split_of_concatenated_json_gives_the_same_ops(
    messages: list[dict[str, object]], seps: list[bytes], cuts: list[int]
) -> None:
    data = b"".join(
        json.dumps(m, ensure_ascii=bool(i % 2), indent=2 if i % 3 == 0 else None).encode() + seps[i]
        for i, m in enumerate(messages)
    )
    whole = feed(JsonStreamFramer(LIMIT), [data])
    pieces = feed(JsonStreamFramer(LIMIT), split(data, cuts))
    assert whole == pieces
    assert [json.loads(e.data) for e in pieces if isinstance(e, InFrame)] == messages


@settings(max_examples=100, deadline=None)
@given(
    items=st.lists(
        st.one_of(ops.map(lambda m: (m, True)), ops.map(lambda m: (m, False))), max_size=5
    ),
    cuts=st.lists(st.integers(min_value=0), max_size=8),
)
def test_cbor_items_and_json_interleave_in_any_split(
    items: list[tuple[dict[str, object], bool]], cuts: list[int]
) -> None:
    data = b"".join(cbor2.dumps(m) if binary else json.dumps(m).encode() for m, binary in items)
    events = feed(JsonStreamFramer(LIMIT), split(data, cuts))
    decoded = [
        (cbor2.loads(e.data) if e.binary else json.loads(e.data), e.binary)
        for e in events
        if isinstance(e, InFrame)
    ]
    assert decoded == items


def test_cbor_with_indefinite_lengths_tags_and_floats_is_one_frame() -> None:
    item = (
        b"\xbf"  # indefinite map
        b"\x62op\x67publish"
        b"\x63msg\x9f\x01\xf9\x3c\x00\xfb\x40\x09\x21\xfb\x54\x44\x2d\x18\xff"  # indefinite array
        b"\x64data\xd8\x48\x5f\x42\x01\x02\x41\x03\xff"  # tag 72 around an indefinite byte string
        b"\xff"
    )
    events = JsonStreamFramer(LIMIT).receive_data(item + b'{"op":"next"}')
    assert events == [InFrame(item, binary=True), InFrame(b'{"op":"next"}')]
    assert cbor2.loads(item)["op"] == "publish"


@pytest.mark.parametrize(
    "item",
    [
        b"\x9f\xff",  # empty indefinite array
        b"\x81\xff",  # a break where an item belongs counts as that item
        b"\x9f\x1f\xff",  # an indefinite integer (invalid) inside
        b"\x9f\xdf\xff",  # an indefinite tag (invalid) inside
        b"\x9f\x1c\xff",  # a reserved additional-info byte (invalid) inside
        b"\x80",  # empty array
        b"\xa1\x60\x40",  # {"": b""}
    ],
)
def test_cbor_edge_items_end_where_the_header_says(item: bytes) -> None:
    events = JsonStreamFramer(LIMIT).receive_data(item + b"{}")
    assert events[-1] == InFrame(b"{}")
    assert all(isinstance(e, InFrame) and e.binary for e in events[:-1])
    assert b"".join(e.data for e in events[:-1] if isinstance(e, InFrame)) in (item, item[:-1])


def test_non_json_tokens_become_frames_of_their_own() -> None:
    data = b'5 true "op" ["id"] } xyz{"op":"a"}null'
    events = feed(JsonStreamFramer(LIMIT), [data])
    assert [e.data for e in events if isinstance(e, InFrame)] == [
        b"5",
        b"true",
        b'"op"',
        b'["id"]',
        b"}",
        b"xyz",
        b'{"op":"a"}',
        b"null",
    ]


def test_braces_and_escaped_quotes_inside_strings_do_not_end_an_object() -> None:
    message = {"op": "publish", "msg": {"data": 'a}"{b\\"}\\\\', "x": "]["}}
    data = json.dumps(message).encode()
    for size in (1, 2, 3, 7):
        chunks = [data[i : i + size] for i in range(0, len(data), size)]
        [event] = feed(JsonStreamFramer(LIMIT), chunks)
        assert isinstance(event, InFrame) and json.loads(event.data) == message


def test_an_unterminated_object_is_cut_at_a_line_that_starts_a_new_op() -> None:
    data = b'{"op": "subscribe", "topic": \n{"op":"set_level","level":"info"}\n'
    for size in (1, 3, len(data)):
        chunks = [data[i : i + size] for i in range(0, len(data), size)]
        assert feed(JsonStreamFramer(LIMIT), chunks) == [
            InFrame(b'{"op": "subscribe", "topic": '),
            InFrame(b'{"op":"set_level","level":"info"}'),
        ]


def test_a_raw_newline_inside_a_string_ends_the_broken_frame() -> None:
    data = b'{"op":"publish","msg":{"data":"unterminated\n{"op":"next"}'
    assert feed(JsonStreamFramer(LIMIT), [data]) == [
        InFrame(b'{"op":"publish","msg":{"data":"unterminated'),
        InFrame(b'{"op":"next"}'),
    ]


def test_pretty_printed_objects_with_nested_lines_stay_whole() -> None:
    message = {"op": "publish", "msg": {"list": [{"op": 1}, {"x": [1, 2]}], "s": "a\nb"}}
    data = json.dumps(message, indent=4).encode()
    assert b"\n" in data
    assert feed(JsonStreamFramer(LIMIT), [data]) == [InFrame(data)]


def test_an_oversized_unterminated_frame_does_not_swallow_the_rest() -> None:
    framer = JsonStreamFramer(64)
    events = framer.receive_data(b'{"op":"publish","msg":{"data":[' + b"1," * 100 + b"\n")
    events += framer.receive_data(b'{"op":"after"}\n')
    assert events == [
        FramingError("frame larger than 64 bytes skipped"),
        InFrame(b'{"op":"after"}'),
    ]


def test_an_oversized_frame_is_skipped_once_and_the_stream_continues() -> None:
    framer = JsonStreamFramer(64)
    big = json.dumps({"op": "publish", "msg": {"data": "}" * 500}}).encode()
    events = []
    for i in range(0, len(big), 10):
        events += framer.receive_data(big[i : i + 10])
    events += framer.receive_data(b'{"op":"after"}')
    assert events == [
        FramingError("frame larger than 64 bytes skipped"),
        InFrame(b'{"op":"after"}'),
    ]
    assert len(framer._buf) == 0  # nothing of the skipped frame is kept


def test_an_oversized_cbor_item_ends_the_stream_without_being_kept() -> None:
    framer = JsonStreamFramer(100)
    item = cbor2.dumps({"op": "publish", "msg": b"\x00" * 5000})
    events = []
    for i in range(0, len(item), 512):
        events += framer.receive_data(item[i : i + 512])
        assert len(framer._buf) <= 512
    events += framer.receive_data(b"{}")
    events += framer.receive_eof()
    assert events == [FramingError("CBOR item larger than 100 bytes", fatal=True)]


def test_buffer_stays_bounded_while_a_huge_value_streams_in() -> None:
    framer = JsonStreamFramer(1000)
    framer.receive_data(b'{"op":"publish","msg":"')
    for _ in range(1000):
        assert framer.receive_data(b"x" * 100) in (
            [],
            [FramingError("frame larger than 1000 bytes skipped")],
        )
        assert len(framer._buf) <= 1000 + 100


def test_an_unterminated_value_at_eof_is_reported() -> None:
    framer = JsonStreamFramer(LIMIT)
    assert framer.receive_data(b'{"op":"a"} {"op":') == [InFrame(b'{"op":"a"}')]
    assert framer.receive_eof() == [FramingError("incomplete frame at the end of the stream")]


class _CountingPattern:
    """Wraps a compiled pattern and counts the bytes its searches look at."""

    def __init__(self, pattern: re.Pattern[bytes], counter: list[int]) -> None:
        self.pattern = pattern
        self.counter = counter

    def search(self, buf: bytes | bytearray, pos: int = 0) -> re.Match[bytes] | None:
        match = self.pattern.search(buf, pos)
        self.counter[0] += (match.end() if match else len(buf)) - pos
        return match


def test_many_small_chunks_of_one_big_object_are_scanned_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The reference rescans its whole buffer for every chunk: O(n^2) bytes looked at.
    scanned = [0]
    for name in ("_NOT_SPACE", "_CONTAINER_STOP", "_STRING_STOP", "_TOKEN_STOP"):
        monkeypatch.setattr(framing, name, _CountingPattern(getattr(framing, name), scanned))
    framer = JsonStreamFramer(LIMIT)
    payload = json.dumps({"op": "publish", "msg": {"data": ["a}b" * 50] * 200}}).encode()
    events = []
    for i in range(0, len(payload), 16):
        events += framer.receive_data(payload[i : i + 16])
    assert events == [InFrame(payload)]
    assert scanned[0] <= 2 * len(payload)


@settings(max_examples=150, deadline=None)
@given(data=st.binary(max_size=300), cuts=st.lists(st.integers(min_value=0), max_size=6))
def test_arbitrary_bytes_never_raise_and_any_split_agrees(data: bytes, cuts: list[int]) -> None:
    whole = feed(JsonStreamFramer(64), [data])
    assert whole == feed(JsonStreamFramer(64), split(data, cuts))
    for event in whole:
        assert isinstance(event, FramingError) or len(event.data) <= 64
    lines = feed(LineFramer(64), split(data, cuts))
    assert all(isinstance(e, FramingError) or len(e.data) <= 64 for e in lines)


# ---- LineFramer ------------------------------------------------------------------


@settings(max_examples=100, deadline=None)
@given(messages=st.lists(ops, max_size=6), cuts=st.lists(st.integers(min_value=0), max_size=10))
def test_lines_in_any_split_give_the_same_frames(
    messages: list[dict[str, object]], cuts: list[int]
) -> None:
    data = b"".join(json.dumps(m).encode() + b"\r\n\n" for m in messages)
    events = feed(LineFramer(LIMIT), split(data, cuts))
    assert [json.loads(e.data) for e in events if isinstance(e, InFrame)] == messages


def test_a_long_line_is_skipped_to_its_newline() -> None:
    framer = LineFramer(10)
    events = framer.receive_data(b"x" * 8)
    events += framer.receive_data(b"y" * 8)
    events += framer.receive_data(b"zz\n{}\n")
    events += framer.receive_data(b"0123456789ABC\n")
    assert events == [
        FramingError("line longer than 10 bytes skipped"),
        InFrame(b"{}"),
        FramingError("line longer than 10 bytes skipped"),
    ]


def test_a_long_line_split_over_chunks_is_skipped_once() -> None:
    framer = LineFramer(10)
    events = [
        event
        for chunk in (b"x" * 20, b"y" * 20, b"z\n{}\n")
        for event in framer.receive_data(chunk)
    ]
    assert events == [FramingError("line longer than 10 bytes skipped"), InFrame(b"{}")]


@pytest.mark.parametrize("tail", [b"{}", b"  {}  "])
def test_a_last_line_without_newline_counts_at_eof(tail: bytes) -> None:
    framer = LineFramer(LIMIT)
    assert framer.receive_data(tail) == []
    assert framer.receive_eof() == [InFrame(b"{}")]


def test_datagram_fragments_fit_and_reassemble() -> None:
    small = b'{"op":"publish"}'
    assert fragment_datagrams(small, 128, "m") == [small]
    text = json.dumps({"op": "publish", "msg": {"data": 'é"\\x' * 3000}}, ensure_ascii=False)
    parts = fragment_datagrams(text.encode(), 500, "m1")
    assert all(len(p) <= 500 for p in parts)
    decoded = [json.loads(p) for p in parts]
    assert [d["num"] for d in decoded] == list(range(len(parts)))
    assert {d["total"] for d in decoded} == {len(parts)} and {d["id"] for d in decoded} == {"m1"}
    assert "".join(d["data"] for d in decoded) == text
    with pytest.raises(ValueError, match="cannot carry"):
        fragment_datagrams(text.encode(), 100, "m")
    with pytest.raises(ValueError, match="cannot carry"):
        fragment_datagrams(text.encode(), 130, "x" * 100)
