"""A graph linked over Zenoh against a bare session sending bad samples and too many tokens.

(And a latched sample sent before its publisher's token, which a well-behaved
peer may also do: its token can reach the link after the sample.)

What a hostile (or broken) peer sends is skipped with one log line per episode, not
one per sample; the entities it declares past ``--zenoh-max-entities`` are
ignored until room frees; the samples waiting are bounded in bytes and dropped
oldest first per topic (docs/limits.md, "Zenoh peers: what they are trusted with").
"""

from __future__ import annotations

import contextlib
import logging
from dataclasses import replace
from typing import TYPE_CHECKING, Any, cast

import anyio
import pytest

import zenoh
from rwt_graph.graph import Graph
from rwt_graph.rosapi.listing import publishers
from rwt_graph.rosapi.visibility import EVERYTHING
from rwt_zenoh.config import make_config
from rwt_zenoh.inbox import Inbox, Sample
from rwt_zenoh.limits import MAX_REMOTE_ENTITIES, SAMPLE_OVERHEAD
from rwt_zenoh.link import open_zenoh_link
from rwt_zenoh.payload import encode_message, type_hash
from rwt_zenoh.wire import (
    LATCHED_QOS,
    VOLATILE_QOS,
    Entity,
    EntityKind,
    Topic,
    dds_type_name,
    pack_attachment,
    topic_keyexpr,
    zid_text,
)

from .support import endpoint, peer, until

if TYPE_CHECKING:
    from collections.abc import AsyncIterator

pytestmark = [pytest.mark.anyio, pytest.mark.timeout(60)]

STRING = "std_msgs/msg/String"
REGISTRY = Graph().registry
STRING_HASH = type_hash(REGISTRY, STRING)


@contextlib.asynccontextmanager
async def linked_with_bare_peer(
    max_entities: int = MAX_REMOTE_ENTITIES,
) -> AsyncIterator[tuple[Graph, zenoh.Session]]:
    """A graph linked on a loopback endpoint, and a bare Zenoh session connected to it."""
    ep = endpoint()
    graph = Graph()
    async with open_zenoh_link(graph, replace(peer(listen=ep), max_entities=max_entities)):
        session = await anyio.to_thread.run_sync(zenoh.open, make_config(peer(connect=(ep,))))
        try:
            yield graph, session
        finally:
            await anyio.to_thread.run_sync(session.close)


def encoded(text: str) -> bytes:
    return bytes(encode_message(REGISTRY, REGISTRY.message(STRING), {"data": text}))


def events(caplog: pytest.LogCaptureFixture, event: str) -> list[str]:
    return [r.getMessage() for r in caplog.records if f"event={event}" in r.getMessage()]


async def test_bad_samples_log_one_line_per_episode_and_good_ones_still_arrive(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger="rwt.zenoh")
    async with linked_with_bare_peer() as (graph, session):
        got: list[dict[str, Any]] = []
        graph.create_subscription("/cam", got.append, STRING)
        key = topic_keyexpr(0, "/cam", dds_type_name(STRING), STRING_HASH)
        publisher: Any = session.declare_publisher(key)
        await until(lambda: bool(publisher.matching_status.matching))
        for n in range(50):
            publisher.put(b"\x00\x01\x00\x00garbage" + bytes([n]))  # not CDR of a String
            publisher.put(encoded("forged"), attachment=b"not an attachment")
        publisher.put(encoded("last"))
        await until(lambda: {"data": "last"} in got)
    assert got == [{"data": "last"}]
    assert len(events(caplog, "zenoh_bad_sample")) == 1


