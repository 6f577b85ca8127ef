"""Actions of the in-memory graph (spec 3.3.10-3.3.15, D4, D15, D18).

An action is provided by a client (its session receives ``send_action_goal``
with goal ids ``action_goal:<name>:<n>``, REF §2.15, and ``cancel_action_goal``)
or by Python code in this process (``LocalActionHandler``). Every goal ends with
exactly one result for its caller: the provider's, or an abort with a reason when
the provider goes away (D4).
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING

from rwt_protocol.errors import FieldError, GraphError, RwtError, UnknownNameError
from rwt_protocol.levels import StatusLevel
from rwt_protocol.names import resolve_name
from rwt_protocol.ops import CancelActionGoal, SendActionGoal
from rwt_protocol.ports import ActionProvider, ClientId, GoalDone, GoalFeedback, GoalStatus

from .calls import ProviderTable, Spawner, convert_args, guarded, require_spawner
from .ratelog import EpisodeLog

if TYPE_CHECKING:
    from .action_status import StatusBoard
    from .clock import Clock
    from .types import ActionType, TypeRegistry

__all__ = [
    "CANCEL_GOAL_TYPE",
    "MAX_LEFT_GOALS",
    "ActionEntry",
    "Actions",
    "Goal",
    "GoalCanceledError",
    "GoalContext",
    "LocalActionHandler",
    "cancel_goals_handler",
    "cancel_service_name",
]

logger = logging.getLogger("rwt.graph")
_episodes = EpisodeLog(logger)  # a peer can trigger these per message

Message = dict[str, object]

MAX_LEFT_GOALS = 256
"""Goals whose callers disconnected that the graph lets run, in all (docs/limits.md).

A goal outlives its caller's connection, as on rosbridge_suite, whose goal table
is shared by every connection (D35): another connection may still cancel it by
its id. Past this many, the oldest of them is canceled, so callers that send
goals and leave cannot pile up work on the providers."""


def _ignore(status: GoalStatus, result: bool, values: object) -> None:
    """The result of a goal whose caller left goes nowhere."""


class GoalContext:
    """What an in-process action handler gets besides the goal.

    Attributes:
        goal_id: the goal's id.
        cancel_requested: set when the caller asked to cancel; a handler that
            honours it returns (or raises ``GoalCanceledError``) promptly.
    """

    def __init__(self, goal: Goal) -> None:
        self._goal = goal
        self.goal_id = goal.goal_id
        self.cancel_requested = False

    def publish_feedback(self, feedback: Message, *, validated: bool = False) -> None:
        """Send feedback to the caller, validated against the feedback type.

        Args:
            feedback: the feedback message as a dict.
            validated: the caller vouches that ``feedback`` is already in the
                internal form of the feedback type (every field present, in
                declaration order, with the types the conversion gives; see
                ``MessageType.from_json``), so it is forwarded unchecked. Only for
                in-process producers that build their messages themselves (the
                TF republisher); the caller keeps ``feedback`` unchanged afterwards.
                Feedback from clients is always checked (spec 3.3.14).

        Raises:
            FieldError: ``feedback`` does not fit the type (``validated`` false).
        """
        if validated:
            self._goal.forward_feedback(feedback)
        else:
            self._goal.feedback(feedback)


LocalActionHandler = Callable[[Message, GoalContext], Awaitable[Message]]
"""An in-process action server: ``async def handler(goal, context) -> result``.

