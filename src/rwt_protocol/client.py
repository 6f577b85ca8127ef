"""The client role of the protocol, sans-IO: ops out, events in.

``ClientSession`` builds the frames a rosbridge client sends (``subscribe``,
``call_service``, ``send_action_goal``, ...) and turns the frames a server sends
into events (``TopicMessage``, ``ServiceResponded``, ``ServiceRequested``, ...).
It keeps the state a client needs to route replies (ids of its calls and goals,
its subscriptions, advertisements and offered services, so a transport can
replay them after reconnecting) and undoes the encodings on the way in:
``fragment`` ops are reassembled by ``num`` (spec 3.1.1, D19), ``png`` ops
decoded (spec 3.1.2, D20), binary frames decoded as CBOR with typed arrays
(spec 3.1.3, D21).

Like ``Session`` it does no I/O and keeps no clock: a transport feeds
``receive_frame`` and sends what ``frames_to_send`` returns. It relies on
nothing beyond the spec, so it works with servers other than rwt (D29: it
accepts that a server never sends ``status``).
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Mapping
from dataclasses import dataclass, field

from .codec_cbor import decode_cbor
from .errors import LocalProtocolError, RemoteProtocolError
from .png import decode_png

__all__ = [
    "ActionFeedbackReceived",
    "ActionResultReceived",
    "ClientEvent",
    "ClientSession",
    "GoalCancelRequested",
    "GoalRequested",
    "ServiceRequested",
    "ServiceResponded",
    "StatusReceived",
    "TopicMessage",
    "UnknownOp",
]

MiB = 1024 * 1024
Message = dict[str, object]
OpId = str | int


@dataclass(frozen=True, slots=True)
class TopicMessage:
    """A ``publish`` from the server: ``msg`` on ``topic`` (spec 3.3.3)."""

    topic: str
    msg: object


@dataclass(frozen=True, slots=True)
class ServiceResponded:
    """The reply to one of our ``call_service`` ops (spec 3.3.9, D28)."""

    id: OpId
    service: str
    result: bool
    values: object


@dataclass(frozen=True, slots=True)
class ServiceRequested:
    """A call of a service we advertised; answer with ``service_response`` (spec 3.3.8)."""

    id: OpId
    service: str
    args: object


@dataclass(frozen=True, slots=True)
class GoalRequested:
    """A goal for an action we advertised (spec 3.3.12)."""

    id: OpId
    action: str
    action_type: str
    args: object
    feedback: bool


@dataclass(frozen=True, slots=True)
class GoalCancelRequested:
    """A request to cancel a goal of an action we advertised (spec 3.3.13)."""

    id: OpId
    action: str


@dataclass(frozen=True, slots=True)
class ActionFeedbackReceived:
    """Feedback for one of our goals (spec 3.3.14)."""

    id: OpId
    action: str
    values: object


@dataclass(frozen=True, slots=True)
class ActionResultReceived:
    """The result of one of our goals (spec 3.3.15, D18): ``status`` is a GoalStatus code."""

    id: OpId
    action: str
    result: bool
    status: int
    values: object


@dataclass(frozen=True, slots=True)
class StatusReceived:
    """A ``status`` message (spec 3.2.2); ``id`` is the op it is about, if any."""

    level: str
    msg: str
    id: OpId | None


@dataclass(frozen=True, slots=True)
class UnknownOp:
    """A frame this client does not understand (kept for logging, never raised)."""

    frame: object
    reason: str


ClientEvent = (
    TopicMessage
    | ServiceResponded
    | ServiceRequested
    | GoalRequested
    | GoalCancelRequested
    | ActionFeedbackReceived
    | ActionResultReceived
    | StatusReceived
    | UnknownOp
)
"""Everything ``ClientSession.receive_frame`` can report."""


@dataclass
class _Partial:
    total: int
    parts: dict[int, str] = field(default_factory=dict)
    size: int = 0


class ClientSession:
    """One client connection's protocol state.

    Args:
        max_pending_fragment_bytes: bound on the text of incomplete fragmented
            messages kept at once; the oldest partial message is dropped beyond it.
    """

    def __init__(self, *, max_pending_fragment_bytes: int = 64 * MiB) -> None:
        self._out: list[str] = []
        self._counter = itertools.count(1)
        self._fragments: dict[OpId, _Partial] = {}
        self._fragment_bytes = 0
        self._fragment_limit = max_pending_fragment_bytes
        self.subscriptions: dict[OpId, Message] = {}
        """Subscribe ops by id, replayed after a reconnect."""
        self.advertisements: dict[OpId, Message] = {}
        """Advertise ops by id, replayed after a reconnect."""
        self.services: dict[str, Message] = {}
        """advertise_service ops by service name, replayed after a reconnect."""
        self.actions: dict[str, Message] = {}
        """advertise_action ops by action name, replayed after a reconnect."""
        self.level: str | None = None

    # ---- output ---------------------------------------------------------------

    def frames_to_send(self) -> list[str]:
        """Take the JSON frames queued for the server, oldest first."""
        frames, self._out = self._out, []
        return frames

    def send_op(self, op: Mapping[str, object]) -> None:
        """Queue any op as given (for ops this class has no method for)."""
        self._out.append(json.dumps(op, separators=(",", ":")))

    def new_id(self, prefix: str) -> str:
        """A fresh id like roslibjs makes: ``<prefix>:<n>``."""
        return f"{prefix}:{next(self._counter)}"

    def replay(self) -> None:
        """Queue again every standing op (level, advertisements, subscriptions, services)."""
        if self.level is not None:
            self.send_op({"op": "set_level", "level": self.level})
        for group in (self.advertisements, self.subscriptions, self.services, self.actions):
            for op in group.values():
                self.send_op(op)

    # ---- topics -----------------------------------------------------------------

    def subscribe(self, topic: str, type_name: str | None = None, **options: object) -> str:
        """Queue ``subscribe`` (spec 3.3.4); ``options`` are its optional fields.

        Returns:
            The subscription id, for ``unsubscribe``.
        """
        sub_id = self.new_id(f"subscribe:{topic}")
        op: Message = {"op": "subscribe", "id": sub_id, "topic": topic}
        if type_name is not None:
            op["type"] = type_name
        op.update({k: v for k, v in options.items() if v is not None})
        self.subscriptions[sub_id] = op
        self.send_op(op)
        return sub_id

    def unsubscribe(self, topic: str, sub_id: OpId) -> None:
        """Queue ``unsubscribe`` of one subscription (spec 3.3.5)."""
        self.subscriptions.pop(sub_id, None)
        self.send_op({"op": "unsubscribe", "id": sub_id, "topic": topic})

    def advertise(
        self, topic: str, type_name: str, *, latch: bool = False, queue_size: int = 100
    ) -> str:
        """Queue ``advertise`` (spec 3.3.1; ``latch``/``queue_size`` ROS 1 3.4.1, D13).

        Returns:
            The advertisement id, for ``unadvertise``.
        """
        adv_id = self.new_id(f"advertise:{topic}")
        op: Message = {"op": "advertise", "id": adv_id, "topic": topic, "type": type_name}
        op.update(latch=latch, queue_size=queue_size)
        self.advertisements[adv_id] = op
        self.send_op(op)
        return adv_id

    def unadvertise(self, topic: str, adv_id: OpId) -> None:
        """Queue ``unadvertise`` of one advertisement (spec 3.3.2)."""
        self.advertisements.pop(adv_id, None)
        self.send_op({"op": "unadvertise", "id": adv_id, "topic": topic})

    def publish(self, topic: str, msg: object, *, latch: bool = False) -> None:
        """Queue ``publish`` (spec 3.3.3)."""
        op: Message = {"op": "publish", "topic": topic, "msg": msg}
        if latch:
            op["latch"] = True
        self.send_op(op)

    # ---- services and actions ------------------------------------------------

    def call_service(self, service: str, args: object = None, **options: object) -> str:
        """Queue ``call_service`` (spec 3.3.8); ``options``: type, timeout, fragment_size...

        Returns:
            The call id; the reply is a ``ServiceResponded`` with it.
        """
        call_id = self.new_id(f"call_service:{service}")
        op: Message = {"op": "call_service", "id": call_id, "service": service}
        op["args"] = {} if args is None else args
        op.update({k: v for k, v in options.items() if v is not None})
        self.send_op(op)
        return call_id

    def advertise_service(self, service: str, type_name: str) -> None:
        """Queue ``advertise_service`` (spec 3.3.6)."""
        op: Message = {"op": "advertise_service", "service": service, "type": type_name}
        self.services[service] = op
        self.send_op(op)

    def unadvertise_service(self, service: str) -> None:
        """Queue ``unadvertise_service`` (spec 3.3.7)."""
        self.services.pop(service, None)
        self.send_op({"op": "unadvertise_service", "service": service})

    def service_response(
        self, service: str, request_id: OpId, values: object, result: bool
    ) -> None:
        """Queue the answer to a ``ServiceRequested`` (spec 3.3.9; ``values`` always set, D28)."""
        self.send_op(
            {
                "op": "service_response",
                "service": service,
                "id": request_id,
                "values": values,
                "result": result,
            }
        )

    def send_action_goal(
        self, action: str, action_type: str, args: object = None, **options: object
    ) -> str:
        """Queue ``send_action_goal`` (spec 3.3.12); ``options``: feedback, fragment_size...

        Returns:
            The goal id; feedback and result events carry it.
        """
        goal_id = self.new_id(f"send_action_goal:{action}")
        op: Message = {
            "op": "send_action_goal",
            "id": goal_id,
            "action": action,
            "action_type": action_type,
        }
        op["args"] = {} if args is None else args
        op.update({k: v for k, v in options.items() if v is not None})
        self.send_op(op)
        return goal_id

    def cancel_action_goal(self, action: str, goal_id: OpId) -> None:
        """Queue ``cancel_action_goal`` (spec 3.3.13)."""
        self.send_op({"op": "cancel_action_goal", "id": goal_id, "action": action})

    def advertise_action(self, action: str, type_name: str) -> None:
        """Queue ``advertise_action`` (spec 3.3.10)."""
        op: Message = {"op": "advertise_action", "action": action, "type": type_name}
        self.actions[action] = op
        self.send_op(op)

    def unadvertise_action(self, action: str) -> None:
        """Queue ``unadvertise_action`` (spec 3.3.11)."""
        self.actions.pop(action, None)
        self.send_op({"op": "unadvertise_action", "action": action})

    def action_feedback(self, action: str, goal_id: OpId, values: object) -> None:
        """Queue feedback for a ``GoalRequested`` (spec 3.3.14)."""
        self.send_op({"op": "action_feedback", "id": goal_id, "action": action, "values": values})

    def action_result(
        self, action: str, goal_id: OpId, values: object, *, status: int, result: bool
    ) -> None:
        """Queue the result of a ``GoalRequested`` (spec 3.3.15; status per GoalStatus, D18)."""
        self.send_op(
            {
                "op": "action_result",
                "id": goal_id,
                "action": action,
                "values": values,
                "status": status,
                "result": result,
            }
        )

    # ---- status and auth -------------------------------------------------------

    def set_level(self, level: str) -> None:
        """Queue ``set_level`` (spec 3.2.1); remembered for reconnects.

        Raises:
            LocalProtocolError: ``level`` is not info, warning, error or none.
        """
        if level not in ("info", "warning", "error", "none"):
            raise LocalProtocolError(f"unknown status level {level!r}")
        self.level = level
        self.send_op({"op": "set_level", "level": level})

    def auth(
        self, mac: str, client: str, dest: str, rand: str, t: float, level: str, end: float
    ) -> None:
        """Queue ``auth`` (ROS 1 spec 3.3.1, D23); times in seconds since the epoch."""
        self.send_op(
            {
                "op": "auth",
                "mac": mac,
                "client": client,
                "dest": dest,
                "rand": rand,
                "t": t,
                "level": level,
                "end": end,
            }
        )

    # ---- input ------------------------------------------------------------------

    def receive_frame(self, frame: str | bytes) -> list[ClientEvent]:
        """Turn one frame from the server into events (none for a partial fragment).

        Binary frames are CBOR (D27); text frames JSON. Never raises for what the
        server sent: anything unusable becomes an ``UnknownOp``.
        """
        try:
            value = decode_cbor(frame) if isinstance(frame, bytes) else json.loads(frame)
        except RemoteProtocolError as exc:
            return [UnknownOp(frame, f"undecodable frame: {exc.message}")]
        except ValueError as exc:
            return [UnknownOp(frame, f"undecodable frame: {exc}")]
        return self._dispatch(value)

    def _dispatch(self, value: object) -> list[ClientEvent]:
        if not isinstance(value, dict) or not isinstance(value.get("op"), str):
            return [UnknownOp(value, "not an op")]
        parse = _PARSERS.get(value["op"])
        if parse is not None:
            try:
                return [parse(value)]
            except (KeyError, TypeError, ValueError) as exc:
                return [UnknownOp(value, f"malformed {value['op']}: {exc}")]
        if value["op"] == "fragment":
            return self._fragment(value)
        if value["op"] == "png":
            return self._png(value)
        return [UnknownOp(value, f"unknown op {value['op']!r}")]

    def _fragment(self, value: dict[str, object]) -> list[ClientEvent]:
        text = self._collect(value, "fragment")
        if isinstance(text, UnknownOp):
            return [text]
        return [] if text is None else self.receive_frame(text)

    def _png(self, value: dict[str, object]) -> list[ClientEvent]:
        data: object = value.get("data")
        if isinstance(value.get("total"), int | float) and value["total"] != 1:
            data = self._collect(value, "png")  # a PNG split into parts (D20)
            if data is None or isinstance(data, UnknownOp):
                return [] if data is None else [data]
        if not isinstance(data, str):
            return [UnknownOp(value, "malformed png")]
        try:
            text = decode_png(data, max_bytes=self._fragment_limit).decode("utf-8")
        except RemoteProtocolError as exc:
            return [UnknownOp(value, f"png: {exc.message}")]
        except UnicodeDecodeError:
            return [UnknownOp(value, "png: the image does not hold UTF-8 text")]
        return self.receive_frame(text)

    def _collect(self, value: dict[str, object], kind: str) -> str | UnknownOp | None:
        """Store one part; return the whole text (joined by ``num``) once complete."""
        part_id, data, num, total = (value.get(k) for k in ("id", "data", "num", "total"))
        if (
            not isinstance(data, str)
            or not isinstance(num, int | float)
            or not isinstance(total, int | float)
        ):
            return UnknownOp(value, f"malformed {kind}")
        key: OpId = f"{kind}:{part_id}"
        partial = self._fragments.setdefault(
            key, _Partial(max(1, round(total)))
        )  # REF §3.4 float total
        if int(num) not in partial.parts:
            partial.parts[int(num)] = data
            partial.size += len(data)
            self._fragment_bytes += len(data)
        self._bound_fragments(key)
        if len(partial.parts) < partial.total:
            return None
        del self._fragments[key]
        self._fragment_bytes -= partial.size
        return "".join(partial.parts[i] for i in sorted(partial.parts))

    def _bound_fragments(self, keep: OpId) -> None:
        while self._fragment_bytes > self._fragment_limit and len(self._fragments) > 1:
            oldest = next(k for k in self._fragments if k != keep)
            self._fragment_bytes -= self._fragments.pop(oldest).size


def _opt_id(value: dict[str, object]) -> OpId:
    op_id = value.get("id")
    return op_id if isinstance(op_id, str | int) else ""


def _parse_publish(v: dict[str, object]) -> ClientEvent:
    return TopicMessage(str(v["topic"]), v.get("msg"))


def _parse_service_response(v: dict[str, object]) -> ClientEvent:
    return ServiceResponded(_opt_id(v), str(v["service"]), bool(v["result"]), v.get("values"))


def _parse_call_service(v: dict[str, object]) -> ClientEvent:
    return ServiceRequested(_opt_id(v), str(v["service"]), v.get("args"))


def _parse_goal(v: dict[str, object]) -> ClientEvent:
    return GoalRequested(
        _opt_id(v),
        str(v["action"]),
        str(v.get("action_type", "")),
        v.get("args"),
        bool(v.get("feedback", False)),
    )


def _parse_cancel(v: dict[str, object]) -> ClientEvent:
    return GoalCancelRequested(_opt_id(v), str(v["action"]))


def _parse_feedback(v: dict[str, object]) -> ClientEvent:
    return ActionFeedbackReceived(_opt_id(v), str(v["action"]), v.get("values"))


def _parse_result(v: dict[str, object]) -> ClientEvent:
    status = v.get("status")
    result = bool(v["result"])
    code = status if isinstance(status, int) else (4 if result else 6)  # D18 defaults
    return ActionResultReceived(_opt_id(v), str(v["action"]), result, code, v.get("values"))


def _parse_status(v: dict[str, object]) -> ClientEvent:
    op_id = v.get("id")
    return StatusReceived(
        str(v["level"]), str(v["msg"]), op_id if isinstance(op_id, str | int) else None
    )


_PARSERS = {
    "publish": _parse_publish,
    "service_response": _parse_service_response,
    "call_service": _parse_call_service,
    "send_action_goal": _parse_goal,
    "cancel_action_goal": _parse_cancel,
    "action_feedback": _parse_feedback,
    "action_result": _parse_result,
    "status": _parse_status,
}
