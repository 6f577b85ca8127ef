"""`rwt serve --ros2` and the real rosbridge_suite 2.1.0, side by side on one ROS 2 graph.

    RWT_ROSBRIDGE_ROS2_URL=ws://127.0.0.1:9627 ROS_DOMAIN_ID=127 \\
        python conformance/ros2_differential.py [--rwt-url ws://127.0.0.1:PORT] [--json OUT]

The peer is a running rosbridge_suite 2.1.0 (``rosbridge_websocket`` + ``rosapi``) on
``ROS_DOMAIN_ID``; rwt is started here as ``rwt serve --ros2 --no-tf`` on the same domain
unless ``--rwt-url`` names one. Each scenario runs once per bridge, against fresh real
rclpy nodes (tests/ros2/peer.py) whose names carry the bridge's label, through roslibpy
(topics, services, rosapi) or plain JSON over a WebSocket (actions and bad input, where
the ``status`` messages are the point). The output is a markdown table: scenario, what
the peer returned, what rwt returned, and whether they are the same. The reading of the
differences is in docs/ros2.md ("Compared with rosbridge_suite 2.1.0").
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import roslibpy
from websockets.sync.client import ClientConnection, connect

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
PEER_PY = REPO / "tests" / "ros2" / "peer.py"
FASTDDS_XML = REPO / "tests" / "ros2" / "fastdds_loopback.xml"
PEER_ENV = "RWT_ROSBRIDGE_ROS2_URL"
WAIT_S = 15.0
"""How long a scenario waits for one expected thing (a message, a reply)."""
QUIET_S = 2.0
"""How long bad input is given to draw a status (none in that time is recorded as such)."""

Scenario = Callable[[str, str], str]
"""``(websocket url, label) -> summary``: one scenario on one bridge."""


def ros_env() -> dict[str, str]:
    """The environment of rclpy processes here: the caller's domain, loopback only."""
    env = dict(os.environ)
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env.setdefault("FASTDDS_DEFAULT_PROFILES_FILE", str(FASTDDS_XML))
    env["PYTHONUNBUFFERED"] = "1"
    return env


class Node:
    """``peer.py MODE NAME [NODE]`` (a real rclpy node) with its JSON lines on a queue."""

    def __init__(self, mode: str, name: str, node: str | None = None) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(PEER_PY), mode, name, *([node] if node else [])],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            env=ros_env(),
        )
        self.lines: list[dict[str, Any]] = []
        self._cond = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.wait(lambda line: bool(line.get("ready")))

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for raw in self.proc.stdout:
            with contextlib.suppress(ValueError), self._cond:
                self.lines.append(json.loads(raw))
                self._cond.notify_all()

    def wait(
        self, match: Callable[[dict[str, Any]], bool], within: float = WAIT_S
    ) -> dict[str, Any] | None:
        """The first line matching ``match`` within ``within`` s, else None."""
        end = time.monotonic() + within
        with self._cond:
            while True:
                for line in self.lines:
                    if match(line):
                        return line
                left = end - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(left)

    def stop(self) -> None:
        """SIGTERM, then SIGKILL; its pipe closed once the reader has seen its end."""
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(10)
        self._reader.join(5)
        if self.proc.stdout is not None:
            self.proc.stdout.close()


@contextlib.contextmanager
def node(mode: str, name: str, node_name: str | None = None) -> Iterator[Node]:
    """A peer.py node for the block."""
    peer = Node(mode, name, node_name)
    try:
        yield peer
    finally:
        peer.stop()


@contextlib.contextmanager
def client(url: str) -> Iterator[roslibpy.Ros]:
    """A connected roslibpy client for the block."""
    host, _, port = url.removeprefix("ws://").rstrip("/").rpartition(":")
    ros = roslibpy.Ros(host, int(port))
    ros.run(timeout=WAIT_S)
    try:
        yield ros
    finally:
        ros.close()


def poll(predicate: Callable[[], bool], within: float = WAIT_S) -> bool:
    """Whether ``predicate`` became true within ``within`` s (polled every 50 ms)."""
    end = time.monotonic() + within
    while not predicate() and time.monotonic() < end:
        time.sleep(0.05)
    return predicate()


def call(ros: roslibpy.Ros, name: str, kind: str, args: dict[str, Any]) -> str:
    """A roslibpy service call's values, or ``error: <text>``."""
    try:
        values = roslibpy.Service(ros, name, kind).call(
            roslibpy.ServiceRequest(args), timeout=WAIT_S
        )
    except Exception as exc:
        return f"error: {str(exc)[:160]}"
    return json.dumps(dict(values), sort_keys=True)