Raising ``GoalCanceledError`` (or being cancelled) ends the goal CANCELED; any other
exception ends it ABORTED."""


class GoalCanceledError(RwtError):
    """Raised by an in-process action handler that honours a cancel request."""

    def __init__(self, message: str = "goal canceled") -> None:
        super().__init__(message)


class Goal:
    """One goal in flight, held by its caller as a ``GoalHandle``."""

    def __init__(
        self,
        entry: ActionEntry,
        goal_id: str,
        caller: ClientId,
        done: GoalDone,
        on_feedback: GoalFeedback | None,
        clock: Clock,
        request_id: str | None = None,
    ) -> None:
        self.entry = entry
        self.goal_id = goal_id
        self.caller = caller
        self.request_id = request_id  # the caller's id of the goal (its op's ``id``), if any
        self._done: GoalDone | None = done
        self._on_feedback = on_feedback
        self._clock = clock
        self.context: GoalContext | None = None
        self.cancel_job: Callable[[], None] | None = None
        self.on_finished: Callable[[], None] | None = None  # its table forgets it

    @property
    def finished(self) -> bool:
        """Whether the caller has its result or stopped waiting."""
        return self._done is None

    def feedback(self, values: object, *, path: str = "$") -> None:
        """Validate and forward one feedback message.

        Raises:
            FieldError: ``values`` does not fit the feedback type.
        """
        msg = self.entry.actiontype.feedback.from_json(values, path=path, now=self._clock.wall())
        self.forward_feedback(msg.msg)

    def forward_feedback(self, msg: Message) -> None:
        """Forward feedback already in the internal form, unchecked (in-process producers)."""
        if self._on_feedback is not None and not self.finished:
            self._on_feedback(msg)

    def finish(self, status: GoalStatus, result: bool, values: object) -> None:
        """Give the caller its one result and drop the goal from its action."""
        if self.entry.goals.pop(self.goal_id, None) is self:
            self.show_status(status)
        finished, self.on_finished = self.on_finished, None
        if finished is not None:
            finished()
        done, self._done = self._done, None
        if done is not None:
            done(status, result, values)

    def request_cancel(self) -> None:
        """Ask the provider to cancel (spec 3.3.13)."""
        if self.finished:
            return
        self.show_status(GoalStatus.CANCELING)
        if self.entry.provider is not None:
            cancel = CancelActionGoal(action=self.entry.spelling, id=self.goal_id)
            self.entry.provider.on_action_cancel(cancel)
        elif self.context is not None:
            self.context.cancel_requested = True

    def forget(self) -> None:
        """The caller left: stop reporting to it and ask the provider to cancel."""
        self.request_cancel()
        self._done = None
        self._on_feedback = None

    def detach(self) -> None:
        """The caller left, the goal runs on: its feedback and result go nowhere (D35)."""
        if self._done is not None:
            self._done = _ignore
        self._on_feedback = None

    def show_status(self, status: GoalStatus) -> None:
        """Tell the action's status topic (``action_status``), if it has one."""
        board = self.entry.status
        if board is not None:
            guarded(f"status of {self.entry.spelling}", partial(board.change, self.goal_id, status))


@dataclass(eq=False)
class ActionEntry:
    """One advertised action (see ``ServiceEntry`` for the fields' meaning)."""

    name: str
    spelling: str
    type_spelling: str
    actiontype: ActionType
    owner: ClientId
    provider: ActionProvider | None = None
    handler: LocalActionHandler | None = None
    goals: dict[str, Goal] = field(default_factory=dict)
    counter: itertools.count[int] = field(default_factory=lambda: itertools.count(1))
    status: StatusBoard | None = None  # publishes ``<action>/_action/status`` (ROS 2)

    @property
    def type_name(self) -> str:
        """The canonical action type (``example_interfaces/action/Fibonacci``)."""
        return self.actiontype.name

    def end_all(self, reason: str) -> None:
        """End every goal ABORTED with ``result: false`` and ``reason`` (D4).

        One failing result does not keep the others from theirs.
        """
        for goal in list(self.goals.values()):
            guarded(
                f"aborting goal {goal.goal_id} of {self.spelling}",
                partial(goal.finish, GoalStatus.ABORTED, False, reason),
            )

    def tell_lost(self, reason: str) -> None:
        """Warn a client provider that its action was replaced (D15)."""
        if self.provider is not None:
            self.provider.on_action_lost(self.spelling, reason)


