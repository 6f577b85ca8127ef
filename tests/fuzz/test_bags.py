"""Fuzzed bag player calls and hostile bags keep the hardening invariant.

A server plays a bag (looping, with the ``/rwt/player`` services) while
hypothesis sends bursts of player calls over WebSocket: seeks to NaN,
infinity, ``1e400``, strings, lists, pauses and resumes, with hostile fields.
And the same server is handed hostile bags to play (``tests/bag/hostile.py``:
truncated, decompression bombs with honest and lying sizes, topic names a
client may not use, thousands of topics): each is refused with a ``BagError``
naming the bag, or plays with the bad names skipped. After every example the
bystanders (memory, WebSocket, TCP, UDP) still get their round trip and a
``/rosapi/topics`` answer, and the player still answers ``get_status``.
"""

from __future__ import annotations

import functools
import itertools
import logging
import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import anyio
import pytest
from anyio.from_thread import BlockingPortal, start_blocking_portal
from hypothesis import given, settings
from hypothesis import strategies as st
from websockets.asyncio.client import connect

from rwt_bag import BagError, Player, serve_controls
from rwt_graph.graph import Graph
from rwt_protocol.names import name_problem
from tests.bag import hostile
from tests.bag.bags import write_bag
from tests.fuzz import driver
from tests.fuzz.conftest import FUZZ
from tests.fuzz.strategies import player_calls
from tests.fuzz.test_transports import TIMEOUT_S, check_bystanders, connect_bystanders
from tests.support.clients import Client, Harness, is_op, running_server

_tags = itertools.count()
_WORK = Path(tempfile.mkdtemp(prefix="rwt-fuzz-bags-"))


@dataclass
class PlayingServer:
    """A server playing a bag in a loop, its graph, and its bystanders."""

    portal: BlockingPortal
    harness: Harness | None = None
    graph: Graph | None = None
    bystanders: list[Client] = field(default_factory=list)
    stop: anyio.Event | None = None


@pytest.fixture(scope="module")
def playing() -> Iterator[PlayingServer]:
    bag = write_bag(_WORK / "robot", "mcap")
    with start_blocking_portal("asyncio") as portal:
        state = PlayingServer(portal)

        async def host(*, task_status: anyio.abc.TaskStatus[None]) -> None:
            graph = Graph()
            stop = anyio.Event()
            async with running_server(graph=graph) as harness:
                # the bystanders first, in this task: their cancel scopes are the harness's
                state.bystanders = await connect_bystanders(harness)
                state.harness, state.graph, state.stop = harness, graph, stop
                player = Player(graph, bag, loop=True, rate=4.0)
                services = serve_controls(graph, player)
                try:
                    async with anyio.create_task_group() as tg:
                        await tg.start(player.run)
                        task_status.started()
                        await stop.wait()
                        tg.cancel_scope.cancel()
                finally:
                    for service in services:
                        service.close()

        future, _ = portal.start_task(host)
        try:
            yield state
        finally:
            assert state.stop is not None
            portal.call(state.stop.set)
            future.result(timeout=30)
            _bag.cache_clear()
            shutil.rmtree(_WORK, ignore_errors=True)


async def _player_alive(bystander: Client, tag: str) -> None:
    await bystander.send(
        {"op": "call_service", "service": "/rwt/player/get_status", "id": f"{tag}-status"}
    )
    with anyio.fail_after(TIMEOUT_S):
        reply = await bystander.expect(is_op("service_response", id=f"{tag}-status"))
    if reply.get("result") is not True or reply["values"]["duration"] <= 0:
        raise driver.Violation(f"the player does not answer: {reply}")


async def _calls_example(state: PlayingServer, frames: list[tuple[bytes, bool]]) -> None:
    assert state.harness is not None
    tag = f"fuzz-bag-{next(_tags)}"
    url = f"ws://127.0.0.1:{state.harness.port('websocket')}"
    async with connect(url, max_size=None) as ws:
        await driver.exchange(driver.ws_wire(ws), frames, tag, TIMEOUT_S)
    await check_bystanders(state.bystanders, tag)
    await _player_alive(state.bystanders[0], tag)