def discovered(ros: roslibpy.Ros, listing: str, name: str) -> bool:
    """Whether ``name`` shows in ``/rosapi/<listing>`` (``services`` or ``nodes``) within WAIT_S.

    DDS discovery of a fresh node takes a moment (longer on a loaded machine); the
    scenarios wait for it through the bridge's own rosapi so both bridges get the same chance.
    """
    kind = f"rosapi_msgs/srv/{listing.capitalize()}"

    def listed() -> bool:
        found = call(ros, f"/rosapi/{listing}", kind, {})
        return not found.startswith("error") and name in json.loads(found)[listing]

    return poll(listed)


def raw(
    url: str, messages: list[dict[str, Any]], until: Callable[[dict[str, Any]], bool], within: float
) -> list[dict[str, Any]]:
    """Send ``messages`` on a plain WebSocket; what came back until ``until`` or ``within`` s."""
    got: list[dict[str, Any]] = []
    ws: ClientConnection
    with connect(url, open_timeout=WAIT_S) as ws:
        for message in messages:
            ws.send(json.dumps(message))
        end = time.monotonic() + within
        while (left := end - time.monotonic()) > 0:
            try:
                got.append(json.loads(ws.recv(timeout=left)))
            except TimeoutError:
                break
            if until(got[-1]):
                break
    return got


def statuses(got: list[dict[str, Any]]) -> str:
    """The status messages in ``got``, ``level: text`` (short), or ``no status``."""
    found = [f"{m.get('level')}: {str(m.get('msg'))[:90]}" for m in got if m.get("op") == "status"]
    return " / ".join(found) or "no status"


# --- scenarios ------------------------------------------------------------------------


def topic_ros_to_ws(url: str, label: str) -> str:
    topic = f"/d_{label}/chatter"
    with node("talk", topic, f"talk_{label}"), client(url) as ros:
        got: list[dict[str, Any]] = []
        listener = roslibpy.Topic(ros, topic, "std_msgs/msg/String")
        listener.subscribe(got.append)
        poll(lambda: bool(got))
        listener.unsubscribe()
        return f"first: {got[0]}" if got else "nothing"


def topic_ws_to_ros(url: str, label: str) -> str:
    topic = f"/d_{label}/heard"
    with node("listen", topic, f"listen_{label}") as peer, client(url) as ros:
        talker = roslibpy.Topic(ros, topic, "std_msgs/msg/String")
        talker.advertise()
        heard = None
        for _ in range(int(WAIT_S / 0.2)):
            talker.publish(roslibpy.Message({"data": "from ws"}))
            heard = peer.wait(lambda line: "heard" in line, within=0.2)
            if heard:
                break
        talker.unadvertise()
        return f"ROS heard {heard['heard']!r}" if heard else "ROS heard nothing"


def latched_late(url: str, label: str) -> str:
    topic = f"/d_{label}/latched"
    with node("latched", topic, f"latched_{label}"), client(url) as ros:
        time.sleep(1.0)  # the subscriber comes late: the one message is long published
        got: list[dict[str, Any]] = []
        listener = roslibpy.Topic(ros, topic, "std_msgs/msg/String")
        listener.subscribe(got.append)
        poll(lambda: bool(got), within=5.0)
        listener.unsubscribe()
        return f"late subscriber got {got[0]}" if got else "late subscriber got nothing"


def service_ws_to_ros(url: str, label: str) -> str:
    name = f"/d_{label}/set"
    with node("serve", name, f"serve_{label}"), client(url) as ros:
        # at once (the bridge may not have discovered the server yet), then after 1 s
        first = call(ros, name, "std_srvs/srv/SetBool", {"data": True})
        seen = discovered(ros, "services", name)
        later = call(ros, name, "std_srvs/srv/SetBool", {"data": True})
        return f"at once: {first}; once listed ({seen}): {later}"


def service_ros_to_ws(url: str, label: str) -> str:
    name = f"/d_{label}/ws_set"
    with client(url) as ros:
        service = roslibpy.Service(ros, name, "std_srvs/srv/SetBool")

        def answer(request: dict[str, Any], response: dict[str, Any]) -> bool:
            response["success"] = bool(request["data"])
            response["message"] = "ws got it"
            return True

        service.advertise(answer)
        with node("call", name, f"call_{label}") as peer:
            line = peer.wait(lambda line: "response" in line or "error" in line)
        service.unadvertise()
        return json.dumps(line) if line else "ROS caller got nothing"


