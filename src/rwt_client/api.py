"""Topic, Service, Action and Param: roslibpy-shaped handles on a ``Ros``."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import anyio

from rwt_protocol.errors import ConfigError
from rwt_protocol.ops import ActionResult
from rwt_protocol.ops.qos import Qos

from .connectors import ConnectionClosedError
from .ros import Callback, CallTimeoutError, Ros, ServiceCallError
from .typed import MessageClass, to_wire

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.qos import QosProfile

__all__ = ["Action", "GoalHandle", "Param", "Service", "Topic"]


class Topic:
    """A topic seen from the client (spec 3.3.1-3.3.5).

    Args:
        ros: the connection.
        name: the topic name; messages come back with this spelling (D26).
        message_type: ``pkg/msg/Type`` or ``pkg/Type``; may be None to subscribe to
            a topic whose type the server knows.
        throttle_rate: ms between messages (spec 3.3.4).
        queue_length: messages buffered while throttled.
        compression: ``none``, ``png``, ``cbor`` or ``cbor-raw`` (decoded here).
        fragment_size: ask the server to fragment above this many characters.
        latch: advertise latched (ROS 1 edition, D13).
        queue_size: publisher queue size (ROS 1 edition).
        message_class: deliver instances of this class (``typed.message_class``)
            instead of dicts.
        qos: protocol 2.1.0's QoS (``rwt.QosProfile``), sent with this object's
            ``subscribe`` (what it asks of the topic) and ``advertise`` (what it
            offers; the server then reads no ``latch`` or ``queue_size``); None:
            no ``qos`` is sent, as before 2.1.0.
    """

    def __init__(
        self,
        ros: Ros,
        name: str,
        message_type: str | None = None,
        *,
        throttle_rate: int = 0,
        queue_length: int = 0,
        compression: str = "none",
        fragment_size: int | None = None,
        latch: bool = False,
        queue_size: int = 100,
        message_class: MessageClass | None = None,
        qos: QosProfile | None = None,
    ) -> None:
        self.ros = ros
        self.name = name
        self.message_type = message_type
        self.options: dict[str, object] = {
            "throttle_rate": throttle_rate,
            "queue_length": queue_length,
            "compression": compression,
            "fragment_size": fragment_size,
        }
        if qos is not None:
            self.options["qos"] = Qos.of(qos)
        self.qos = qos
        self.latch = latch
        self.queue_size = queue_size
        self.message_class = message_class
        self._sub_id: str | None = None
        self._adv_id: str | None = None

    @property
    def is_advertised(self) -> bool:
        """Whether ``advertise`` was called and not undone."""
        return self._adv_id is not None

    @property
    def is_subscribed(self) -> bool:
        """Whether ``subscribe`` was called and not undone."""
        return self._sub_id is not None

    async def subscribe(self, callback: Callback, *, confirm: bool = False) -> None:
        """Deliver each message to ``callback(msg)`` (one subscription per Topic object).

        Args:
            callback: called with each message.
            confirm: wait one round trip for the server's refusal, as ``advertise``
                does (``Ros.refusal``); without it a refused subscription is
                silent (rosbridge does not acknowledge ``subscribe``).

        Raises:
            OpRefusedError: with ``confirm``, the server refused it (an access rule,
                ``--max-subscriptions``, a type conflict): the status text says why,
                and the subscription is forgotten (never replayed).
            ConnectionClosedError: with ``confirm``, the connection dropped before
                the answer; the subscription is forgotten too.
        """
        if self._sub_id is not None:
            await self.unsubscribe()
        cls = self.message_class
        deliver: Callback = callback if cls is None else (lambda msg: callback(cls.from_dict(msg)))
        sub_id = self._sub_id = self.ros.session.subscribe(
            self.name, self.message_type, **self.options
        )
        self.ros.add_topic_callback(self.name, sub_id, deliver)
        await self.ros.flush()
        if not confirm:
            return
        refusal = await self.ros.refusal("subscribe", sub_id, self.name)
        if refusal is not None:
            self.ros.remove_topic_callback(self.name, sub_id)
            self.ros.session.forget_subscription(sub_id)
            self._sub_id = None
            raise refusal

    async def unsubscribe(self) -> None:
        """Stop this object's subscription."""
        if self._sub_id is None:
            return
        self.ros.remove_topic_callback(self.name, self._sub_id)
        self.ros.session.unsubscribe(self.name, self._sub_id)
        self._sub_id = None
        await self.ros.flush()

    async def advertise(self) -> None:
        """Announce that this client publishes the topic, once the server took it (spec 3.3.1).

        Waits one round trip (``Ros.advertise``).

        Raises:
            ConfigError: no ``message_type`` was given.
            OpRefusedError: the server refused it, for example because the topic
                has another type there; the topic stays unadvertised.
        """
        if self._adv_id is not None:
            return
        if self.message_type is None:
            raise ConfigError(f"advertising {self.name} needs a message type")
        self._adv_id = await self.ros.advertise(
            self.name,
            self.message_type,
            latch=self.latch,
            queue_size=self.queue_size,
            qos=self.qos,
        )

    async def unadvertise(self) -> None:
        """Stop publishing (spec 3.3.2)."""
        if self._adv_id is None:
            return
        self.ros.session.unadvertise(self.name, self._adv_id)
        self._adv_id = None
        await self.ros.flush()

    async def publish(self, msg: object) -> None:
        """Publish a dict or a message-class instance, advertising first if needed."""
        if self._adv_id is None and self.message_type is not None:
            await self.advertise()
        self.ros.session.publish(self.name, to_wire(msg), latch=self.latch)
        await self.ros.flush()


