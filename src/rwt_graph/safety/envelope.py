"""The envelope: what remote clients publish on a bounded topic, checked at the one publish point.

``Envelope.install`` puts it on a graph's core (``GraphCore.envelope``); from then on
every publish of a remote client (``GraphCore.publish``, ``publish_serialized``: every
front end, every transport and encoding) passes ``admit`` before a subscriber sees
it, and in-process code and the links do not (docs/safety.md, D66):

- a NaN or an infinity in any float field is refused (D67);
- a field out of its bound is clamped (the message goes on) or refused (an
  ``EnvelopeError`` naming the field, the bound and the value; nothing delivered);
- past ``max_rate_hz`` (the topic's, all remote clients together, a burst of
  ``RATE_BURST``) a command is dropped;
- a command delivered makes its client a commander of the topic: when none of
  them commanded for ``deadman_s``, or the last one's connection ends, the
  envelope publishes the topic's ``stop`` once (D68).

The envelope holds each bounded topic as a publisher of its type (node
``/rwt_safety``) from install on, so the topic always has that type: a client
cannot make it with another one, whatever it advertises or publishes first, and a
link carries the stop to the robot's own nodes. What happened is told to the
publisher through the port's ``PublishNotes`` (a warning, once per episode) and to
the audit trail (``audit``).

Time is the envelope's own monotonic clock, never the graph's (a bag's time
during playback is not a dead-man's). Its timer is driven from outside:
``next_deadline`` and ``expire`` (the server's ``rwt_transports.deadman``).
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass, field
from itertools import groupby
from typing import TYPE_CHECKING

from rwt_protocol.errors import GraphError
from rwt_protocol.names import resolve_name
from rwt_protocol.ports import PublishNote

from .audit import AuditTrail, SafetyEvent
from .fields import BoundedField, compile_field, non_finite, replaced
from .rules import RulesError, SafetyRules, TopicRule

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.ports import ClientId, PublishNotes

    from ..core import GraphCore
    from ..topics import Topic
    from ..types import MessageType, TypeRegistry

__all__ = ["NODE", "RATE_BURST", "STATUS_TOPIC", "Envelope", "EnvelopeError"]

logger = logging.getLogger("rwt.safety")

NODE = "/rwt_safety"
"""The node of the envelope's publishers (its stops)."""
STATUS_TOPIC = "/rwt/safety"
"""The latched topic (``std_msgs/msg/String``, JSON) with the rules and the last events."""
RATE_BURST = 2.0
"""Commands a bounded topic takes at once beyond its ``max_rate_hz`` (jitter of a steady sender)."""
SHOWN_EVENTS = 20
"""The newest events ``STATUS_TOPIC`` carries."""


class EnvelopeError(GraphError):
    """A command the envelope refused: nothing was delivered (D67).

    Attributes:
        topic: the topic.
        field: the field that broke its bound (``linear.x``), or is not finite.
        value: the value sent.
    """

    def __init__(self, message: str, topic: str, field: str, value: object) -> None:
        super().__init__(message)
        self.topic = topic
        self.field = field
        self.value = value


@dataclass
class _Guarded:
    """One bounded topic: its rule, compiled, and its state."""

    rule: TopicRule
    msgtype: MessageType
    fields: tuple[BoundedField, ...]
    tokens: float = RATE_BURST
    refilled: float = 0.0
    commanders: dict[ClientId, float] = field(default_factory=dict)


