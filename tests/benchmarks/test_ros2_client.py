"""B21's lean WebSocket subscriber (benchmarks/ros2_client.py) times and checks each image."""

from __future__ import annotations

import base64

import pytest
from benchmarks.loadgen.wire import server_frame
from benchmarks.ros2_client import IMAGE_BYTES, ClientError, FrameWalk

HEADER = '{"op":"publish","topic":"/cam","msg":{"header":{"stamp":{"sec":%d,"nanosec":%d},'
PROBE = (HEADER % (0, 0)) + '"frame_id":"probe"},"height":0,"data":""}}'


def image(sec: int, nanosec: int, data: bytes = bytes(IMAGE_BYTES)) -> bytes:
    """A publish frame of a 640x480 rgb8 image, as a bridge writes it."""
    text = (HEADER % (sec, nanosec)) + '"frame_id":""},"height":480,"width":640,"data":"'
    return server_frame(text.encode() + base64.b64encode(data) + b'"}}')


def feed(walk: FrameWalk, stream: bytes, chunk: int, now: float) -> None:
    buffer = bytearray(chunk)
    for at in range(0, len(stream), chunk):
        piece = stream[at : at + chunk]
        buffer[: len(piece)] = piece
        walk.feed(buffer, len(piece), now)


@pytest.mark.parametrize("chunk", [7, 65536, 1 << 20, 1 << 22])
def test_each_image_is_timed_by_its_stamp_whatever_the_chunking(chunk: int) -> None:
    walk = FrameWalk("image")
    stream = server_frame(PROBE.encode()) + image(100, 500_000_000) + image(101, 0)
    feed(walk, stream, chunk, now=102.0)
    assert walk.probes == 1
    assert walk.latencies == [1.5, 1.0]
    assert walk.stamps == [100.5, 101.0]
    assert walk.last == 102.0


def test_an_image_with_one_wrong_byte_is_an_error() -> None:
    data = bytearray(IMAGE_BYTES)
    data[-1000] = 1
    walk = FrameWalk("image")
    with pytest.raises(ClientError, match="wrong image data"):
        feed(walk, server_frame(PROBE.encode()) + image(100, 0, bytes(data)), 65536, 101.0)


def test_an_image_of_the_wrong_size_is_an_error() -> None:
    walk = FrameWalk("image")
    with pytest.raises(ClientError, match="not one image"):
        feed(walk, server_frame(PROBE.encode()) + image(100, 0, bytes(IMAGE_BYTES // 2)), 4096, 0)


def test_the_tail_is_learnt_from_the_probe_whatever_the_key_order() -> None:
    probe = (HEADER % (0, 0)) + '"frame_id": "probe"}, "data": "", "step": 1920}}'
    text = (HEADER % (7, 0)) + '"frame_id": ""}, "data": "'
    frame = text.encode() + base64.b64encode(bytes(IMAGE_BYTES)) + b'", "step": 1920}}'
    walk = FrameWalk("image")
    feed(walk, server_frame(probe.encode()) + server_frame(frame), 65536, now=8.0)
    assert walk.latencies == [1.0]
    wrong = frame.replace(b'"step": 1920', b'"step": 1921')
    with pytest.raises(ClientError, match="wrong image data"):
        feed(walk, server_frame(wrong), 65536, now=9.0)


def test_string_stamps_and_pings_go_through_small_frames() -> None:
    walk = FrameWalk("string")
    text = "5.250000".ljust(100, "x")
    data = '{"op":"publish","topic":"/s","msg":{"data":"' + text + '"}}'
    ping = bytes((0x89, 2)) + b"hi"
    feed(walk, ping + server_frame(data.encode()), 3, now=6.0)
    assert walk.latencies == [0.75]
    assert walk.pongs == [b"hi"]
