"""The MCP tools: a robot's graph, topics, services, actions, parameters and TF.

Each tool is a method of ``RobotTools`` over the session's one connection
(``link.RobotLink``); ``build_server`` registers them on an MCPServer (the official
SDK's, 2.x: it answers the 2026-07-28 revision and 2025-era clients, D52). Every
wait and size is bounded by a constant of this module or of ``render``
(docs/limits.md, "MCP front end"); an error of the server (a refused call, a
timeout, a connection down) becomes an MCP tool error with its text.
"""

from __future__ import annotations

import contextlib
import functools
import inspect
import json
import logging
import re
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from contextlib import asynccontextmanager
from typing import Any

import anyio
import pybase64
from mcp.server.mcpserver import Context, MCPServer
from mcp.server.mcpserver.exceptions import ToolError
from mcp.server.mcpserver.tools import Tool
from mcp.server.request_state import RequestStateSecurity
from mcp.types import (
    CallToolResult,
    ImageContent,
    InputRequiredResult,
    TextContent,
    ToolAnnotations,
)
from pydantic import BaseModel, ValidationError
from typing_extensions import TypedDict  # pydantic reads it on Python 3.11

from rwt_graph.media.images import ImageError
from rwt_graph.media.threads import in_image_thread
from rwt_protocol.errors import GraphError, OpRefusedError, RwtError
from rwt_protocol.names import name_problem
from rwt_protocol.ops.qos import Qos
from rwt_protocol.qos import QosProfile

from . import render
from .app import APP_URI, AppSite, RobotApp, app_settings
from .approval import Approvals
from .catalog import APP_TOOLS, TOOLS, WRITE_TOOLS
from .guard import Guard
from .link import Goal, RobotLink
from .render import IMAGE_TYPES, encode_image, json_schema, message_text, summarise
from .resources import TopicResources, Watched
from .robot import Robot, Subscription
from .tasks import TasksExtension, TaskStore

__all__ = [
    "MAX_ECHO_CHARS",
    "MAX_ECHO_COUNT",
    "MAX_ECHO_IMAGES",
    "MAX_LIST_ITEMS",
    "MAX_PUBLISH_DURATION_S",
    "MAX_PUBLISH_RATE_HZ",
    "MAX_WAIT_S",
    "RobotTools",
    "build_server",
    "goal_report",
    "release_server",
    "warm_up",
]

#: Any wait a tool takes (echo, service call, goal, cancel, transform), in seconds.
MAX_WAIT_S = 60.0
#: Messages one ``echo`` returns.
MAX_ECHO_COUNT = 100
#: Images one ``echo`` returns (each its own image content).
MAX_ECHO_IMAGES = 4
#: Characters of message text one ``echo`` returns in all; it stops once past them.
MAX_ECHO_CHARS = 32_000
#: Names a listing tool returns (``total`` says how many there were).
MAX_LIST_ITEMS = 1000
#: ``publish_for``'s rate and duration.
MAX_PUBLISH_RATE_HZ = 50.0
MAX_PUBLISH_DURATION_S = 60.0
#: The robot app's pad's top speeds (``robot_app``'s ``max_linear`` m/s, ``max_angular`` rad/s).
MAX_APP_SPEED = 10.0
#: The longest wait for the video token the robot app asks for, seconds.
_TOKEN_WAIT_S = 5.0
#: The status codes of ``action_msgs/GoalStatus`` a result may carry (D18).
GOAL_STATES = {4: "succeeded", 5: "canceled", 6: "aborted"}
_LAST_PROGRESS_S = 1.0  # sending the last feedback, once the goal ended
_MAX_FIELD_ERRORS = 5  # fields a bad call's tool error names
_TF_TOPIC_TIMEOUT = {"sec": 5, "nanosec": 0}  # the republisher drops its topic 5 s after us

Message = dict[str, Any]

# The SDK logs every request at INFO ("Processing request of type CallToolRequest"): a
# line per request, at the rate a peer chooses (docs/limits.md, "Logs a peer can trigger")
logging.getLogger("mcp.server.lowlevel.server").setLevel(logging.WARNING)
# ... and a line per failed tool call or read (MCPServer, INFO: the agent gets the error),
# per malformed notification (the runner, WARNING): a peer's to trigger at will
logging.getLogger("mcp.server.mcpserver.server").setLevel(logging.WARNING)
logging.getLogger("mcp.server.runner").setLevel(logging.ERROR)


# The listings are typed dicts, not models: a model of 1000 topics took 5 to 12 ms
# to build, for an answer that is a dict again at once (docs/limits.md, "MCP front end").


class Names(TypedDict):
    """Names from rosapi, sorted: at most ``MAX_LIST_ITEMS``, of ``total``."""

    names: list[str]
    total: int


class TopicInfo(TypedDict):
    """A topic and its type."""

    name: str
    type: str


