"""Topics as MCP resources: list, read the latest message, subscribe to updates.

A topic ``/robot/odom`` is the resource ``ros://topics/robot/odom``
(``TOPIC_URI``). ``resources/list`` lists them ``RESOURCES_PER_PAGE`` at a time,
sorted by name, with MCP's cursor to the next page (``nextCursor``).
``resources/read`` answers the latest message, summarised as
``echo``'s are (``render.message_text``): the one kept for a subscribed topic,
else the first to arrive within ``READ_WAIT_S`` (a latched topic's at once).
``resources/subscribe`` subscribes the session's connection to the topic,
throttled by the server to one message per ``UPDATE_INTERVAL_S``, and sends
``notifications/resources/updated`` at most once per ``UPDATE_INTERVAL_S`` per
topic, however fast it publishes (docs/limits.md, "MCP front end"); a session
subscribes to at most ``MAX_SUBSCRIBED`` topics, and a subscription the server
refuses (``--max-subscriptions``) is an error with the server's reason. Each of
these requests is rated as a tool call is (``guard.Guard.check_rate``).
"""

from __future__ import annotations

import binascii
import contextlib
import logging
from typing import TYPE_CHECKING, Any

import anyio
import pybase64
from mcp.server.fastmcp.exceptions import ToolError
from mcp.server.lowlevel.helper_types import ReadResourceContents
from mcp.shared.exceptions import McpError
from mcp.types import (
    INVALID_PARAMS,
    ErrorData,
    ListResourcesRequest,
    ListResourcesResult,
    Resource,
    ResourceTemplate,
    ServerResult,
)
from pydantic import AnyUrl

from rwt_client import Topic
from rwt_protocol.errors import OpRefusedError, RwtError

from .render import message_text

if TYPE_CHECKING:
    from mcp.server.lowlevel import Server
    from mcp.server.session import ServerSession

    from .guard import Guard
    from .link import RobotLink

__all__ = [
    "MAX_SUBSCRIBED",
    "READ_WAIT_S",
    "RESOURCES_PER_PAGE",
    "TOPIC_URI",
    "UPDATE_INTERVAL_S",
    "TopicResources",
]

logger = logging.getLogger("rwt.mcp")

TOPIC_URI = "ros://topics"
"""A topic's resource URI is this and the topic's name: ``ros://topics/robot/odom``."""
#: Seconds between two updates of one subscribed topic (at most 2 a second).
UPDATE_INTERVAL_S = 0.5
#: Topics one session may subscribe to at once; one more is an error.
MAX_SUBSCRIBED = 16
#: Topics one ``resources/list`` answers; ``nextCursor`` asks for the next ones.
RESOURCES_PER_PAGE = 200
#: Seconds ``resources/read`` waits for a message of a topic not subscribed.
READ_WAIT_S = 2.0


def topic_of(uri: AnyUrl | str) -> str:
    """The topic name of a resource URI.

    Raises:
        McpError: not a ``ros://topics/...`` URI.
    """
    text = str(uri)
    prefix = TOPIC_URI + "/"
    if not text.startswith(prefix) or len(text) == len(prefix):
        raise McpError(ErrorData(code=INVALID_PARAMS, message=f"uri {text}: not {prefix}<topic>"))
    return "/" + text[len(prefix) :]


def _refused(message: str) -> McpError:
    return McpError(ErrorData(code=INVALID_PARAMS, message=message))


def _cursor(after: str) -> str:
    """The cursor of the page after topic ``after`` (opaque to the client, MCP's rule)."""
    return pybase64.urlsafe_b64encode(after.encode()).decode()


def _after(cursor: str | None) -> str:
    """The topic a cursor continues after; "" for the first page.

    Raises:
        McpError: not a cursor this server gave.
    """
    if cursor is None:
        return ""
    try:
        after = pybase64.b64decode(cursor, altchars="-_", validate=True).decode()
    except (binascii.Error, ValueError):
        after = ""
    if not after.startswith("/"):
        raise _refused(f"cursor {cursor[:64]!r}: not a cursor of this server's resources/list")
    return after


class _Watch:
    """One subscribed topic: its subscription and the latest message."""

    def __init__(self, topic: Topic) -> None:
        self.topic = topic
        self.latest: Any = None
        self.fresh = False


