"""The rosbridge server: listeners, one graph, one session per connection.

``RosbridgeServer`` owns the graph and starts listeners on it; every transport
makes a ``rwt_protocol.session.Session`` per connection (D22: one dispatcher
behind all transports). The server also keeps the latched ``/client_count``
and ``/connected_clients`` topics that rosbridge publishes (PROTOCOL-DECISIONS
D14), from node ``/rosbridge_websocket``, offers rosapi (REF §7.1) from node
``/rosapi`` and tf2_web_republisher (REF §7.3) from node ``/tf2_web_republisher``.
Each connection is a node of its own (``/rwt_client_<n>``).
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field

import anyio
from anyio.abc import SocketAttribute, SocketStream, TaskGroup, TaskStatus

from rwt_graph.calls import Spawner
from rwt_graph.graph import Graph
from rwt_graph.local import LocalPublisher
from rwt_graph.rosapi import Rosapi, VisibilityFor, install_rosapi
from rwt_graph.tf import TFRepublisher
from rwt_graph.types.convert import time_value
from rwt_protocol.errors import RwtError
from rwt_protocol.session import Session, SessionConfig

from .tf import install_tf_republisher
from .websocket import WebSocketOptions, serve_websocket_connection

__all__ = ["SERVER_NODE", "RosbridgeServer", "ServerConfig", "spawner_for"]

logger = logging.getLogger("rwt.server")

#: The node of the server's own publishers, as rosbridge names it.
SERVER_NODE = "/rosbridge_websocket"


@dataclass(frozen=True)
class ServerConfig:
    """Settings of a server (names follow rosbridge_websocket's parameters).

    Attributes:
        host: address to bind (``--host``; 127.0.0.1 by default).
        port: WebSocket port (``--port``; 0 picks a free one).
        session: per-connection protocol settings.
        websocket: WebSocket settings.
        rosapi: offer the ``/rosapi/*`` services.
        rosapi_visibility: what each client may see through rosapi (access rules);
            None shows everything.
        tf: offer tf2_web_republisher's action and service with a TF buffer fed by
            ``/tf`` and ``/tf_static`` (``rwt serve --no-tf`` turns it off).
    """

    host: str = "127.0.0.1"
    port: int = 9090
    session: SessionConfig = field(default_factory=SessionConfig)
    websocket: WebSocketOptions = field(default_factory=WebSocketOptions)
    rosapi: bool = True
    rosapi_visibility: VisibilityFor | None = None
    tf: bool = True


class RosbridgeServer:
    """Serves one graph to rosbridge clients.

    Args:
        graph: the graph to serve; a new ROS 2 graph by default.
        config: server settings.
    """

    def __init__(self, graph: Graph | None = None, config: ServerConfig | None = None) -> None:
        self.graph = graph or Graph()
        self.config = config or ServerConfig()
        self.sessions: dict[str, Session] = {}
        self._connected: dict[str, dict[str, object]] = {}
        self._ids = itertools.count(1)
        self._client_count = _latched(self.graph, "/client_count", "std_msgs/msg/Int32")
        self._connected_clients = _latched(
            self.graph, "/connected_clients", "rosbridge_msgs/msg/ConnectedClients"
        )
        self._publish_clients()
        self.rosapi: Rosapi | None = None
        if self.config.rosapi:
            self.rosapi = install_rosapi(self.graph, visibility=self.config.rosapi_visibility)
        self.tf: TFRepublisher | None = None
        if self.config.tf:
            self.tf = install_tf_republisher(self.graph)

    async def serve(
        self,
        *,
        task_status: TaskStatus[str] = anyio.TASK_STATUS_IGNORED,
        on_listening: Callable[[str], None] | None = None,
    ) -> None:
        """Listen for WebSocket connections until cancelled.

        Args:
            task_status: receives the URL (``ws://HOST:PORT``) once listening,
                for ``TaskGroup.start``.
            on_listening: called with the same URL, for the CLI's first line.

        Raises:
            OSError: the address cannot be bound.
        """
        listener = await anyio.create_tcp_listener(
            local_host=self.config.host, local_port=self.config.port, reuse_port=False
        )
        async with listener, anyio.create_task_group() as tg:
            self.graph.spawner = spawner_for(tg)
            port = listener.extra(SocketAttribute.local_port)
            url = f"ws://{_url_host(self.config.host)}:{port}"
            logger.info("listening on %s", url)
            if on_listening is not None:
                on_listening(url)
            task_status.started(url)
            try:
                await listener.serve(self._handle_websocket, task_group=tg)
            finally:
                self.graph.spawner = None

    async def _handle_websocket(self, stream: SocketStream) -> None:
        peer = _peer(stream)
        try:
            await serve_websocket_connection(stream, peer, self._new_session, self.config.websocket)
        except Exception:  # one broken connection must never take the server down
            logger.exception("connection from %s failed", peer)

    def _new_session(self, peer: str, on_output: Callable[[], None]) -> Session:
        client_id = f"ws:{peer}#{next(self._ids)}"
        session = _TrackedSession(self, self.graph, client_id, self.config.session, on_output)
        address = _address(peer)
        self.graph.nodes.attach(client_id, host=address)
        self.sessions[client_id] = session
        self._connected[client_id] = {
            "ip_address": address,
            "connection_time": time_value(self.graph.clock.wall(), self.graph.registry.dialect),
        }
        self._publish_clients()
        return session

    def _session_closed(self, client_id: str) -> None:
        self.sessions.pop(client_id, None)
        self._connected.pop(client_id, None)
        self._publish_clients()

    def _publish_clients(self) -> None:
        """Publish ``/client_count`` and ``/connected_clients`` (D14), both latched."""
        if self._client_count is not None:
            self._client_count.publish({"data": len(self.sessions)})
        if self._connected_clients is not None:
            clients = [
                {"ip_address": info["ip_address"], "connection_time": info["connection_time"]}
                for info in self._connected.values()
            ]
            self._connected_clients.publish({"clients": clients})


class _TrackedSession(Session):
    """A session that tells its server when it closes."""

    def __init__(
        self,
        server: RosbridgeServer,
        graph: Graph,
        client_id: str,
        config: SessionConfig,
        on_output: Callable[[], None],
    ) -> None:
        super().__init__(graph, client_id, config=config, on_output=on_output)
        self._server = server

    def close(self) -> None:
        was_closed = self.closed
        super().close()
        if not was_closed:
            self._server._session_closed(self.client_id)


def spawner_for(tg: TaskGroup) -> Spawner:
    """A graph spawner running jobs in ``tg``; each job can be cancelled alone."""

    def spawn(job: Callable[[], Awaitable[None]]) -> Callable[[], None]:
        scope = anyio.CancelScope()

        async def run() -> None:
            with scope:
                await job()

        tg.start_soon(run)
        return scope.cancel

    return spawn


def _latched(graph: Graph, topic: str, type_name: str) -> LocalPublisher | None:
    try:
        return graph.create_publisher(topic, type_name, latch=True, node=SERVER_NODE)
    except RwtError as exc:  # a registry without the type: no such topic
        logger.warning("not publishing %s: %s", topic, exc.message)
        return None


def _address(peer: str) -> str:
    """The address part of ``HOST:PORT`` (IPv6 addresses keep their colons)."""
    host, sep, _ = peer.rpartition(":")
    return host if sep else peer


def _peer(stream: SocketStream) -> str:
    address = stream.extra(SocketAttribute.remote_address, None)
    if isinstance(address, tuple):
        return f"{address[0]}:{address[1]}"
    return str(address) if address else "unknown"


def _url_host(host: str) -> str:
    return f"[{host}]" if ":" in host else host
