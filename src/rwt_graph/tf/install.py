"""tf2_web_republisher, built in: a TF buffer and its republishing interfaces (paper IV.A).

``install_tf_republisher(graph, sleep=...)`` gives a graph what the
tf2_web_republisher node gives a ROS system (REF §7.3), on node
``/tf2_web_republisher``:

- a ``TFBuffer`` fed by ``/tf`` and ``/tf_static`` (``tf2_msgs/TFMessage``) from
  any publisher: clients or Python code in this process;
- the action ``/tf2_web_republisher`` (``TFSubscription``; roslibjs
  ``ROS2TFClient``): feedback ``{transforms}`` at each tick with the changed pairs,
  until the goal is cancelled;
- the service ``/republish_tfs`` (``RepublishTFs``; roslibpy ``TFClient``):
  answers ``topic_name``, a new latched ``TFArray`` topic ``/tf_repub_<n>`` that
  ticks while it has subscribers and goes after ``timeout`` without any;
- the actionlib topics ``/tf2_web_republisher/goal``, ``cancel``, ``feedback``,
  ``status`` and ``result`` (roslibjs ``TFClient``, which ros3djs uses), in either
  dialect; see ``actionlib.py``.

The graph keeps no clock loop and imports no event loop, so the caller
injects ``sleep(seconds)``, an awaitable such as ``anyio.sleep``; the ticking loops
run through the graph's spawner, which a running server lends it
(``GraphCore.serving``).
"""

from __future__ import annotations

import contextlib
import itertools
import logging
from collections.abc import Awaitable, Callable, Iterator
from typing import TYPE_CHECKING

from rwt_graph.actions import GoalCanceledError, GoalContext
from rwt_graph.calls import require_spawner
from rwt_graph.types import Dialect

from ..ratelog import EpisodeLog
from .actionlib import ActionlibServer
from .buffer import TFBuffer, TFError, stamp_seconds
from .republisher import TFRequest, TFSubscription

if TYPE_CHECKING:
    from rwt_graph.graph import Graph
    from rwt_graph.local import LocalPublisher

__all__ = ["MIN_TOPIC_TIMEOUT_S", "TF_NODE", "Sleep", "TFRepublisher", "install_tf_republisher"]

logger = logging.getLogger("rwt.tf")
_episodes = EpisodeLog(logger)  # a peer can trigger these per message

Message = dict[str, object]
Sleep = Callable[[float], Awaitable[None]]
"""``await sleep(seconds)``: the event loop's sleep, injected by whoever runs the graph."""

#: The node of everything the republisher registers, as the ROS node is named.
TF_NODE = "/tf2_web_republisher"
#: The topics ``/republish_tfs`` answers with: ``/tf_repub_0``, ``/tf_repub_1``, ...
REPUBLISH_TOPIC_PREFIX = "/tf_repub_"

#: A ``/republish_tfs`` topic lives at least this long without subscribers, so the
#: client has time to subscribe after the response (seconds).
MIN_TOPIC_TIMEOUT_S = 1.0
#: Ticking requests (goals and topics) at most; further ones are refused.
MAX_ACTIVE = 1000

_TF_TYPE = "tf2_msgs/msg/TFMessage"