def action_goal(url: str, label: str) -> str:
    name = f"/d_{label}/fib"
    kind = "test_msgs/action/Fibonacci"
    with node("fibonacci", name, f"fib_{label}"):
        with client(url) as ros:  # until each bridge's rosapi lists the action server

            def listed() -> bool:
                found = call(ros, "/rosapi/action_servers", "rosapi_msgs/srv/GetActionServers", {})
                return not found.startswith("error") and name in json.loads(found)["action_servers"]

            poll(listed)
        done = raw(
            url,
            [
                {
                    "op": "send_action_goal",
                    "id": "g1",
                    "action": name,
                    "action_type": kind,
                    "args": {"order": 3},
                    "feedback": True,
                }
            ],
            lambda m: m.get("op") == "action_result",
            WAIT_S,
        )
        feedback = [m["values"] for m in done if m.get("op") == "action_feedback"]
        result = [
            {k: m.get(k) for k in ("status", "result", "values")}
            for m in done
            if m.get("op") == "action_result"
        ]
        cancelled = raw(
            url,
            [
                {
                    "op": "send_action_goal",
                    "id": "g2",
                    "action": name,
                    "action_type": kind,
                    "args": {"order": 40},
                    "feedback": True,
                },
                {"op": "cancel_action_goal", "id": "g2", "action": name},
            ],
            lambda m: m.get("op") == "action_result",
            WAIT_S,
        )
        cancel = [
            {k: m.get(k) for k in ("status", "result")}
            for m in cancelled
            if m.get("op") == "action_result"
        ]
    return (
        f"feedback {len(feedback)} (last {feedback[-1] if feedback else None}); "
        f"result {result}; cancelled {cancel} {statuses(cancelled)}"
    )


def params(url: str, label: str) -> str:
    target = f"params_{label}"
    with node("params", target), client(url) as ros:
        discovered(ros, "nodes", f"/{target}")
        parts = [
            "get speed "
            + call(
                ros,
                "/rosapi/get_param",
                "rosapi_msgs/srv/GetParam",
                {"name": f"/{target}:speed", "default_value": ""},
            ),
            "set speed "
            + call(
                ros,
                "/rosapi/set_param",
                "rosapi_msgs/srv/SetParam",
                {"name": f"/{target}:speed", "value": "2.5"},
            ),
            "get again "
            + call(
                ros,
                "/rosapi/get_param",
                "rosapi_msgs/srv/GetParam",
                {"name": f"/{target}:speed", "default_value": ""},
            ),
        ]
        names = call(ros, "/rosapi/get_param_names", "rosapi_msgs/srv/GetParamNames", {})
        mine = (
            sorted(n for n in json.loads(names).get("names", []) if target in n)
            if not names.startswith("error")
            else names
        )
        parts.append(f"names {mine}")
        return "; ".join(parts)


def rosapi_listings(url: str, label: str) -> str:
    topic = f"/d_{label}/listed"
    with node("talk", topic, f"listed_{label}"), client(url) as ros:
        time.sleep(1.0)
        out = []
        topics = call(ros, "/rosapi/topics", "rosapi_msgs/srv/Topics", {})
        if topics.startswith("error"):
            out.append(f"topics {topics}")
        else:
            value = json.loads(topics)
            pairs = dict(zip(value["topics"], value["types"], strict=False))
            out.append(f"topics has {topic}: {pairs.get(topic)}")
        out.append(
            "topic_type "
            + call(ros, "/rosapi/topic_type", "rosapi_msgs/srv/TopicType", {"topic": topic})
        )
        services = call(ros, "/rosapi/services", "rosapi_msgs/srv/Services", {})
        out.append(
            "services "
            + (
                services
                if services.startswith("error")
                else f"{len(json.loads(services)['services'])} listed"
            )
        )
        nodes = call(ros, "/rosapi/nodes", "rosapi_msgs/srv/Nodes", {})
        out.append(
            "nodes has talker "
            + (
                nodes
                if nodes.startswith("error")
                else str(f"/listed_{label}" in json.loads(nodes)["nodes"])
            )
        )
        out.append(
            "publishers "
            + call(ros, "/rosapi/publishers", "rosapi_msgs/srv/Publishers", {"topic": topic})
        )
        out.append(
            "subscribers "
            + call(ros, "/rosapi/subscribers", "rosapi_msgs/srv/Subscribers", {"topic": topic})
        )
        return "; ".join(out)


def missing_type(url: str, label: str) -> str:
    got = raw(
        url,
        [
            {
                "op": "subscribe",
                "id": "s",
                "topic": f"/d_{label}/nope",
                "type": "nope_msgs/msg/Nope",
            },
            {
                "op": "advertise",
                "id": "a",
                "topic": f"/d_{label}/nope2",
                "type": "nope_msgs/msg/Nope",
            },
        ],
        lambda m: False,
        QUIET_S,
    )
    return statuses(got)