class Topics(TypedDict):
    """Topics from rosapi, sorted: at most ``MAX_LIST_ITEMS``, of ``total``."""

    topics: list[TopicInfo]
    total: int


class TypeDefinition(BaseModel):
    """A message type: rosapi's typedefs (root first) and a JSON schema of its messages."""

    type: str
    typedefs: list[dict[str, Any]]
    json_schema: dict[str, Any]


class Published(BaseModel):
    """What ``publish`` and ``publish_for`` sent: messages, and whether a final one.

    ``safety``: what the robot's safety envelope did (a field clamped, a message
    dropped past its rate), each told once.
    """

    topic: str
    type: str
    count: int
    final_sent: bool = False
    safety: list[str] = []


class ServiceAnswer(BaseModel):
    """A service's response values."""

    service: str
    values: Any


class GoalReport(BaseModel):
    """A goal of this session: ``state`` is running, succeeded, canceled or aborted.

    ``unknown: <why>`` when the connection dropped before the result came.
    """

    goal_id: str
    action: str
    state: str
    status: int | None
    result: Any
    feedback_count: int
    last_feedback: Any


class ParameterValue(BaseModel):
    """A parameter's name and value (null: not set)."""

    name: str
    value: Any


class Transform(BaseModel):
    """``source_frame``'s pose in ``target_frame``: metres and a unit quaternion."""

    target_frame: str
    source_frame: str
    translation: dict[str, float]
    rotation: dict[str, float]


@contextlib.contextmanager
def _tool_errors() -> Iterator[None]:
    """Rwt's errors (a refused call, a timeout, a lost connection) as tool errors."""
    try:
        yield
    except RwtError as exc:
        raise ToolError(str(exc)) from None


def tool_qos(qos: Message | None) -> QosProfile | None:
    """A tool's ``qos`` argument, read as a rosbridge op's (protocol 2.1.0, D62).

    Raises:
        ToolError: ``qos.<field>: <what is wrong>``.
    """
    if qos is None:
        return None
    try:
        return Qos.model_validate(qos).profile()
    except ValidationError as exc:
        error = exc.errors()[0]
        field = ".".join(["qos", *(str(part) for part in error["loc"])])
        raise ToolError(f"{field}: {error['msg']}"[:200]) from None


async def subscribe_confirmed(
    robot: Robot,
    topic: str,
    type_name: str | None,
    callback: Callable[[Any], None],
    what: str,
    qos: QosProfile | None = None,
) -> Subscription:
    """Subscribe to ``topic``, knowing whether the robot refused it (D43).

    rosbridge does not acknowledge ``subscribe``: a client waits one round trip
    for the refusal (``robot.ClientRobot``), else a subscription the server refused
    (``--max-subscriptions``, a type conflict) would look like a quiet topic.

    Raises:
        ToolError: ``<what>: the server refused the subscription: <its status text>``,
            the access rules' refusal, or the connection's error.
    """
    try:
        return await robot.subscribe(topic, type_name, callback, qos=qos)
    except OpRefusedError as exc:
        raise ToolError(f"{what}: the server refused the subscription: {exc.reason}") from None
    except RwtError as exc:
        raise ToolError(str(exc)) from None


def _wait(timeout_s: float) -> float:
    if not 0 < timeout_s <= MAX_WAIT_S:
        raise ToolError(f"timeout_s must be in (0, {MAX_WAIT_S:g}] seconds, not {timeout_s:g}")
    return timeout_s


def _names(names: list[str]) -> Names:
    return {"names": sorted(names)[:MAX_LIST_ITEMS], "total": len(names)}


