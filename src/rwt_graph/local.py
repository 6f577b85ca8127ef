"""Handles given to in-process publishers and subscribers (the embedding API)."""

from __future__ import annotations

import contextlib
import logging
from typing import TYPE_CHECKING

from rwt_protocol.errors import GraphError

from .ratelog import EpisodeLog
from .types.wire import check_wire_header

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.ports import ClientId, MessageEvent

    from .core import GraphCore
    from .topics import Topic

__all__ = ["LocalActionServer", "LocalPublisher", "LocalService", "LocalSubscription"]

logger = logging.getLogger("rwt.graph")
_episodes = EpisodeLog(logger)  # a peer can trigger these per message


class LocalPublisher:
    """Publishes on one topic from this process; made by ``Graph.create_publisher``."""

    def __init__(self, port: GraphCore, client: ClientId, entry: Topic, *, latch: bool) -> None:
        self._port = port
        self._client = client
        self._entry = entry  # kept while ``client`` publishes on it (``Topic.in_use``)
        self.topic = entry.name
        self.msgtype = entry.msgtype
        self.latch = latch

    def publish(self, msg: object, *, validated: bool = False, wire: bytes | None = None) -> None:
        """Publish a message given as a dict, a rosbags message object or serialized.

        Missing fields get their defaults (D7) and a missing header stamp is now
        (D8), as for a client's publish.

        A serialized message (``bytes``, ``bytearray`` or ``memoryview``, as
        rclpy's ``Publisher.publish`` takes one) is the dialect's wire form:
        CDR with its 4-byte encapsulation header for ROS 2 (what rclpy's
        ``serialize_message`` gives), the ROS 1 format for ROS 1. It goes to
        the subscribers that send that form as it is (Foxglove clients,
        cbor-raw, the ROS 2 and Zenoh links), and is decoded once, on first
        use, for the others (rosbridge JSON and CBOR subscribers, Python
        callbacks): a robot that has the bytes already (a driver's CDR, a
        recording) so skips the conversion and serialization of a dict, the
        fast path of ``docs/embedding.md``. Only the header is checked here:
        bytes that do not decode as the topic's type reach those subscribers
        as an error (a rosbridge subscriber's error ``status``, a logged
        callback failure), and the others unchanged.

        Args:
            msg: the message.
            validated: the caller vouches that ``msg`` is a dict already in the
                internal form of the topic's type (every field present, in
                declaration order, with the types ``MessageType.from_json`` gives),
                so it is sent unchecked. Only for producers in this process that
                build their messages themselves (the TF republisher); the caller
                keeps ``msg`` unchanged afterwards, as subscribers share it.
            wire: with ``validated``, ``msg`` in the dialect's wire serialization
                as it was read (a bag's record), passed on to subscribers that
                send that form (``MessageEvent.wire``); ignored otherwise.

        Raises:
            FieldError: ``msg`` does not fit the topic's type (``validated`` false).
            CdrError: a serialized ``msg`` of a ROS 2 topic has no CDR
                encapsulation header (a ``ValueError``).
            GraphError: the publisher was closed.
        """
        entry, client = self._entry, self._client
        if client not in entry.publishers:  # ``close``d, or the graph let the client go
            raise GraphError(f"the publisher of {self.topic} was closed")
        # ``deliver``, not ``publish_local``: no look-up by name, a call less per message;
        # positional: a keyword costs 20-40 ns a call, paid per message of a burst
        if type(msg) is bytes:  # serialized: the fewest steps (per message of a burst)
            check_wire_header(self.msgtype.dialect, msg)
            self._port.deliver_wire(entry, self.latch, client, msg)
            return
        if isinstance(msg, (bytearray, memoryview)):
            data = bytes(msg)
            check_wire_header(self.msgtype.dialect, data)
            self._port.deliver_wire(entry, self.latch, client, data)
            return
        if validated:
            assert isinstance(msg, dict)
            self._port.deliver(entry, msg, self.latch, client, wire)
            return
        converted = self.msgtype.from_python(msg, now=self._port.clock.wall())
        self._port.deliver(entry, converted, self.latch, client)

    def close(self) -> None:
        """Stop publishing; the topic goes when nobody else uses it."""
        self._port.unadvertise(self._client, self.topic)
        self._port.nodes.forget(self._client)


class LocalSubscription:
    """Calls a Python callback with each message; made by ``Graph.create_subscription``."""

    def __init__(
        self,
        port: GraphCore,
        client: ClientId,
        topic: str,
        callback: Callable[[dict[str, object]], None],
    ) -> None:
        self._port = port
        self._client = client
        self.topic = topic
        self._callback = callback

    def on_message(self, event: MessageEvent) -> None:
        """Run the callback; its exceptions are logged, never propagated."""
        try:
            self._callback(event.msg)
        except Exception:
            _episodes.log(
                logging.ERROR,
                f"callback_failed {self.topic}",
                "callback of the subscription to %s failed",
                self.topic,
                exc_info=True,
            )

    def close(self) -> None:
        """Stop receiving messages."""
        self._port.unsubscribe(self._client, self.topic)
        self._port.nodes.forget(self._client)


class LocalService:
    """An in-process service; made by ``Graph.create_service``."""

    def __init__(self, port: GraphCore, client: ClientId, service: str) -> None:
        self._port = port
        self._client = client
        self.service = service

    def close(self) -> None:
        """Withdraw the service; pending callers get ``result: false`` (D15)."""
        with contextlib.suppress(GraphError):  # already replaced by a newer advertiser
            self._port.services.unadvertise(self._client, self.service)
        self._port.nodes.forget(self._client)


class LocalActionServer:
    """An in-process action server; made by ``Graph.create_action_server``."""

    def __init__(self, port: GraphCore, client: ClientId, action: str) -> None:
        self._port = port
        self._client = client
        self.action = action

    def close(self) -> None:
        """Withdraw the action; goals in flight abort (D4)."""
        with contextlib.suppress(GraphError):
            self._port.unadvertise_action(self._client, self.action)
        self._port.nodes.forget(self._client)
