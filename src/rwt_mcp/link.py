"""The MCP session's one robot, its publishers and the goals it sent.

One ``robot.Robot`` for the whole MCP session (docs/agents.md): for ``rwt mcp URL``
a rosbridge client (``robot.ClientRobot``), connected in the background at start
and reconnected by the client when it drops, a tool called while it is down
failing at once with the client's reason; for ``rwt serve --mcp`` the session's
own ``session.McpSession`` on the server's graph.
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import anyio
from mcp.server.mcpserver.exceptions import ToolError

from rwt_client import Ros
from rwt_client.connectors import ConnectionClosedError
from rwt_client.ros import jittered
from rwt_protocol.errors import RwtError

from .robot import ClientRobot, GoalRun, Publisher, Robot

if TYPE_CHECKING:
    from rwt_protocol.qos import QosProfile

__all__ = ["FIRST_CONNECT_WAIT_S", "MAX_GOALS", "MAX_PUBLISHERS", "Goal", "RobotLink"]

logger = logging.getLogger(__name__)

#: Goals this session remembers (running, or finished and not yet read): a new goal
#: drops the oldest finished one; with all of them running it is refused.
MAX_GOALS = 32
#: Topics this session keeps advertised for ``publish``; the least recently used
#: is unadvertised past this.
MAX_PUBLISHERS = 32
#: Seconds a tool called before the first connection was made waits for it (an agent's
#: first call right after starting ``rwt mcp``); then it fails with the client's reason.
FIRST_CONNECT_WAIT_S = 5.0
_RECONNECT_MAX_S = 5.0


@dataclass
class Goal:
    """A goal sent by ``send_action_goal``: its handle, and what came back so far."""

    action: str
    handle: GoalRun
    feedback_count: int = 0
    last_feedback: Any = None
    status: int | None = None
    result: Any = None
    error: str | None = None
    listeners: list[Any] = field(default_factory=list)
    done: anyio.Event = field(default_factory=anyio.Event)

    def on_feedback(self, values: object) -> None:
        """Keep the latest feedback; pass it to the tool call waiting, if any."""
        self.feedback_count += 1
        self.last_feedback = values
        for listener in self.listeners:
            listener(values)

    async def watch(self) -> None:
        """Wait for the result (a task of the client's) and keep it; then ``done`` is set."""
        try:
            end = await self.handle.result()
        except RwtError as exc:  # the connection dropped: the goal's end is not known
            self.error = str(exc)
        else:
            self.status = end.status if end.status is not None else (4 if end.result else 6)
            self.result = end.values
        finally:
            self.done.set()


class RobotLink:
    """The robot an MCP session uses, reached once.

    Args:
        url: the server, as ``rwt_client.connectors.server_url`` returns it.
        robot: the robot to use (``rwt serve --mcp``'s session); None: a client
            of ``url`` that reconnects when the connection drops.
    """

    def __init__(self, url: str, robot: Robot | None = None) -> None:
        self.url = url
        self.robot: Robot = robot or ClientRobot(Ros(url, reconnect=True))
        self.goals: OrderedDict[str, Goal] = OrderedDict()
        self._publishers: OrderedDict[tuple[str, str, QosProfile | None], Publisher] = OrderedDict()
        self._ready = anyio.Event()  # the first connection was made

    async def connect(self, stop: anyio.Event) -> None:
        """Connect, retrying with back-off until the server answers or ``stop`` is set.

        Once connected, the client reconnects by itself. Runs in the task that
        later calls ``close`` (the client's task group belongs to that task).
        """
        delay_s = 0.1
        while not stop.is_set():
            try:
                await self.robot.connect()
            except ConnectionClosedError as exc:
                logger.warning("%s; retrying", exc.message)
                with anyio.move_on_after(jittered(delay_s)):  # back-off, as the client's
                    await stop.wait()
                delay_s = min(delay_s * 2, _RECONNECT_MAX_S)
                continue
            if isinstance(self.robot, ClientRobot):  # a server's own session: nothing to say
                logger.info("connected to %s", self.url)
            self._ready.set()
            return

    async def connected(self) -> Robot:
        """The robot, once connected.

        A tool called while the first connection is still being made waits for
        it, ``FIRST_CONNECT_WAIT_S`` at most.

        Raises:
            ToolError: not connected (yet, or any more): the client's reason.
        """
        with anyio.move_on_after(FIRST_CONNECT_WAIT_S):
            await self._ready.wait()
        try:
            self.robot.require_connection()
        except ConnectionClosedError as exc:
            raise ToolError(exc.message) from None
        return self.robot

    async def publisher(
        self, topic: str, message_type: str, qos: QosProfile | None = None
    ) -> Publisher:
        """The publisher of ``topic``, advertised on first use (bounded cache).

        ``qos``: what it offers (D62); a publisher is kept per topic, type and QoS.

        Raises:
            OpRefusedError: the robot refused the advertisement.
            ToolError: the access rules refuse it, or the robot cannot be reached.
        """
        key = (topic, message_type, qos)
        found = self._publishers.get(key)
        if found is not None:
            self._publishers.move_to_end(key)
            return found
        publisher = await (await self.connected()).advertise(topic, message_type, qos)
        self._publishers[key] = publisher
        if len(self._publishers) > MAX_PUBLISHERS:
            _, oldest = self._publishers.popitem(last=False)
            await oldest.unadvertise()
        return publisher

    async def send_goal(self, action: str, action_type: str, goal: object) -> Goal:
        """Send a goal and remember it (``MAX_GOALS``).

        Raises:
            ToolError: ``MAX_GOALS`` goals are running, or the connection is down.
        """
        self._make_room()
        record: Goal | None = None

        def on_feedback(values: object) -> None:
            if record is not None:
                record.on_feedback(values)

        robot = await self.connected()
        handle = await robot.send_goal(action, action_type, goal, on_feedback)
        record = self.goals[handle.id] = Goal(action, handle)
        robot.spawn(record.watch)
        return record

    def _make_room(self) -> None:
        if len(self.goals) < MAX_GOALS:
            return
        for goal_id, goal in self.goals.items():
            if goal.done.is_set():
                del self.goals[goal_id]
                return
        raise ToolError(f"{MAX_GOALS} goals of this session are running: cancel one or wait for it")

    async def cancel(self, record: Goal) -> None:
        """Ask to cancel ``record``'s goal on the robot it was sent to (D35).

        Raises:
            RwtError: the robot refused the cancel, or cannot be reached.
            ToolError: the access rules refuse the action.
        """
        await self.robot.cancel_goal(record.action, record.handle.id)

    async def close(self) -> None:
        """Let the robot go (idempotent)."""
        await self.robot.aclose()
