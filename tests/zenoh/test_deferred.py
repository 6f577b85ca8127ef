"""Large samples over the Zenoh link: the deferred paths against the general ones (deferred.py).

A message with 64 KiB or more of top-level ``uint8[]`` is serialized by the
outbox's thread (``zenoh-deferred-encode``) and a remote sample that large is
copied on the event loop (``zenoh-late-copy``). Both must give what the general
paths give: the same CDR bytes, the same decoded values, whatever the sizes and
alignments; and a peer's bad large sample is still refused.
"""

from __future__ import annotations

import contextlib
import logging
import os
import subprocess
import sys
from typing import TYPE_CHECKING, Any

import anyio
import pytest

import zenoh
from rwt_graph.graph import Graph
from rwt_graph.rosapi.listing import publishers, subscribers
from rwt_graph.rosapi.visibility import EVERYTHING
from rwt_graph.types.wire import CDR_TRAILING_SLACK
from rwt_protocol.shortcuts import ENV_VAR
from rwt_zenoh.config import make_config
from rwt_zenoh.deferred import (
    DEFER_BYTES,
    Deferred,
    DeferredEncoder,
    byte_fields,
    held_payload,
    payload_bytes,
)
from rwt_zenoh.link import open_zenoh_link
from rwt_zenoh.payload import decode_message, encode_message, type_hash
from rwt_zenoh.wire import dds_type_name, topic_keyexpr

from .processes import REPO
from .support import WAIT_S, endpoint, peer, until

if TYPE_CHECKING:
    from collections.abc import AsyncIterator

    from rwt_graph.types import MessageType

REGISTRY = Graph().registry
IMAGE = "sensor_msgs/msg/Image"


