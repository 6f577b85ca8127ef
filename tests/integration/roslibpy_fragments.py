"""Publish one large message as ``fragment`` ops through the real roslibpy client.

Usage: python roslibpy_fragments.py HOST PORT TOPIC TYPE SIZE FRAGMENT_SIZE

roslibpy cannot fragment what it sends, so this script cuts the publish op's JSON
text into ``fragment`` ops (spec 3.1.1, last part first: order must not matter)
and sends each through roslibpy's own connection. The message is a
``std_msgs/String`` of SIZE characters. The script then waits for the test to
publish an acknowledgement on ``/rwt_ack`` (the length the server delivered)
and prints it as JSON. Every wait is bounded. Runs in its own process because
twisted's reactor starts once per process.
"""

from __future__ import annotations

import json
import sys
import threading

import roslibpy


def main() -> int:
    host, port, topic, type_name, size, fragment_size = sys.argv[1:7]
    ros = roslibpy.Ros(host, int(port))
    ros.run(timeout=10)
    acked = threading.Event()
    ack: list[object] = []

    def on_ack(message: dict[str, object]) -> None:
        ack.append(message["data"])
        acked.set()

    roslibpy.Topic(ros, "/rwt_ack", "std_msgs/String").subscribe(on_ack)
    publisher = roslibpy.Topic(ros, topic, type_name)
    publisher.advertise()
    text = json.dumps({"op": "publish", "topic": topic, "msg": {"data": "r" * int(size)}})
    step = int(fragment_size)
    chunks = [text[i : i + step] for i in range(0, len(text), step)]
    for num in reversed(range(len(chunks))):
        fragment = {"op": "fragment", "id": "roslibpy-big", "data": chunks[num]}
        fragment.update(num=num, total=len(chunks))
        ros.send_on_ready(roslibpy.Message(fragment))
    ok = acked.wait(30)
    print(json.dumps({"acked": ok, "ack": ack, "fragments": len(chunks)}), flush=True)
    ros.terminate()
    return 0 if ok else 2


if __name__ == "__main__":
    sys.exit(main())
