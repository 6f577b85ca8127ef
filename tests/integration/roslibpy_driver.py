"""Run one client scenario with the real, unmodified roslibpy against a rosbridge server.

Usage: python roslibpy_driver.py WS_URL SCENARIO.json

This is the roslibpy twin of tests/js/rosclient.mjs; both read the same scenario
format (see client_harness.py, which writes the files and reads the output):

    {"timeout_ms": 30000, "step_timeout_ms": 10000, "steps": [
        {"op": "connect", "conn": "sub"},
        {"op": "subscribe", "conn": "sub", "topic": "/chatter", "type": "std_msgs/String"},
        {"op": "subscribe", "conn": "sub", "topic": "/image", "compression": "png"},
        {"op": "sync", "conn": "sub"},
        {"op": "signal", "name": "ready"},
        {"op": "await"},
        {"op": "advertise", "conn": "pub", "topic": "/chatter", "type": "std_msgs/String"},
        {"op": "publish", "conn": "pub", "topic": "/chatter", "msgs": [{"data": "hi"}]},
        {"op": "unsubscribe", "conn": "sub", "topic": "/chatter"},
        {"op": "wait", "conn": "sub", "topic": "/chatter", "count": 1},
        {"op": "quiet", "ms": 300},
        {"op": "close", "conn": "pub"},
        {"op": "api", "conn": "sub", "call": "get_topics", "args": [], "as": "topics"},
        {"op": "api", "conn": "sub", "call": "get_time", "blocking": true, "as": "now"},
        {"op": "tf", "conn": "sub", "as": "tf", "client": "TFClient", "fixed_frame": "base_link",
         "frames": ["arm"], "angular_thres": 0.1, "trans_thres": 0.05, "rate": 10.0},
        {"op": "tf_wait", "as": "tf", "frame": "arm", "count": 3},
        {"op": "tf_dispose", "as": "tf"}]}

`sync` is a barrier: the connection publishes a token on its own sync topic and
waits until it receives it back, which proves that the server has processed every
op this connection sent before it. `signal` prints {"event": NAME}; `await` reads
one line from stdin (the test harness sends it). Stdout's last line is
{"result": {"received": {conn: {topic: [msg, ...]}}, "wire": {...},
"status_count": n, "statuses": []}}
where "received" is what the Topic.subscribe callback saw and "wire" is every
publish the connection got for that topic (a listener via Ros.on that is kept
after unsubscribe). "status_count" counts status frames, which roslibpy cannot
hand to user code (it logs "No handler registered for operation status" for each,
without saying on which connection), so "statuses" stays empty here.

`api` calls a method of the client's Ros object by name (roslibpy: `get_topics`,
`get_param`...; roslib: `getTopics`..., and `Param.get`/`Param.set`/`Param.delete`
with the parameter name as first argument) and records what it gave under
"calls": {AS: {"ok": value} or {"error": text}}. roslibpy methods get a callback
and an errback; with "blocking": true the method is called without them and its
return value is recorded (roslibpy's `get_time` builds its Time only then).

`tf` makes a TF client of the library (roslibpy: `TFClient`, which uses the
`/republish_tfs` service; roslib: `TFClient` (actionlib topics), `ROS2TFClient`
(the action), or `TFClient+service`: roslib's TFClient fed through its
`processResponse` from a `/republish_tfs` call, the service route older roslibjs
took in non-groovy mode) and subscribes to `frames`; every transform a frame's
callback gets is recorded under "tf": {AS: {frame: [{translation, rotation}]}}.
`tf_wait` waits for `count` transforms of a frame; `tf_dispose` disposes the client.

Services and actions (the result also carries "served", "feedback", "goal_ids"
and "order", see below):

    {"op": "advertise_service", "conn": "p", "service": "/add",
     "type": "example_interfaces/AddTwoInts", "reply": "add"},
    {"op": "call", "conn": "c", "as": "sum", "service": "/add",
     "type": "example_interfaces/AddTwoInts", "args": {"a": 1, "b": 2}, "wait": false},
    {"op": "wait_calls", "as": ["sum"]},
    {"op": "wait_served", "conn": "p", "service": "/add", "count": 1},
    {"op": "advertise_action", "conn": "p", "action": "/fib",
     "type": "example_interfaces/action/Fibonacci"},
    {"op": "send_goal", "conn": "c", "as": "g", "action": "/fib",
     "type": "example_interfaces/action/Fibonacci", "args": {"order": 5}, "wait": false},
    {"op": "wait_feedback", "as": "g", "count": 1},
    {"op": "cancel_goal", "conn": "c", "as": "g"}

`advertise_service` answers every request by the rule `reply` (serve_fixture.py
follows the same rules in process):
    set_bool  {success: data, message: "on" or "off"}      (std_srvs/SetBool)
    trigger   {success: true, message: "triggered"}        (std_srvs/Trigger)
    empty     {}                                           (std_srvs/Empty)
    add       {sum: a + b}                                 (AddTwoInts)
    scale     {points: each point times factor, note: "<n> points"}
              (rwt_test_interfaces/Scale, tests/integration/data)
    refuse    fails the call: roslib throws Error("refused") from advertiseAsync;
              roslibpy returns False (it cannot give a reason)
    hold      never answers (the test kills the provider); roslibpy blocks its
              reactor thread in the callback, since it answers when the callback returns
    gather    roslib only: holds requests until "count" wait, then answers them by
              the `add` rule, newest first (roslibpy answers inside its callback, so
              it cannot hold a request)
Each request the provider got is recorded under "served": {conn: {service: [args]}}.

`call` calls the client's Service with a callback and a failure callback and
records what they got under "calls": {AS: {"ok": values} or {"error": ...}};
the names of finished calls are appended to "order": {conn: [AS, ...]} as the
callbacks run. "wait": false returns at once (concurrent calls); `wait_calls`
waits for several. `wait_served` waits until a provider got `count` requests.

`advertise_action` (roslib only: roslibpy 2.x has no action server) serves
goals by the Fibonacci rules, also followed by serve_fixture.py: an order below 0
is aborted (setFailed); an order from 100 on sends one feedback {sequence: [0, 1]}
and waits for a cancel, then ends canceled with that sequence (setCanceled);
otherwise one feedback per new term, then succeeded with the sequence
(order 5: [0, 1, 1, 2, 3, 5]). Goals are recorded under "served" too.
`send_goal` records the result callback's value or the failure callback's
under "calls" (roslibpy: {"status": n, "values": result} from either callback),
each feedback under "feedback": {AS: [values]} and the id the client returned
under "goal_ids": {AS: id}. `cancel_goal` cancels it with the client's own method.

Exit codes: 0 done, 2 a step failed or timed out, 3 the whole scenario timed out,
64 bad usage. Every wait is bounded.
"""