async def test_a_latched_sample_before_its_publishers_token_reaches_a_late_subscriber() -> None:
    async with linked_with_bare_peer() as (graph, session):
        zid = zid_text(bytes(cast("Any", session.info.zid())))
        topic = Topic("/map", dds_type_name(STRING), STRING_HASH, LATCHED_QOS)
        entity = Entity(0, zid, 1, 2, EntityKind.PUBLISHER, "/", "mapper", topic=topic)
        early: list[dict[str, Any]] = []
        graph.create_subscription("/map", early.append, STRING, node="/early")
        publisher: Any = session.declare_publisher(
            topic_keyexpr(0, "/map", topic.dds_type, STRING_HASH)
        )
        await until(lambda: bool(publisher.matching_status.matching))
        publisher.put(encoded("map"), attachment=pack_attachment(1, 0, entity.gid()))
        await until(lambda: len(early) == 1)  # through the link's relay: no token yet
        liveliness: Any = session.liveliness()
        node = liveliness.declare_token(
            Entity(0, zid, 1, 1, EntityKind.NODE, "/", "mapper").token()
        )
        token = liveliness.declare_token(entity.token())
        # the token says transient local: the relay goes, the sample stays latched
        await until(lambda: publishers(graph, EVERYTHING, "/map") == ["/mapper"])
        late: list[dict[str, Any]] = []
        graph.create_subscription("/map", late.append, STRING, node="/late")
        token.undeclare()
        node.undeclare()
    assert late == [{"data": "map"}]
    assert early == [{"data": "map"}]


def publisher_token(zid: str, n: int) -> str:
    topic = Topic(f"/many/t{n}", dds_type_name(STRING), STRING_HASH, VOLATILE_QOS)
    return Entity(0, zid, 1, n + 2, EntityKind.PUBLISHER, "/", "crowd", topic=topic).token()


async def test_tokens_past_the_entity_cap_are_ignored_until_room_frees(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger="rwt.zenoh")
    async with linked_with_bare_peer(max_entities=5) as (graph, session):
        zid = zid_text(bytes(cast("Any", session.info.zid())))
        liveliness: Any = session.liveliness()

        def many() -> list[str]:
            return [name for name in graph.topics if name.startswith("/many/")]

        node = liveliness.declare_token(Entity(0, zid, 1, 1, EntityKind.NODE, "/", "crowd").token())
        tokens = [liveliness.declare_token(publisher_token(zid, n)) for n in range(20)]
        await until(lambda: len(many()) == 4)  # the node and four publishers
        await anyio.sleep(0.3)  # more would arrive meanwhile
        assert sorted(many()) == [f"/many/t{n}" for n in range(4)]
        for token in tokens:
            token.undeclare()
        await until(lambda: not many())
        late = liveliness.declare_token(publisher_token(zid, 99))
        await until(lambda: many() == ["/many/t99"])
        late.undeclare()
        node.undeclare()
    assert len(events(caplog, "zenoh_entity_ignored")) == 1


def sample(size: int, seen: list[bytes] | None = None, tag: bytes = b"") -> Sample:
    def deliver(payload: bytes, _attachment: bytes | None) -> None:
        if seen is not None:
            seen.append(payload)

    return Sample(deliver, tag.ljust(size - SAMPLE_OVERHEAD, b"."), None)


def test_a_full_inbox_drops_the_oldest_of_the_busiest_topic() -> None:
    inbox = Inbox(max_bytes=10_000, max_samples=1000)
    tickets: list[str] = []
    for n in range(20):  # a flood on /cam: 1 KB samples
        if inbox.put("/cam", sample(1000, tag=b"cam%d" % n)):
            tickets.append("/cam")
    if inbox.put("/cmd_vel", sample(300, tag=b"cmd")):  # a quiet topic still gets in
        tickets.append("/cmd_vel")
    assert inbox.bytes <= 10_000
    taken = [inbox.take(topic) for topic in tickets]
    payloads = [s.payload.rstrip(b".") for s in taken if s is not None]
    assert payloads[-1] == b"cmd"
    cams = payloads[:-1]
    assert cams == sorted(cams, key=lambda p: int(p[3:]))  # in order, the newest kept
    assert cams[-1] == b"cam19"
    assert len(cams) < 20
    assert inbox.dropped == 20 - len(cams)
    assert inbox.bytes == 0
    assert inbox.take("/cam") is None  # every ticket redeemed: nothing left behind


def test_a_sample_larger_than_the_inbox_is_dropped_on_arrival() -> None:
    inbox = Inbox(max_bytes=4096)
    assert not inbox.put("/cloud", sample(8192))
    assert inbox.dropped == 1
    assert inbox.bytes == 0
