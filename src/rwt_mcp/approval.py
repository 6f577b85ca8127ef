"""A person's approval before an MCP tool acts on a topic, service or action that needs it.

The safety rules (``rwt_graph.safety.rules``: ``approval = true`` on a ``[[topic]]``,
``[[service]]`` or ``[[action]]``) name what an agent may touch only with a person's
yes. ``Approvals.confirm`` asks, before the tool does anything (docs/agents.md, D69):

- a 2026-07-28 client, through a multi round-trip request: the tool call is answered
  with an input-required result carrying a form elicitation and a request state
  (the time it was asked; the SDK seals it, bound to the tool and its arguments), and
  the client calls again with the person's answer;
- a 2025-era client, through elicitation: the server asks the client
  (``elicitation/create``) while the call waits;
- a client that offers neither gets a tool error saying why.

The person declining (or dismissing the form), or no answer within the rules'
``approval_timeout_s``, is a tool error saying nothing was done; every outcome is one
line of the audit trail (``approval_given``, ``approval_declined``,
``approval_timeout``, ``approval_unavailable``). A goal that needs approval is
asked for before it starts, never answered as a task.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from typing import Any

import anyio
from mcp.server.elicitation import render_elicitation_schema
from mcp.server.mcpserver import Context
from mcp.server.mcpserver.exceptions import ToolError
from mcp_types import ElicitRequest, ElicitRequestFormParams, ElicitResult, InputRequiredResult
from mcp_types.version import is_version_at_least
from pydantic import BaseModel, Field

from rwt_graph.safety.rules import SafetyRules

__all__ = ["APPROVAL_KEY", "MAX_SHOWN_CHARS", "Approval", "Approvals", "Recorder"]

APPROVAL_KEY = "approval"
"""The key of the elicitation in an input-required result (and of its answer)."""
MAX_SHOWN_CHARS = 400
"""Characters of a message, request or goal the person is shown (then ``...``)."""
_MODERN = "2026-07-28"  # the first revision that asks through input-required results

# tool -> (the family its target is in, the argument naming it, what it does)
_TARGETS = {
    "publish": ("topics", "topic", "publish on"),
    "publish_for": ("topics", "topic", "publish repeatedly on"),
    "call_service": ("services", "service", "call the service"),
    "send_action_goal": ("actions", "action", "send a goal to"),
}
_PAYLOAD = {
    "publish": "msg",
    "publish_for": "msg",
    "call_service": "args",
    "send_action_goal": "goal",
}

Recorder = Callable[[str, str, str, str], None]
"""``(kind, client, target, detail)``: an approval's outcome for the audit trail."""


class Approval(BaseModel):
    """The form a person answers: allow the call, or not."""

    approve: bool = Field(description="Allow the agent to do this")