class Envelope:
    """The safety envelope of one graph (module text).

    Args:
        rules: the rules.
        registry: the graph's types, against which every rule is checked.
        clock: monotonic seconds (injectable for tests).

    Raises:
        RulesError: a rule names an unknown type, a field its type lacks, a bound on a
            field that is not a number, or a stop message that does not fit its type,
            is not finite or breaks its own bounds; the text names the file and line.
    """

    def __init__(
        self,
        rules: SafetyRules,
        registry: TypeRegistry,
        *,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.rules = rules
        self.registry = registry
        self.clock = clock
        self.audit = AuditTrail(clock=clock, on_event=self._event)
        self.on_commanded: Callable[[], None] | None = None
        """Called when a topic becomes commanded (a dead-man deadline appears): wakes the timer."""
        self.changed = False
        """Set when the status (``status``) changed since ``STATUS_TOPIC`` was published."""
        self._plans: dict[str, tuple[tuple[str, bool, MessageType | None], ...]] = {}
        self._topics = {rule.name: self._compile(rule) for rule in rules.topics}
        self._frontends: dict[ClientId, str] = {}
        self._core: GraphCore | None = None
        self._client: ClientId = ""

    # ---- set-up ------------------------------------------------------------------------

    def _compile(self, rule: TopicRule) -> _Guarded:
        try:
            msgtype = self.registry.message(rule.type)
        except GraphError as exc:
            raise RulesError(f"{rule.where('type')}: type {rule.type!r}: {exc}") from None
        fields = []
        for path, (low, high) in rule.bounds.items():
            try:
                fields.append(compile_field(msgtype, path, low, high, self.registry.message))
            except (ValueError, GraphError) as exc:  # the path, or a nested type
                raise RulesError(f"{rule.where(f'bounds.{path}')}: {exc}") from None
        guarded = _Guarded(rule, msgtype, tuple(fields))
        if rule.stop is not None:
            self._check_stop(guarded)
        return guarded

    def _check_stop(self, guarded: _Guarded) -> None:
        """The stop must fit the type, be finite and keep its own bounds."""
        rule = guarded.rule
        try:
            stop = guarded.msgtype.from_json(rule.stop, path="stop", now=0.0).msg
        except GraphError as exc:
            raise RulesError(f"{rule.where('stop')}: stop: {exc}") from None
        bad = non_finite(guarded.msgtype, stop, self.registry.message, self._plans)
        if bad is not None:
            raise RulesError(f"{rule.where('stop')}: stop: {bad[0]} is {_num(bad[1])}, not finite")
        for bounded in guarded.fields:
            for _, value in bounded.values(stop):
                if not bounded.low <= value <= bounded.high:  # type: ignore[operator]
                    raise RulesError(
                        f"{rule.where('stop')}: stop: {bounded.text} {value} "
                        f"is outside {bounded.bound}"
                    )

    def install(self, core: GraphCore) -> None:
        """Bind every publish of ``core``'s remote clients (``core.envelope``).

        Holds each bounded topic as a publisher of its type (node ``/rwt_safety``) and
        keeps ``STATUS_TOPIC`` for the server (``reserve_topic``).

        Raises:
            RulesError: a bounded topic exists already with another type, or the graph
                has an envelope already.
        """
        if core.envelope is not None:
            raise RulesError("the graph has safety rules already")
        self._core = core
        self._client = core.local_client()
        core.nodes.bind(self._client, NODE)
        for guarded in self._topics.values():
            try:
                core.advertise(self._client, guarded.rule.name, guarded.msgtype.name)
            except GraphError as exc:
                raise RulesError(f"{guarded.rule.where('type')}: {exc}") from None
        core.reserve_topic(STATUS_TOPIC)
        core.advertise(self._client, STATUS_TOPIC, "std_msgs/msg/String", latch=True)
        core.envelope = self
        self.publish_status()

    def connected(self, client: ClientId, frontend: str) -> None:
        """Name the front end ``client`` came through (``rosbridge``, ``foxglove``): the audit's."""
        self._frontends[client] = frontend

    # ---- the check at the publish point -----------------------------------------------

    def admit(
        self, client: ClientId, entry: Topic, msg: dict[str, object], notes: PublishNotes | None
    ) -> dict[str, object] | None:
        """Check a remote client's message on ``entry``: the one hook (module text).

        Args:
            client: the publisher (never an in-process one: the graph asks only for others).
            entry: the topic.
            msg: the message, converted to the topic's type (never changed here).
            notes: where the publisher hears of a clamp or a drop (None: nowhere).

        Returns:
            The message to deliver (``msg``, or a clamped copy), or None: dropped (rate).

        Raises:
            EnvelopeError: a value is not finite, or out of bounds with ``reject``.
        """
        guarded = self._topics.get(entry.name)
        if guarded is None:
            return msg
        rule = guarded.rule
        bad = non_finite(guarded.msgtype, msg, self.registry.message, self._plans)
        if bad is not None:
            where, value = bad
            self._record("reject", client, rule.name, where, value, "", "not finite")
            raise EnvelopeError(
                f"{rule.name}: {where} is {_num(value)}, not a finite number "
                "(refused: nothing published)",
                rule.name,
                where,
                value,
            )
        outside = [
            (bounded, path, value)
            for bounded in guarded.fields
            for path, value in bounded.values(msg)
            if not bounded.low <= value <= bounded.high  # type: ignore[operator]
        ]
        if outside and rule.on_violation == "reject":
            bounded, path, value = outside[0]
            shown = _path_text(path)
            self._record("reject", client, rule.name, shown, value, bounded.bound, "refused")
            raise EnvelopeError(
                f"{rule.name}: {shown} {_num(value)} is outside {bounded.bound} "
                "(refused: nothing published)",
                rule.name,
                shown,
                value,
            )
        now = self.clock()
        if rule.max_rate_hz is not None and not self._take(guarded, now):
            text = f"{rule.name}: more than {rule.max_rate_hz:g} commands a second: dropped"
            first = self._record("rate_drop", client, rule.name, "", None, "", text)
            if notes is not None:
                notes(PublishNote(text, dropped=True, first=first))
            return None
        if outside:
            msg = self._clamped(client, rule.name, msg, outside, notes)
        if rule.deadman_s is not None:
            commanded = bool(guarded.commanders)
            guarded.commanders[client] = now
            if not commanded and self.on_commanded is not None:
                self.on_commanded()
        return msg

    def _clamped(
        self,
        client: ClientId,
        topic: str,
        msg: dict[str, object],
        outside: list[tuple[BoundedField, tuple[str | int, ...], object]],
        notes: PublishNotes | None,
    ) -> dict[str, object]:
        changes: list[tuple[tuple[str | int, ...], object]] = []
        said = []
        first = False
        for bounded, group in groupby(outside, key=lambda item: item[0]):  # in ``fields``' order
            places = [(path, value) for _, path, value in group]
            changes.extend((path, bounded.clamp(value)) for path, value in places)
            # one event and one clause per bound, however many elements a client sent out of it
            path, value = places[0]
            sent = changes[-len(places)][1]
            shown = _path_text(path)
            more = f", and {len(places) - 1} more of {bounded.text}" if len(places) > 1 else ""
            said.append(
                f"{shown} {_num(value)} clamped to {_num(sent)} (bound {bounded.bound}){more}"
            )
            detail = f"sent {_num(sent)}{more}"
            first = (
                self._record("clamp", client, topic, shown, value, bounded.bound, detail) or first
            )
        if notes is not None:
            notes(PublishNote(f"{topic}: {'; '.join(said)}", dropped=False, first=first))
        return replaced(msg, changes)

    def _take(self, guarded: _Guarded, now: float) -> bool:
        """A token of the topic's rate (a bucket of ``RATE_BURST``), if one is left."""
        rate = guarded.rule.max_rate_hz or 0.0
        guarded.tokens = min(RATE_BURST, guarded.tokens + (now - guarded.refilled) * rate)
        guarded.refilled = now
        if guarded.tokens < 1.0:
            return False
        guarded.tokens -= 1.0
        return True

    # ---- the dead-man -------------------------------------------------------------------

    def gone(self, client: ClientId, *, ended: bool = True) -> None:
        """``client`` left the graph (``GraphCore.release``).

        Args:
            client: the participant.
            ended: its connection ended (close, idle, cut, peer gone): a topic it
                commanded and no one else did within ``deadman_s`` gets its stop now.
                False: one request of a front end without connections was answered
                (an HTTP request, a 2026-07-28 MCP request): its command stands
                until ``deadman_s`` passes, kept under one key per transport
                (``http:requests``), so a flood of requests holds one entry, not one each.
        """
        now = self.clock()
        for guarded in self._topics.values():
            last = guarded.commanders.pop(client, None)
            if last is None:
                continue
            if not ended:  # its command stands, kept under one key for all such requests
                requests = f"{client.split(':', 1)[0]}:requests"
                guarded.commanders[requests] = max(last, guarded.commanders.get(requests, last))
                continue
            deadman = guarded.rule.deadman_s or 0.0
            if not any(now - each < deadman for each in guarded.commanders.values()):
                self._stop(guarded, client, "its connection ended")
        self._frontends.pop(client, None)

    def next_deadline(self) -> float | None:
        """When the next dead-man falls due (the ``clock``'s seconds), or None: none commanded."""
        deadlines = [
            max(guarded.commanders.values()) + (guarded.rule.deadman_s or 0.0)
            for guarded in self._topics.values()
            if guarded.commanders
        ]
        return min(deadlines, default=None)

    def expire(self, now: float | None = None) -> None:
        """Publish the stop of each topic none of whose commanders commanded for ``deadman_s``."""
        now = self.clock() if now is None else now
        for guarded in self._topics.values():
            if not guarded.commanders:
                continue
            client, last = max(guarded.commanders.items(), key=lambda item: item[1])
            deadman = guarded.rule.deadman_s or 0.0
            if now - last >= deadman:
                self._stop(guarded, client, f"no command for {deadman:g} s")

    def _stop(self, guarded: _Guarded, client: ClientId, why: str) -> None:
        """Publish the topic's stop, once for this run of commands."""
        guarded.commanders.clear()
        core = self._core
        rule = guarded.rule
        if core is None or rule.stop is None:
            return
        stop = guarded.msgtype.from_json(rule.stop, path="stop", now=core.clock.wall()).msg
        entry = core.topics.get(rule.name)
        latch = entry is not None and entry.latched is not None  # a latched command is replaced
        core.publish_local(self._client, rule.name, stop, latch)
        self._record("deadman_stop", client, rule.name, "", None, "", why)

    # ---- the audit and the status ----------------------------------------------------

    def _record(
        self,
        kind: str,
        client: ClientId,
        target: str,
        field_text: str,
        value: object,
        bound: str,
        detail: str,
    ) -> bool:
        frontend = self._frontends.get(client) or client.split(":", 1)[0]
        event = SafetyEvent(kind, client, frontend, target, field_text, value, bound, detail)
        self.changed = True
        return self.audit.record(event)

    def record_approval(self, kind: str, client: ClientId, target: str, detail: str) -> None:
        """Record an approval's outcome, as the MCP front end asked a person (D69).

        ``kind``: ``approval_given``, ``approval_declined``, ``approval_timeout`` or
        ``approval_unavailable``; ``detail``: the tool and what it would have done.
        """
        self._record(kind, client, resolve_name(target), "", None, "", detail)

    def _event(self, event: SafetyEvent) -> None:
        self.changed = True

    def status(self) -> dict[str, object]:
        """The rules and the newest events as JSON values (``STATUS_TOPIC``, the console)."""
        topics = [
            {
                "name": guarded.rule.name,
                "type": guarded.msgtype.name,
                "bounds": {b.text: [b.low, b.high] for b in guarded.fields},
                "on_violation": guarded.rule.on_violation,
                "max_rate_hz": guarded.rule.max_rate_hz,
                "deadman_s": guarded.rule.deadman_s,
                "approval": guarded.rule.approval,
                "commanded": bool(guarded.commanders),
            }
            for guarded in self._topics.values()
        ]
        rules = self.rules
        return {
            "topics": topics,
            "services": [rule.name for rule in rules.services if rule.approval],
            "actions": [rule.name for rule in rules.actions if rule.approval],
            "approval_timeout_s": rules.approval_timeout_s,
            "events": [event.as_dict() for event in self.audit.last()[-SHOWN_EVENTS:]],
        }

    def publish_status(self) -> None:
        """Publish ``status`` on ``STATUS_TOPIC`` (latched) and clear ``changed``."""
        self.changed = False
        if self._core is None:
            return
        text = json.dumps(self.status(), separators=(",", ":"), allow_nan=False)
        self._core.publish_local(self._client, STATUS_TOPIC, {"data": text}, True)


def _path_text(path: tuple[str | int, ...]) -> str:
    """``("position", 2)`` as ``position[2]``, ``("linear", "x")`` as ``linear.x``."""
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else f".{part}" if text else part
    return text


def _num(value: object) -> str:
    """A number as a message shows it: ``0.5``, ``NaN``, ``Infinity`` (as JSON clients write)."""
    if isinstance(value, float):
        if math.isnan(value):
            return "NaN"
        return f"{value:g}" if math.isfinite(value) else ("Infinity" if value > 0 else "-Infinity")
    return str(value)