class _Tracebacks(logging.Handler):
    """Counts log records that carry a traceback (a hostile call must not make one)."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.exc_info:
            self.records.append(record)


def test_fuzzed_player_calls_keep_the_invariant(playing: PlayingServer) -> None:
    tracebacks = _Tracebacks()
    logging.getLogger().addHandler(tracebacks)

    @FUZZ
    @given(frames=st.lists(player_calls(), min_size=1, max_size=8))
    def burst(frames: list[tuple[bytes, bool]]) -> None:
        playing.portal.call(_calls_example, playing, frames)
        if tracebacks.records:
            record = tracebacks.records[0]
            raise driver.Violation(f"a call logged a traceback: {record.getMessage()}")

    try:
        burst()
    finally:
        logging.getLogger().removeHandler(tracebacks)


# ---- hostile bags -------------------------------------------------------------

MIB = hostile.MIB


@functools.cache
def _bag(kind: str, arg: int) -> Path:
    """The hostile bag ``kind`` with its size parameter, made once per run."""
    where = _WORK / f"{kind}-{arg}"
    where.mkdir()
    if kind == "truncated":
        good = write_bag(where / "good", "ros1")
        return hostile.truncated(good, where / "cut.bag", keep=arg / 10)
    if kind == "bomb-declared":  # refused by its header: cheap however large it claims
        return hostile.mcap_bomb(where / "b.mcap", size=MIB, declared=arg * 1024 * MIB)
    if kind == "bomb-lying":
        return hostile.mcap_bomb(where / "b.mcap", size=arg * 16 * MIB, declared=4096)
    if kind == "bomb-chunks":
        return hostile.mcap_bomb(where / "b.mcap", size=9 * MIB, chunks=arg * 4)
    if kind == "bomb-ros1":
        return hostile.ros1_bomb(where / "b.bag", size=arg * 64 * MIB)
    if kind == "bad-names":
        return hostile.bad_names(where / "names", ("mcap", "sqlite3")[arg % 2])
    assert kind == "many-topics"
    return hostile.many_topics(where / "many", arg * 500)


BAG_KINDS = st.sampled_from(
    [
        "truncated",
        "bomb-declared",
        "bomb-lying",
        "bomb-chunks",
        "bomb-ros1",
        "bad-names",
        "many-topics",
    ]
)


async def _bag_example(state: PlayingServer, kind: str, arg: int) -> None:
    assert state.graph is not None
    bag = await anyio.to_thread.run_sync(_bag, kind, arg)
    graph = state.graph
    tag = f"fuzz-bag-{next(_tags)}"
    try:
        player = Player(graph, bag, topics=["/chatter", "/t*", "/x*", "/a*", "/n*", "/.*"])
        with anyio.fail_after(60):
            await player.run()
    except BagError as exc:
        if str(bag) not in str(exc):
            raise driver.Violation(f"a bag error that does not name the bag: {exc}") from exc
        if kind in ("bad-names", "many-topics"):
            raise driver.Violation(f"a playable bag was refused: {exc}") from exc
    else:
        if kind not in ("bad-names", "many-topics"):
            raise driver.Violation(f"the hostile bag {kind} played")
    bad = [name for name in graph.topics if name_problem(name) is not None]
    if bad:
        raise driver.Violation(f"bad names reached the graph: {bad[:3]}")
    await check_bystanders(state.bystanders, tag)
    await _player_alive(state.bystanders[0], tag)


def test_hostile_bags_are_refused_and_the_server_serves_on(playing: PlayingServer) -> None:
    @settings(parent=FUZZ, max_examples=min(FUZZ.max_examples, 25))
    @given(kind=BAG_KINDS, arg=st.integers(min_value=1, max_value=4))
    def one(kind: str, arg: int) -> None:
        playing.portal.call(_bag_example, playing, kind, arg)

    one()
