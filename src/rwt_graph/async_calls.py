"""Async helpers for Python code that calls services and actions of a graph.

The graph is synchronous and loop-agnostic; these wrap its callback API in
anyio events so embedding code can ``await`` a service call or a goal, with a
timeout. In-process and client-advertised providers look the same.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import anyio

from rwt_protocol.errors import ServiceCallError

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_graph.graph import Graph
    from rwt_protocol.ports import GoalStatus

__all__ = ["GoalOutcome", "ServiceCallError", "call_service", "send_action_goal"]

Message = dict[str, object]


@dataclass(frozen=True)
class GoalOutcome:
    """How a goal ended: its ``GoalStatus`` and result message (D18)."""

    status: GoalStatus
    result: Message


async def call_service(
    graph: Graph, service: str, args: object = None, *, timeout_s: float | None = 10.0
) -> Message:
    """Call ``service`` and wait for its response.

    Args:
        graph: the graph providing the service.
        service: service name.
        args: request fields as a dict, a list (positional) or None.
        timeout_s: seconds to wait; None waits for ever.

    Returns:
        The response message as a dict.

    Raises:
        ServiceCallError: the call failed, or timed out (the call is forgotten).
        GraphError, FieldError: the service does not exist or ``args`` does not fit.
    """
    done = anyio.Event()
    outcome: list[tuple[bool, object]] = []

    def reply(result: bool, values: object) -> None:
        outcome.append((result, values))
        done.set()

    pending = graph.port.call_service(graph.port.local_client(), service, args, reply)
    with anyio.move_on_after(timeout_s):
        await done.wait()
    if not outcome:
        pending.forget()
        raise ServiceCallError(f"call to {service} timed out after {timeout_s:g} s")
    result, values = outcome[0]
    if not result or not isinstance(values, dict):
        raise ServiceCallError(str(values))
    return values


async def send_action_goal(
    graph: Graph,
    action: str,
    goal: object = None,
    *,
    on_feedback: Callable[[Message], None] | None = None,
    timeout_s: float | None = None,
) -> GoalOutcome:
    """Send a goal to ``action`` and wait for its end.

    Cancelling the waiting task (or the timeout) asks the action server to cancel.

    Raises:
        ServiceCallError: the goal could not run (``result: false``) or timed out.
        GraphError, FieldError: the action does not exist or ``goal`` does not fit.
    """
    done = anyio.Event()
    outcome: list[tuple[GoalStatus, bool, object]] = []

    def finish(status: GoalStatus, result: bool, values: object) -> None:
        outcome.append((status, result, values))
        done.set()

    handle = graph.port.send_action_goal(
        graph.port.local_client(), action, goal, finish, on_feedback
    )
    try:
        with anyio.move_on_after(timeout_s):
            await done.wait()
    finally:
        if not outcome:
            handle.forget()
    if not outcome:
        raise ServiceCallError(f"goal to {action} timed out after {timeout_s:g} s")
    status, result, values = outcome[0]
    if not result or not isinstance(values, dict):
        raise ServiceCallError(str(values))
    return GoalOutcome(status, values)
