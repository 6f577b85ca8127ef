"""B22's ROS 1 side: rospy publishers and a rospy subscriber, run by Debian's Python.

``/usr/bin/python3 benchmarks/ros1_nodes.py COMMAND ...`` with ``ROS_MASTER_URI``
set. Only the standard library and rospy (``python3-rospy``, ``ros-std-msgs``,
``ros-sensor-msgs``): the benchmark itself runs in rwt's environment, which has no
rospy, and imports ``tree_cpu_s`` and ``string_data`` from here.

- ``pub-string SECONDS TOPIC``: waits for one subscriber, then publishes 100 B
  ``std_msgs/String`` (``string_data``) as fast as rospy goes for SECONDS.
- ``pub-image SECONDS TOPIC HZ``: the same with a 640x480 rgb8
  ``sensor_msgs/Image`` paced at HZ.
- ``sub-string TOPIC COUNT PID``: subscribes, prints ``ready``, counts the
  messages (each must be ``string_data(i)``, in order) and reads the CPU of
  process PID and its descendants as it subscribes and at the last message.

Each prints one JSON line with what it measured (times are ``time.time()``, the
clock bags are stamped with).
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

__all__ = ["string_data", "tree_cpu_s"]

_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")
IMAGE_WIDTH, IMAGE_HEIGHT = 640, 480
_IDLE_S = 5.0
"""A subscriber that got messages stops waiting for the rest after this long without one."""


def string_data(seq: int) -> str:
    """The ``data`` of message ``seq``: 100 characters, the number first (8 digits)."""
    return f"{seq:08d}" + "x" * 92


def tree_cpu_s(pid: int) -> float:
    """CPU seconds (user + system) of ``pid`` and its live descendants, from /proc (Linux).

    ``rosbag`` runs its C++ ``record`` and ``play`` as child processes, so a
    process alone would miss the work. A process that is gone counts 0.
    """
    children: dict[int, list[int]] = {}
    cpu: dict[int, float] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text("ascii").rpartition(")")[2].split()
        except OSError:  # gone meanwhile
            continue
        children.setdefault(int(fields[1]), []).append(int(entry.name))
        cpu[int(entry.name)] = (int(fields[11]) + int(fields[12])) * _TICK_S
    total, todo = 0.0, [pid]
    while todo:
        current = todo.pop()
        total += cpu.get(current, 0.0)
        todo.extend(children.get(current, []))
    return total


def _emit(result: dict[str, object]) -> None:
    print(json.dumps(result), flush=True)


def _wait_for_subscriber(pub: object) -> None:
    import rospy  # noqa: PLC0415

    while pub.get_num_connections() < 1 and not rospy.is_shutdown():  # type: ignore[attr-defined]
        time.sleep(0.01)
    time.sleep(0.2)  # the subscriber's side of the link is up too
    print("go", flush=True)


def pub_string(seconds: float, topic: str) -> None:
    """Publish strings as fast as rospy goes for ``seconds`` (queue_size=None: no drops here)."""
    import rospy  # noqa: PLC0415
    from std_msgs.msg import String  # noqa: PLC0415

    rospy.init_node("b22_pub", anonymous=True, disable_signals=True)
    pub = rospy.Publisher(topic, String, queue_size=None)
    _wait_for_subscriber(pub)
    msgs = [String(data=string_data(i)) for i in range(1000)]
    sent = 0
    first = time.time()
    stop = first + seconds
    while time.time() < stop:
        for _ in range(100):
            msg = msgs[sent % 1000]
            pub.publish(msg)
            sent += 1
    _emit({"sent": sent, "first": first, "last": time.time()})


def pub_image(seconds: float, topic: str, hz: float) -> None:
    """Publish a 640x480 rgb8 image at ``hz`` for ``seconds``."""
    import rospy  # noqa: PLC0415
    from sensor_msgs.msg import Image  # noqa: PLC0415

    rospy.init_node("b22_pub", anonymous=True, disable_signals=True)
    pub = rospy.Publisher(topic, Image, queue_size=None)
    _wait_for_subscriber(pub)
    size = IMAGE_WIDTH * IMAGE_HEIGHT * 3
    data = (bytes(range(256)) * (size // 256 + 1))[:size]
    msg = Image(height=IMAGE_HEIGHT, width=IMAGE_WIDTH, encoding="rgb8", step=IMAGE_WIDTH * 3)
    msg.data = data
    msg.header.frame_id = "camera"
    count = max(1, round(seconds * hz))
    first = time.time()
    for i in range(count):
        delay = first + i / hz - time.time()
        if delay > 0:
            time.sleep(delay)
        msg.header.stamp = rospy.Time.from_sec(time.time())
        pub.publish(msg)
    _emit({"sent": count, "first": first, "last": time.time()})


def sub_string(topic: str, count: int, pid: int) -> None:
    """Count ``count`` strings on ``topic``; ``pid``'s CPU from subscribing to the last one."""
    import rospy  # noqa: PLC0415
    from std_msgs.msg import String  # noqa: PLC0415

    state: dict[str, float] = {"got": 0, "wrong": 0}

    def arrived(msg: object) -> None:
        now = time.time()
        got = int(state["got"])
        if got == 0:
            state["first"] = now
        if msg.data != string_data(got):  # type: ignore[attr-defined]
            state["wrong"] += 1
        state["got"] = got + 1
        state["last"] = now
        if got + 1 == count:
            state["cpu1"] = tree_cpu_s(pid)

    rospy.init_node("b22_sub", anonymous=True, disable_signals=True)
    state["cpu0"] = tree_cpu_s(pid)  # the player waits for this subscriber
    rospy.Subscriber(topic, String, arrived, queue_size=None, tcp_nodelay=True)
    print("ready", flush=True)
    start = time.time()
    while state["got"] < count:
        time.sleep(0.01)
        idle = time.time() - state.get("last", start)
        if idle > (_IDLE_S if state["got"] else 60.0):
            break
    cpu = state.get("cpu1", tree_cpu_s(pid)) - state.get("cpu0", 0.0)
    _emit(
        {
            "got": int(state["got"]),
            "wrong": int(state["wrong"]),
            "first": state.get("first", 0.0),
            "last": state.get("last", 0.0),
            "cpu_s": cpu,
        }
    )
    rospy.signal_shutdown("done")


def main(argv: list[str]) -> None:
    """Dispatch the command line (module docstring)."""
    command, args = argv[0], argv[1:]
    if command == "pub-string":
        pub_string(float(args[0]), args[1])
    elif command == "pub-image":
        pub_image(float(args[0]), args[1], float(args[2]))
    elif command == "sub-string":
        sub_string(args[0], int(args[1]), int(args[2]))
    else:
        raise SystemExit(f"unknown command {command!r}")


if __name__ == "__main__":
    main(sys.argv[1:])
