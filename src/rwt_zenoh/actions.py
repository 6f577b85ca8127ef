"""Actions on the wire: ROS 2's mapping of an action to services and a topic.

An action ``/fib`` of type ``pkg/action/Name`` is, as rclcpp and rmw_zenoh see it:

- ``/fib/_action/send_goal``, service ``pkg/action/Name_SendGoal``: request
  ``{goal_id: UUID, goal}``, response ``{accepted, stamp}``;
- ``/fib/_action/get_result``, service ``pkg/action/Name_GetResult``: request
  ``{goal_id}``, response ``{status, result}`` once the goal has ended;
- ``/fib/_action/cancel_goal``, service ``action_msgs/srv/CancelGoal``;
- ``/fib/_action/feedback``, topic ``pkg/action/Name_FeedbackMessage``:
  ``{goal_id, feedback}``.

The graph's types are the goal, result and feedback; the wrappers above are
registered in its rosbags type store from their definitions (rosidl's), so their
CDR is what rosbags writes. ``ActionWire`` encodes and decodes them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from rosbags.typesys import get_types_from_msg

from rwt_graph.types.wire import read_cdr

from .wire import WireError

if TYPE_CHECKING:
    from rwt_graph.types import ActionType, MessageType, TypeRegistry

__all__ = [
    "CANCEL_SUFFIX",
    "FEEDBACK_SUFFIX",
    "GET_RESULT_SUFFIX",
    "SEND_GOAL_SUFFIX",
    "ActionWire",
    "action_of",
    "stamp_of",
]

SEND_GOAL_SUFFIX = "/_action/send_goal"
GET_RESULT_SUFFIX = "/_action/get_result"
CANCEL_SUFFIX = "/_action/cancel_goal"
FEEDBACK_SUFFIX = "/_action/feedback"

_UUID = "unique_identifier_msgs/msg/UUID"
_TIME = "builtin_interfaces/msg/Time"


def action_of(service: str, dds_type: str) -> tuple[str, str] | None:
    """The action and its type behind a ``send_goal`` service, else None.

    ``/fib/_action/send_goal`` of ``pkg::action::dds_::Name_SendGoal_`` ->
    ``("/fib", "pkg/action/Name")``.
    """
    namespace, sep, name = dds_type.partition("::dds_::")
    if not service.endswith(SEND_GOAL_SUFFIX) or not sep or not name.endswith("_SendGoal_"):
        return None
    package, _, kind = namespace.partition("::")
    if kind != "action":
        return None
    return service[: -len(SEND_GOAL_SUFFIX)], f"{package}/action/{name[: -len('_SendGoal_')]}"


def stamp_of(seconds: float) -> tuple[int, int]:
    """``builtin_interfaces/msg/Time`` of ``seconds`` since the epoch: ``(sec, nanosec)``."""
    sec = int(seconds)
    return sec, min(int((seconds - sec) * 1e9), 999_999_999)


class ActionWire:
    """Encodes and decodes the wrappers of one action type.

    Args:
        registry: a ROS 2 registry; the wrappers are added to its type store once.
        actiontype: the action type.

    Raises:
        WireError: the registry is not ROS 2.
    """

    def __init__(self, registry: TypeRegistry, actiontype: ActionType) -> None:
        self.registry = registry
        self.actiontype = actiontype
        base = actiontype.name  # pkg/action/Name
        self.send_goal_request = f"{base}_SendGoal_Request"
        self.send_goal_response = f"{base}_SendGoal_Response"
        self.get_result_request = f"{base}_GetResult_Request"
        self.get_result_response = f"{base}_GetResult_Response"
        self.feedback_message = f"{base}_FeedbackMessage"
        store = registry.typestore()
        if self.feedback_message not in store.fielddefs:
            definitions = {
                self.send_goal_request: f"{_UUID} goal_id\n{actiontype.goal.rosbags_name} goal",
                self.send_goal_response: f"bool accepted\n{_TIME} stamp",
                self.get_result_request: f"{_UUID} goal_id",
                self.get_result_response: f"int8 status\n{actiontype.result.rosbags_name} result",
                self.feedback_message: (
                    f"{_UUID} goal_id\n{actiontype.feedback.rosbags_name} feedback"
                ),
            }
            types: dict[str, Any] = {}
            for name, text in definitions.items():
                types.update(get_types_from_msg(text, name))
            store.register(types)

    def dds_type(self, part: str) -> str:
        """``pkg::action::dds_::Name_<part>_``: ``SendGoal``, ``GetResult``, ``FeedbackMessage``."""
        package, _, name = self.actiontype.name.split("/")
        return f"{package}::action::dds_::{name}_{part}_"

    def _encode(self, name: str, **fields: object) -> bytes:
        store = self.registry.typestore()
        cls: Any = store.types[name]
        return bytes(store.serialize_cdr(cls(**fields), name))

    def _decode(self, name: str, data: bytes) -> Any:
        try:
            return read_cdr(self.registry.typestore(), data, name)
        except Exception as exc:  # rosbags raises assorted errors for malformed bytes
            raise WireError(f"{name}: not a CDR message of this type ({exc})") from None

    def _uuid(self, goal_id: bytes) -> Any:
        import numpy as np  # noqa: PLC0415 - rosbags' arrays

        if len(goal_id) != 16:
            raise WireError(f"goal id of {len(goal_id)} bytes (expected 16)")
        return self.registry.typestore().types[_UUID](uuid=np.frombuffer(goal_id, np.uint8))

    def _rosbags(self, mtype: MessageType, msg: dict[str, object]) -> Any:
        return mtype.to_rosbags(dict(msg), self.registry.typestore())

    def send_goal(self, goal_id: bytes, goal: dict[str, object]) -> bytes:
        """A ``SendGoal`` request."""
        nested = self._rosbags(self.actiontype.goal, goal)
        return self._encode(self.send_goal_request, goal_id=self._uuid(goal_id), goal=nested)

    def read_send_goal(self, data: bytes) -> tuple[bytes, dict[str, object]]:
        """The goal id and goal of a ``SendGoal`` request.

        Raises:
            WireError: not such a request.
            FieldError: the goal does not fit its type.
        """
        obj = self._decode(self.send_goal_request, data)
        goal = self.actiontype.goal.from_python(obj.goal)
        return bytes(obj.goal_id.uuid), goal

    def accepted(self, accepted: bool, now: float) -> bytes:
        """A ``SendGoal`` response stamped ``now`` (seconds since the epoch)."""
        sec, nanosec = stamp_of(now)
        stamp = self.registry.typestore().types[_TIME](sec=sec, nanosec=nanosec)
        return self._encode(self.send_goal_response, accepted=accepted, stamp=stamp)

    def read_accepted(self, data: bytes) -> bool:
        """Whether a ``SendGoal`` response accepted the goal.

        Raises:
            WireError: not such a response.
        """
        return bool(self._decode(self.send_goal_response, data).accepted)

    def get_result(self, goal_id: bytes) -> bytes:
        """A ``GetResult`` request."""
        return self._encode(self.get_result_request, goal_id=self._uuid(goal_id))

    def read_get_result(self, data: bytes) -> bytes:
        """The goal id of a ``GetResult`` request.

        Raises:
            WireError: not such a request.
        """
        return bytes(self._decode(self.get_result_request, data).goal_id.uuid)

    def result(self, status: int, result: dict[str, object]) -> bytes:
        """A ``GetResult`` response."""
        nested = self._rosbags(self.actiontype.result, result)
        return self._encode(self.get_result_response, status=status, result=nested)

    def read_result(self, data: bytes) -> tuple[int, dict[str, object]]:
        """The status and result of a ``GetResult`` response.

        Raises:
            WireError: not such a response.
        """
        obj = self._decode(self.get_result_response, data)
        result = self.actiontype.result.from_python(obj.result)
        return int(obj.status), result

    def feedback(self, goal_id: bytes, feedback: dict[str, object]) -> bytes:
        """A ``FeedbackMessage``."""
        nested = self._rosbags(self.actiontype.feedback, feedback)
        return self._encode(self.feedback_message, goal_id=self._uuid(goal_id), feedback=nested)

    def read_feedback(self, data: bytes) -> tuple[bytes, dict[str, object]]:
        """The goal id and feedback of a ``FeedbackMessage``.

        Raises:
            WireError: not such a message.
        """
        obj = self._decode(self.feedback_message, data)
        feedback = self.actiontype.feedback.from_python(obj.feedback)
        return bytes(obj.goal_id.uuid), feedback