class Actions(ProviderTable[ActionEntry]):
    """The action table of a graph (see ``ProviderTable`` for the arguments)."""

    def __init__(
        self, registry: TypeRegistry, clock: Clock, spawner: Callable[[], Spawner | None]
    ) -> None:
        super().__init__("action", registry, clock, spawner)
        # caller -> its goals in flight, so that a caller's release costs its goals
        self._goals_of: dict[ClientId, set[Goal]] = {}
        # (action, the caller's id of the goal) -> the newest such goal in flight (D35)
        self._by_request: dict[tuple[str, str], Goal] = {}
        self._left: dict[Goal, None] = {}  # goals whose callers left, oldest first

    def send_goal(
        self,
        client: ClientId,
        action: str,
        args: object,
        done: GoalDone,
        on_feedback: GoalFeedback | None,
        *,
        path: str = "$",
        request_id: str | None = None,
    ) -> Goal:
        """Start the goal ``args`` on ``action`` (spec 3.3.12).

        ``on_feedback`` gets each feedback message (None: nobody asked).
        ``request_id``: the caller's id of the goal (a rosbridge op's ``id``), by
        which any client may cancel it (``cancel``) and which lets it outlive
        its caller (D35); None: only the caller's handle cancels it. A
        client provider gets the goal as a ``SendActionGoal`` op of its own: its
        spellings, the goal in the internal form, the id
        ``action_goal:<name>:<n>`` and ``feedback: true``.

        Raises:
            UnknownNameError: no such action.
            GraphError: its client provider is busy
                (docs/limits.md).
            FieldError: ``args`` does not fit the goal type.
        """
        entry = self.entries.get(resolve_name(action))
        if entry is None:
            raise UnknownNameError("action", action)
        goal_msg = convert_args(entry.actiontype.goal, args, path=path, now=self.clock.wall())
        goal_id = f"action_goal:{entry.spelling}:{next(entry.counter)}"
        goal = Goal(entry, goal_id, client, done, on_feedback, self.clock, request_id)
        entry.goals[goal_id] = goal
        self._goals_of.setdefault(client, set()).add(goal)
        if request_id is not None:
            self._by_request[(entry.name, request_id)] = goal
        goal.on_finished = partial(self._untrack, goal)
        if entry.handler is not None:
            self._run_local(entry, entry.handler, goal, goal_msg.msg)
        else:
            assert entry.provider is not None
            try:
                entry.provider.on_action_goal(
                    SendActionGoal(
                        action=entry.spelling,
                        action_type=entry.type_spelling,
                        args=goal_msg.msg,
                        id=goal_id,
                        feedback=True,
                    )
                )
            except RwtError as exc:  # refused (provider busy): the caller's goal fails
                del entry.goals[goal_id]
                self._untrack(goal)
                self.log_refusal(entry.spelling, client, exc.message)
                raise
        if not goal.finished:
            goal.show_status(GoalStatus.EXECUTING)
        return goal

    def cancel(self, action: str, request_id: str) -> None:
        """Ask to cancel the goal of ``action`` its caller named ``request_id``, whoever asks (D35).

        The caller's own goal is its connection's to find first; this finds the
        newest goal in flight with that id, from any caller, also one whose
        caller left. Who may ask is the access rules' to say (the action's name).

        Raises:
            GraphError: warning when no such goal is in flight.
        """
        goal = self._by_request.get((resolve_name(action), request_id))
        if goal is None or goal.finished:
            raise GraphError(
                f"no goal {request_id!r} in progress on {action}", level=StatusLevel.WARNING
            )
        goal.request_cancel()

    def feedback(
        self,
        client: ClientId,
        action: str,
        goal_id: str | int | None,
        values: object,
        *,
        path: str = "$",
    ) -> None:
        """Route the provider's feedback ``values`` for the goal ``goal_id`` (spec 3.3.14).

        Raises:
            GraphError: not the provider; no or an unknown goal id (warning).
            FieldError: ``values`` does not fit the feedback type.
        """
        self._goal(client, action, goal_id).feedback(values, path=path)

    def result(
        self,
        client: ClientId,
        action: str,
        goal_id: str | int | None,
        result: bool,
        values: object,
        *,
        status: int | None = None,
        path: str = "$",
    ) -> None:
        """Route the provider's result for the goal ``goal_id`` (spec 3.3.15, D18).

        ``status`` defaults to SUCCEEDED when ``result`` is true, ABORTED
        otherwise; the caller's ``result`` is true for every terminal status (D18).

        Raises:
            GraphError: not the provider; no or an unknown goal id (warning);
                status not terminal.
            FieldError: ``values`` does not fit the result type (the goal aborts).
        """
        goal = self._goal(client, action, goal_id)
        final = _terminal(status, result)
        if not result:
            goal.finish(final, True, goal.entry.actiontype.result.default())
            return
        try:
            msg = goal.entry.actiontype.result.from_json(
                {} if values is None else values, path=path, now=self.clock.wall()
            )
        except FieldError as exc:
            goal.finish(
                GoalStatus.ABORTED, False, f"invalid result from the provider: {exc.message}"
            )
            raise
        goal.finish(final, True, msg.msg)

    def release(self, client: ClientId) -> None:
        """Drop the actions ``client`` provides; forget the goals it sent.

        Costs what ``client`` provides and sent, not the size of the table.
        """
        for entry in self.take_owned(client):
            entry.end_all(f"action {entry.spelling} is gone: its provider disconnected")
        for goal in sorted(self._goals_of.pop(client, ()), key=lambda g: g.goal_id):
            if goal.entry.goals.get(goal.goal_id) is not goal:
                continue
            if goal.request_id is None:
                guarded(f"forgetting goal {goal.goal_id}", goal.forget)
                continue
            goal.detach()  # it runs on, cancellable by its id (D35)
            self._left[goal] = None
            while len(self._left) > MAX_LEFT_GOALS:
                oldest = next(iter(self._left))
                del self._left[oldest]
                guarded(f"forgetting goal {oldest.goal_id}", oldest.forget)

    def _untrack(self, goal: Goal) -> None:
        goals = self._goals_of.get(goal.caller)
        if goals is not None:
            goals.discard(goal)
            if not goals:
                del self._goals_of[goal.caller]
        key = (goal.entry.name, goal.request_id or "")
        if goal.request_id is not None and self._by_request.get(key) is goal:
            del self._by_request[key]
        self._left.pop(goal, None)

    def _goal(self, client: ClientId, action: str, goal_id: str | int | None) -> Goal:
        entry = self.owned(client, action)
        key = None if goal_id is None else str(goal_id)  # the graph's goal ids are strings
        goal = None if key is None else entry.goals.get(key)
        if goal is None:
            raise GraphError(f"no goal {key!r} in progress on {action}", level=StatusLevel.WARNING)
        return goal

    def _run_local(
        self, entry: ActionEntry, handler: LocalActionHandler, goal: Goal, goal_msg: Message
    ) -> None:
        spawn = require_spawner(self._spawner(), f"action {entry.spelling}")
        context = goal.context = GoalContext(goal)
        result_type = entry.actiontype.result

        async def run() -> None:
            try:
                outcome = await handler(goal_msg, context)
                msg = result_type.from_python(outcome, now=self.clock.wall())
            except GoalCanceledError:
                goal.finish(GoalStatus.CANCELED, True, result_type.default())
            except Exception:
                _episodes.log(
                    logging.ERROR,
                    f"action_failed {entry.name}",
                    "action %s failed on goal %s",
                    entry.spelling,
                    goal.goal_id,
                    exc_info=True,
                )
                goal.finish(GoalStatus.ABORTED, True, result_type.default())
            else:
                goal.finish(GoalStatus.SUCCEEDED, True, msg)
            finally:  # cancelled by the event loop (the server is stopping)
                goal.finish(GoalStatus.CANCELED, True, result_type.default())

        goal.cancel_job = spawn(run)


