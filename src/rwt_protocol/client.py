"""The client role of the protocol, sans-IO: ops out, events in.

``ClientSession`` builds the frames a rosbridge client sends (``subscribe``,
``call_service``, ``send_action_goal``, ...) and turns the frames a server sends
into events: the op models themselves (``ops.Publish``, ``ops.ServiceResponse``,
``ops.CallService``, ...), validated as the server validates what it receives.
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
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeGuard

from pydantic import ValidationError

from .codecs.cbor import decode_cbor
from .codecs.json import decode_json, decode_publish, encode_op, parse_object
from .codecs.png import decode_png
from .errors import RemoteProtocolError
from .framing.fragments import PartKind, Reassembler
from .ops import (
    ActionFeedback,
    ActionResult,
    AdvertiseAction,
    AdvertiseService,
    Auth,
    CallService,
    CancelActionGoal,
    Fragment,
    OpModel,
    Png,
    Publish,
    PublishView,
    SendActionGoal,
    ServiceResponse,
    SetLevel,
    Status,
    Subscribe,
    Unadvertise,
    UnadvertiseAction,
    UnadvertiseService,
    Unsubscribe,
)
from .ops import Advertise as AdvertiseOp
from .ports import GoalStatus

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

    from .levels import StatusLevel, WireLevel
    from .ops.qos import Qos

__all__ = ["ClientEvent", "ClientSession", "UnknownOp"]

MiB = 1024 * 1024
Message = dict[str, object]
OpId = str | int


@dataclass(frozen=True, slots=True)
class UnknownOp:
    """A frame this client does not understand (kept for logging, never raised)."""

    frame: object
    reason: str


ClientEvent = (
    PublishView
    | ServiceResponse
    | CallService
    | SendActionGoal
    | CancelActionGoal
    | ActionFeedback
    | ActionResult
    | Status
    | UnknownOp
)
"""Everything ``ClientSession.receive_frame`` can report: the server's ops, as their models.