class RobotTools:
    """The tools over one connection (``RobotLink``); see docs/agents.md for each."""

    def __init__(self, link: RobotLink, site: AppSite | None = None) -> None:
        self.link = link
        self.guard = Guard()
        self.site = site or AppSite()
        self.approvals: Approvals | None = None  # what waits for a person (docs/safety.md)

    # ---- the graph ------------------------------------------------------------------

    async def list_topics(self) -> Topics:
        """Every topic of the robot and its message type (rosapi)."""
        with _tool_errors():
            topics = await (await self.link.connected()).get_topics_and_types()
        listed: list[TopicInfo] = [
            {"name": name, "type": topics[name]} for name in sorted(topics)[:MAX_LIST_ITEMS]
        ]
        return {"topics": listed, "total": len(topics)}

    async def list_services(self) -> Names:
        """Every service of the robot (rosapi)."""
        with _tool_errors():
            return _names(await (await self.link.connected()).get_services())

    async def list_nodes(self) -> Names:
        """Every node of the robot (rosapi)."""
        with _tool_errors():
            return _names(await (await self.link.connected()).get_nodes())

    async def list_actions(self) -> Names:
        """Every action server of the robot (rosapi's action_servers, where offered)."""
        with _tool_errors():
            return _names(await (await self.link.connected()).get_action_servers())

    async def list_parameters(self) -> Names:
        """Every parameter name of the robot (rosapi; ROS 2: ``/node:param``)."""
        with _tool_errors():
            return _names(await (await self.link.connected()).get_params())

    async def type_definition(self, type: str) -> TypeDefinition:
        """A message type's fields (rosapi message_details) and a JSON schema for building one.

        Args:
            type: a message type, ``pkg/msg/Type`` or ``pkg/Type``.
        """
        with _tool_errors():
            typedefs = await (await self.link.connected()).get_message_details(type)
        if not typedefs:
            raise ToolError(f"the server knows no message type {type!r}")
        return TypeDefinition(type=type, typedefs=typedefs, json_schema=json_schema(typedefs))

    # ---- topics ---------------------------------------------------------------------

    async def echo(
        self,
        topic: str,
        count: int = 1,
        timeout_s: float = 5.0,
        type: str | None = None,
        qos: Message | None = None,
    ) -> list[TextContent | ImageContent]:
        """Up to ``count`` messages of a topic, or those of ``timeout_s`` seconds.

        Large arrays are summarised (``"<int[921600]>"``), long strings cut; images
        (sensor_msgs/Image, CompressedImage) come as image content.

        Args:
            topic: the topic name.
            count: messages wanted (1 to MAX_ECHO_COUNT; images: MAX_ECHO_IMAGES).
            timeout_s: the longest wait, seconds (at most MAX_WAIT_S).
            type: the message type; None asks the server.
            qos: rosbridge's QoS object (history, depth, reliability, durability,
                deadline, lifespan): {"durability": "transient_local"} gets what a
                latched topic keeps at once.
        """
        profile = tool_qos(qos)
        seconds = _wait(timeout_s)
        ros = await self.link.connected()
        with _tool_errors():
            message_type = type or await ros.get_topic_type(topic)
        images = message_type in IMAGE_TYPES
        wanted = min(max(count, 1), MAX_ECHO_IMAGES if images else MAX_ECHO_COUNT)
        received: list[Message] = []
        enough = anyio.Event()

        def take(msg: Message) -> None:
            if len(received) < wanted:
                received.append(msg)
            if len(received) >= wanted:
                enough.set()

        subscription = await subscribe_confirmed(
            ros, topic, message_type or None, take, f"echo {topic}", profile
        )
        with _tool_errors():
            try:
                with anyio.move_on_after(seconds):
                    await enough.wait()
            finally:
                await subscription.unsubscribe()
        complete = len(received) >= wanted
        return await self._echoed(topic, message_type, received[:wanted], images, complete)

    @staticmethod
    async def _echoed(
        topic: str, message_type: str, messages: list[Message], images: bool, complete: bool
    ) -> list[TextContent | ImageContent]:
        """The echo's content blocks; images decoded and encoded in an image thread."""
        content: list[TextContent | ImageContent] = []
        chars = 0
        for msg in messages:
            if images:
                try:
                    data, mime = await in_image_thread(encode_image, msg, message_type)
                except ImageError as exc:
                    raise ToolError(f"{topic}: {exc}") from None
                encoded = pybase64.b64encode(data).decode()
                content.append(ImageContent(type="image", data=encoded, mime_type=mime))
            shown = {key: value for key, value in msg.items() if not (images and key == "data")}
            text = message_text(shown)
            chars += len(text)
            if chars > MAX_ECHO_CHARS:
                break
            content.append(TextContent(type="text", text=text))
        summary = {"topic": topic, "type": message_type, "received": len(messages)}
        if not complete:
            summary["timed_out"] = True
        return [TextContent(type="text", text=json.dumps(summary)), *content]

    async def publish(
        self, topic: str, type: str, msg: Message, ctx: Context, qos: Message | None = None
    ) -> Published:
        """Publish one message (the topic is advertised on first use and stays advertised).

        Args:
            topic: the topic name.
            type: its message type (see ``type_definition``).
            msg: the message as JSON.
            ctx: the MCP request (a person's approval is asked through it, where needed).
            qos: rosbridge's QoS object the topic is advertised with (history, depth,
                reliability, durability, deadline, lifespan): {"durability":
                "transient_local", "depth": 1} keeps it for late subscribers.
        """
        profile = tool_qos(qos)
        with _tool_errors():
            publisher = await self.link.publisher(topic, type, profile)
            note = await publisher.publish(msg)
        return Published(topic=topic, type=type, count=1, safety=[note] if note else [])

    async def publish_for(
        self,
        topic: str,
        type: str,
        msg: Message,
        rate_hz: float,
        duration_s: float,
        ctx: Context,
        final_msg: Message | None = None,
        qos: Message | None = None,
    ) -> Published:
        """Publish ``msg`` at ``rate_hz`` for ``duration_s`` seconds, then ``final_msg`` once.

        For a velocity command followed by a stop (a zero Twist as ``final_msg``).

        Args:
            topic: the topic name.
            type: its message type.
            msg: the message repeated.
            rate_hz: messages a second (at most MAX_PUBLISH_RATE_HZ).
            duration_s: seconds (at most MAX_PUBLISH_DURATION_S).
            ctx: the MCP request (a person's approval is asked through it, where needed).
            final_msg: sent once at the end, also when the call is cancelled.
            qos: rosbridge's QoS object the topic is advertised with, as publish's:
                {"reliability": "best_effort"} for a stream of commands where the
                latest counts, {"durability": "transient_local", "depth": 1} keeps
                the final message for later subscribers.
        """
        profile = tool_qos(qos)
        if not 0 < rate_hz <= MAX_PUBLISH_RATE_HZ:
            raise ToolError(f"rate_hz must be in (0, {MAX_PUBLISH_RATE_HZ:g}]")
        if not 0 < duration_s <= MAX_PUBLISH_DURATION_S:
            raise ToolError(f"duration_s must be in (0, {MAX_PUBLISH_DURATION_S:g}]")
        count = 0
        notes: dict[str, None] = {}  # each told once, in order
        with _tool_errors():
            publisher = await self.link.publisher(topic, type, profile)
            start = anyio.current_time()
            deadline = start + duration_s
            try:
                # the deadline is checked between publishes, never cancels one: a publish
                # cut off after its frame went out would be sent and not counted
                while anyio.current_time() < deadline:
                    _noted(notes, await publisher.publish(msg))
                    count += 1
                    await anyio.sleep_until(min(deadline, start + count / rate_hz))
            finally:
                if final_msg is not None:
                    with anyio.CancelScope(shield=True):  # the stop goes out, whatever happens
                        _noted(notes, await publisher.publish(final_msg))
        return Published(
            topic=topic,
            type=type,
            count=count,
            final_sent=final_msg is not None,
            safety=list(notes),
        )

    # ---- services and parameters ----------------------------------------------------

    async def call_service(
        self,
        service: str,
        ctx: Context,
        type: str | None = None,
        args: Message | None = None,
        timeout_s: float = 10.0,
    ) -> ServiceAnswer:
        """Call a service and return its response.

        Args:
            service: the service name.
            ctx: the MCP request (a person's approval is asked through it, where needed).
            type: its service type (optional; rosbridge servers look it up).
            args: the request as JSON (omitted: an empty request).
            timeout_s: the longest wait, seconds (at most MAX_WAIT_S).
        """
        with _tool_errors():
            values = await (await self.link.connected()).call_service(
                service, args or {}, type_name=type, timeout_s=_wait(timeout_s)
            )
        return ServiceAnswer(service=service, values=summarise(values))

    async def get_parameter(self, name: str) -> ParameterValue:
        """A parameter's value (rosapi; ROS 2 names are ``/node:param``); null if unset."""
        with _tool_errors():
            value = await (await self.link.connected()).get_param(name)
        return ParameterValue(name=name, value=summarise(value))

    async def set_parameter(self, name: str, value: Any) -> ParameterValue:
        """Set a parameter (rosapi); the answer reads it back.

        A set the server refuses is a tool error with its reason (rosapi's
        ``successful: false``, or a failed call).
        """
        with _tool_errors():
            robot = await self.link.connected()
            await robot.set_param(name, value)
            return ParameterValue(name=name, value=summarise(await robot.get_param(name)))

    # ---- actions --------------------------------------------------------------------

    async def send_action_goal(
        self,
        action: str,
        type: str,
        goal: Message,
        ctx: Context,
        timeout_s: float = 30.0,
    ) -> GoalReport:
        """Send a goal and wait up to ``timeout_s`` for its result; feedback as progress.

        A goal still running then goes on: ``action_goal_status`` reads it later,
        ``cancel_action_goal`` cancels it.

        Args:
            action: the action name.
            type: its action type, ``pkg/action/Type``.
            goal: the goal as JSON.
            ctx: the MCP request (progress notifications, when the client asked).
            timeout_s: the longest wait, seconds (at most MAX_WAIT_S).
        """
        seconds = _wait(timeout_s)
        with _tool_errors():
            record = await self.link.send_goal(action, type, goal)
        async with _progress(record, ctx):
            await self._settle(record, seconds)
        return goal_report(record)

    async def start_goal(
        self, arguments: dict[str, Any], before_send: Callable[[], None] | None = None
    ) -> Goal:
        """Send a goal of ``send_action_goal``'s ``arguments`` without waiting (a task's start).

        Args:
            arguments: the tool's arguments, as the client sent them.
            before_send: called once the arguments and the guard passed, before
                the goal is sent (a task's running slot, ``tasks.TaskStore.reserve``);
                its ``ToolError`` refuses the goal, and nothing is sent.

        Raises:
            ToolError: arguments that fail the tool's schema (each wrong field
                named), the guard's refusal, ``before_send``'s, or the server's.
        """
        template = _TEMPLATES["send_action_goal"]
        try:
            valid = template.fn_metadata.validate_arguments(arguments)
        except ValidationError as exc:
            raise ToolError(_bad_arguments(exc)) from None
        _wait(valid.get("timeout_s", 30.0))
        self.guard.admit("send_action_goal", arguments)
        if before_send is not None:
            before_send()
        with _tool_errors():
            return await self.link.send_goal(valid["action"], valid["type"], valid["goal"])

    async def cancel_action_goal(
        self, action: str, goal_id: str, timeout_s: float = 5.0
    ) -> GoalReport:
        """Cancel a goal by its id; for a goal of this session, wait for its end.

        Args:
            action: the action name.
            goal_id: the id ``send_action_goal`` returned (or another client's).
            timeout_s: the longest wait for the goal's end, seconds (at most MAX_WAIT_S).
        """
        seconds = _wait(timeout_s)
        ros = await self.link.connected()
        record = self.link.goals.get(goal_id)
        try:
            await ros.cancel_goal(action, goal_id)
        except GraphError as exc:  # no such goal in flight: this session's has ended
            if record is None:
                raise ToolError(str(exc)) from None
        except RwtError as exc:
            raise ToolError(str(exc)) from None
        if record is None:
            return GoalReport(
                goal_id=goal_id,
                action=action,
                state="cancel sent",
                status=None,
                result=None,
                feedback_count=0,
                last_feedback=None,
            )
        await self._settle(record, seconds)
        return goal_report(record)

    async def action_goal_status(self, goal_id: str) -> GoalReport:
        """A goal of this session: running, or how it ended and its result."""
        record = self.link.goals.get(goal_id)
        if record is None:
            known = ", ".join(self.link.goals) or "none"
            raise ToolError(f"no goal {goal_id!r} in this session (goals: {known})")
        return goal_report(record)

    @staticmethod
    async def _settle(record: Goal, timeout_s: float) -> None:
        """Wait up to ``timeout_s`` for the goal's end; it may still be running then."""
        with anyio.move_on_after(timeout_s):
            await record.done.wait()

    # ---- the robot app -------------------------------------------------------------

    async def robot_app(
        self,
        camera: str = "",
        cmd_vel: str = "/cmd_vel",
        max_linear: float = 0.5,
        max_angular: float = 1.0,
    ) -> RobotApp:
        """Show the robot in an app: its camera, and a pad that drives it while held.

        A host that renders MCP Apps shows ``ui://rwt/robot`` with this answer: the
        camera's video (WebRTC, else MJPEG), and a pad publishing
        geometry_msgs/msg/Twist on ``cmd_vel`` only while it is held, a zero Twist
        when let go. Other hosts get the settings as text.

        Args:
            camera: an image topic to show (sensor_msgs/msg/Image); empty: no camera.
            cmd_vel: the geometry_msgs/msg/Twist topic the pad drives.
            max_linear: the pad's top speed, m/s (at most MAX_APP_SPEED).
            max_angular: the pad's top turn rate, rad/s (at most MAX_APP_SPEED).
        """
        for name, value in (("max_linear", max_linear), ("max_angular", max_angular)):
            if not 0 < value <= MAX_APP_SPEED:
                raise ToolError(f"{name} must be in (0, {MAX_APP_SPEED:g}]")
        for name, topic in (("camera", camera), ("cmd_vel", cmd_vel)):
            problem = name_problem(topic) if topic or name == "cmd_vel" else None
            if problem is not None:  # it goes into URLs and the app's calls: a name or none
                raise ToolError(f"{name}: not a topic name: {problem}")
        refused = None
        if self.guard.read_only:
            refused = "the MCP server is read-only"
        elif self.approvals is not None and self.approvals.target("publish", {"topic": cmd_vel}):
            refused = f"cmd_vel {cmd_vel}: each command needs a person's approval (docs/safety.md)"
        else:
            try:
                self.link.robot.check_access("topics_pub", cmd_vel, "cmd_vel", op="robot_app")
            except ToolError as exc:
                refused = str(exc)
        token = await self._video_token() if camera and self.site.auth is not False else None
        return app_settings(
            self.site, camera or None, token, cmd_vel, refused, max_linear, max_angular
        )

    async def _video_token(self) -> str | None:
        """A video token for the app's camera (``/rwt/video_token``); None: none to have."""
        try:
            ros = await self.link.connected()
            answer = await ros.call_service(
                "/rwt/video_token", {}, type_name="std_srvs/srv/Trigger", timeout_s=_TOKEN_WAIT_S
            )
        except (RwtError, TimeoutError, ToolError):  # no auth secret, or not offered
            return None
        if not isinstance(answer, dict) or not answer.get("success"):
            return None
        token = answer.get("message")
        return token if isinstance(token, str) else None

    # ---- TF ---------------------------------------------------------------------------

    async def lookup_transform(
        self, target_frame: str, source_frame: str, timeout_s: float = 5.0
    ) -> Transform:
        """``source_frame``'s latest pose in ``target_frame``, from the TF republisher.

        Asks the server's tf2_web_republisher (``/republish_tfs``) for the one
        frame and reads the first transform it sends.

        Args:
            target_frame: the fixed frame (``map``, ``odom``, ``base_link``).
            source_frame: the frame whose pose is wanted.
            timeout_s: the longest wait, seconds (at most MAX_WAIT_S).
        """
        seconds = _wait(timeout_s)
        ros = await self.link.connected()
        request = {
            "source_frames": [source_frame],
            "target_frame": target_frame,
            "angular_thres": 0.0,
            "trans_thres": 0.0,
            "rate": 10.0,
            "timeout": _TF_TOPIC_TIMEOUT,
        }
        found: list[Message] = []
        got = anyio.Event()

        def take(msg: Message) -> None:
            for transform in msg.get("transforms", []):
                child = str(transform.get("child_frame_id", "")).lstrip("/")
                if not found and child == source_frame.lstrip("/"):
                    found.append(transform)
                    got.set()

        with _tool_errors(), anyio.move_on_after(seconds):
            answer = await ros.call_service("/republish_tfs", request, timeout_s=seconds)
            name = answer.get("topic_name") if isinstance(answer, dict) else None
            if not isinstance(name, str):
                raise ToolError(f"/republish_tfs answered no topic_name: {answer!r}")
            topic = await subscribe_confirmed(
                ros, name, "tf2_web_republisher/msg/TFArray", take, f"lookup_transform {name}"
            )
            try:
                await got.wait()
            finally:
                await topic.unsubscribe()
        if not found:
            raise ToolError(
                f"no transform from {source_frame!r} to {target_frame!r} within {seconds:g} s "
                "(are both frames on /tf or /tf_static, and joined?)"
            )
        values = found[0].get("transform", {})
        return Transform(
            target_frame=target_frame,
            source_frame=source_frame,
            translation=values.get("translation", {}),
            rotation=values.get("rotation", {}),
        )


