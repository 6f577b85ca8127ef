"""A hostile Zenoh peer against a linked server: the server keeps serving a bystander.

Hypothesis drives a bare Zenoh session (loopback only, multicast off) through the
grammar's Zenoh actions (``strategies.zenoh_peer_actions``): liveliness tokens with
odd parts (empty, ``%``, wildcards, huge and negative numbers, lone surrogates,
long strings, too few or too many parts), withdrawals, and samples with garbage
payloads and attachments on topics a WebSocket bystander subscribes to. After each
burst the peer puts one good sample: the bystander must receive it (so the link
still decodes and delivers, in order, after the garbage) and get its publish round
trip and a ``/rosapi/topics`` answer (docs/limits.md, "Zenoh peers").
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import anyio
import pytest
from anyio.from_thread import start_blocking_portal
from hypothesis import given

import zenoh
from rwt_graph.graph import Graph
from rwt_zenoh.config import make_config
from rwt_zenoh.link import open_zenoh_link
from rwt_zenoh.payload import encode_message, type_hash
from rwt_zenoh.wire import topic_keyexpr
from tests.fuzz import driver, grammar
from tests.fuzz.conftest import FUZZ
from tests.fuzz.strategies import zenoh_peer_actions
from tests.support.clients import is_op, running_server
from tests.zenoh.support import endpoint, peer

if TYPE_CHECKING:
    from anyio.abc import TaskStatus
    from anyio.from_thread import BlockingPortal

    from tests.support.clients import Client

STRING = "std_msgs/msg/String"
REGISTRY = Graph().registry
STRING_HASH = type_hash(REGISTRY, STRING)
TIMEOUT_S = 10.0
_tags = itertools.count()


def key_of(topic: str) -> str:
    return topic_keyexpr(0, topic, grammar.STRING_DDS, STRING_HASH)


@dataclass
class LinkedServer:
    """An in-process server linked over Zenoh, its bystander, and the hostile peer's session."""

    portal: BlockingPortal
    session: Any = None
    bystander: Client | None = None
    tokens: dict[str, Any] = field(default_factory=dict)
    publishers: dict[str, Any] = field(default_factory=dict)
    garbage: int = 0  # samples put that are not a good String with a good attachment

    def start(self) -> contextlib.AbstractContextManager[None]:
        ep = endpoint()

        async def host(*, task_status: TaskStatus[tuple[Client, anyio.Event]]) -> None:
            stop = anyio.Event()
            async with (
                running_server() as harness,
                open_zenoh_link(harness.server.graph, peer(listen=ep)),
            ):
                bystander = await harness.connect("ws", "bystander")
                with anyio.fail_after(TIMEOUT_S):
                    for topic in ("/fuzz", "/chatter", "/bystander"):
                        await bystander.send({"op": "subscribe", "topic": topic, "type": STRING})
                    await bystander.send({"op": "advertise", "topic": "/bystander", "type": STRING})
                    await bystander.send({"op": "set_level", "level": "info", "id": "ready"})
                    await bystander.expect(is_op("status", id="ready"))
                task_status.started((bystander, stop))
                await stop.wait()

        future, (self.bystander, stop) = self.portal.start_task(host)
        self.session = zenoh.open(make_config(peer(connect=(ep,))))
        self.publishers = {
            t: self.session.declare_publisher(key_of(t)) for t in ("/fuzz", "/chatter")
        }

        @contextlib.contextmanager
        def running() -> Iterator[None]:
            try:
                yield
            finally:
                self.session.close()
                self.portal.call(stop.set)
                future.result(timeout=30)

        return running()

    def act(self, actions: list[tuple[str, Any]]) -> None:
        """Do what the hostile peer does; what Zenoh itself refuses never reaches the link."""
        liveliness = self.session.liveliness()
        for kind, what in actions:
            with contextlib.suppress(zenoh.ZError, ValueError, UnicodeError):
                if kind == "token" and what not in self.tokens:
                    self.tokens[what] = liveliness.declare_token(what)
                elif kind == "untoken" and what in self.tokens:
                    self.tokens.pop(what).undeclare()
                elif kind == "sample":
                    topic, payload, attachment = what
                    self.publishers[topic].put(payload, attachment=attachment)
                    self.garbage += 1

    async def check(self, tag: str) -> None:
        """The bystander gets the peer's good sample, its own publish, and a rosapi answer."""
        bystander = self.bystander
        assert bystander is not None
        try:
            with anyio.fail_after(TIMEOUT_S):
                await bystander.expect(
                    lambda m: m.get("topic") == "/fuzz" and m.get("msg") == {"data": tag}
                )
                await bystander.send({"op": "publish", "topic": "/bystander", "msg": {"data": tag}})
                await bystander.expect(
                    lambda m: m.get("topic") == "/bystander" and m.get("msg") == {"data": tag}
                )
                await bystander.send({"op": "call_service", "service": "/rosapi/topics", "id": tag})
                reply = await bystander.expect(is_op("service_response", id=tag))
        except Exception as exc:
            raise driver.Violation(f"the bystander was not served: {exc!r}") from exc
        assert reply["result"] is True
        assert "/bystander" in reply["values"]["topics"]
        bystander.backlog.clear()

    def good_sample(self, tag: str) -> None:
        payload = encode_message(REGISTRY, REGISTRY.message(STRING), {"data": tag})
        self.publishers["/fuzz"].put(bytes(payload))


class Lines(logging.Handler):
    """Counts the lines a logger writes."""

    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.count = 0

    def emit(self, record: logging.LogRecord) -> None:
        self.count += 1


@pytest.fixture(scope="module")
def linked() -> Iterator[LinkedServer]:
    with start_blocking_portal("asyncio") as portal:
        state = LinkedServer(portal)
        with state.start():
            yield state


@pytest.fixture
def zenoh_lines() -> Iterator[Lines]:
    lines = Lines()
    logger = logging.getLogger("rwt.zenoh")
    level = logger.level
    logger.addHandler(lines)
    logger.setLevel(logging.INFO)
    try:
        yield lines
    finally:
        logger.removeHandler(lines)
        logger.setLevel(level)


def test_a_hostile_zenoh_peer_leaves_the_bystander_served(
    linked: LinkedServer, zenoh_lines: Lines
) -> None:
    # the peer's good samples reach the bystander only once the link subscribes
    ready = linked.publishers["/fuzz"]
    for _ in range(int(TIMEOUT_S / 0.02)):
        if ready.matching_status.matching:
            break
        time.sleep(0.02)
    assert ready.matching_status.matching

    @FUZZ
    @given(actions=zenoh_peer_actions())
    def burst(actions: list[tuple[str, Any]]) -> None:
        tag = f"zenoh-fuzz-{next(_tags)}"
        linked.act(actions)
        linked.good_sample(tag)
        linked.portal.call(linked.check, tag)

    burst()
    # one log line per episode of each kind of trouble (EpisodeLog), not one per sample:
    # a dozen kinds (bad sample and refused sample per topic, skipped tokens per kind,
    # ignored entities) and their summaries
    if linked.garbage >= 60:
        assert zenoh_lines.count <= 40, (zenoh_lines.count, linked.garbage)