class TopicResources:
    """The topics of the robot behind ``link`` as resources of ``server``.

    Args:
        link: the session's connection.
        guard: the session's access rules (a topic they refuse is an error).
    """

    def __init__(self, link: RobotLink, guard: Guard) -> None:
        self.link = link
        self.guard = guard
        self.watched: dict[str, _Watch] = {}
        self._session: ServerSession | None = None
        self._changed = anyio.Event()
        self._notifying = False

    def register(self, server: Server[Any, Any]) -> None:
        """Answer ``resources/*`` requests on ``server`` (the FastMCP's low-level server)."""

        async def list_page(request: ListResourcesRequest) -> ServerResult:
            cursor = request.params.cursor if request.params is not None else None
            return ServerResult(await self.list_resources(cursor))

        # a paginated answer needs the request: the handler is registered as the SDK's
        # decorator would register a new-style one
        server.request_handlers[ListResourcesRequest] = list_page
        # the SDK's decorators are untyped; each registers the handler it is given
        server.list_resource_templates()(self.list_templates)  # type: ignore[no-untyped-call]
        server.read_resource()(self.read)  # type: ignore[no-untyped-call]

        async def subscribe(uri: AnyUrl) -> None:
            await self.subscribe(uri, server.request_context.session)

        server.subscribe_resource()(subscribe)  # type: ignore[no-untyped-call]
        server.unsubscribe_resource()(self.unsubscribe)  # type: ignore[no-untyped-call]

    async def list_resources(self, cursor: str | None = None) -> ListResourcesResult:
        """A page of the robot's topics, each with its type as description.

        Args:
            cursor: the ``nextCursor`` of the page before; None: the first page.

        Returns:
            At most ``RESOURCES_PER_PAGE`` topics, sorted by name, after the
            cursor's; ``nextCursor`` when more follow. A topic that appears or
            goes between two pages is listed or not, as it sorts.

        Raises:
            McpError: a cursor this server did not give, the rate cap, or the
                connection down.
        """
        self._rated("resources/list")
        after = _after(cursor)
        try:
            topics = await (await self.link.connected()).get_topics_and_types()
        except (RwtError, ToolError) as exc:
            raise _refused(str(exc)) from None
        names = sorted(name for name in topics if name > after)
        page = names[:RESOURCES_PER_PAGE]
        resources = [
            Resource(
                uri=AnyUrl(TOPIC_URI + name if name.startswith("/") else f"{TOPIC_URI}/{name}"),
                name=name,
                description=topics[name],
                mimeType="application/json",
            )
            for name in page
        ]
        more = len(names) > len(page)
        return ListResourcesResult(
            resources=resources, nextCursor=_cursor(page[-1]) if more else None
        )

    async def list_templates(self) -> list[ResourceTemplate]:
        """One template: ``ros://topics/{topic}``."""
        return [
            ResourceTemplate(
                uriTemplate=TOPIC_URI + "/{topic}",
                name="topic",
                description="a topic's latest message, summarised (subscribe for updates)",
                mimeType="application/json",
            )
        ]

    async def read(self, uri: AnyUrl) -> list[ReadResourceContents]:
        """The topic's latest message as JSON text (summarised, ``render.message_text``).

        Raises:
            McpError: a bad URI, a topic the rules refuse, no message within
                ``READ_WAIT_S``, or the connection down.
        """
        self._rated("resources/read")
        topic = self._allowed(uri)
        watch = self.watched.get(topic)
        if watch is not None and watch.latest is not None:
            return [ReadResourceContents(message_text(watch.latest), "application/json")]
        got: list[Any] = []
        arrived = anyio.Event()

        def take(msg: Any) -> None:
            if not got:
                got.append(msg)
                arrived.set()

        try:
            subscription = Topic(await self.link.connected(), topic)
            await subscription.subscribe(take, confirm=True)
            try:
                with anyio.move_on_after(READ_WAIT_S):
                    await arrived.wait()
            finally:
                await subscription.unsubscribe()
        except OpRefusedError as exc:
            raise _refused(
                f"uri {uri}: the server refused the subscription: {exc.reason}"
            ) from None
        except (RwtError, ToolError) as exc:
            raise _refused(str(exc)) from None
        if not got:
            raise _refused(f"{topic}: no message within {READ_WAIT_S:g} s (READ_WAIT_S)")
        return [ReadResourceContents(message_text(got[0]), "application/json")]

    async def subscribe(self, uri: AnyUrl, session: ServerSession) -> None:
        """Subscribe to the topic; updates go to ``session`` (``UPDATE_INTERVAL_S``).

        Raises:
            McpError: a bad URI, a topic the rules refuse, ``MAX_SUBSCRIBED``
                topics subscribed already, a subscription the server refused
                (``--max-subscriptions``: its status text), or the connection down.
        """
        self._rated("resources/subscribe")
        topic = self._allowed(uri)
        self._session = session
        if topic in self.watched:
            return
        if len(self.watched) >= MAX_SUBSCRIBED:
            raise _refused(f"uri {uri}: {MAX_SUBSCRIBED} topics are subscribed (MAX_SUBSCRIBED)")
        throttle_ms = int(UPDATE_INTERVAL_S * 1000)
        try:
            ros = await self.link.connected()
            watch = _Watch(Topic(ros, topic, throttle_rate=throttle_ms, queue_length=1))

            def take(msg: Any) -> None:
                watch.latest, watch.fresh = msg, True
                self._changed.set()

            await watch.topic.subscribe(take, confirm=True)
        except OpRefusedError as exc:
            raise _refused(
                f"uri {uri}: the server refused the subscription: {exc.reason}"
            ) from None
        except (RwtError, ToolError) as exc:
            raise _refused(str(exc)) from None
        self.watched[topic] = watch
        if not self._notifying:
            self._notifying = True
            ros.spawn(self._notify)

    async def unsubscribe(self, uri: AnyUrl) -> None:
        """Stop the topic's updates (nothing if it was not subscribed)."""
        watch = self.watched.pop(topic_of(uri), None)
        if watch is not None:
            with contextlib.suppress(RwtError):  # the connection is down: nothing to undo
                await watch.topic.unsubscribe()

    async def _notify(self) -> None:
        """Send ``notifications/resources/updated`` for changed topics, each round a pause."""
        while self._session is not None:
            await self._changed.wait()
            self._changed = anyio.Event()
            for topic, watch in list(self.watched.items()):
                if watch.fresh:
                    watch.fresh = False
                    try:
                        await self._session.send_resource_updated(AnyUrl(TOPIC_URI + topic))
                    except (anyio.ClosedResourceError, anyio.BrokenResourceError):
                        return  # the MCP session ended
            await anyio.sleep(UPDATE_INTERVAL_S)

    def _allowed(self, uri: AnyUrl) -> str:
        topic = topic_of(uri)
        try:
            self.guard.check_access("topics_sub", topic, "uri topic")
        except ToolError as exc:
            raise _refused(str(exc)) from None
        return topic

    def _rated(self, request: str) -> None:
        """The session's rate cap for ``request``, as a tool's (``Guard.check_rate``)."""
        try:
            self.guard.check_rate(request)
        except ToolError as exc:
            raise _refused(str(exc)) from None