_MAX_NOTES = 4  # distinct safety notes one ``publish_for`` reports


def _noted(notes: dict[str, None], note: str | None) -> None:
    """Keep ``note`` (a safety envelope's word on one publish) once, at most ``_MAX_NOTES``."""
    if note and len(notes) < _MAX_NOTES:
        notes[note] = None


def goal_report(record: Goal) -> GoalReport:
    """The goal as ``send_action_goal`` reports it: running, or how it ended (D18)."""
    status = record.status
    if record.error is not None:
        state = f"unknown: {record.error}"
    elif status is None:
        state = "running"
    else:
        state = GOAL_STATES.get(status, f"status {status}")
    return GoalReport(
        goal_id=record.handle.id,
        action=record.action,
        state=state,
        status=status,
        result=summarise(record.result),
        feedback_count=record.feedback_count,
        last_feedback=summarise(record.last_feedback),
    )


class _Latest:
    """The latest feedback not yet sent as a notification (one slot, overwritten)."""

    def __init__(self) -> None:
        self.values: object = None
        self.fresh = False
        self._ready = anyio.Event()

    def put(self, values: object) -> None:
        self.values, self.fresh = values, True
        self._ready.set()

    async def take(self) -> object:
        await self._ready.wait()
        self._ready = anyio.Event()
        self.fresh = False
        return self.values