def _terminal(status: int | None, result: bool) -> GoalStatus:
    if status is None:
        return GoalStatus.SUCCEEDED if result else GoalStatus.ABORTED
    try:
        code = GoalStatus(status)
    except ValueError:
        raise GraphError(f"unknown goal status {status}") from None
    if code not in (GoalStatus.SUCCEEDED, GoalStatus.CANCELED, GoalStatus.ABORTED):
        raise GraphError(f"goal status {status} is not terminal (expected 4, 5 or 6)")
    return code


CANCEL_GOAL_TYPE = "action_msgs/srv/CancelGoal"
_ERROR_NONE = 0
_ERROR_UNKNOWN_GOAL_ID = 2


def cancel_service_name(action: str) -> str:
    """The ROS 2 cancel service of an action: ``<action>/_action/cancel_goal``."""
    return f"{action.rstrip('/')}/_action/cancel_goal"


def cancel_goals_handler(entry: ActionEntry) -> Callable[[Message], Message]:
    """The handler of ``entry``'s ``action_msgs/srv/CancelGoal`` service.

    A request with a zero goal id cancels every goal of the action (what roslib's
    ``Action.cancelAllGoals`` sends). Goals here are named by rosbridge ids, not
    UUIDs, so a non-zero id answers ``ERROR_UNKNOWN_GOAL_ID``; a stamp is not used.
    """

    def cancel(request: Message) -> Message:
        info = request.get("goal_info")
        goal_id = info.get("goal_id") if isinstance(info, dict) else None
        uuid = goal_id.get("uuid") if isinstance(goal_id, dict) else b""
        if isinstance(uuid, bytes | bytearray | list) and any(uuid):
            return {"return_code": _ERROR_UNKNOWN_GOAL_ID, "goals_canceling": []}
        for goal in list(entry.goals.values()):
            goal.request_cancel()
        return {"return_code": _ERROR_NONE, "goals_canceling": []}

    return cancel
