"""The msgspec publish path accepts exactly what the general path accepts."""

from __future__ import annotations

import pytest

from rwt_protocol.codecs.json import decode_json, decode_publish_one_pass, parse_object
from rwt_protocol.errors import RemoteProtocolError
from rwt_protocol.ops import Publish

FRAMES = [
    b'{"op":"publish","topic":"/a","msg":{"data":"x"}}',
    b'{"op": "publish", "id": "p1", "topic": "/a", "msg": {"data": 1}, "latch": true}',
    b'{"op":"publish","topic":"/a"}',
    b'{"op":"publish","topic":"/a","msg":{},"id":7,"extra":[1,2]}',
    b'{"op":"publish","topic":"/a","msg":[1,2]}',
    b'{"op":"publish","topic":"/a","msg":{"x":NaN}}',
    b'{"op":"publish","topic":"/a","msg":{},"id":true}',
    b'{"op":"publish","topic":"/a","msg":{},"id":1.5}',
    b'{"op":"publish","topic":"/a","msg":{},"latch":"yes"}',
    b'{"op":"publish","topic":5,"msg":{}}',
    b'{"op":"publish","msg":{}}',
    b'{"op":"subscribe","topic":"/publish","type":"std_msgs/msg/String"}',
    b'{"op":"publish","topic":"/a","msg":{}',
    b'{"op":"publish","topic":"/a","msg":{},"type":"std_msgs/String","qos":{"depth":1}}',
    b'{"op":"publish","topic":"/a","msg":{},"qos":{"depth":-1}}',
    b'{"op":"publish","topic":"/a","msg":{},"qos":"abcd"}',
    b'{"op":"publish","topic":"/a","msg":{},"queue_size":5}',
    b'{"op":"publish","topic":"/a","msg":{},"queue_size":-5}',
]


def assert_decoders_agree(frame: str | bytes) -> None:
    """The msgspec path and the general path accept and refuse ``frame`` alike, with one value.

    The fast path may decline a frame the general path reads (NaN, Infinity, or
    another op, a ``qos`` or ``queue_size`` that the model checks); it never accepts
    one the general path refuses.
    """
    fast = decode_publish_one_pass(frame)  # the shortcut, whatever RWT_NO_SHORTCUTS says
    try:
        general = parse_object(decode_json(frame))
    except RemoteProtocolError:
        assert fast is None  # the general path explains the refusal
        return
    text = frame if isinstance(frame, str) else frame.decode()
    if fast is None:
        assert (
            not isinstance(general, Publish)
            or "NaN" in text
            or "Infinity" in text
            or (general.qos is not None or general.queue_size is not None)
        )
        return
    assert isinstance(general, Publish)
    assert (fast.topic, fast.msg, fast.id, fast.latch) == (
        general.topic,
        general.msg,
        general.id,
        general.latch,
    )


@pytest.mark.parametrize("frame", FRAMES)
def test_fast_path_agrees_with_the_general_path(frame: bytes) -> None:
    assert_decoders_agree(frame)