@asynccontextmanager
async def _progress(record: Goal, ctx: Context) -> AsyncIterator[None]:
    """Forward the goal's feedback as MCP progress notifications while the call waits.

    Feedback arriving while a notification is being sent replaces the one
    waiting (the notifications are a view, not a log; ``feedback_count`` counts
    all); the last feedback before the call ends is always sent, within
    ``_LAST_PROGRESS_S``.
    """
    latest = _Latest()

    async def send(values: object) -> None:
        await ctx.report_progress(record.feedback_count, None, message_text(values))

    async def forward() -> None:
        while True:
            await send(await latest.take())

    record.listeners.append(latest.put)
    try:
        async with anyio.create_task_group() as tg:
            tg.start_soon(forward)
            try:
                yield
            finally:
                tg.cancel_scope.cancel()
        if latest.fresh:
            with anyio.move_on_after(_LAST_PROGRESS_S):  # a client that reads nothing
                await send(latest.values)
    finally:
        record.listeners.remove(latest.put)


_TOOL_META: dict[str, dict[str, Any]] = {
    name: {"ui": {"resourceUri": APP_URI}} for name in APP_TOOLS
}
"""The tools a host shows as an app (MCP Apps: the tool's ``_meta.ui``)."""


def build_server(
    link: RobotLink,
    guard: Guard | None = None,
    tasks: TaskStore | None = None,
    watched: Watched | None = None,
    site: AppSite | None = None,
    host: str = "",
    approvals: Approvals | None = None,
    request_state: RequestStateSecurity | None = None,
) -> tuple[MCPServer, TasksExtension]:
    """An MCPServer whose tools and resources drive the robot behind ``link``.

    Every tool call passes ``guard`` first (``guard.Guard.admit``: access rules,
    read-only mode, rate and size caps); the topics are resources
    (``resources.TopicResources``), with ``resources/subscribe`` for 2025-era
    clients and ``subscriptions/listen`` for 2026-07-28 ones; ``send_action_goal``
    answers a task to a client that takes tasks (``tasks.TasksExtension``). The
    caller connects ``link`` beside it (``cli.serve_stdio``, ``http.McpEndpoint``).

    Args:
        link: the session's connection.
        guard: the session's rules; None: a ``Guard()`` (no access rules, writes allowed).
        tasks: the front end's tasks; None: a store of this server's own.
        watched: the front end's watched topics (``resources.TopicResources``'s
            ``shared``); None: this server's own.
        site: where the robot app finds the server's video (``app.AppSite``);
            None: not known.
        host: the client's host, for its share of ``tasks``' running slots
            (``tasks.TaskStore.reserve``, D60); ``""``: the front end's one client.
        approvals: the calls that wait for a person's approval (``approval.Approvals``,
            docs/safety.md); None: none.
        request_state: how a 2026-07-28 round's request state is sealed, shared by
            every server of a front end so that any of them takes the next round
            (the SDK's ``RequestStateSecurity``); None: a key of this server's own.

    Returns:
        The server, and its tasks extension (``TasksExtension.hold`` keeps the
        connection of the goals it started).
    """
    guard = guard or Guard()
    tools = RobotTools(link, site)
    tools.approvals = approvals
    resources = TopicResources(link, guard, watched, site)
    report = functools.partial(_report_json, goal_report)
    extension = TasksExtension(tasks or TaskStore(), link, guard, tools.start_goal, report, host)
    extension.approvals = approvals
    server = MCPServer(
        "rwt",
        instructions=(
            "Tools of a ROS robot behind a rosbridge server: list its graph, read "
            "(echo) and publish topics, call services, send and cancel action goals, "
            "get and set parameters, look up transforms. type_definition gives the "
            "JSON schema of a message type. Topics are resources too (ros://topics/...): "
            "read one for its latest message, subscribe for updates."
            + (
                " This server is read-only: publish, calls, goals and set are refused."
                if guard.read_only
                else ""
            )
        ),
        extensions=[extension],
        subscriptions=resources.bus,
        request_state_security=request_state,
    )
    manager = server._tool_manager  # the SDK's registry: a tool made once, shared below
    for name in TOOLS:
        function = _guarded(guard, name, getattr(tools, name), approvals)
        manager._tools[name] = _tool_template(name, function).model_copy(update={"fn": function})
    tools.guard = guard
    resources.register(server._lowlevel_server)  # the SDK's way to add handlers
    _call_tools(server)
    return server, extension