class TFRepublisher:
    """A running republisher; made by ``install_tf_republisher``.

    Attributes:
        buffer: the TF buffer, for lookups from Python (``buffer.lookup(target, source)``).
        active: requests ticking now (goals and republished topics).
    """

    def __init__(
        self, graph: Graph, sleep: Sleep, *, node: str = TF_NODE, max_active: int = MAX_ACTIVE
    ) -> None:
        self.graph = graph
        self.sleep = sleep
        self.node = node
        self.max_active = max_active
        self.active = 0
        self.buffer = TFBuffer()
        self.dialect = graph.registry.dialect
        self._topic_ids = itertools.count()
        self._closers: list[Callable[[], None]] = []
        self.closed = False
        graph.reserve_topic(f"{REPUBLISH_TOPIC_PREFIX}*")  # clients can neither squat nor forge

    def start(self) -> None:
        """Subscribe to ``/tf`` and ``/tf_static``; offer the action and the service.

        Raises:
            GraphError: ``/tf`` or ``/tf_static`` has another type, or a name is taken
                by a participant that cannot be replaced.
        """
        graph, node = self.graph, self.node
        for topic, static in (("/tf", False), ("/tf_static", True)):
            sub = graph.create_subscription(
                topic, self._listener(static=static), _TF_TYPE, node=node
            )
            self._closers.append(sub.close)
        ros1 = self.dialect is Dialect.ROS1
        action = graph.create_action_server(
            "/tf2_web_republisher",
            "tf2_web_republisher/TFSubscription"
            if ros1
            else "tf2_web_republisher_interfaces/action/TFSubscription",
            self.run_goal,
            node=node,
        )
        self._closers.append(action.close)
        service = graph.create_service(
            "/republish_tfs",
            "tf2_web_republisher/srv/RepublishTFs",
            self.republish,
            node=node,
        )
        self._closers.append(service.close)
        self._closers.append(ActionlibServer(self).start())

    def close(self) -> None:
        """Withdraw everything ``start`` registered (running loops end at their next tick)."""
        self.closed = True
        closers, self._closers = self._closers, []
        for close in reversed(closers):
            close()

    def _listener(self, *, static: bool) -> Callable[[Message], None]:
        def on_message(msg: Message) -> None:
            self.buffer.add_message(msg, static=static)

        return on_message

    @contextlib.contextmanager
    def slot(self) -> Iterator[None]:
        """Count one ticking request for as long as the block runs.

        Raises:
            TFError: ``max_active`` requests tick already.
        """
        self.reserve()
        try:
            yield
        finally:
            self.release()

    def reserve(self) -> None:
        """Count one more ticking request.

        Raises:
            TFError: ``max_active`` requests tick already.
        """
        if self.active >= self.max_active:
            raise TFError(f"too many TF subscriptions ({self.max_active} running)")
        self.active += 1

    def release(self) -> None:
        """A ticking request ended."""
        self.active -= 1

    def subscription(self, msg: Message) -> TFSubscription:
        """A fresh subscription for a goal or request dict.

        Raises:
            TFError: the request is unusable (see ``TFRequest.from_message``).
        """
        return TFSubscription(self.buffer, TFRequest.from_message(msg), self.dialect)

    # ---- the action (ROS 2 clients) ---------------------------------------------

    async def run_goal(self, goal: Message, context: GoalContext) -> Message:
        """Tick a ``TFSubscription`` goal until it is cancelled (then it ends CANCELED).

        Raises:
            GoalCanceledError: the caller cancelled (or left).
            TFError: the goal is unusable or too many run (the goal aborts).
        """
        subscription = self.subscription(goal)
        with self.slot():
            while not (context.cancel_requested or self.closed):
                transforms = subscription.changed()
                if transforms:
                    # built here in the internal form: no need to check it again
                    context.publish_feedback({"transforms": transforms}, validated=True)
                await self.sleep(subscription.request.period_s)
        raise GoalCanceledError

    # ---- the service (roslibpy, roslibjs processResponse) -------------------------

    def republish(self, request: Message) -> Message:
        """Answer ``RepublishTFs``: start a ``/tf_repub_<n>`` topic, return its name.

        Raises:
            TFError: the request is unusable or too many run (the call fails).
            GraphError: no event loop runs this graph.
        """
        subscription = self.subscription(request)
        timeout = request.get("timeout")
        assert isinstance(timeout, dict)
        timeout_s = max(stamp_seconds(timeout), MIN_TOPIC_TIMEOUT_S)
        spawn = require_spawner(self.graph.port.spawner, "service /republish_tfs")
        name = f"{REPUBLISH_TOPIC_PREFIX}{next(self._topic_ids)}"
        self.reserve()  # counted now and released by the job: a refusal fails this call
        try:
            publisher = self.graph.create_publisher(
                name, "tf2_web_republisher/msg/TFArray", latch=True, node=self.node
            )
        except BaseException:
            self.release()
            raise

        async def run() -> None:
            try:
                await self._serve_topic(publisher, subscription, timeout_s)
            except Exception:  # a spawned job must not take the server down
                _episodes.log(
                    logging.ERROR,
                    f"republish_failed {name}",
                    "republishing on %s failed",
                    name,
                    exc_info=True,
                )
            finally:
                self.release()
                publisher.close()

        spawn(run)
        return {"topic_name": name}

    async def _serve_topic(
        self, publisher: LocalPublisher, subscription: TFSubscription, timeout_s: float
    ) -> None:
        """Tick while the topic has subscribers; return after ``timeout_s`` without any.

        Ticks wait for a subscriber: the first values (sent once) then reach the
        client that asked, not only the latched slot.
        """
        clock = self.graph.clock
        last_subscribed = clock.monotonic()
        while not self.closed:
            now = clock.monotonic()
            if self.has_subscribers(publisher.topic):
                last_subscribed = now
                transforms = subscription.changed()
                if transforms:
                    publisher.publish({"transforms": transforms}, validated=True)
            elif now - last_subscribed >= timeout_s:
                logger.debug("%s: no subscriber for %.1f s, removed", publisher.topic, timeout_s)
                return
            await self.sleep(subscription.request.period_s)

    def has_subscribers(self, topic: str) -> bool:
        """Whether anyone subscribes to ``topic`` (a resolved name)."""
        entry = self.graph.topics.get(topic)
        return entry is not None and bool(entry.subscribers)


def install_tf_republisher(
    graph: Graph, sleep: Sleep, *, node: str = TF_NODE, max_active: int = MAX_ACTIVE
) -> TFRepublisher:
    """Give ``graph`` a TF buffer and tf2_web_republisher's interfaces (see the module).

    Args:
        graph: the graph to serve.
        sleep: ``await sleep(seconds)`` of the event loop that runs the graph
            (``anyio.sleep``; ``rwt_graph.tf.loop.install_tf_republisher`` passes it).
        node: the node rosapi lists for the republisher's topics, action and service.
        max_active: requests ticking at most (bounds what clients can start).

    Returns:
        The republisher; ``republisher.buffer.lookup(target, source)`` answers from Python.

    Raises:
        GraphError: ``/tf`` or ``/tf_static`` is in use with another type.
    """
    republisher = TFRepublisher(graph, sleep, node=node, max_active=max_active)
    republisher.start()
    return republisher
