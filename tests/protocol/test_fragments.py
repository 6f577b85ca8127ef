"""Fragmentation and reassembly (spec 3.1.1, D19)."""

from __future__ import annotations

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from rwt_protocol.errors import RemoteProtocolError
from rwt_protocol.framing.fragments import (
    FRAGMENT_OVERHEAD,
    MAX_PARTS,
    PartKind,
    Reassembler,
    fragment_frames,
    fresh_id,
    split_text,
)

FRAG = PartKind.FRAGMENT


def reassembler(max_bytes: int = 10_000_000, max_pending: int = 4) -> Reassembler:
    return Reassembler(max_bytes=max_bytes, max_pending=max_pending, timeout_s=60.0)


@given(text=st.text(max_size=2000), size=st.integers(1, 300), data=st.data())
def test_fragments_reassemble_in_any_order(text: str, size: int, data: st.DataObject) -> None:
    frames = [json.loads(f) for f in fragment_frames(text, "m1", size)]
    assert [f["num"] for f in frames] == list(range(len(frames)))
    assert all(f["total"] == len(frames) and type(f["total"]) is int for f in frames)
    assert all(len(f["data"]) <= size for f in frames)
    order = data.draw(st.permutations(frames))
    parts = reassembler()
    results = [
        parts.add(FRAG, f["id"], f["num"], f["total"], data=f["data"], now=0.0) for f in order
    ]
    assert results[:-1] == [None] * (len(results) - 1)
    assert results[-1] == text
    assert len(parts) == 0 and parts.held_bytes == 0


def test_split_text_cuts_by_characters() -> None:
    assert split_text("abcdefg", 3) == ["abc", "def", "g"]
    assert split_text("", 3) == [""]
    assert split_text("\u00e9\u00e9\u00e9", 2) == ["\u00e9\u00e9", "\u00e9"]
    with pytest.raises(ValueError, match="at least 1"):
        split_text("x", 0)


def test_fresh_ids_are_unique_and_never_falsy() -> None:
    ids = {fresh_id("publish") for _ in range(100)}
    assert len(ids) == 100
    assert all(i.startswith("rwt:publish:") for i in ids)


def test_a_single_part_message_is_returned_at_once() -> None:
    assert reassembler().add(FRAG, "x", 0, 1, data='{"op":"x"}', now=0.0) == '{"op":"x"}'


def test_duplicate_and_inconsistent_parts_are_refused() -> None:
    parts = reassembler()
    assert parts.add(FRAG, "m", 0, 3, data="a", now=0.0) is None
    with pytest.raises(RemoteProtocolError, match="duplicate part 0"):
        parts.add(FRAG, "m", 0, 3, data="a", now=0.0)
    with pytest.raises(RemoteProtocolError, match="total 4 differs from 3"):
        parts.add(FRAG, "m", 1, 4, data="b", now=0.0)
    with pytest.raises(RemoteProtocolError, match="num 3 is not below total 3"):
        parts.add(FRAG, "m", 3, 3, data="b", now=0.0)
    assert parts.add(FRAG, "m", 2, 3, data="c", now=0.0) is None
    assert parts.add(FRAG, "m", 1, 3, data="b", now=0.0) == "abc"


def test_fragment_and_png_ids_are_separate() -> None:
    parts = reassembler()
    assert parts.add(FRAG, 7, 0, 2, data="f0", now=0.0) is None
    assert parts.add(PartKind.PNG, 7, 0, 2, data="p0", now=0.0) is None
    assert parts.add(PartKind.PNG, 7, 1, 2, data="p1", now=0.0) == "p0p1"
    assert parts.add(FRAG, 7, 1, 2, data="f1", now=0.0) == "f0f1"


def test_pending_messages_are_bounded_in_number() -> None:
    parts = reassembler(max_pending=2)
    parts.add(FRAG, "a", 0, 2, data="x", now=0.0)
    parts.add(FRAG, "b", 0, 2, data="x", now=0.0)
    with pytest.raises(RemoteProtocolError, match="too many incomplete messages"):
        parts.add(FRAG, "c", 0, 2, data="x", now=0.0)
    assert parts.add(FRAG, "a", 1, 2, data="y", now=0.0) == "xy"
    assert parts.add(FRAG, "c", 0, 2, data="x", now=0.0) is None


def test_held_bytes_are_bounded_and_an_oversized_message_is_dropped() -> None:
    parts = reassembler(max_bytes=3 * (100 + FRAGMENT_OVERHEAD))
    parts.add(FRAG, "small", 0, 2, data="s" * 100, now=0.0)
    parts.add(FRAG, "big", 0, 5, data="b" * 100, now=0.0)
    with pytest.raises(RemoteProtocolError, match="'big' dropped"):
        parts.add(FRAG, "big", 2, 5, data="b" * 200, now=0.0)
    assert len(parts) == 1
    assert parts.held_bytes == 100 + FRAGMENT_OVERHEAD
    assert parts.add(FRAG, "small", 1, 2, data="t", now=0.0) == "s" * 100 + "t"
    with pytest.raises(RemoteProtocolError, match="dropped"):
        parts.add(FRAG, "whole", 0, 1, data="w" * 1000, now=0.0)


def test_tiny_parts_cost_their_overhead() -> None:
    parts = reassembler(max_bytes=10 * FRAGMENT_OVERHEAD)
    for num in range(9):
        parts.add(FRAG, "m", num, 1_000_000, data="", now=0.0)
    with pytest.raises(RemoteProtocolError):
        parts.add(FRAG, "m", 9, 1_000_000, data="xx", now=0.0)
    assert parts.held_bytes == 0


def test_incomplete_messages_expire_after_their_latest_part() -> None:
    parts = reassembler()
    parts.add(FRAG, "old", 0, 3, data="x", now=0.0)
    parts.add(FRAG, "new", 0, 2, data="x", now=30.0)
    assert parts.next_deadline() == 60.0
    parts.add(FRAG, "old", 1, 3, data="y", now=50.0)
    assert parts.next_deadline() == 90.0
    assert parts.expire(89.9) == []
    assert parts.expire(90.0) == [(FRAG, "new", 1, 2)]
    assert parts.expire(110.0) == [(FRAG, "old", 2, 3)]
    assert parts.next_deadline() is None
    assert parts.held_bytes == 0


def test_clear_forgets_everything() -> None:
    parts = reassembler()
    parts.add(FRAG, "a", 0, 2, data="x", now=0.0)
    parts.clear()
    assert len(parts) == 0 and parts.held_bytes == 0 and parts.next_deadline() is None


def test_a_tiny_fragment_size_is_raised_to_bound_the_part_count() -> None:
    text = "x" * (MAX_PARTS * 3 + 1)
    frames = fragment_frames(text, "m", 1)
    assert len(frames) == 7501  # parts of ceil(30001 / 10000) = 4 characters
    assert len(frames) <= MAX_PARTS
    assert "".join(json.loads(f)["data"] for f in frames) == text