def release_server(server: MCPServer) -> None:
    """Let go of what a server built by ``build_server`` holds, once it answers nothing more.

    Its handlers are its own bound methods and closures, so a server is a cycle of some
    400 objects that only the cyclic collector frees. A 2026-07-28 request builds one
    (``rwt_transports.http.mcp``): under a flood they piled up into collections of 15,000-
    20,000 objects that stopped the event loop 8-10 ms, which every other client waited
    out (benchmarks B25). Emptied here, they go when their last reference does.
    """
    low = server._lowlevel_server
    low._request_handlers.clear()
    low._notification_handlers.clear()
    low.middleware.clear()
    low.extensions.clear()
    vars(low).pop("get_tool_input_schema", None)  # a bound method of ``server``
    server._tool_manager._tools.clear()
    server._extensions.clear()


def warm_up() -> None:
    """Build what a session's first server builds once (the tools' models, the SDK's parts).

    A front end calls it while it starts (``http.McpEndpoint``), before the server
    freezes its start-up objects (``rwt_transports.process.gcfreeze``): otherwise the first
    request builds them while every client waits on the event loop (tens of ms), and
    full collections walk them ever after. Nothing is connected.
    """
    build_server(RobotLink("ws://127.0.0.1:9"))


_TEMPLATES: dict[str, Tool] = {}