def publish_statuses(url: str, topic: str, type_name: str, msg: dict[str, Any]) -> str:
    """The statuses a bridge sends for advertising ``topic`` and publishing ``msg`` on it."""
    got = raw(
        url,
        [
            {"op": "advertise", "topic": topic, "type": type_name},
            {"op": "publish", "topic": topic, "msg": msg},
        ],
        lambda m: False,
        QUIET_S,
    )
    return statuses(got)


def wrong_field_type(url: str, label: str) -> str:
    return publish_statuses(url, f"/d_{label}/typed", "std_msgs/msg/String", {"data": 5})


def int_out_of_range(url: str, label: str) -> str:
    return publish_statuses(url, f"/d_{label}/int8", "std_msgs/msg/Int8", {"data": 300})


def service_bad_args(url: str, label: str) -> str:
    name = f"/d_{label}/badset"
    with node("serve", name, f"badserve_{label}"), client(url) as ros:
        discovered(ros, "services", name)
        got = raw(
            url,
            [
                {
                    "op": "call_service",
                    "id": "c",
                    "service": name,
                    "type": "std_srvs/srv/SetBool",
                    "args": {"data": "yes"},
                }
            ],
            lambda m: m.get("op") == "service_response",
            WAIT_S,
        )
    reply = [
        {k: m.get(k) for k in ("result", "values")}
        for m in got
        if m.get("op") == "service_response"
    ]
    return f"{reply} {statuses(got)}"


SCENARIOS: dict[str, Scenario] = {
    "topic ROS -> ws": topic_ros_to_ws,
    "topic ws -> ROS": topic_ws_to_ros,
    "transient-local, late subscriber": latched_late,
    "service ws calls ROS": service_ws_to_ros,
    "service ROS calls ws": service_ros_to_ws,
    "action goal, feedback, result, cancel": action_goal,
    "rosapi listings": rosapi_listings,
    "type not installed": missing_type,
    "wrong field type (publish)": wrong_field_type,
    "int out of range (publish)": int_out_of_range,
    "service call with wrong arg type": service_bad_args,
    # last: rosapi 2.1.0's set_param can stall it (docs/ros2.md)
    "parameters get/set/names": params,
}


def run_all(peer_url: str, rwt_url: str) -> dict[str, dict[str, str]]:
    """``{scenario: {"peer": summary, "rwt": summary}}`` (an exception is its summary)."""
    results: dict[str, dict[str, str]] = {}
    for title, scenario in SCENARIOS.items():
        row = {}
        for label, url in (("peer", peer_url), ("rwt", rwt_url)):
            try:
                row[label] = scenario(url, label)
            except Exception as exc:
                row[label] = f"raised {type(exc).__name__}: {str(exc)[:120]}"
        results[title] = row
        print(f"{title}: peer={row['peer']!r} rwt={row['rwt']!r}", file=sys.stderr, flush=True)
    return results


def table(results: dict[str, dict[str, str]]) -> str:
    """The results as a markdown table."""
    lines = ["| scenario | rosbridge_suite 2.1.0 | rwt --ros2 | same |", "|---|---|---|---|"]
    for title, row in results.items():
        # labels differ by bridge; compare with them neutralised
        same = row["peer"].replace("peer", "X") == row["rwt"].replace("rwt", "X")
        cells = [row[k].replace("|", "/") for k in ("peer", "rwt")]
        lines.append(f"| {title} | {cells[0]} | {cells[1]} | {'yes' if same else 'no'} |")
    return "\n".join(lines)


@contextlib.contextmanager
def rwt_server() -> Iterator[str]:
    """``rwt serve --ros2 --no-tf --port 0`` on the caller's domain; yields its URL."""
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "rwt",
            "serve",
            "--host",
            "127.0.0.1",
            "--ros2",
            "--no-tf",
            "--port",
            "0",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        env=ros_env(),
        text=True,
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        if "listening on" not in line:
            raise RuntimeError(f"rwt serve did not start: {line!r}")
        yield line.split("listening on", 1)[1].strip()
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)
        if proc.stdout is not None:
            proc.stdout.close()


def main(argv: list[str] | None = None) -> int:
    """Run every scenario on both bridges and print the table; 2 when no peer is given."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--peer-url", default=os.environ.get(PEER_ENV))
    parser.add_argument("--rwt-url", help="a running rwt serve --ros2 (default: start one)")
    parser.add_argument("--json", type=Path, help="also write the results here")
    args = parser.parse_args(argv)
    if not args.peer_url:
        print(f"no peer: set {PEER_ENV} or --peer-url", file=sys.stderr)
        return 2
    with contextlib.ExitStack() as stack:
        rwt_url = args.rwt_url or stack.enter_context(rwt_server())
        results = run_all(args.peer_url, rwt_url)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    print(table(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
