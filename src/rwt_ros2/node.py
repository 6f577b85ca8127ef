"""The rclpy node of the link, spinning in its own thread.

rclpy runs its executor on a thread of its own so the event loop never waits
for DDS; callbacks reach the loop through a ``Handoff``. The link's topic
subscriptions have a thread of their own too (``takeloop``, the
``ros2-take-loop`` shortcut), which waits on them alone. Entities are created
and messages published from the event loop's thread, which rclpy allows (each
entity has its own lock; the executor is woken to wait on new ones).

The executor is rclpy's single-threaded one. Its multi-threaded executor hands
every ready callback to a thread pool and yields it again until a pool thread
starts it: measured here, a 500 Hz ``String`` then cost 20-55 ms of CPU per
delivery and lost 87-95 % of the messages (benchmarks/README.md, ROS 2 bridge).
Calls and goals from ROS 2 therefore never block the executor: their callbacks
are coroutines awaiting an ``answer.Answer`` the event loop completes.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.shortcuts import enabled

from .runtime import load_rclpy
from .takeloop import TakeLoop

__all__ = ["MAX_WAITING", "SPIN_TIMEOUT_S", "RosNode"]

logger = logging.getLogger("rwt.ros2")

SPIN_TIMEOUT_S = 0.1
"""How long one executor wait lasts, seconds: how soon the thread notices shutdown."""

MAX_WAITING = 64
"""Calls and goals from ROS 2 waiting for the graph at once; one more is answered
at once with the default response (a goal: aborted), logged once per episode.
Each waits as a coroutine, not a thread; the bound keeps ROS 2 callers from
piling up work behind a provider that never answers."""


class RosNode:
    """An rclpy context, node and executor, spinning on a daemon thread.

    Args:
        name: the node's name (``rwt``).
        namespace: its namespace (``/`` or ``/robot``).

    Attributes:
        rclpy: the rclpy module.
        node: the ``rclpy.node.Node``.
        fqn: the node's fully qualified name (``/rwt``, ``/robot/rwt``).

    Raises:
        Ros2Unavailable: rclpy cannot be imported.
        rclpy's RCLError: the middleware cannot start (a bad ``ROS_DOMAIN_ID``...).
    """

    def __init__(self, name: str, namespace: str = "/") -> None:
        rclpy = self.rclpy = load_rclpy()
        from rclpy.callback_groups import ReentrantCallbackGroup  # noqa: PLC0415
        from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415

        self.context = rclpy.Context()
        rclpy.init(
            # rwt logs on its own; through /rosout (``rosout``), not rcl's console or files
            args=["--ros-args", "--disable-stdout-logs", "--disable-external-lib-logs"],
            context=self.context,
            signal_handler_options=_no_signals(rclpy),
        )
        try:
            self.node: Any = rclpy.create_node(
                name, namespace=namespace or "/", context=self.context
            )
        except Exception:
            self.context.try_shutdown()
            raise
        ns = self.node.get_namespace().rstrip("/")
        self.fqn = f"{ns}/{self.node.get_name()}"
        # reentrant: a call or goal awaiting the graph must not hold back the topics
        self.group = ReentrantCallbackGroup()
        #: taken by each call or goal from ROS 2 while it waits for the graph
        self.waiting = threading.BoundedSemaphore(MAX_WAITING)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, name="rwt-ros2", daemon=True)
        self._episodes = EpisodeLog(logger)
        #: the link's subscriptions' own thread (``ros2-take-loop``); None: the executor's
        self.takes = TakeLoop(self.node) if enabled("ros2-take-loop") else None

    def start(self) -> None:
        """Start spinning (and taking)."""
        self._thread.start()
        if self.takes is not None:
            self.takes.start()

    def _spin(self) -> None:
        while self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
            except Exception as exc:
                if not self.context.ok():  # shutdown under the executor's feet
                    return
                # one callback failed (an entity destroyed under a call it was answering,
                # a peer's odd request): the others, and the thread, go on
                self._episodes.log(
                    logging.WARNING,
                    f"spin:{type(exc).__name__}",
                    "event=ros2_callback_failed error=%r",
                    exc,
                    exc_info=True,
                )

    def close(self) -> None:
        """Stop spinning, then destroy the node and the context."""
        if self.takes is not None:  # its subscriptions go before the node
            self.takes.close()
        self.context.try_shutdown()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()

    def forget_destroyed(self) -> int:
        """Drop the weak references rclpy keeps to the node's destroyed entities.

        rclpy's ``CallbackGroup.add_entity`` (rclpy 9, ROS 2 Kilted) keeps a
        ``weakref.ref`` of every subscription, client, service, timer and waitable
        added to a group, a publisher's QoS event handlers among them, and never
        removes one: a node whose entities come and go grows by a dead reference
        (about 100 bytes with its slot in the set) per entity. The link's
        publishers come and go with the topics clients advertise and leave: some
        12 a second at the churn soak's rates, about 5 MB an hour
        (docs/benchmarks.md, B26). The link calls this every sweep, from the event
        loop's thread, which creates the entities; the executor's thread only looks
        them up.

        Returns:
            How many references were dropped.
        """
        dropped = 0
        for group in {id(g): g for g in (self.group, self.node.default_callback_group)}.values():
            entities = getattr(group, "entities", None)
            if not isinstance(entities, set):  # another rclpy: nothing of ours to tidy
                continue
            dead = [ref for ref in list(entities) if ref() is None]
            for ref in dead:
                entities.discard(ref)
            dropped += len(dead)
        return dropped

    def owns(self, node: str, namespace: str) -> bool:
        """Whether the endpoint of ``node`` in ``namespace`` is this node's."""
        return f"{namespace.rstrip('/')}/{node}" == self.fqn


def _no_signals(rclpy: Any) -> Any:
    """Rclpy must not take SIGINT and SIGTERM: the server's own handlers stop it."""
    from rclpy.signals import SignalHandlerOptions  # noqa: PLC0415

    del rclpy
    return SignalHandlerOptions.NO
