"""The MCP tools, declared once: each tool's safety class and what its access rule checks.

Every set of tools the front ends keep is read from ``TOOLS``: the order a server lists
them in (``tools.build_server``), those that change the robot (``WRITE_TOOLS``: refused
in read-only mode, logged when they run, annotated ``readOnlyHint: false``), the
listings that share a lower rate (``LISTINGS``), the name each tool's access rule checks
(``TOOL_NAMES``), the tools answered with a task (``TASK_TOOLS``) and the tools a host
shows as an app (``APP_TOOLS``). A new tool is one entry here and its method on
``tools.RobotTools``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

__all__ = [
    "APP_TOOLS",
    "LISTINGS",
    "TASK_TOOLS",
    "TOOLS",
    "TOOL_NAMES",
    "WRITE_TOOLS",
    "ToolSpec",
]


@dataclass(frozen=True)
class ToolSpec:
    """What the front end must know of one tool, beyond its signature and text.

    Attributes:
        write: it changes the robot (publishes, calls, sends or cancels goals, sets).
        listing: it lists the graph (the largest answers: a lower shared rate).
        names: the access family and the argument naming what it touches
            (``("topics_pub", "topic")``: a topic it publishes, held to
            ``--topics-pub-glob``, D50); None: it names nothing.
        task: a client that takes tasks gets a task for it (``tasks.TasksExtension``).
        app: a host shows it as an MCP App (``app.APP_URI``, D54).
    """

    write: bool = False
    listing: bool = False
    names: tuple[str, str] | None = None
    task: bool = False
    app: bool = False


TOOLS: Mapping[str, ToolSpec] = {
    "list_topics": ToolSpec(listing=True),
    "list_services": ToolSpec(listing=True),
    "list_nodes": ToolSpec(listing=True),
    "list_actions": ToolSpec(listing=True),
    "list_parameters": ToolSpec(listing=True),
    "type_definition": ToolSpec(),
    "echo": ToolSpec(names=("topics_sub", "topic")),
    "publish": ToolSpec(write=True, names=("topics_pub", "topic")),
    "publish_for": ToolSpec(write=True, names=("topics_pub", "topic")),
    "call_service": ToolSpec(write=True, names=("services", "service")),
    "send_action_goal": ToolSpec(write=True, names=("actions", "action"), task=True),
    "cancel_action_goal": ToolSpec(write=True, names=("actions", "action")),
    "action_goal_status": ToolSpec(),
    "get_parameter": ToolSpec(names=("params", "name")),
    "set_parameter": ToolSpec(write=True, names=("params", "name")),
    "lookup_transform": ToolSpec(),
    "robot_app": ToolSpec(names=("topics_sub", "camera"), app=True),
}
"""Every tool, in the order a server lists them."""

WRITE_TOOLS = frozenset(name for name, spec in TOOLS.items() if spec.write)
"""The tools that change the robot: refused in read-only mode, logged when they run."""
LISTINGS = frozenset({name for name, spec in TOOLS.items() if spec.listing} | {"resources/list"})
"""The requests that list the graph (``resources/list`` too): one lower rate for all."""
TOOL_NAMES: Mapping[str, tuple[str, str]] = {
    name: spec.names for name, spec in TOOLS.items() if spec.names is not None
}
"""For each tool that names something: its access family and the argument naming it."""
TASK_TOOLS = frozenset(name for name, spec in TOOLS.items() if spec.task)
"""The tools answered with a task where the client takes tasks: those that wait past a call."""
APP_TOOLS = frozenset(name for name, spec in TOOLS.items() if spec.app)
"""The tools a host shows as an app (their ``_meta.ui.resourceUri``)."""
