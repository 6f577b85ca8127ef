"""The robot as the MCP tools see it: one interface, two ways to reach it.

The tools (``tools``, ``resources``, ``tasks``) are written once against ``Robot``:
rosapi's queries (``rwt_client.rosapi.RosapiMixin``, over ``call_service``), a
subscription, a publisher, a goal and its cancel. Two classes implement it:

- ``ClientRobot``: a remote server through rwt's client (``rwt mcp URL``, a
  rosbridge connection that reconnects).
- ``session.McpSession``: ``rwt serve --mcp``'s session on the connection runtime,
  which calls the graph port directly, as Foxglove's session does
  (docs/architecture.md).

Every method raises ``RwtError`` (or a subclass) for what the robot refuses, and
``ToolError`` where the refusal is the access rules' (its text names the rule).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from rwt_client import Action, Ros, Topic
from rwt_client.rosapi import RosapiMixin

if TYPE_CHECKING:
    from rwt_protocol.qos import QosProfile

__all__ = ["ClientRobot", "GoalEnd", "GoalRun", "Publisher", "Robot", "Subscription"]

Callback = Callable[[Any], None]


@dataclass(frozen=True)
class GoalEnd:
    """How a goal ended (``action_result``, D18).

    Attributes:
        status: the terminal ``action_msgs/GoalStatus`` code, None if not told.
        result: whether it succeeded (rosbridge's ``result`` field).
        values: the result message, or the reason it failed (D28).
    """

    status: int | None
    result: bool
    values: Any


class Subscription(Protocol):
    """A topic subscription of the robot's; ``unsubscribe`` ends it (idempotent)."""

    async def unsubscribe(self) -> None:
        """Stop the messages."""
        ...


class Publisher(Protocol):
    """A topic advertised for publishing."""

    async def publish(self, msg: object) -> str | None:
        """Publish ``msg`` (a dict in rosbridge's JSON form).

        Returns:
            What the robot's safety envelope did to it (a clamp, a drop), where the
            robot says at once (``rwt serve --mcp``), else None (docs/safety.md).

        Raises:
            RwtError: the message does not fit the type, or the robot refused it.
        """
        ...

    async def unadvertise(self) -> None:
        """Stop publishing (idempotent)."""
        ...


class GoalRun(Protocol):
    """A goal sent: its id (by which any allowed connection cancels it, D35) and its end."""

    @property
    def id(self) -> str:
        """The goal's id, as ``cancel_goal`` names it."""
        ...

    async def result(self) -> GoalEnd:
        """Wait for the goal's end.

        Raises:
            RwtError: the connection dropped: the goal's end is not known.
        """
        ...


class Robot(Protocol):
    """What the MCP tools ask of a robot (the module's text).

    Also every rosapi query of ``RosapiMixin`` (``get_topics_and_types``, ``get_param``...).
    """

    url: str
    """Where the robot is, for logs (``ws://...``, ``mcp:<client id>``)."""

    async def call_service(
        self,
        service: str,
        args: object = None,
        *,
        type_name: str | None = None,
        timeout_s: float | None = None,
    ) -> object:
        """Call ``service``; its response values (rosbridge's JSON form).

        Raises:
            ServiceCallError: it failed (``<service> failed: <reason>``).
            CallTimeoutError: no answer within ``timeout_s`` seconds.
        """
        ...

    async def get_topic_type(self, topic: str) -> str:
        """``topic``'s type, "" when unknown (rosapi)."""
        ...

    async def get_topics_and_types(self) -> dict[str, str]:
        """Every topic and its type (rosapi)."""
        ...

    async def get_services(self) -> list[str]:
        """Every service (rosapi)."""
        ...

    async def get_nodes(self) -> list[str]:
        """Every node (rosapi)."""
        ...

    async def get_action_servers(self) -> list[str]:
        """Every action server (rosapi)."""
        ...

    async def get_params(self) -> list[str]:
        """Every parameter name (rosapi)."""
        ...

    async def get_message_details(self, type_name: str) -> list[dict[str, object]]:
        """A message type's typedefs, root first (rosapi)."""
        ...

    async def get_param(self, name: str, default: object = None) -> object:
        """A parameter's value (rosapi)."""
        ...

    async def set_param(self, name: str, value: object) -> None:
        """Set a parameter (rosapi); ``ServiceCallError`` when refused."""
        ...

    async def subscribe(
        self,
        topic: str,
        type_name: str | None,
        callback: Callback,
        *,
        throttle_ms: int = 0,
        queue_length: int = 0,
        qos: QosProfile | None = None,
    ) -> Subscription:
        """Deliver ``topic``'s messages (rosbridge's JSON form) to ``callback``.

        ``throttle_ms`` and ``queue_length`` as ``subscribe``'s (spec 3.3.4); ``qos``
        protocol 2.1.0's (D62-D65), what the subscription asks of the topic.

        Raises:
            OpRefusedError: the robot refused it (a cap, a type conflict); the
                reason is its text.
            ToolError: the access rules refuse the topic.
        """
        ...

    async def advertise(
        self, topic: str, type_name: str, qos: QosProfile | None = None
    ) -> Publisher:
        """Advertise ``topic`` of ``type_name``, once the robot took it.

        ``qos``: protocol 2.1.0's (D62), what it offers.

        Raises:
            OpRefusedError: the robot refused it (a type conflict, a cap).
            ToolError: the access rules refuse the topic.
        """
        ...

    async def send_goal(
        self, action: str, type_name: str, goal: object, on_feedback: Callback
    ) -> GoalRun:
        """Send ``goal`` to ``action``; each feedback goes to ``on_feedback``.

        Raises:
            RwtError: the robot refused it, or the connection is down.
            ToolError: the access rules refuse the action.
        """
        ...

    async def cancel_goal(self, action: str, goal_id: str) -> None:
        """Ask to cancel the goal ``goal_id`` of ``action``, any connection's (D35)."""
        ...

    def check_access(self, family: str, name: str, what: str, op: str) -> None:
        """Refuse ``name`` if the robot's access rules would (``guard.Guard``'s families).

        For an answer that names what the agent may use later (the robot app's
        pad). ``ClientRobot`` checks nothing: its server decides.

        Raises:
            ToolError: ``<what> <name>: refused by <rule>``.
        """
        ...

    def spawn(self, function: Callable[[], Any]) -> bool:
        """Run ``function`` (async) in the robot's task group, until it closes.

        Returns:
            Whether it runs (False: the robot is closed).
        """
        ...

    def require_connection(self) -> None:
        """Raise ``ConnectionClosedError`` (the reason) unless the robot can be reached."""
        ...

    async def connect(self) -> None:
        """Reach the robot (``ConnectionClosedError`` if it cannot be reached now)."""
        ...

    async def aclose(self) -> None:
        """Let the robot go (idempotent): what this connection held is released."""
        ...


class _ClientSubscription:
    def __init__(self, topic: Topic) -> None:
        self._topic = topic

    async def unsubscribe(self) -> None:
        await self._topic.unsubscribe()


class _ClientGoal:
    def __init__(self, handle: Any) -> None:
        self._handle = handle

    @property
    def id(self) -> str:
        return str(self._handle.id)

    async def result(self) -> GoalEnd:
        reply = await self._handle.result()
        return GoalEnd(reply.status, bool(reply.result), reply.values)


class ClientRobot(RosapiMixin):
    """A robot behind a rosbridge server, through rwt's client (``rwt mcp URL``).

    Args:
        ros: the client (``rwt_client.Ros``), connected by ``connect``.
    """

    def __init__(self, ros: Ros) -> None:
        self.ros = ros
        self.url = ros.url

    async def call_service(
        self,
        service: str,
        args: object = None,
        *,
        type_name: str | None = None,
        timeout_s: float | None = None,
    ) -> object:
        """As ``Robot.call_service``."""
        return await self.ros.call_service(service, args, type_name=type_name, timeout_s=timeout_s)

    async def subscribe(
        self,
        topic: str,
        type_name: str | None,
        callback: Callback,
        *,
        throttle_ms: int = 0,
        queue_length: int = 0,
        qos: QosProfile | None = None,
    ) -> Subscription:
        """As ``Robot.subscribe``: one round trip for the server's refusal (D43)."""
        subscription = Topic(
            self.ros,
            topic,
            type_name,
            throttle_rate=throttle_ms,
            queue_length=queue_length,
            qos=qos,
        )
        await subscription.subscribe(callback, confirm=True)
        return _ClientSubscription(subscription)

    async def advertise(
        self, topic: str, type_name: str, qos: QosProfile | None = None
    ) -> Publisher:
        """As ``Robot.advertise``."""
        publisher = Topic(self.ros, topic, type_name, qos=qos)
        await publisher.advertise()
        return publisher

    async def send_goal(
        self, action: str, type_name: str, goal: object, on_feedback: Callback
    ) -> GoalRun:
        """As ``Robot.send_goal``."""
        handle = await Action(self.ros, action, type_name).send_goal(goal, on_feedback=on_feedback)
        return _ClientGoal(handle)

    async def cancel_goal(self, action: str, goal_id: str) -> None:
        """As ``Robot.cancel_goal``: sent at once."""
        self.ros.session.cancel_action_goal(action, goal_id)
        await self.ros.flush()

    def check_access(self, family: str, name: str, what: str, op: str) -> None:
        """Nothing: the server checks what this connection asks for."""

    def spawn(self, function: Callable[[], Any]) -> bool:
        """In the client's task group."""
        self.ros.spawn(function)
        return True

    def require_connection(self) -> None:
        """As the client's."""
        self.ros.require_connection()

    async def connect(self) -> None:
        """Connect the client (``ConnectionClosedError`` if the server does not answer)."""
        await self.ros.connect()

    async def aclose(self) -> None:
        """Close the client."""
        await self.ros.close()