A ``publish`` is a ``PublishView`` (``ops.Publish``, or its msgspec twin
``ops.PublishFrame`` from the hot path); every other op is its model
(``ops.ServiceResponse``, ``ops.Status``, ...), an ``ActionResult`` with its
``status`` filled in when the advertiser left it out (D18).
"""


class ClientSession:
    """One client connection's protocol state.

    Args:
        max_pending_fragment_bytes: bound on the text of incomplete fragmented
            messages kept at once (the server's ``Reassembler``, D19); a message
            that would go over it is dropped and reported as an ``UnknownOp``.
        max_pending_fragments: incomplete fragmented messages kept at once.
        fragment_timeout_s: seconds after its latest part at which an
            incomplete message is forgotten (``now`` comes with each frame).
    """

    def __init__(
        self,
        *,
        max_pending_fragment_bytes: int = 64 * MiB,
        max_pending_fragments: int = 64,
        fragment_timeout_s: float = 600.0,
    ) -> None:
        self._out: list[str] = []
        self._counter = itertools.count(1)
        self._fragments = Reassembler(
            max_bytes=max_pending_fragment_bytes,
            max_pending=max_pending_fragments,
            timeout_s=fragment_timeout_s,
        )
        self._fragment_limit = max_pending_fragment_bytes
        self.subscriptions: dict[OpId, Subscribe] = {}
        """Subscribe ops by id, replayed after a reconnect."""
        self.advertisements: dict[OpId, AdvertiseOp] = {}
        """Advertise ops by id, replayed after a reconnect."""
        self.services: dict[str, AdvertiseService] = {}
        """advertise_service ops by service name, replayed after a reconnect."""
        self.actions: dict[str, AdvertiseAction] = {}
        """advertise_action ops by action name, replayed after a reconnect."""
        self.level: WireLevel | None = None

    # ---- output ---------------------------------------------------------------

    def frames_to_send(self) -> list[str]:
        """Take the JSON frames queued for the server, oldest first."""
        frames, self._out = self._out, []
        return frames

    def send(self, op: OpModel) -> None:
        """Queue any op as built (for ops this class has no method for)."""
        self._out.append(encode_op(op).decode())

    def new_id(self, prefix: str) -> str:
        """A fresh id like roslibjs makes: ``<prefix>:<n>``."""
        return f"{prefix}:{next(self._counter)}"

    def replay(self) -> None:
        """Queue again every standing op (level, advertisements, subscriptions, services)."""
        if self.level is not None:
            self.send(SetLevel(level=self.level))
        groups: tuple[Mapping[Any, OpModel], ...] = (
            self.advertisements,
            self.subscriptions,
            self.services,
            self.actions,
        )
        for group in groups:
            for op in group.values():
                self.send(op)

    # ---- topics -----------------------------------------------------------------

    def subscribe(self, topic: str, type_name: str | None = None, **options: Any) -> str:
        """Queue ``subscribe`` (spec 3.3.4); ``options`` are its optional fields.

        Returns:
            The subscription id, for ``unsubscribe``.
        """
        sub_id = self.new_id(f"subscribe:{topic}")
        op = Subscribe(topic=topic, type=type_name, id=sub_id, **options)
        self.subscriptions[sub_id] = op
        self.send(op)
        return sub_id

    def forget_subscription(self, sub_id: OpId) -> None:
        """Drop a subscription the server refused: nothing is sent, nothing replayed."""
        self.subscriptions.pop(sub_id, None)

    def unsubscribe(self, topic: str, sub_id: OpId) -> None:
        """Queue ``unsubscribe`` of one subscription (spec 3.3.5)."""
        self.subscriptions.pop(sub_id, None)
        self.send(Unsubscribe(topic=topic, id=sub_id))

    def advertise(
        self,
        topic: str,
        type_name: str,
        *,
        latch: bool = False,
        queue_size: int = 100,
        qos: Qos | None = None,
    ) -> str:
        """Queue ``advertise`` (spec 3.3.1; ``latch``/``queue_size`` ROS 1 3.4.1, D13).

        ``qos``: protocol 2.1.0's, sent only when given (the server then reads no
        ``latch`` or ``queue_size``).

        Returns:
            The advertisement id, for ``unadvertise``.
        """
        adv_id = self.new_id(f"advertise:{topic}")
        fields: dict[str, Any] = {} if qos is None else {"qos": qos}
        op = AdvertiseOp(
            topic=topic, type=type_name, id=adv_id, latch=latch, queue_size=queue_size, **fields
        )
        self.advertisements[adv_id] = op
        self.send(op)
        return adv_id

    def forget_advertisement(self, adv_id: OpId) -> None:
        """Drop an advertisement the server refused: nothing is sent, nothing replayed."""
        self.advertisements.pop(adv_id, None)

    def unadvertise(self, topic: str, adv_id: OpId) -> None:
        """Queue ``unadvertise`` of one advertisement (spec 3.3.2)."""
        self.advertisements.pop(adv_id, None)
        self.send(Unadvertise(topic=topic, id=adv_id))

    def publish(self, topic: str, msg: object, *, latch: bool = False) -> None:
        """Queue ``publish`` (spec 3.3.3)."""
        # ``latch`` is sent only when true, as roslibpy does
        self.send(
            Publish(topic=topic, msg=msg, latch=True) if latch else Publish(topic=topic, msg=msg)
        )

    # ---- services and actions ------------------------------------------------

    def call_service(self, service: str, args: object = None, **options: Any) -> str:
        """Queue ``call_service`` (spec 3.3.8); ``options``: type, timeout, fragment_size...

        Returns:
            The call id; the reply is a ``ServiceResponded`` with it.
        """
        call_id = self.new_id(f"call_service:{service}")
        args = {} if args is None else args
        self.send(CallService(service=service, args=args, id=call_id, **options))
        return call_id

    def advertise_service(self, service: str, type_name: str) -> None:
        """Queue ``advertise_service`` (spec 3.3.6)."""
        op = AdvertiseService(service=service, type=type_name)
        self.services[service] = op
        self.send(op)

    def unadvertise_service(self, service: str) -> None:
        """Queue ``unadvertise_service`` (spec 3.3.7)."""
        self.services.pop(service, None)
        self.send(UnadvertiseService(service=service))

    def service_response(
        self, service: str, request_id: OpId, values: object, result: bool
    ) -> None:
        """Queue the answer to a ``ServiceRequested`` (spec 3.3.9; ``values`` always set, D28)."""
        self.send(ServiceResponse(service=service, result=result, values=values, id=request_id))

    def send_action_goal(
        self, action: str, action_type: str, args: object = None, **options: Any
    ) -> str:
        """Queue ``send_action_goal`` (spec 3.3.12); ``options``: feedback, fragment_size...

        Returns:
            The goal id; feedback and result events carry it.
        """
        goal_id = self.new_id(f"send_action_goal:{action}")
        args = {} if args is None else args
        self.send(
            SendActionGoal(action=action, action_type=action_type, args=args, id=goal_id, **options)
        )
        return goal_id

    def cancel_action_goal(self, action: str, goal_id: OpId) -> None:
        """Queue ``cancel_action_goal`` (spec 3.3.13)."""
        self.send(CancelActionGoal(action=action, id=goal_id))

    def advertise_action(self, action: str, type_name: str) -> None:
        """Queue ``advertise_action`` (spec 3.3.10)."""
        op = AdvertiseAction(action=action, type=type_name)
        self.actions[action] = op
        self.send(op)

    def unadvertise_action(self, action: str) -> None:
        """Queue ``unadvertise_action`` (spec 3.3.11)."""
        self.actions.pop(action, None)
        self.send(UnadvertiseAction(action=action))

    def action_feedback(self, action: str, goal_id: OpId, values: object) -> None:
        """Queue feedback for a ``GoalRequested`` (spec 3.3.14)."""
        self.send(ActionFeedback(action=action, id=goal_id, values=values))

    def action_result(
        self, action: str, goal_id: OpId, values: object, *, status: int, result: bool
    ) -> None:
        """Queue the result of a ``GoalRequested`` (spec 3.3.15; status per GoalStatus, D18)."""
        self.send(
            ActionResult(
                action=action, id=goal_id, result=result, values=values, status=int(status)
            )
        )

    # ---- status and auth -------------------------------------------------------

    def set_level(self, level: StatusLevel) -> None:
        """Queue ``set_level`` (spec 3.2.1); remembered for reconnects."""
        self.level = level.wire
        self.send(SetLevel(level=level.wire))

    def auth(
        self, mac: str, client: str, dest: str, rand: str, t: float, level: str, end: float
    ) -> None:
        """Queue ``auth`` (ROS 1 spec 3.3.1, D23); times in seconds since the epoch."""
        self.send(Auth(mac=mac, client=client, dest=dest, rand=rand, t=t, level=level, end=end))

    # ---- input ------------------------------------------------------------------

    def receive_frame(self, frame: str | bytes, now: float = 0.0) -> list[ClientEvent]:
        """Turn one frame from the server into events (none for a partial fragment).

        Binary frames are CBOR (D27); text frames JSON. Each op is validated by
        its model (``rwt_protocol.ops``), as the server validates what it
        receives: ``"result": "false"`` is not a boolean. Never raises for what
        the server sent: anything unusable becomes an ``UnknownOp``.

        Args:
            frame: one text (JSON) or binary (CBOR) frame.
            now: monotonic seconds, for forgetting incomplete fragmented messages.
        """
        if isinstance(frame, str):
            fast = decode_publish(frame)
            if fast is not None:
                return [fast]
        try:
            value = decode_cbor(frame) if isinstance(frame, bytes) else decode_json(frame)
        except RemoteProtocolError as exc:
            return [UnknownOp(frame, f"undecodable frame: {exc.message}")]
        return self._dispatch(value, now)

    def _dispatch(self, value: object, now: float) -> list[ClientEvent]:
        if isinstance(value, dict) and value.get("op") in ("fragment", "png"):
            return self._part(value, now)
        try:
            op = parse_object(value)
        except RemoteProtocolError as exc:
            return [UnknownOp(value, exc.message)]
        if isinstance(op, ActionFeedback | ActionResult) and op.id is None:
            return [UnknownOp(value, f"{op.op}: missing field at $.id")]  # only rwt sends one
        event = _EVENTS.get(type(op))
        if event is None:
            return [UnknownOp(value, f"unexpected op {type(op).__name__} from a server")]
        return [event(op)]

    def _part(self, value: dict[str, object], now: float) -> list[ClientEvent]:
        """A ``fragment`` or ``png`` op: collect its parts, then decode the whole (D19, D20)."""
        kind = PartKind(str(value["op"]))
        # the reference computes ``total`` by a division, a float near the count (REF §3.4)
        counts = {k: round(v) for k in ("num", "total") if _finite_float(v := value.get(k))}
        try:
            part: Fragment | Png = _PART_MODELS[kind].model_validate({**value, **counts})
        except ValidationError as exc:
            return [UnknownOp(value, f"malformed {kind}: {exc.errors()[0]['msg']}")]
        self._fragments.expire(now)
        text: str | None = part.data
        if part.total not in (None, 1):
            try:
                text = self._fragments.add(
                    kind, part.id or "", part.num or 0, part.total or 1, data=part.data, now=now
                )
            except RemoteProtocolError as exc:
                return [UnknownOp(value, f"{kind}: {exc.message}")]
        if text is None:
            return []
        if kind is PartKind.FRAGMENT:
            return self.receive_frame(text, now)
        try:
            whole = decode_png(text, max_bytes=self._fragment_limit).decode("utf-8")
        except RemoteProtocolError as exc:
            return [UnknownOp(value, f"png: {exc.message}")]
        except UnicodeDecodeError:
            return [UnknownOp(value, "png: the image does not hold UTF-8 text")]
        return self.receive_frame(whole, now)


def _finite_float(value: object) -> TypeGuard[float]:
    return isinstance(value, float) and math.isfinite(value)


_PART_MODELS: dict[PartKind, type[Fragment | Png]] = {
    PartKind.FRAGMENT: Fragment,
    PartKind.PNG: Png,
}


def _with_status(op: ActionResult) -> ActionResult:
    """``op`` with its ``status``: an advertiser may leave it out (D18)."""
    if op.status is not None:
        return op
    status = GoalStatus.SUCCEEDED if op.result else GoalStatus.ABORTED
    return op.model_copy(update={"status": int(status)})


def _as_is(op: ClientEvent) -> ClientEvent:
    return op


_EVENTS: dict[type[OpModel], Callable[[Any], ClientEvent]] = {
    Publish: _as_is,
    ServiceResponse: _as_is,
    CallService: _as_is,
    SendActionGoal: _as_is,
    CancelActionGoal: _as_is,
    ActionFeedback: _as_is,
    ActionResult: _with_status,
    Status: _as_is,
}
"""The ops a server sends a client, each with the event it becomes (itself, mostly)."""
