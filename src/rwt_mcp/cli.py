"""``rwt mcp URL``: an MCP server over stdio in front of a rosbridge server.

The command line's entry (``rwt_cli.app`` loads ``mcp_command`` when ``rwt mcp``
runs); ``serve_stdio`` runs the server (docs/agents.md).
"""

from __future__ import annotations

import functools
import logging
import sys
from pathlib import Path
from typing import Annotated

import anyio
import typer
from mcp.server.stdio import stdio_server

from rwt_client.connectors import server_url
from rwt_graph.safety.audit import AuditTrail, SafetyEvent
from rwt_graph.safety.rules import RulesError, SafetyRules, load_rules
from rwt_protocol.errors import ConfigError

from .app import AppSite
from .approval import Approvals
from .guard import Guard
from .link import RobotLink
from .tasks import TaskStore
from .tools import build_server

__all__ = ["mcp_command", "serve_stdio", "stdio_site"]


def stdio_site(url: str) -> AppSite:
    """Where the robot app looks for a remote server's video: WebRTC offers on its port.

    ``url``'s WebSocket form (``ws://``, ``wss://``) as HTTP; whether that server
    answers offers, or runs a video server, is not known from here: the app tries
    WebRTC and says what the server answered. Other URLs (TCP): no video.
    """
    scheme, _, rest = url.partition("://")
    web = {"ws": "http", "wss": "https", "http": "http", "https": "https"}.get(scheme)
    if web is None:
        return AppSite()
    return AppSite(base=f"{web}://{rest.split('/', 1)[0]}")


def stdio_approvals(rules: SafetyRules, client: str) -> Approvals:
    """The approvals of ``rules`` for the stdio front end, its audit trail on stderr (D69)."""
    trail = AuditTrail()

    def record(kind: str, who: str, target: str, detail: str) -> None:
        trail.record(SafetyEvent(kind, who, "mcp", target, detail=detail))

    return Approvals(rules, client, record)


async def serve_stdio(
    url: str, *, read_only: bool = False, safety: SafetyRules | None = None
) -> None:
    """Serve MCP on this process's stdin and stdout until stdin closes.

    One rosbridge connection to ``url`` for the whole session, made in the
    background: tools called before it is up fail with the client's reason. The
    client's first request decides the protocol's era (the SDK's dual-era loop,
    D52): a 2025-era client's ``initialize``, or a 2026-07-28 client's requests,
    each with its ``_meta``.

    Args:
        url: the rosbridge server (``rwt_client.connectors.server_url``'s forms).
        read_only: refuse the tools that change the robot (``guard.WRITE_TOOLS``).
        safety: safety rules whose approvals this front end asks a person for
            (``approval.Approvals``); the bounds are the server's (docs/safety.md).
    """
    link = RobotLink(url)
    client = f"stdio:{url}"
    guard = Guard(client=client, read_only=read_only)
    approvals = None if safety is None else stdio_approvals(safety, client)
    server, _tasks = build_server(
        link, guard, TaskStore(), site=stdio_site(url), approvals=approvals
    )
    lowlevel = server._lowlevel_server
    ended = anyio.Event()

    async def stdio() -> None:
        try:
            async with stdio_server() as (read, write):
                await lowlevel.run(read, write, lowlevel.create_initialization_options())
        finally:
            ended.set()

    async with anyio.create_task_group() as tg:
        tg.start_soon(stdio)
        try:
            await link.connect(ended)
            await ended.wait()
        finally:  # in this task: the client's task group was entered here (connect)
            await link.close()


def mcp_command(
    url: Annotated[
        str,
        typer.Argument(
            help="The rosbridge server: ws://HOST:PORT, wss://..., tcp://HOST:PORT or HOST:PORT.",
            show_default=False,
        ),
    ],
    read_only: Annotated[
        bool,
        typer.Option(
            "--read-only",
            help="Refuse the tools that change the robot: publish, publish_for, call_service,"
            " send_action_goal, cancel_action_goal, set_parameter.",
        ),
    ] = False,
    safety: Annotated[
        Path | None,
        typer.Option(
            "--safety",
            metavar="FILE",
            help="Safety rules (TOML, as rwt serve --safety): the topics, services and"
            " actions marked approval = true wait for a person's yes (elicitation).",
        ),
    ] = None,
) -> None:
    """Serve MCP (Model Context Protocol) over stdio in front of a rosbridge server.

    AI agents (Claude, Cursor, any MCP client) start it as a stdio server and
    drive the robot through its tools: the graph, topics (echo, images, publish),
    services, actions, parameters and TF; its topics are resources to read and
    subscribe to. Logs go to stderr.
    """
    try:
        target = server_url(url)
    except ConfigError as exc:
        raise typer.BadParameter(str(exc), param_hint="URL") from None
    try:
        rules = None if safety is None else load_rules(safety)
    except RulesError as exc:
        raise typer.BadParameter(exc.message, param_hint="--safety") from None
    # stdout carries MCP: logs go to stderr, a line per retry to connect (back-off up to 5 s)
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr, format="rwt mcp: %(message)s")
    anyio.run(functools.partial(serve_stdio, target, read_only=read_only, safety=rules))
