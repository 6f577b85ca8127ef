"""Topics as MCP resources: list, read the latest message, subscribe to updates.

A topic ``/robot/odom`` is the resource ``ros://topics/robot/odom``
(``TOPIC_URI``). ``resources/list`` lists them ``RESOURCES_PER_PAGE`` at a time,
sorted by name, with MCP's cursor to the next page (``nextCursor``).
The first page starts with the robot app (``app.APP_URI``, MCP Apps), whose
``resources/read`` is its HTML. ``resources/read`` of a topic answers the latest
message, summarised as
``echo``'s are (``render.message_text``): the one kept for a subscribed topic,
else the first to arrive within ``READ_WAIT_S`` (a latched topic's at once).
Both ask the topic for its latest message (``LATEST``, protocol 2.1.0's ``qos``,
D63): the newest a transient-local topic keeps, at once, and never a policy the
topic's offer cannot meet (D64).
``resources/subscribe`` (2025-era clients) and ``subscriptions/listen`` with
``resourceSubscriptions`` (2026-07-28 clients, D52) subscribe the session's
connection to the topic, throttled by the server to one message per
``UPDATE_INTERVAL_S``, and send ``notifications/resources/updated`` (on the
session's event stream, or the listen request's) at most once per
``UPDATE_INTERVAL_S`` per topic, however fast it publishes (docs/limits.md, "MCP
front end"); a listen stream's topics are unsubscribed when it ends. A session
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
from mcp.server.mcpserver.exceptions import ToolError
from mcp.server.subscriptions import InMemorySubscriptionBus, ListenHandler, ResourceUpdated
from mcp.shared.exceptions import MCPError
from mcp.types import (
    INVALID_PARAMS,
    EmptyResult,
    ListResourcesResult,
    ListResourceTemplatesResult,
    PaginatedRequestParams,
    ReadResourceRequestParams,
    ReadResourceResult,
    RequestParams,
    Resource,
    ResourceTemplate,
    SubscribeRequestParams,
    SubscriptionsListenRequestParams,
    SubscriptionsListenResult,
    TextResourceContents,
    UnsubscribeRequestParams,
)

from rwt_protocol.errors import OpRefusedError, RwtError
from rwt_protocol.qos import Durability, QosProfile, Reliability

from .app import APP_MIME, APP_URI, AppSite, app_html, app_resource_meta
from .render import message_text

if TYPE_CHECKING:
    from mcp.server.context import ServerRequestContext
    from mcp.server.lowlevel import Server
    from mcp.server.session import ServerSession

    from .guard import Guard
    from .link import RobotLink
    from .robot import Subscription

__all__ = [
    "LATEST",
    "MAX_SUBSCRIBED",
    "READ_WAIT_S",
    "RESOURCES_PER_PAGE",
    "TOPIC_URI",
    "UPDATE_INTERVAL_S",
    "TopicResources",
    "Watched",
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

LATEST = QosProfile(
    depth=1, reliability=Reliability.BEST_AVAILABLE, durability=Durability.BEST_AVAILABLE
)
"""What a topic resource asks of its topic (D63): its latest message. Depth 1: of what a
transient-local topic keeps, the newest (with no ``qos`` a subscription takes all it
keeps, oldest first); ``best_available``: what the offer gives, so no offer leaves it
out (D64)."""


def topic_of(uri: str) -> str:
    """The topic name of a resource URI.

    Raises:
        MCPError: not a ``ros://topics/...`` URI.
    """
    text = str(uri)
    prefix = TOPIC_URI + "/"
    if not text.startswith(prefix) or len(text) == len(prefix):
        raise MCPError(INVALID_PARAMS, f"uri {text}: not {prefix}<topic>")
    return "/" + text[len(prefix) :]


def _refused(message: str) -> MCPError:
    return MCPError(INVALID_PARAMS, message)


def _cursor(after: str) -> str:
    """The cursor of the page after topic ``after`` (opaque to the client, MCP's rule)."""
    return pybase64.urlsafe_b64encode(after.encode()).decode()


def _after(cursor: str | None) -> str:
    """The topic a cursor continues after; "" for the first page.

    Raises:
        MCPError: not a cursor this server gave.
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

    def __init__(self) -> None:
        self.subscription: Subscription | None = None
        self.latest: Any = None
        self.fresh = False


Watched = dict[str, _Watch]
"""Topics watched, by name: ``TopicResources.shared``."""


class TopicResources:
    """The topics of the robot behind ``link`` as resources of ``server``.

    Args:
        link: the session's connection.
        guard: the session's access rules (a topic they refuse is an error).
        shared: the topics watched by the front end's other servers, whose latest
            message a read answers too (a 2026-07-28 request reads what another
            request's listen stream holds); None: this server's own only.
    """

    def __init__(
        self,
        link: RobotLink,
        guard: Guard,
        shared: dict[str, _Watch] | None = None,
        site: AppSite | None = None,
    ) -> None:
        self.link = link
        self.guard = guard
        self.site = site or AppSite()
        self.watched: dict[str, _Watch] = {}
        self.shared = shared if shared is not None else self.watched
        self.bus = InMemorySubscriptionBus()  # the listen streams' (2026-07-28)
        self._holders: dict[str, int] = {}  # topic: listen streams and a subscribe
        self._session: ServerSession | None = None
        self._changed = anyio.Event()
        self._notifying = False

    def register(self, server: Server[Any]) -> None:
        """Answer ``resources/*`` and ``subscriptions/listen`` on ``server`` (its low level)."""

        async def list_page(
            _ctx: ServerRequestContext[Any, Any], params: PaginatedRequestParams | None
        ) -> ListResourcesResult:
            return await self.list_resources(params.cursor if params is not None else None)

        async def templates(
            _ctx: ServerRequestContext[Any, Any], _params: PaginatedRequestParams | None
        ) -> ListResourceTemplatesResult:
            return ListResourceTemplatesResult(resource_templates=await self.list_templates())

        async def read(
            _ctx: ServerRequestContext[Any, Any], params: ReadResourceRequestParams
        ) -> ReadResourceResult:
            if params.uri == APP_URI:
                self._rated("resources/read")
                app = TextResourceContents(
                    uri=APP_URI,
                    text=app_html(),
                    mime_type=APP_MIME,
                    _meta=app_resource_meta(self.site),
                )
                return ReadResourceResult(contents=[app])
            text = await self.read(params.uri)
            contents = TextResourceContents(uri=params.uri, text=text, mime_type="application/json")
            return ReadResourceResult(contents=[contents])

        async def subscribe(
            ctx: ServerRequestContext[Any, Any], params: SubscribeRequestParams
        ) -> EmptyResult:
            await self.subscribe(params.uri, ctx.session)
            return EmptyResult()

        async def unsubscribe(
            _ctx: ServerRequestContext[Any, Any], params: UnsubscribeRequestParams
        ) -> EmptyResult:
            await self.unsubscribe(params.uri)
            return EmptyResult()

        listen = ListenHandler(self.bus)

        async def listen_topics(
            ctx: ServerRequestContext[Any, Any], params: SubscriptionsListenRequestParams
        ) -> SubscriptionsListenResult:
            uris = list(params.notifications.resource_subscriptions or ())
            held: list[str] = []
            try:
                for uri in uris[: MAX_SUBSCRIBED + 1]:
                    await self.subscribe(uri, None)
                    held.append(uri)
                return await listen(ctx, params)
            finally:
                for uri in held:
                    await self.unsubscribe(uri, listening=True)

        handlers: tuple[tuple[str, type[RequestParams], Any], ...] = (
            ("resources/list", PaginatedRequestParams, list_page),
            ("resources/templates/list", PaginatedRequestParams, templates),
            ("resources/read", ReadResourceRequestParams, read),
            ("resources/subscribe", SubscribeRequestParams, subscribe),
            ("resources/unsubscribe", UnsubscribeRequestParams, unsubscribe),
            ("subscriptions/listen", SubscriptionsListenRequestParams, listen_topics),
        )
        for method, params_type, handler in handlers:  # each handler takes its params type
            server.add_request_handler(method, params_type, handler)

    async def list_resources(self, cursor: str | None = None) -> ListResourcesResult:
        """A page of the robot's topics, each with its type as description.

        Args:
            cursor: the ``nextCursor`` of the page before; None: the first page.

        Returns:
            At most ``RESOURCES_PER_PAGE`` topics, sorted by name, after the
            cursor's; ``nextCursor`` when more follow. A topic that appears or
            goes between two pages is listed or not, as it sorts.

        Raises:
            MCPError: a cursor this server did not give, the rate cap, or the
                connection down.
        """
        self._rated("resources/list")
        after = _after(cursor)
        try:
            topics = await (await self.link.connected()).get_topics_and_types()
        except (RwtError, ToolError) as exc:
            raise _refused(str(exc)) from None
        names = sorted(name for name in topics if name > after)
        page = names[: RESOURCES_PER_PAGE - (cursor is None)]  # the first page holds the app
        resources = [
            Resource(
                uri=TOPIC_URI + name if name.startswith("/") else f"{TOPIC_URI}/{name}",
                name=name,
                description=topics[name],
                mime_type="application/json",
            )
            for name in page
        ]
        if cursor is None:  # the robot app first (MCP Apps), then the topics
            app = Resource(
                uri=APP_URI,
                name="robot app",
                description="the camera and a pad that drives the robot while held "
                "(the robot_app tool's app)",
                mime_type=APP_MIME,
            )
            resources.insert(0, app)
        more = len(names) > len(page)
        return ListResourcesResult(
            resources=resources, next_cursor=_cursor(page[-1]) if more else None
        )

    async def list_templates(self) -> list[ResourceTemplate]:
        """One template: ``ros://topics/{topic}``."""
        return [
            ResourceTemplate(
                uri_template=TOPIC_URI + "/{topic}",
                name="topic",
                description="a topic's latest message, summarised (subscribe for updates)",
                mime_type="application/json",
            )
        ]

    async def read(self, uri: str) -> str:
        """The topic's latest message as JSON text (summarised, ``render.message_text``).

        Raises:
            MCPError: a bad URI, a topic the rules refuse, no message within
                ``READ_WAIT_S``, or the connection down.
        """
        self._rated("resources/read")
        topic = self._allowed(uri)
        watch = self.watched.get(topic) or self.shared.get(topic)
        if watch is not None and watch.latest is not None:
            return message_text(watch.latest)
        got: list[Any] = []
        arrived = anyio.Event()

        def take(msg: Any) -> None:
            if not got:
                got.append(msg)
                arrived.set()

        try:
            ros = await self.link.connected()
            subscription = await ros.subscribe(topic, None, take, qos=LATEST)
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
        return message_text(got[0])

    async def subscribe(self, uri: str, session: ServerSession | None) -> None:
        """Subscribe to the topic; updates go to ``session`` and the listen streams.

        Args:
            uri: the topic's resource URI.
            session: a 2025-era session's (``resources/subscribe``); None: a
                listen stream's (2026-07-28), which unsubscribes when it ends.

        Raises:
            MCPError: a bad URI, a topic the rules refuse, ``MAX_SUBSCRIBED``
                topics subscribed already, a subscription the server refused
                (``--max-subscriptions``: its status text), or the connection down.
        """
        self._rated("resources/subscribe")
        topic = self._allowed(uri)
        if session is not None:
            self._session = session
        if topic not in self.watched:
            await self._watch(uri, topic)
        if session is None:
            self._holders[topic] = self._holders.get(topic, 0) + 1

    async def _watch(self, uri: str, topic: str) -> None:
        """Subscribe the connection to ``topic``, throttled (``UPDATE_INTERVAL_S``)."""
        if len(self.watched) >= MAX_SUBSCRIBED:
            raise _refused(f"uri {uri}: {MAX_SUBSCRIBED} topics are subscribed (MAX_SUBSCRIBED)")
        throttle_ms = int(UPDATE_INTERVAL_S * 1000)
        try:
            ros = await self.link.connected()
            watch = _Watch()

            def take(msg: Any) -> None:
                watch.latest, watch.fresh = msg, True
                self._changed.set()

            watch.subscription = await ros.subscribe(
                topic, None, take, throttle_ms=throttle_ms, queue_length=1, qos=LATEST
            )
        except OpRefusedError as exc:
            raise _refused(
                f"uri {uri}: the server refused the subscription: {exc.reason}"
            ) from None
        except (RwtError, ToolError) as exc:
            raise _refused(str(exc)) from None
        self.watched[topic] = self.shared[topic] = watch
        if not self._notifying:
            self._notifying = True
            ros.spawn(self._notify)

    async def unsubscribe(self, uri: str, *, listening: bool = False) -> None:
        """Stop the topic's updates (nothing if it was not subscribed).

        Args:
            uri: the topic's resource URI.
            listening: a listen stream's end: the topic stays while another
                stream or a ``resources/subscribe`` holds it.
        """
        topic = topic_of(uri)
        if listening:
            left = self._holders.get(topic, 0) - 1
            if left > 0:
                self._holders[topic] = left
                return
            self._holders.pop(topic, None)
        watch = self.watched.pop(topic, None)
        if watch is not None:
            if self.shared.get(topic) is watch:
                del self.shared[topic]
            with contextlib.suppress(RwtError):  # the connection is down: nothing to undo
                if watch.subscription is not None:
                    await watch.subscription.unsubscribe()

    async def _notify(self) -> None:
        """Send ``notifications/resources/updated`` for changed topics, each round a pause."""
        while True:
            await self._changed.wait()
            self._changed = anyio.Event()
            for topic, watch in list(self.watched.items()):
                if watch.fresh:
                    watch.fresh = False
                    uri = TOPIC_URI + topic
                    await self.bus.publish(ResourceUpdated(uri))  # the listen streams
                    if self._session is not None:
                        try:
                            await self._session.send_resource_updated(uri)
                        except (anyio.ClosedResourceError, anyio.BrokenResourceError):
                            self._session = None  # the MCP session ended
            await anyio.sleep(UPDATE_INTERVAL_S)

    def _allowed(self, uri: str) -> str:
        topic = topic_of(uri)
        try:
            self.link.robot.check_access("topics_sub", topic, "uri topic", "resources/read")
        except ToolError as exc:
            raise _refused(str(exc)) from None
        return topic

    def _rated(self, request: str) -> None:
        """The session's rate cap for ``request``, as a tool's (``Guard.check_rate``)."""
        try:
            self.guard.check_rate(request)
        except ToolError as exc:
            raise _refused(str(exc)) from None