from __future__ import annotations

import json
import logging
import os
import sys
import threading
import time
from collections import UserDict
from enum import Enum
from urllib.parse import urlsplit

import roslibpy
import roslibpy.tf


def _die(code: int, message: str) -> None:
    sys.stderr.write(f"roslibpy_driver: {message}\n")
    sys.stderr.flush()
    os._exit(code)


class _StatusCounter(logging.Handler):
    """Counts the status frames roslibpy refused ("No handler registered ...")."""

    def __init__(self, driver: Driver) -> None:
        super().__init__(level=logging.DEBUG)
        self.driver = driver

    def emit(self, record: logging.LogRecord) -> None:
        exc = record.exc_info[1] if record.exc_info else None
        if exc is not None and 'operation "status"' in str(exc):
            self.driver.count_status(record)


def _plain(value: object) -> object:
    """roslibpy's results (UserDicts such as Time) as plain JSON values."""
    if isinstance(value, UserDict):
        return {key: _plain(item) for key, item in value.data.items()}
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(item) for item in value]
    if isinstance(value, Enum):  # roslibpy's GoalStatus in action results
        return value.value
    return value


def _set_bool(request: dict) -> dict:
    return {"success": request["data"], "message": "on" if request["data"] else "off"}


def _scale(request: dict) -> dict:
    factor = request["factor"]
    points = [{"x": p["x"] * factor, "y": p["y"] * factor} for p in request["points"]]
    return {"points": points, "note": f"{len(points)} points"}


#: The `reply` rules of `advertise_service` that compute a response.
REPLIES = {
    "set_bool": _set_bool,
    "trigger": lambda request: {"success": True, "message": "triggered"},
    "empty": lambda request: {},
    "add": lambda request: {"sum": request["a"] + request["b"]},
    "scale": _scale,
}


class Conn:
    def __init__(self, name: str, ros: roslibpy.Ros) -> None:
        self.name = name
        self.ros = ros
        self.topics: dict[str, roslibpy.Topic] = {}
        self.received: dict[str, list] = {}
        self.wire: dict[str, list] = {}
        self.wire_listeners: dict[str, object] = {}
        self.closed = False
        self.sync_counter = 0
        self.sync_seen: set[str] = set()
        self.served: dict[str, list] = {}
        self.services: dict[str, roslibpy.Service] = {}