class Approvals:
    """Which tool calls of one MCP server wait for a person, and the asking (module text).

    Args:
        rules: the safety rules (their ``approval`` entries and ``approval_timeout_s``).
        client: who asks (the MCP session's client id), for the audit.
        record: where each outcome goes (the envelope's audit trail).
    """

    def __init__(self, rules: SafetyRules, client: str, record: Recorder) -> None:
        self.rules = rules
        self.client = client
        self.record = record

    def target(self, tool: str, arguments: dict[str, Any]) -> str | None:
        """The topic, service or action the call touches that needs a person, or None."""
        found = _TARGETS.get(tool)
        if found is None:
            return None
        family, argument, _ = found
        name = arguments.get(argument)
        if not isinstance(name, str) or not self.rules.needs_approval(family, name):
            return None
        return name

    async def confirm(
        self, tool: str, arguments: dict[str, Any], ctx: Context[Any, Any] | None
    ) -> InputRequiredResult | None:
        """Ask a person before ``tool`` acts, if its target needs it.

        Returns:
            None: go on (no approval needed, or the person said yes); an
            ``InputRequiredResult`` to answer this round with (2026-07-28: the question).

        Raises:
            ToolError: the person declined, did not answer within the timeout, or the
                client offers no way to ask; nothing is done.
        """
        target = self.target(tool, arguments)
        if target is None:
            return None
        what = _describe(tool, target, arguments)
        if ctx is None or not _can_ask(ctx):
            self.record("approval_unavailable", self.client, target, what)
            raise ToolError(
                f"{tool} {target}: this needs a person's approval, and this MCP client offers "
                "no way to ask one (elicitation): nothing was done"
            )
        version = ctx.protocol_version
        if version is not None and is_version_at_least(version, _MODERN):
            return self._round(tool, target, what, ctx)
        await self._elicit(tool, target, what, ctx)
        return None

    def _round(
        self, tool: str, target: str, what: str, ctx: Context[Any, Any]
    ) -> InputRequiredResult | None:
        """A 2026-07-28 round: the question, or the answer to the one asked before."""
        asked = _asked(ctx.request_state)
        answer = (ctx.input_responses or {}).get(APPROVAL_KEY)
        if asked is None or answer is None:  # not asked yet (an answer unasked for is not one)
            return _question(what, ctx.request_state if asked is not None else None)
        if time.time() - asked > self.rules.approval_timeout_s:
            self._timed_out(tool, target, what)
        if not isinstance(answer, ElicitResult):
            raise ToolError(f"{tool} {target}: the approval's answer is not a form's answer")
        self._decide(tool, target, what, answer.action, answer.content)
        return None

    async def _elicit(self, tool: str, target: str, what: str, ctx: Context[Any, Any]) -> None:
        """A 2025-era client: ``elicitation/create`` while the call waits."""
        with anyio.move_on_after(self.rules.approval_timeout_s):
            result = await ctx.elicit(_message(what), Approval)
            data = getattr(result, "data", None)
            content = {"approve": data.approve} if isinstance(data, Approval) else None
            self._decide(tool, target, what, result.action, content)
            return
        self._timed_out(tool, target, what)

    def _decide(
        self, tool: str, target: str, what: str, action: str, content: dict[str, Any] | None
    ) -> None:
        if action == "accept" and content is not None and content.get("approve") is True:
            self.record("approval_given", self.client, target, what)
            return
        self.record("approval_declined", self.client, target, f"{what} ({action})")
        raise ToolError(f"{tool} {target}: the person did not approve it: nothing was done")

    def _timed_out(self, tool: str, target: str, what: str) -> None:
        seconds = self.rules.approval_timeout_s
        self.record("approval_timeout", self.client, target, what)
        raise ToolError(
            f"{tool} {target}: no answer from the person within {seconds:g} s: nothing was done"
        )


def _can_ask(ctx: Context[Any, Any]) -> bool:
    """Whether the client declared form elicitation (a bare ``elicitation: {}`` counts)."""
    capabilities = ctx.client_capabilities
    elicitation = capabilities.elicitation if capabilities is not None else None
    return elicitation is not None and (elicitation.form is not None or elicitation.url is None)


def _question(what: str, state: str | None) -> InputRequiredResult:
    """The input-required result asking ``what``; its state is when it was asked."""
    params = ElicitRequestFormParams(
        message=_message(what), requested_schema=render_elicitation_schema(Approval)
    )
    asked = state or json.dumps({"asked": time.time()})
    return InputRequiredResult(
        input_requests={APPROVAL_KEY: ElicitRequest(params=params)}, request_state=asked
    )


def _asked(state: str | None) -> float | None:
    """When the question was asked, from a request state this server made (the SDK sealed it)."""
    if not state:
        return None
    try:
        asked = json.loads(state).get("asked")
    except (ValueError, AttributeError):
        return None
    return float(asked) if isinstance(asked, int | float) else None


def _message(what: str) -> str:
    return f"An AI agent asks to {what}. Allow it?"


def _describe(tool: str, target: str, arguments: dict[str, Any]) -> str:
    """``publish on /cmd_vel: {...}``, the payload cut at ``MAX_SHOWN_CHARS``."""
    verb = _TARGETS[tool][2]
    payload = json.dumps(arguments.get(_PAYLOAD[tool]), separators=(",", ":"), default=str)
    if len(payload) > MAX_SHOWN_CHARS:
        payload = payload[:MAX_SHOWN_CHARS] + "..."
    extra = ""
    if tool == "publish_for":
        rate, seconds = arguments.get("rate_hz"), arguments.get("duration_s")
        final = json.dumps(arguments.get("final_msg"), separators=(",", ":"), default=str)
        extra = f" at {rate} Hz for {seconds} s, then {final[:MAX_SHOWN_CHARS]}"
    return f"{verb} {target}: {payload}{extra}"
