"""What an MCP session may do: read-only mode, rate and size caps, the write log.

Every tool call passes ``Guard.admit`` before it runs (``tools.build_server``
wraps each tool): a call refused here is a tool error that names the rule, and
the robot never hears of it. The rules (docs/mcp.md, "Safety"):

- read-only mode (``--mcp-read-only``, ``rwt mcp --read-only``): the tools that
  change the robot (``WRITE_TOOLS``) are refused;
- a rate per tool and session (``TOOL_CALLS_PER_S``, a bucket of ``TOOL_BURST``),
  the listings' together a lower one (``LISTINGS``: ``LISTING_CALLS_PER_S``, a
  bucket of ``LISTING_BURST``), and a size for a call's arguments
  (``MAX_TOOL_ARGUMENT_BYTES``);
- every write is logged with its client, once per episode (``rwt.mcp`` logger);
  every refusal by read-only mode or a cap is logged by the access log as a glob's
  is (``access.log_refused``: ``event=access_denied ... rule=TOOL_CALLS_PER_S``).

The access rules (``--topics-glob`` and friends) are not the guard's: the robot
checks each name it is asked for (``session.McpSession``, through the server's one
access gate; ``rwt mcp URL``'s server, for its own connection). ``refusal_text`` is
the tool error they give.

No I/O: the time comes from ``clock``.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import NoReturn

from mcp.server.mcpserver.exceptions import ToolError

from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.names import name_problem
from rwt_protocol.runtime.access import AccessPolicy, Family, TopicUse, log_refused

from .catalog import APP_TOOLS, LISTINGS, TOOL_NAMES, WRITE_TOOLS

__all__ = [
    "FAMILIES",
    "LISTINGS",
    "LISTING_BURST",
    "LISTING_CALLS_PER_S",
    "MAX_TOOL_ARGUMENT_BYTES",
    "TOOL_BURST",
    "TOOL_CALLS_PER_S",
    "TOOL_NAMES",
    "WRITE_TOOLS",
    "Guard",
    "refusal_text",
]

logger = logging.getLogger("rwt.mcp")

#: Calls a second one session may make of one tool, on average; more is a tool error.
TOOL_CALLS_PER_S = 10.0
#: Calls of one tool a session may make at once after a quiet spell (the bucket's size).
TOOL_BURST = 10
#: A call's arguments, as JSON, in bytes: a larger call is a tool error.
MAX_TOOL_ARGUMENT_BYTES = 64 * 1024
#: Listings a second one session may make, all of them together, on average.
LISTING_CALLS_PER_S = 2.0
#: Listings a session may make at once after a quiet spell.
LISTING_BURST = 5
FAMILIES: Mapping[str, tuple[Family, TopicUse | None]] = {
    "topics": (Family.TOPICS, None),
    "topics_pub": (Family.TOPICS, TopicUse.PUBLISH),
    "topics_sub": (Family.TOPICS, TopicUse.SUBSCRIBE),
    "services": (Family.SERVICES, None),
    "actions": (Family.ACTIONS, None),
    "params": (Family.PARAMS, None),
}
"""A ``TOOL_NAMES`` family as the access rules name it: ``topics`` (a listing: either
use), ``topics_pub`` (publishing), ``topics_sub`` (subscribing, reading), ``services``,
``actions``, ``params``."""


@dataclass
class _Bucket:
    tokens: float
    at: float


@dataclass
class Guard:
    """One MCP session's rules, checked before each tool runs.

    Attributes:
        client: who the session is, for the write log (``mcp:127.0.0.1:5123#3``).
        read_only: refuse ``WRITE_TOOLS``.
        clock: monotonic seconds.
    """

    client: str = "stdio"
    read_only: bool = False
    clock: Callable[[], float] = time.monotonic
    _buckets: dict[str, _Bucket] = field(default_factory=dict, repr=False)
    _writes: EpisodeLog = field(default_factory=lambda: EpisodeLog(logger), repr=False)

    def admit(self, tool: str, arguments: Mapping[str, object]) -> None:
        """Let a call of ``tool`` with ``arguments`` run, or refuse it.

        Raises:
            ToolError: read-only mode and a write; the arguments over
                ``MAX_TOOL_ARGUMENT_BYTES``; the tool called faster than
                ``TOOL_CALLS_PER_S``; a topic, service or action name that is not a
                ROS name (``names.name_problem``, the rule rosbridge's ops follow).
                The text names the rule.
        """
        if self.read_only and tool in WRITE_TOOLS:
            self._refuse(tool, "--mcp-read-only", "refused, the MCP server is read-only")
        self._check_size(tool, arguments)
        self.check_rate(tool)
        family_field = TOOL_NAMES.get(tool)
        target = arguments.get(family_field[1]) if family_field else None
        # An app checks each name it takes itself, naming the field (and "" is no camera).
        named = family_field is not None and family_field[0] != "params" and tool not in APP_TOOLS
        if named and isinstance(target, str) and (problem := name_problem(target)):
            raise ToolError(f"{tool}: {problem}")  # as a rosbridge op's name is checked
        if tool in WRITE_TOOLS:
            self._writes.log(
                logging.INFO,
                f"{tool}:{target}",
                "event=mcp_write client=%s tool=%s target=%s",
                self.client,
                tool,
                target,
            )

    def _refuse(self, tool: str, rule: str, why: str, then: str = "") -> NoReturn:
        """Refuse a call of ``tool`` by ``rule`` (not a glob), logged and said.

        The access log's line, once per episode (``access.log_refused``), and the tool
        error ``<tool>: <why> (<rule>)`` followed by ``then`` (what to do).
        """
        log_refused(client=self.client, op=tool, rule=rule, reason=why, now=self.clock())
        raise ToolError(f"{tool}: {why} ({rule}){then}")

    def _check_size(self, tool: str, arguments: Mapping[str, object]) -> None:
        size = len(json.dumps(arguments, default=repr).encode())
        if size > MAX_TOOL_ARGUMENT_BYTES:
            why = f"the arguments are {size} bytes, over {MAX_TOOL_ARGUMENT_BYTES}"
            self._refuse(tool, "MAX_TOOL_ARGUMENT_BYTES", why)

    def check_rate(self, tool: str) -> None:
        """A token bucket per tool: ``TOOL_BURST`` calls, refilled at ``TOOL_CALLS_PER_S``.

        ``tool`` may also name a request that is not a tool (``resources/read``):
        each has its own bucket, but the ``LISTINGS``, which share one of
        ``LISTING_BURST`` calls, refilled at ``LISTING_CALLS_PER_S``.

        Raises:
            ToolError: ``<tool>: called more than 10 times a second (TOOL_CALLS_PER_S):
                ...``; a listing: ``listings called more than 2 times a second
                (LISTING_CALLS_PER_S)``.
        """
        if tool in LISTINGS:
            key, rate, burst, name = (
                "listings",
                LISTING_CALLS_PER_S,
                LISTING_BURST,
                "listings called",
            )
        else:
            key, rate, burst, name = tool, TOOL_CALLS_PER_S, TOOL_BURST, "called"
        now = self.clock()
        bucket = self._buckets.setdefault(key, _Bucket(float(burst), now))
        bucket.tokens = min(burst, bucket.tokens + (now - bucket.at) * rate)
        bucket.at = now
        if bucket.tokens < 1:
            bound = "LISTING_CALLS_PER_S" if tool in LISTINGS else "TOOL_CALLS_PER_S"
            why = f"{name} more than {rate:g} times a second"
            self._refuse(tool, bound, why, ": wait and call again")
        bucket.tokens -= 1


def refusal_text(policy: AccessPolicy, glob: str, what: str, name: str) -> str:
    """The tool error for ``name`` refused by ``glob`` of ``policy`` (the agent reads it).

    ``<what> <name>: refused by <rule>``, the rule named as its option with its
    patterns (``topic /cmd: refused by --topics-sub-glob [/battery]``); ``what`` is
    the tool argument that named it (``topic``, ``service``, ``action``, ``name``).
    """
    patterns = ", ".join(policy.patterns(glob))
    return f"{what} {name}: refused by --{glob.replace('_', '-')} [{patterns}]"