def image(size: int, frame_id: str = "cam", encoding: str = "mono8") -> dict[str, object]:
    """An Image in the internal form whose ``data`` holds ``size`` bytes (not all equal)."""
    msg = REGISTRY.message(IMAGE).default()
    msg["header"] = {"stamp": {"sec": 7, "nanosec": 9}, "frame_id": frame_id}
    msg.update(height=1, width=size, encoding=encoding, step=size, is_bigendian=0)
    msg["data"] = bytes(range(256)) * (size // 256) + bytes(size % 256)
    return msg


def with_data(type_name: str, size: int, **fields: object) -> dict[str, object]:
    msg = REGISTRY.message(type_name).default()
    msg.update(fields)
    msg["data"] = bytes([size % 251]) * size
    return msg


CASES = [
    *(
        (IMAGE, image(size, frame_id))
        for size in (DEFER_BYTES, DEFER_BYTES + 1, 100_003, 1_000_000)
        for frame_id in ("", "a", "abc", "abcde")  # the CDR offsets of data differ
    ),
    ("sensor_msgs/msg/CompressedImage", with_data("sensor_msgs/msg/CompressedImage", 70_001)),
    ("std_msgs/msg/UInt8MultiArray", with_data("std_msgs/msg/UInt8MultiArray", 65_539)),
    (  # data between a nested array and a bool
        "sensor_msgs/msg/PointCloud2",
        with_data("sensor_msgs/msg/PointCloud2", 99_999, is_dense=True, point_step=3),
    ),
]


def deferred(type_name: str, msg: dict[str, object]) -> Deferred | None:
    return DeferredEncoder(REGISTRY, on=True).defer(REGISTRY.message(type_name), msg)


@pytest.mark.parametrize(("type_name", "msg"), CASES)
def test_a_deferred_message_is_the_general_paths_cdr(type_name: str, msg: dict[str, Any]) -> None:
    mtype = REGISTRY.message(type_name)
    late = deferred(type_name, msg)
    assert late is not None
    made = late.make()
    assert bytes(made) == bytes(encode_message(REGISTRY, mtype, msg))
    assert len(late) == len(made)  # what the outbox's bound counted
    assert decode_message(REGISTRY, mtype, bytes(made)) == msg


def test_small_messages_and_types_without_bytes_are_serialized_on_the_loop() -> None:
    assert deferred(IMAGE, image(DEFER_BYTES - 1)) is None
    assert deferred("std_msgs/msg/String", {"data": "x" * 200_000}) is None
    assert DeferredEncoder(REGISTRY, on=False).defer(REGISTRY.message(IMAGE), image(10**6)) is None
    assert byte_fields(REGISTRY.message(IMAGE)) == ("data",)
    assert byte_fields(REGISTRY.message("std_msgs/msg/String")) == ()


def test_a_large_payload_stays_zenohs_until_the_loop_copies_it() -> None:
    large, small = bytes(range(256)) * 400, b"\x00\x01\x00\x00small"
    held = held_payload(zenoh.ZBytes(large), late=True)
    assert isinstance(held, zenoh.ZBytes)
    assert len(held) == len(large)
    assert payload_bytes(held) == large
    assert held_payload(zenoh.ZBytes(small)) == small
    assert payload_bytes(small) == small
    assert held_payload(zenoh.ZBytes(large), late=False) == large  # the shortcut off


# ---- through the link: two graphs, and a bare peer sending bad large samples ------------


@contextlib.asynccontextmanager
async def two_graphs() -> AsyncIterator[tuple[Graph, Graph]]:
    first = endpoint()
    a, b = Graph(), Graph()
    async with open_zenoh_link(a, peer(listen=first)), open_zenoh_link(b, peer(connect=(first,))):
        yield a, b


@pytest.mark.anyio
@pytest.mark.timeout(60)
async def test_large_images_cross_the_link_equal_in_order() -> None:
    sent = [image(size, frame_id) for size, frame_id in ((65_537, "odd"), (300_001, ""), (4, "s"))]
    sent += [image(1_000_000, str(n)) for n in range(20)]
    async with two_graphs() as (a, b):
        got: list[dict[str, object]] = []
        b.create_subscription("/cam", got.append, IMAGE, node="/viewer")
        pub = a.create_publisher("/cam", IMAGE, node="/camera")
        await until(lambda: "/viewer" in subscribers(a, EVERYTHING, "/cam"))
        await until(lambda: "/camera" in publishers(b, EVERYTHING, "/cam"))
        probe = image(8, "probe")
        with anyio.fail_after(WAIT_S):
            while not got:
                pub.publish(probe)
                await anyio.sleep(0.1)
        await anyio.sleep(0.3)  # the probes in flight arrive
        del got[:]
        for msg in sent:
            pub.publish(msg)
        await until(lambda: len(got) >= len(sent))
    assert got == sent


@contextlib.asynccontextmanager
async def bare_peer() -> AsyncIterator[tuple[Graph, zenoh.Session]]:
    ep = endpoint()
    graph = Graph()
    async with open_zenoh_link(graph, peer(listen=ep)):
        session = await anyio.to_thread.run_sync(zenoh.open, make_config(peer(connect=(ep,))))
        try:
            yield graph, session
        finally:
            await anyio.to_thread.run_sync(session.close)


def cdr(mtype: MessageType, msg: dict[str, object]) -> bytes:
    return bytes(encode_message(REGISTRY, mtype, msg))


@pytest.mark.anyio
@pytest.mark.timeout(60)
async def test_bad_large_samples_of_a_peer_are_refused_and_good_ones_arrive(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger="rwt.zenoh")
    mtype = REGISTRY.message(IMAGE)
    good = image(200_000, "good")
    slack = image(100_000, "slack")
    async with bare_peer() as (graph, session):
        got: list[dict[str, object]] = []
        graph.create_subscription("/cam", got.append, IMAGE)
        key = topic_keyexpr(0, "/cam", dds_type_name(IMAGE), type_hash(REGISTRY, IMAGE))
        # BLOCK, as a reliable ROS 2 publisher: with Zenoh's default (DROP) a loaded machine
        # may drop some of these 200 kB samples before they leave, and the good ones with them
        publisher: Any = session.declare_publisher(
            key, congestion_control=zenoh.CongestionControl.BLOCK
        )
        await until(lambda: bool(publisher.matching_status.matching))
        publisher.put(b"\x00\x01\x00\x00" + b"\xff" * 200_000)  # data longer than the sample
        publisher.put(b"\x07\x07" + bytes(200_000))  # no CDR header
        tiny = cdr(mtype, image(8, "tiny"))
        publisher.put(tiny + bytes(DEFER_BYTES + len(tiny)))  # too much after the payload
        publisher.put(cdr(mtype, slack) + bytes(CDR_TRAILING_SLACK))  # allowed after the payload
        publisher.put(cdr(mtype, good))
        await until(lambda: len(got) >= 2)
        await anyio.sleep(0.3)  # nothing else comes
    assert got == [slack, good]
    bad = [r.getMessage() for r in caplog.records if "event=zenoh_bad_sample" in r.getMessage()]
    assert len(bad) == 1  # one line for the episode


def test_the_switch_turns_both_off() -> None:
    """``RWT_NO_SHORTCUTS`` names them; off, the loop serializes and Zenoh's thread copies."""
    code = (
        "import zenoh\n"
        "from rwt_graph.graph import Graph\n"
        "from rwt_zenoh.deferred import DeferredEncoder, held_payload\n"
        "from benchmarks.zenoh_link import message\n"
        "r = Graph().registry\n"
        "d = DeferredEncoder(r).defer(r.message('sensor_msgs/msg/Image'), message(1_000_000))\n"
        "print(d is None, type(held_payload(zenoh.ZBytes(bytes(100_000)))).__name__)\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join((str(REPO / "src"), str(REPO)))}
    outputs = []
    for value in ("0", "zenoh-deferred-encode,zenoh-late-copy"):
        result = subprocess.run(
            [sys.executable, "-c", code],
            env={**env, ENV_VAR: value},
            capture_output=True,
            text=True,
            check=False,
            timeout=60,
        )
        assert result.returncode == 0, result.stderr[-2000:]
        outputs.append(result.stdout.split())
    assert outputs == [["False", "ZBytes"], ["True", "bytes"]]