def _tool_template(name: str, function: Callable[..., Awaitable[Any]]) -> Tool:
    """The tool ``name`` as the SDK describes it (schemas, argument model), made once.

    Every session's tool ``name`` has the same signature and text, only its function
    (bound to the session's link and guard) differs: each session shares this one's
    models (``Tool.model_copy``) instead of building them again, which was most of an
    MCP session's cost (about 20 ms of the event loop's time each; docs/limits.md).
    """
    template = _TEMPLATES.get(name)
    if template is None:
        made = Tool.from_function(
            function,
            name=name,
            description=_described(inspect.getdoc(function) or ""),
            structured_output=name != "echo",
            annotations=ToolAnnotations(read_only_hint=name not in WRITE_TOOLS),
            meta=_TOOL_META.get(name),
        )  # kept without this session's function, so that it keeps nothing of the session
        template = _TEMPLATES[name] = made.model_copy(update={"fn": _no_session})
    return template


async def _no_session(**_: Any) -> None:
    """A template's function: every session's copy of a tool has its own (``_tool_template``)."""
    raise RuntimeError("a tool template was called instead of a session's tool")


def _call_tools(server: MCPServer) -> None:
    """Call the tools as MCPServer does, but for two things.

    Arguments that fail a tool's input schema are a tool error naming each field,
    briefly (MCPServer's own text is pydantic's whole report, with links). A result
    the tool made already (``_as_result``: a typed answer, built to its output
    schema) goes out as it is, not validated again against the schema.
    """
    manager = server._tool_manager
    call = manager.call_tool

    async def call_tool(
        name: str, arguments: dict[str, Any], context: Any, convert_result: bool = False
    ) -> Any:
        try:
            result = await call(name, arguments, context=context, convert_result=False)
        except ToolError as exc:
            if not isinstance(exc.__cause__, ValidationError):
                raise
            raise ToolError(f"{name}: {_bad_arguments(exc.__cause__)}") from None
        tool = manager.get_tool(name)
        answered = isinstance(result, CallToolResult | InputRequiredResult)
        if not convert_result or answered or tool is None:
            return result
        return tool.fn_metadata.convert_result(result)

    manager.call_tool = call_tool  # type: ignore[method-assign]


