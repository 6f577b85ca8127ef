"""``rwt serve --topics-pub-glob --topics-sub-glob`` with roslibpy (D50, REF §13.5).

A real client may publish a topic it may not subscribe to: the subscribe is
refused with an error status naming the topic, the publish reaches the robot,
and the server's log names the glob that refused; no status refuses the
advertise or the publish, and rosapi lists the topic (the pub glob allows it).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from tests.integration.client_harness import run_client_script

if TYPE_CHECKING:
    from pathlib import Path

PUBLISH_AND_SUBSCRIBE = """
import json, time
import roslibpy

ros = roslibpy.Ros("127.0.0.1", {port})
ros.run(timeout=20)
statuses, heard = [], []
# roslibpy's own status handler only logs: take the statuses instead
ros.factory.on_ready(lambda proto: proto._message_handlers.update(status=statuses.append))
echo = roslibpy.Topic(ros, "/cmd", "std_msgs/msg/String")
echo.subscribe(heard.append)
topic = roslibpy.Topic(ros, "/cmd", "std_msgs/msg/String")
topic.advertise()
deadline = time.monotonic() + 10
while not statuses and time.monotonic() < deadline:
    time.sleep(0.05)
topic.publish(roslibpy.Message({{"data": "go"}}))
topics = []
ros.get_topics(topics.append)
while not topics and time.monotonic() < deadline:
    time.sleep(0.05)
time.sleep(0.3)
got = {{"statuses": statuses, "heard": heard, "topics": topics}}
print(json.dumps(got, default=dict), flush=True)
ros.terminate()
"""


def test_roslibpy_may_publish_a_topic_it_may_not_subscribe_to(tmp_path: Path) -> None:
    globs = ("--topics-pub-glob", "[/cmd]", "--topics-sub-glob", "[]")
    got, _, logged = run_client_script(tmp_path, globs, PUBLISH_AND_SUBSCRIBE)
    assert [(s["level"], s["msg"]) for s in got["statuses"]] == [
        ("error", "subscribe: topic /cmd is not allowed on this server")
    ]
    assert got["heard"] == []
    assert "/cmd" in got["topics"][0]["topics"]  # listed: the pub glob allows it (REF §13.5)
    assert "event=access_denied" in logged and "glob=topics_sub_glob" in logged
