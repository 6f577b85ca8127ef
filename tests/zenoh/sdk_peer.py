"""A ROS 2 peer on Zenoh written by others: zenoh-ros2-sdk (ROBOTIS), driven over stdin.

``python sdk_peer.py ENDPOINT`` connects to ``ENDPOINT`` (loopback only, multicast
off) and holds, as its own nodes: a subscription to ``/to_sdk``, a publisher on
``/from_sdk`` (both ``std_msgs/msg/String``) and the service ``/sdk/add``
(``example_interfaces/srv/AddTwoInts``, answering ``a + b``). It prints ``ready``,
then answers each command on stdin with one JSON line:

- ``publish TEXT``: publish ``TEXT`` on ``/from_sdk``; ``true``.
- ``received``: the texts that reached ``/to_sdk`` so far.
- ``call SERVICE A B``: call ``SERVICE`` (AddTwoInts) with a client of the SDK;
  the sum, or ``null`` when no response came within 3 s.
- ``graph``: the topics and services the SDK sees, from liveliness tokens.
- ``latched TOPIC``: subscribe to ``TOPIC`` as transient local, as a late joiner;
  the texts received within 2 s (the publishers' caches answer its query).

The SDK keeps one Zenoh session per process, hence a process of its own.
"""

from __future__ import annotations

import json
import os
import sys

ENDPOINT = sys.argv[1]
HOST, PORT = ENDPOINT.removeprefix("tcp/").rsplit(":", 1)
# the SDK's bundled config (rmw_zenoh's defaults) listens on localhost; keep it on loopback
os.environ["ZENOH_CONFIG_OVERRIDE"] = (
    'listen/endpoints=["tcp/127.0.0.1:0"];scouting/multicast/enabled=false'
)

import time  # noqa: E402

from zenoh_ros2_sdk import (  # noqa: E402 - after the environment it reads
    ROS2Publisher,
    ROS2ServiceClient,
    ROS2ServiceServer,
    ROS2Subscriber,
    get_service_names_and_types,
    get_topic_names_and_types,
)
from zenoh_ros2_sdk.qos import QosDurability, QosProfile  # noqa: E402

STRING = "string data"
ADD = ("example_interfaces/srv/AddTwoInts", "int64 a\nint64 b", "int64 sum")
where = {"router_ip": HOST, "router_port": int(PORT)}

received: list[str] = []
listener = ROS2Subscriber(
    "/to_sdk",
    "std_msgs/msg/String",
    lambda msg: received.append(msg.data),
    msg_definition=STRING,
    node_name="sdk_listener",
    **where,
)
talker = ROS2Publisher(
    "/from_sdk", "std_msgs/msg/String", msg_definition=STRING, node_name="sdk_talker", **where
)
server: ROS2ServiceServer


def add(request: object) -> object:
    return server.response_msg_class(sum=request.a + request.b)  # type: ignore[attr-defined]


server = ROS2ServiceServer(
    "/sdk/add",
    ADD[0],
    add,
    request_definition=ADD[1],
    response_definition=ADD[2],
    node_name="sdk_adder",
    **where,
)
clients: dict[str, ROS2ServiceClient] = {}


def call(service: str, a: int, b: int) -> int | None:
    client = clients.get(service)
    if client is None:
        client = clients[service] = ROS2ServiceClient(
            service,
            ADD[0],
            request_definition=ADD[1],
            response_definition=ADD[2],
            timeout=3.0,
            node_name="sdk_caller",
            **where,
        )
    response = client.call(a=a, b=b)
    return None if response is None else int(response.sum)


def latched(topic: str) -> list[str]:
    texts: list[str] = []
    ROS2Subscriber(
        topic,
        "std_msgs/msg/String",
        lambda msg: texts.append(msg.data),
        msg_definition=STRING,
        node_name="sdk_late_listener",
        qos=QosProfile(durability=QosDurability.TRANSIENT_LOCAL),
        **where,
    )
    time.sleep(2.0)
    return texts


print("ready", flush=True)
for line in sys.stdin:
    command, _, rest = line.strip().partition(" ")
    answer: object
    if command == "publish":
        talker.publish(data=rest)
        answer = True
    elif command == "received":
        answer = list(received)
    elif command == "call":
        service, a, b = rest.split()
        answer = call(service, int(a), int(b))
    elif command == "latched":
        answer = latched(rest)
    elif command == "graph":
        answer = {
            "topics": dict(get_topic_names_and_types(**where)),
            "services": dict(get_service_names_and_types(**where)),
        }
    else:
        answer = f"unknown command {command!r}"
    print(json.dumps(answer), flush=True)
os._exit(0)  # the SDK's session threads would hold the interpreter open