class Driver:
    def __init__(self, url: str, scenario: dict) -> None:
        parts = urlsplit(url)
        if parts.scheme not in ("ws", "wss") or parts.hostname is None or parts.port is None:
            _die(64, f"expected ws://HOST:PORT, got {url!r}")
        self.host = parts.hostname
        self.port = parts.port
        self.scenario = scenario
        self.step_timeout = scenario.get("step_timeout_ms", 10000) / 1000.0
        self.conns: dict[str, Conn] = {}
        self.cond = threading.Condition()
        self.current = "start"
        self.status_count = 0
        self.calls: dict[str, dict] = {}
        self.tf: dict[str, dict[str, list]] = {}
        self.tf_clients: dict[str, roslibpy.tf.TFClient] = {}
        self.order: dict[str, list[str]] = {}
        self.feedback: dict[str, list] = {}
        self.goals: dict[str, tuple[roslibpy.ActionClient, str]] = {}
        self.overall = scenario.get("timeout_ms", 30000) / 1000.0

    # -- bookkeeping, called from roslibpy's reactor thread -------------------
    def count_status(self, record: logging.LogRecord) -> None:
        # roslibpy does not say which connection the frame came on: count per process.
        with self.cond:
            self.status_count += 1
            self.cond.notify_all()

    def _record(self, store: dict[str, list], topic: str, msg: object) -> None:
        with self.cond:
            store.setdefault(topic, []).append(msg)
            self.cond.notify_all()

    def _until(self, predicate, what: str) -> None:
        deadline = time.monotonic() + self.step_timeout
        with self.cond:
            while not predicate():
                left = deadline - time.monotonic()
                if left <= 0:
                    _die(2, f"timed out after {self.step_timeout:.1f}s waiting for {what()}")
                self.cond.wait(left)

    # -- steps -----------------------------------------------------------------
    def conn(self, step: dict) -> Conn:
        name = step["conn"]
        if name not in self.conns:
            _die(2, f"step {self.current}: connection {name!r} was never opened")
        return self.conns[name]

    def topic(
        self,
        conn: Conn,
        name: str,
        msg_type: str | None,
        typeless: bool = False,
        compression: str | None = None,
    ) -> roslibpy.Topic:
        if name not in conn.topics:
            if msg_type is None and not typeless:
                _die(2, f"step {self.current}: topic {name} needs a type on first use")
            conn.topics[name] = roslibpy.Topic(conn.ros, name, msg_type, compression=compression)
        return conn.topics[name]

    def do_connect(self, step: dict) -> None:
        ros = roslibpy.Ros(self.host, self.port)
        try:
            ros.run(timeout=self.step_timeout)
        except roslibpy.core.RosTimeoutError:
            _die(2, f"could not connect {step['conn']!r} to ws://{self.host}:{self.port}")
        conn = Conn(step["conn"], ros)
        with self.cond:
            self.conns[conn.name] = conn

    def do_advertise(self, step: dict) -> None:
        conn = self.conn(step)
        self.topic(conn, step["topic"], step["type"]).advertise()

    def _add_wire_listener(self, conn: Conn, name: str) -> None:
        def on_wire(msg: object) -> None:
            self._record(conn.wire, name, msg)

        conn.wire_listeners[name] = on_wire
        conn.ros.on(name, on_wire)

    def do_subscribe(self, step: dict) -> None:
        conn = self.conn(step)
        name = step["topic"]
        conn.received.setdefault(name, [])
        conn.wire.setdefault(name, [])
        if name not in conn.wire_listeners:
            self._add_wire_listener(conn, name)

        def on_message(msg: object) -> None:
            self._record(conn.received, name, msg)

        # A subscribe step may leave the type out (the server knows the topic):
        # roslibpy then sends "type": null.
        # "compression" goes with the subscribe (roslibpy decodes cbor, not png ops).
        topic = self.topic(conn, name, step.get("type"), True, step.get("compression"))
        topic.subscribe(on_message)

    def do_unsubscribe(self, step: dict) -> None:
        conn = self.conn(step)
        name = step["topic"]
        conn.topics[name].unsubscribe()
        # Topic.unsubscribe() removes every listener of the topic's event, ours too:
        # put the wire listener back so that anything the server still sends shows.
        self._add_wire_listener(conn, name)

    def do_publish(self, step: dict) -> None:
        conn = self.conn(step)
        topic = self.topic(conn, step["topic"], step.get("type"))
        msgs = step["msgs"] if "msgs" in step else [step["msg"]]
        for msg in msgs:
            topic.publish(roslibpy.Message(msg))

    def do_sync(self, step: dict) -> None:
        conn = self.conn(step)
        name = f"/rwt_test_sync/{conn.name}"
        if name not in conn.topics:
            topic = roslibpy.Topic(conn.ros, name, "std_msgs/String")
            conn.topics[name] = topic

            def on_sync(msg: dict) -> None:
                with self.cond:
                    conn.sync_seen.add(msg.get("data"))
                    self.cond.notify_all()

            topic.subscribe(on_sync)
            topic.advertise()
        conn.sync_counter += 1
        token = f"{conn.name}:{os.getpid()}:{conn.sync_counter}"
        conn.topics[name].publish(roslibpy.Message({"data": token}))
        self._until(
            lambda: token in conn.sync_seen,
            lambda: f"sync token {token} to come back on {name} ({conn.name})",
        )

    def do_wait(self, step: dict) -> None:
        conn = self.conn(step)
        name, count = step["topic"], step["count"]
        self._until(
            lambda: len(conn.received.get(name, [])) >= count,
            lambda: (
                f"{count} messages on {name} at {conn.name} "
                f"(got {len(conn.received.get(name, []))})"
            ),
        )

    def do_api(self, step: dict) -> None:
        conn = self.conn(step)
        method = getattr(conn.ros, step["call"])
        args = step.get("args", [])
        if step.get("blocking"):
            try:
                value = method(*args)
            except Exception as exc:
                self.calls[step["as"]] = {"error": f"{type(exc).__name__}: {exc}"}
            else:
                self.calls[step["as"]] = {"ok": _plain(value)}
            return
        done = threading.Event()

        def ok(value: object = None) -> None:
            self.calls[step["as"]] = {"ok": _plain(value)}
            done.set()

        def failed(error: object) -> None:
            self.calls[step["as"]] = {"error": str(error)}
            done.set()

        method(*args, callback=ok, errback=failed)
        if not done.wait(self.step_timeout):
            _die(2, f"timed out after {self.step_timeout:.1f}s waiting for {step['call']}")

    def do_tf(self, step: dict) -> None:
        conn = self.conn(step)
        if step["client"] != "TFClient":
            _die(64, f"roslibpy has no TF client {step['client']!r}")
        client = roslibpy.tf.TFClient(
            conn.ros,
            fixed_frame=step["fixed_frame"],
            angular_threshold=step["angular_thres"],
            translation_threshold=step["trans_thres"],
            rate=step["rate"],
        )
        got: dict[str, list] = {frame: [] for frame in step["frames"]}
        with self.cond:
            self.tf[step["as"]] = got
            self.tf_clients[step["as"]] = client
        for frame in step["frames"]:

            def on_transform(transform: dict, frame: str = frame) -> None:
                self._record(got, frame, _plain(transform))

            client.subscribe(frame, on_transform)

    def do_tf_wait(self, step: dict) -> None:
        got, frame, count = self.tf[step["as"]], step["frame"], step["count"]
        self._until(
            lambda: len(got[frame]) >= count,
            lambda: f"{count} transforms of {frame} ({step['as']}, got {len(got[frame])})",
        )

    def do_tf_dispose(self, step: dict) -> None:
        self.tf_clients[step["as"]].dispose()

    # -- services and actions --------------------------------------------------------
    def _finish(self, conn: Conn, name: str, outcome: dict) -> None:
        with self.cond:
            self.calls[name] = outcome
            self.order.setdefault(conn.name, []).append(name)
            self.cond.notify_all()

    def do_advertise_service(self, step: dict) -> None:
        conn = self.conn(step)
        name, reply = step["service"], step["reply"]
        if reply == "gather":
            _die(64, "roslibpy answers when Service.advertise's callback returns: no 'gather'")
        if reply not in REPLIES and reply not in ("refuse", "hold"):
            _die(64, f"unknown reply rule {reply!r}")
        conn.served.setdefault(name, [])

        def handler(request: dict, response: roslibpy.ServiceResponse) -> bool:
            self._record(conn.served, name, _plain(request))
            if reply == "hold":
                # roslibpy sends the response when this returns: block its reactor
                # thread until the test kills this process (bounded by the scenario).
                threading.Event().wait(self.overall)
                return False
            if reply == "refuse":
                return False
            response.update(REPLIES[reply](request))
            return True

        service = roslibpy.Service(conn.ros, name, step["type"])
        service.advertise(handler)
        conn.services[name] = service

    def do_call(self, step: dict) -> None:
        conn = self.conn(step)
        name = step["as"]
        service = roslibpy.Service(conn.ros, step["service"], step["type"])
        service.call(
            roslibpy.ServiceRequest(step.get("args", {})),
            callback=lambda response: self._finish(conn, name, {"ok": _plain(response)}),
            errback=lambda error: self._finish(conn, name, {"error": _plain(error)}),
        )
        if step.get("wait", True):
            self._wait_calls([name])

    def _wait_calls(self, names: list[str]) -> None:
        self._until(
            lambda: all(name in self.calls for name in names),
            lambda: f"{[n for n in names if n not in self.calls]} to end",
        )

    def do_wait_calls(self, step: dict) -> None:
        self._wait_calls(step["as"])

    def do_wait_served(self, step: dict) -> None:
        conn = self.conn(step)
        name, count = step["service"], step["count"]
        self._until(
            lambda: len(conn.served.get(name, [])) >= count,
            lambda: f"{count} requests for {name} at {conn.name}",
        )

    def do_advertise_action(self, step: dict) -> None:
        # Its protocol answers send_action_goal with "Action server capabilities
        # not yet implemented".
        _die(64, "roslibpy 2.x has no action server")

    def do_send_goal(self, step: dict) -> None:
        conn = self.conn(step)
        name = step["as"]
        client = roslibpy.ActionClient(conn.ros, step["action"], step["type"])
        with self.cond:
            self.feedback[name] = []
        goal_id = client.send_goal(
            roslibpy.Goal(step["args"]),
            lambda result: self._finish(conn, name, {"ok": _plain(result)}),
            lambda feedback: self._record(self.feedback, name, _plain(feedback)),
            lambda error: self._finish(conn, name, {"error": _plain(error)}),
        )
        self.goals[name] = (client, goal_id)
        if step.get("wait", True):
            self._wait_calls([name])

    def do_wait_feedback(self, step: dict) -> None:
        name, count = step["as"], step["count"]
        self._until(
            lambda: len(self.feedback.get(name, [])) >= count,
            lambda: f"{count} feedback messages for {name}",
        )

    def do_cancel_goal(self, step: dict) -> None:
        client, goal_id = self.goals[step["as"]]
        client.cancel_goal(goal_id)

    def do_quiet(self, step: dict) -> None:
        # A bounded window for negative assertions ("nothing more arrives").
        time.sleep(step["ms"] / 1000.0)

    def do_signal(self, step: dict) -> None:
        print(json.dumps({"event": step["name"]}), flush=True)

    def do_await(self, step: dict) -> None:
        line = sys.stdin.readline()
        if not line:
            _die(2, "stdin closed while awaiting the go-ahead")

    def do_close(self, step: dict) -> None:
        conn = self.conn(step)
        conn.ros.close(timeout=self.step_timeout)
        conn.closed = True

    # -- main --------------------------------------------------------------------
    def run(self) -> dict:
        for index, step in enumerate(self.scenario["steps"]):
            self.current = f"#{index} {json.dumps(step)[:200]}"
            handler = getattr(self, "do_" + step["op"], None)
            if handler is None:
                _die(64, f"unknown step op {step['op']!r}")
            handler(step)
        with self.cond:
            return {
                "received": {c.name: c.received for c in self.conns.values()},
                "wire": {c.name: c.wire for c in self.conns.values()},
                "status_count": self.status_count,
                "statuses": [],
                "calls": self.calls,
                "tf": self.tf,
                "served": {c.name: c.served for c in self.conns.values()},
                "feedback": self.feedback,
                "goal_ids": {name: goal_id for name, (_, goal_id) in self.goals.items()},
                "order": self.order,
            }

    def shutdown(self) -> None:
        for conn in self.conns.values():
            if conn.closed:
                continue
            try:
                conn.ros.close(timeout=2)
            except Exception as exc:  # best effort: the result is already out
                sys.stderr.write(f"roslibpy_driver: close {conn.name}: {exc!r}\n")


def main(argv: list[str]) -> None:
    if len(argv) != 3:
        _die(64, "usage: roslibpy_driver.py WS_URL SCENARIO.json")
    with open(argv[2], encoding="utf-8") as f:
        scenario = json.load(f)
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr)
    driver = Driver(argv[1], scenario)
    logging.getLogger("roslibpy").addHandler(_StatusCounter(driver))

    overall = scenario.get("timeout_ms", 30000) / 1000.0

    def on_timeout() -> None:
        _die(3, f"scenario timed out after {overall:.1f}s at step {driver.current}")

    watchdog = threading.Timer(overall, on_timeout)
    watchdog.daemon = True
    watchdog.start()

    result = driver.run()
    sys.stdout.write(json.dumps({"result": result}) + "\n")
    sys.stdout.flush()
    driver.shutdown()
    # The twisted reactor runs in a daemon thread; leave without waiting for it.
    sys.stderr.flush()
    os._exit(0)


if __name__ == "__main__":
    main(sys.argv)
