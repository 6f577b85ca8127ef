"""A Foxglove client's queue (``OutQueue``) against a plain model of its rules.

The queue keeps its counters per push with the fewest steps (its peak only when data
leaves); the model recounts everything from its list after each step. Both must agree
on what is taken, what is dropped, when the client is told, and the peak.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hypothesis import given, settings
from hypothesis import strategies as st

from rwt_foxglove.outqueue import OutQueue
from rwt_protocol.server.outbox import OutFrame


@dataclass
class Model:
    """The rules of docs/foxglove.md, written plainly: a list, recounted at every step."""

    max_bytes: int
    max_messages: int
    frames: list[OutFrame] = field(default_factory=list)
    dropped: int = 0
    peak: int = 0
    episode: int = 0
    told: bool = False

    def data(self) -> list[OutFrame]:
        return [frame for frame in self.frames if frame.droppable]

    def data_bytes(self) -> int:
        return sum(len(frame.data) for frame in self.data())

    def push(self, frame: OutFrame) -> bool:
        self.frames.append(frame)
        if not frame.droppable:
            return False
        over = len(self.data()) > self.max_messages or self.data_bytes() > self.max_bytes
        if not over:
            self.peak = max(self.peak, self.data_bytes())
            return False
        # the oldest data go first; the frame just pushed always stays
        while len(self.data()) > 1 and (
            len(self.data()) > self.max_messages or self.data_bytes() > self.max_bytes
        ):
            self.frames.remove(self.data()[0])
            self.dropped += 1
            self.episode += 1
        self.peak = max(self.peak, self.data_bytes())
        if not self.episode or self.told:
            return False
        self.told = True
        return True

    def take(self, max_bytes: int) -> list[OutFrame]:
        taken: list[OutFrame] = []
        size = 0
        while self.frames and (not taken or size < max_bytes):
            frame = self.frames.pop(0)
            taken.append(frame)
            size += len(frame.data)
        if not self.frames:
            self.episode, self.told = 0, False
        return taken


steps = st.lists(
    st.one_of(
        st.tuples(st.just("data"), st.integers(0, 300)),
        st.tuples(st.just("control"), st.integers(0, 300)),
        st.tuples(st.just("take"), st.integers(1, 900)),
    ),
    max_size=60,
)


@settings(max_examples=300, deadline=None)
@given(max_bytes=st.integers(1, 1000), max_messages=st.integers(1, 8), steps=steps)
def test_the_queue_follows_its_rules(
    max_bytes: int, max_messages: int, steps: list[tuple[str, int]]
) -> None:
    queue = OutQueue(max_bytes, max_messages)
    model = Model(max_bytes, max_messages)
    for number, (what, size) in enumerate(steps):
        if what == "take":
            assert queue.take(size) == model.take(size)
        else:
            frame = OutFrame(bytes([number % 256]) * size, droppable=what == "data")
            assert queue.push(frame) == model.push(frame), "told of the drops"
        assert queue.dropped == model.dropped
        assert queue.data_bytes == model.data_bytes()
        assert queue.data_count == len(model.data())
        assert queue.episode_drops == model.episode
        assert queue.peak_bytes == model.peak
        assert len(queue) == len(model.frames)


def test_one_message_larger_than_the_bound_is_kept_and_nothing_is_told() -> None:
    queue = OutQueue(max_bytes=10, max_messages=4)
    assert not queue.push(OutFrame(b"x" * 50, droppable=True))
    assert (queue.dropped, queue.data_bytes, queue.peak_bytes) == (0, 50, 50)
    assert queue.push(OutFrame(b"y", droppable=True)), "the first drop of an episode is told"
    assert (queue.dropped, queue.data_bytes, queue.peak_bytes) == (1, 1, 50)
