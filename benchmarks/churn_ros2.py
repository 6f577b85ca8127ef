"""B26's ROS 2 peer: rclpy nodes that come and go beside ``rwt serve --ros2``.

``python -m benchmarks.churn_ros2 [--hz 0.5]`` (a process of its own, with the run's ROS 2
environment: ``benchmarks/churn.py``). It imports rclpy, never rwt.

- A node that stays, ``/soak_r2_talker``, publishes ``CHATTER`` (``std_msgs/msg/String``)
  at ``CHATTER_HZ``: the topic the ``ros2-link`` front end's WebSocket clients subscribe
  to and leave, so that the link makes and drops its rclpy subscription of it.
- At ``--hz`` (0: none, the talker only), a cycle: a node ``/soak_r2_<n>`` is made,
  subscribes to the robot's ``/soak/steady`` and waits for a message, publishes one
  ``std_msgs/msg/String`` on ``OUT`` (a rotating pool of names), calls the robot's
  ``/soak/set_bool`` through the link, and is destroyed with all it held. So the link
  mirrors a node, a subscription, a publisher and a service client appearing and going,
  each cycle. The node starts without rcl's ``~/get_type_description`` service
  (``NO_TYPE_DESCRIPTION``): rclpy 9 (ROS 2 Kilted) leaves that service in the
  middleware when it destroys the node, for as long as its process lives, and every
  participant of the domain, ``rwt serve --ros2`` as much as a bare rclpy node, keeps
  its discovery data (about 7.7 KB of native heap per node that came and went; see
  docs/benchmarks.md, B26). The soak measures what rwt keeps, not what this process
  leaves behind.

``--steps`` keeps some of a cycle's steps (``sub``, ``pub``, ``call``; ``node``: the node
alone), to find which of them costs memory. ``ready`` once the talker runs; then one
JSON line per cycle: ``{"cycle": n, "ok": true}`` or ``{"cycle": n, "ok": false,
"error": "..."}``. Ends on SIGTERM.
"""

from __future__ import annotations

import argparse
import json
import signal
import threading
import time
from typing import Any

__all__ = ["CHATTER", "CHATTER_HZ", "NO_TYPE_DESCRIPTION", "OUT", "main"]

CHATTER = "/soak/r2/chatter"
CHATTER_HZ = 10.0
OUT = "/soak/r2/out"
POOL = 8
"""Topic names a front end rotates through (``OUT`` + ``/t<n % POOL>``)."""
WAIT_S = 15.0
"""Bound on each step of a cycle: discovery on a loaded machine, not a speed figure."""


def _spin_until(executor: Any, done: threading.Event, within: float, what: str) -> None:
    end = time.monotonic() + within
    while not done.is_set():
        if time.monotonic() > end:
            raise TimeoutError(f"{what} within {within:.0f} s")
        executor.spin_once(timeout_sec=0.05)


NO_TYPE_DESCRIPTION = "start_type_description_service"
"""The rcl parameter (read-only, so set as an override when the node is made) that, False,
starts a node without its ``~/get_type_description`` service (the module's text)."""


def _cycle(rclpy: Any, executor: Any, n: int, steps: set[str]) -> None:
    from rclpy.parameter import Parameter  # noqa: PLC0415 (rclpy: in the peer's process only)
    from std_msgs.msg import String  # noqa: PLC0415 (rclpy's messages: after rclpy.init)

    overrides = [Parameter(NO_TYPE_DESCRIPTION, value=False)]
    node = rclpy.create_node(f"soak_r2_{n}", parameter_overrides=overrides)
    executor.add_node(node)
    try:
        if "sub" in steps:
            heard = threading.Event()
            node.create_subscription(String, "/soak/steady", lambda _m: heard.set(), 10)
            _spin_until(executor, heard, WAIT_S, "no /soak/steady message")
        if "pub" in steps:
            publisher = node.create_publisher(String, f"{OUT}/t{n % POOL}", 10)
            publisher.publish(String(data=f"r2 {n}"))
        if "call" in steps:
            _call(node, executor)
        if steps == {"node"}:
            executor.spin_once(timeout_sec=0.5)  # the link's sweep sees it, as a cycle's
    finally:
        executor.remove_node(node)
        node.destroy_node()


def _call(node: Any, executor: Any) -> None:
    from std_srvs.srv import SetBool  # noqa: PLC0415

    client = node.create_client(SetBool, "/soak/set_bool")
    if not client.wait_for_service(timeout_sec=WAIT_S):
        raise TimeoutError("/soak/set_bool not offered")
    future = client.call_async(SetBool.Request(data=True))
    answered = threading.Event()
    future.add_done_callback(lambda _f: answered.set())
    _spin_until(executor, answered, WAIT_S, "no answer from /soak/set_bool")
    if not future.result().success:
        raise RuntimeError("/soak/set_bool answered success: false")


def main(argv: list[str] | None = None) -> None:
    """Run until SIGTERM (see the module's docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hz", type=float, default=0.5)
    parser.add_argument("--steps", default="sub,pub,call")
    args = parser.parse_args(argv)
    steps = set(args.steps.split(","))
    import rclpy  # noqa: PLC0415 (in the peer's process only)
    from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415
    from rclpy.signals import SignalHandlerOptions  # noqa: PLC0415
    from std_msgs.msg import String  # noqa: PLC0415

    stop = threading.Event()
    # rclpy's own handler would shut the context down under the cycle in flight
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    talker = rclpy.create_node("soak_r2_talker")
    chatter = talker.create_publisher(String, CHATTER, 10)
    count = [0]

    def tick() -> None:
        count[0] += 1
        chatter.publish(String(data=str(count[0])))

    talker.create_timer(1.0 / CHATTER_HZ, tick)
    executor = SingleThreadedExecutor()
    executor.add_node(talker)
    print("ready", flush=True)
    n = 0
    due = time.monotonic()
    while not stop.is_set():
        if args.hz <= 0:  # the talker only
            executor.spin_once(timeout_sec=0.05)
            continue
        try:
            _cycle(rclpy, executor, n, steps)
            print(json.dumps({"cycle": n, "ok": True}), flush=True)
        except Exception as exc:  # a failed cycle is a figure, not an end
            error = f"{type(exc).__name__}: {exc}"[:200]
            print(json.dumps({"cycle": n, "ok": False, "error": error}), flush=True)
        n += 1
        due = max(due + 1.0 / args.hz, time.monotonic())
        while not stop.is_set() and time.monotonic() < due:
            executor.spin_once(timeout_sec=min(0.05, max(0.0, due - time.monotonic())))
    executor.shutdown()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