class Service:
    """A service seen from the client (spec 3.3.6-3.3.9)."""

    def __init__(self, ros: Ros, name: str, service_type: str | None = None) -> None:
        self.ros = ros
        self.name = name
        self.service_type = service_type
        self.is_advertised = False

    async def call(self, request: object = None, *, timeout_s: float | None = None) -> Any:
        """Call the service; return the response values.

        Raises:
            ServiceCallError: ``result: false`` (the text is in ``values``).
            CallTimeoutError: no reply within ``timeout_s``.
            ConnectionClosedError: the connection dropped.
        """
        return await self.ros.call_service(
            self.name, to_wire(request), type_name=self.service_type, timeout_s=timeout_s
        )

    async def advertise(self, handler: Callable[[Any], object]) -> None:
        """Serve requests with ``handler(request) -> response`` (plain or async).

        An exception in the handler answers ``result: false`` with its text.

        Raises:
            ConfigError: no ``service_type`` was given.
        """
        if self.service_type is None:
            raise ConfigError(f"advertising {self.name} needs a service type")
        self.ros.set_service_handler(self.name, handler)
        self.ros.session.advertise_service(self.name, self.service_type)
        self.is_advertised = True
        await self.ros.flush()

    async def unadvertise(self) -> None:
        """Stop serving (spec 3.3.7)."""
        self.ros.set_service_handler(self.name, None)
        self.ros.session.unadvertise_service(self.name)
        self.is_advertised = False
        await self.ros.flush()


class GoalHandle:
    """A goal sent with ``Action.send_goal``: wait for its result or cancel it."""

    def __init__(self, action: Action, goal_id: str, waiter: Any) -> None:
        self.action = action
        self.id = goal_id
        self._waiter = waiter

    async def result(self, *, timeout_s: float | None = None) -> ActionResult:
        """Wait for the ``action_result``; ``status`` says how it ended (D18).

        Raises:
            CallTimeoutError: no result within ``timeout_s`` (None waits forever).
            ConnectionClosedError: the connection dropped.
        """
        try:
            with anyio.fail_after(timeout_s):
                await self._waiter.done.wait()
        except TimeoutError:
            raise CallTimeoutError(
                f"no action_result for {self.action.name} within {timeout_s:g} s"
            ) from None
        finally:
            if self._waiter.done.is_set():
                self.action.ros.forget(self.id)
        if self._waiter.error is not None:
            raise self._waiter.error
        reply = self._waiter.reply
        assert isinstance(reply, ActionResult)
        return reply

    async def cancel(self) -> None:
        """Send ``cancel_action_goal`` (spec 3.3.13); the result arrives later (status 5)."""
        self.action.ros.session.cancel_action_goal(self.action.name, self.id)
        await self.action.ros.flush()


class Action:
    """An action seen from the client (spec 3.3.10-3.3.15)."""

    def __init__(self, ros: Ros, name: str, action_type: str) -> None:
        self.ros = ros
        self.name = name
        self.action_type = action_type

    async def send_goal(
        self, goal: object = None, *, on_feedback: Callback | None = None
    ) -> GoalHandle:
        """Send a goal; feedback (asked for when ``on_feedback`` is given) goes to it.

        Raises:
            ConnectionClosedError: the connection is down (reconnecting, or closed):
                the goal would be lost.
        """
        self.ros.require_connection()
        goal_id = self.ros.session.send_action_goal(
            self.name, self.action_type, to_wire(goal), feedback=on_feedback is not None
        )
        waiter = self.ros.goal_waiter(goal_id, on_feedback)
        await self.ros.flush()
        return GoalHandle(self, goal_id, waiter)

    async def advertise(self, handler: Callback) -> None:
        """Serve goals with ``handler(goal: ServerGoal) -> result`` (plain or async)."""
        self.ros.set_action_handler(self.name, handler)
        self.ros.session.advertise_action(self.name, self.action_type)
        await self.ros.flush()

    async def unadvertise(self) -> None:
        """Stop serving (spec 3.3.11)."""
        self.ros.set_action_handler(self.name, None)
        self.ros.session.unadvertise_action(self.name)
        await self.ros.flush()


class Param:
    """A parameter through rosapi (``<node>:<name>`` in ROS 2, REF §7.1)."""

    def __init__(self, ros: Ros, name: str) -> None:
        self.ros = ros
        self.name = name

    async def get(self, default: object = None) -> object:
        """The value, or ``default`` when unset."""
        return await self.ros.get_param(self.name, default)

    async def set(self, value: object) -> None:
        """Set the value (any JSON value)."""
        await self.ros.set_param(self.name, value)

    async def delete(self) -> None:
        """Delete the parameter."""
        await self.ros.delete_param(self.name)


_ = (ConnectionClosedError, ServiceCallError)  # re-exported by the package