def _report_json(report: Callable[[Goal], GoalReport], record: Goal) -> dict[str, Any]:
    """The goal's report as JSON values (a task's ``statusMessage`` and result)."""
    return report(record).model_dump(mode="json")


def _bad_arguments(exc: ValidationError) -> str:
    """``bad arguments: <field>: <what is wrong> (got <type>); ...``, briefly."""
    wrong = [
        f"{'.'.join(map(str, error['loc'])) or 'arguments'}: {error['msg']}"
        + ("" if error["type"] == "missing" else f" (got {type(error['input']).__name__})")
        for error in exc.errors()[:_MAX_FIELD_ERRORS]
    ]
    return f"bad arguments: {'; '.join(wrong)}"


def _guarded(
    guard: Guard,
    name: str,
    function: Callable[..., Awaitable[Any]],
    approvals: Approvals | None = None,
) -> Callable[..., Awaitable[Any]]:
    """``function`` (a tool) run only once ``guard`` admits the call (same signature).

    Then, where ``approvals`` say so, once a person approved it (``Approvals.confirm``):
    a 2026-07-28 call is answered with the question this round.
    """

    @functools.wraps(function)
    async def guarded(*args: Any, **kwargs: Any) -> Any:
        arguments = {k: v for k, v in kwargs.items() if k != "ctx"}
        guard.admit(name, arguments)
        if approvals is not None:
            asked = await approvals.confirm(name, arguments, kwargs.get("ctx"))
            if asked is not None:
                return asked
        result = await function(*args, **kwargs)
        if isinstance(result, BaseModel):
            return _as_result(result.model_dump(mode="json"))
        return _as_result(result) if isinstance(result, dict) else result

    return guarded


def _as_result(structured: dict[str, Any]) -> CallToolResult:
    """A tool's typed answer as MCP's result: structured content and the same as JSON text.

    Made once here: the SDK, handed the answer, would serialise it twice and check
    it against the tool's output schema with a generic JSON schema validator
    (about 100 ms for a listing of 1000 topics, docs/limits.md); the answer is
    built to that schema already (its model or typed dict).
    """
    text = json.dumps(structured, ensure_ascii=False, separators=(",", ":"))
    return CallToolResult(
        content=[TextContent(type="text", text=text)], structured_content=structured
    )


def _described(doc: str) -> str:
    """A tool's docstring for the agent: each bound's name followed by its value."""
    bounds = {**vars(render), **globals()}
    return _BOUND.sub(lambda match: f"{match[0]} ({bounds[match[0]]:g})", doc)


_BOUND = re.compile(r"\bMAX_[A-Z_]+\b")
