"""Gaps in a remote publisher's sequence numbers are the messages lost on the way (D61)."""

from __future__ import annotations

from rwt_zenoh.gaps import SequenceGaps
from rwt_zenoh.wire import attachment_source, pack_attachment

GID = bytes(range(16))


def test_a_gap_counts_the_messages_between() -> None:
    gaps = SequenceGaps()
    assert gaps.seen(GID, 7) == 0  # the first heard: what came before was not for us
    assert gaps.seen(GID, 8) == 0
    assert gaps.seen(GID, 12) == 3  # 9, 10 and 11 were lost
    assert gaps.seen(GID, 13) == 0
    assert gaps.seen(bytes(16), 40) == 0  # each publisher on its own


def test_a_number_that_goes_back_is_no_gap_and_moves_nothing() -> None:
    gaps = SequenceGaps()
    gaps.seen(GID, 100)
    assert gaps.seen(GID, 50) == 0  # a latched sample replayed to a late subscriber
    assert gaps.seen(GID, 100) == 0  # a repeat
    assert gaps.seen(GID, 101) == 0  # so 101 is the next, as before


def test_the_publishers_kept_are_bounded() -> None:
    gaps = SequenceGaps(max_tracked=2)
    gaps.seen(b"a" * 16, 1)
    gaps.seen(b"b" * 16, 1)
    gaps.seen(b"c" * 16, 1)  # a is forgotten: its next gap goes unnoticed
    assert gaps.seen(b"a" * 16, 9) == 0
    assert gaps.seen(b"c" * 16, 3) == 1


def test_the_attachment_gives_its_sequence_number_and_source() -> None:
    assert attachment_source(pack_attachment(42, 123, GID)) == (42, GID)
