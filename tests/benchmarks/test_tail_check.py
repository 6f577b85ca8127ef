"""The cbor-raw tail check of the load generator: it must catch wrong frames."""

from __future__ import annotations

import os

import pytest
from benchmarks.loadgen.engine import GeneratorError
from benchmarks.loadgen.tail import TailStream
from benchmarks.loadgen.wire import server_frame

MARK = b"\x66/image"
DATA = [os.urandom(70_000), os.urandom(70_000), os.urandom(100)]


def _frame(i: int, *, data: bytes | None = None, mark: bytes = MARK, binary: bool = True) -> bytes:
    payload = b"\xa2\x62op" + mark + b"\x00" * 40 + (DATA[i % 3] if data is None else data)
    return server_frame(payload, binary=binary)


def _stream() -> TailStream:
    return TailStream(lambda i: DATA[i % 3], MARK)


@pytest.mark.parametrize("chunk", [1, 7, 4096, 1 << 20])
def test_right_frames_pass_in_any_chunking(chunk: int) -> None:
    wire = b"".join(_frame(i) for i in range(7))
    check = _stream()
    for start in range(0, len(wire), chunk):
        check.feed(wire[start : start + chunk])
    assert check.received == 7


def test_a_frame_cut_short_is_not_counted() -> None:
    wire = _frame(0) + _frame(1)
    check = _stream()
    assert check.feed(wire[:-1]) == 1


@pytest.mark.parametrize(
    ("frame", "message"),
    [
        (_frame(1, data=DATA[1][:-1] + bytes([DATA[1][-1] ^ 1])), "wrong data"),
        (_frame(1, data=DATA[0]), "wrong data"),  # the previous message again
        (_frame(1, mark=b"\x66/other"), "does not name the topic"),
        (_frame(1, binary=False), "not a message of this stream"),
        (server_frame(b"\x00" * 10_000 + DATA[1], binary=True), "not a message of this stream"),
    ],
    # the frames hold random data: ids by position keep collection the same in every
    # process (pytest-xdist compares them)
    ids=["altered", "previous", "other-topic", "text", "padded"],
)
def test_wrong_frames_are_caught(frame: bytes, message: str) -> None:
    check = _stream()
    check.feed(_frame(0))
    with pytest.raises(GeneratorError, match=message):
        check.feed(frame)
