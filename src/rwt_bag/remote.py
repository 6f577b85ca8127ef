"""``rwt record URL OUT``: record any rosbridge server, as a client.

The topics of the remote server (from rosapi, looked up again every
``discover_s``) that match the patterns are subscribed to with roslibpy's
options (CBOR by default: binary arrays without base64) and republished into a
local graph, which a ``Recorder`` records. The local graph checks each message
against the type the server names, with the local registry's definitions
(``--interfaces`` adds custom ones); a topic of an unknown type is skipped with
a warning, not recorded with a guessed definition.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import anyio

from rwt_client import Ros, Topic
from rwt_graph.graph import Graph
from rwt_protocol.errors import GraphError, RwtError

from .reader import is_latched
from .recorder import Recorder
from .selection import TopicSelection

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence
    from pathlib import Path

    from anyio.abc import TaskStatus

    from rwt_graph.local import LocalPublisher
    from rwt_graph.types import TypeRegistry

    from .formats import BagFormat, Compression, SplitPolicy

__all__ = ["RemoteRecorder"]

logger = logging.getLogger("rwt.bag")


class RemoteRecorder:
    """Records topics of the rosbridge server at ``url`` into a bag.

    Args:
        url: ``ws://``, ``wss://`` or ``tcp://`` address of the server.
        path: the bag to create.
        registry: the local types (its dialect must fit the server's messages).
        topics: glob patterns of the topics to record; all by default.
        selection: the topics with regular expressions and exclusions; replaces
            ``topics`` when given.
        fmt, split, repeat_latched: as ``Recorder``.
        chunk_compression: as ``Recorder``'s ``compression`` (MCAP chunks).
        compression: the subscriptions' compression (``cbor`` or ``none``).
        discover_s: seconds between rosapi lookups of new topics.

    Attributes:
        recorder: the ``Recorder`` of the local graph (its ``stats``).
        started: set once connected and subscribed to the topics found first.
    """

    def __init__(
        self,
        url: str,
        path: Path,
        registry: TypeRegistry,
        *,
        topics: Sequence[str] = ("*",),
        fmt: BagFormat | str = "mcap",
        split: SplitPolicy | None = None,
        compression: str = "cbor",
        discover_s: float = 1.0,
        selection: TopicSelection | None = None,
        chunk_compression: Compression | None = None,
        repeat_latched: bool = True,
    ) -> None:
        self.url = url
        self.graph = Graph(registry)
        self.selection = selection or TopicSelection(tuple(topics))
        self.recorder = Recorder(
            self.graph,
            path,
            fmt=fmt,
            split=split,
            selection=self.selection,
            compression=chunk_compression,
            repeat_latched=repeat_latched,
        )
        self._compression = compression
        self._discover_s = discover_s
        self._bridged: dict[str, Topic] = {}
        self._skipped: set[str] = set()
        self._stop = anyio.Event()
        self.started = anyio.Event()

    async def run(self, *, task_status: TaskStatus[None] = anyio.TASK_STATUS_IGNORED) -> None:
        """Record until ``stop`` or cancelled.

        Raises:
            BagError: the bag cannot be created.
            TransportError, OSError: the server cannot be reached.
        """
        async with Ros(self.url) as ros, anyio.create_task_group() as tg:
            await tg.start(self.recorder.run)
            await self._discover(ros)
            self.started.set()
            task_status.started()
            while not self._stop.is_set():
                with anyio.move_on_after(self._discover_s):
                    await self._stop.wait()
                if not self._stop.is_set():
                    await self._discover(ros)
            tg.cancel_scope.cancel()  # the recorder writes the rest and closes the bag

    def stop(self) -> None:
        """End ``run`` gracefully: the bag is closed, then the connection.

        (Cancelling ``run`` also closes the bag, but interrupts the client's
        close handshake.)
        """
        self._stop.set()

    async def _discover(self, ros: Ros) -> None:
        try:
            found = await ros.get_topics_and_types()
        except RwtError as exc:  # a server without rosapi: only already-bridged topics
            logger.warning("event=record_discovery_failed reason=%s", exc)
            return
        for name, type_name in found.items():
            if name in self._bridged or name in self._skipped:
                continue
            if not self.selection.matches(name):
                continue
            await self._bridge(ros, name, type_name)
        self.recorder.discover()

    async def _bridge(self, ros: Ros, name: str, type_name: str) -> None:
        try:
            msgtype = self.graph.registry.message(type_name)
            latched = is_latched(name, msgtype.rosbags_name, None)
            publisher = self.graph.create_publisher(
                name, type_name, latch=latched, node="/rwt_record_bridge"
            )
        except GraphError as exc:
            logger.warning("event=record_skip topic=%s type=%s reason=%s", name, type_name, exc)
            self._skipped.add(name)
            return
        self.recorder.discover()  # subscribe before the first message arrives
        topic = Topic(ros, name, type_name, compression=self._compression)
        await topic.subscribe(_republish(publisher))
        self._bridged[name] = topic


def _republish(publisher: LocalPublisher) -> Callable[[object], None]:
    def on_message(msg: object) -> None:
        try:
            publisher.publish(msg)
        except GraphError as exc:  # a message the local definition refuses
            logger.warning("event=record_refused topic=%s reason=%s", publisher.topic, exc)

    return on_message
