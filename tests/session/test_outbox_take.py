"""Taking the whole queue at once leaves the outbox as taking it frame by frame does.

``Outbox.take`` hands a writer everything when it all fits, without the
per-frame bookkeeping; the counters it resets must be those the frame-by-frame
path brings to zero, for every mix of topic messages, replies, fragmented
groups and a held oversized message.
"""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from rwt_protocol.runtime.outbox import Outbox, OutFrame

# a message's parts share its kind: a topic message's are droppable, a reply's are not
FRAMES = st.lists(
    st.one_of(
        st.tuples(st.integers(1, 400), st.just(True), st.sampled_from([None, "topic1", "topic2"])),
        st.tuples(st.integers(1, 400), st.just(False), st.sampled_from([None, "reply1"])),
    ),
    max_size=40,
)


def _filled(spec: list[tuple[int, bool, str | None]]) -> Outbox:
    box = Outbox(limit_bytes=4000, frame_overhead_bytes=16, max_messages=20)
    for size, droppable, group in spec:
        box.extend([OutFrame(b"x" * size, droppable=droppable, group=group)])
    return box


def _state(box: Outbox) -> tuple[int, ...]:
    return (
        len(box),
        box.queued_bytes,
        box.undroppable_bytes,
        box.held_bytes,
        box.fill_bytes,
        box.taken_frames,
        box.dropped,
    )


@settings(max_examples=200, deadline=None)
@given(FRAMES)
def test_taking_all_at_once_is_taking_one_by_one(spec: list[tuple[int, bool, str | None]]) -> None:
    whole, stepwise = _filled(spec), _filled(spec)
    taken = whole.take(None)
    one_by_one: list[OutFrame] = []
    while frames := stepwise.take(1):  # one frame a call: the general path
        one_by_one += frames
    assert [f.data for f in taken] == [f.data for f in one_by_one]
    assert _state(whole) == _state(stepwise)
    for box in (whole, stepwise):  # and both go on the same way
        box.extend([OutFrame(b"y" * 10, droppable=True)])
    assert _state(whole) == _state(stepwise)
