"""A real rclpy node for the ROS 2 link's tests, in its own process.

Usage: python peer.py MODE NAME [NODE]   (the environment carries ROS_DOMAIN_ID etc.)

The node is NODE, else ``peer_MODE`` (``params`` and ``many_params`` name it NAME).

Modes (each prints ``ready`` once its entities exist, then JSON lines):
  talk TOPIC            std_msgs/String "n" every 50 ms, forever
  listen TOPIC          prints {"heard": data} for each std_msgs/String
  latched TOPIC [NODE]  one transient-local std_msgs/String "latched" ("latched by NODE"
                        when named), then idles
  image TOPIC           sensor_msgs/Image 8x4 rgb8 (a red left half) every 50 ms
  camodom TOPIC         sensor_msgs/Image of 100 KB (mono8 320x320) on TOPIC every 10 ms
                        and std_msgs/String "n" (a count) on /odom every 20 ms
  clock TOPIC           rosgraph_msgs/Clock as a simulator publishes /clock: from 1000 s,
                        0.05 s more every 50 ms
  joints TOPIC          sensor_msgs/JointState (name ["a"], position [1.5]) every 50 ms
  garbage TOPIC         raw bytes that are no std_msgs/String CDR, every 50 ms
  mixed TOPIC           every 50 ms a burst of ten raw samples, std_msgs/String "g0", "g1"...
                        (counting on) each followed by bytes that are no String CDR
  point_raw TOPIC       geometry_msgs/PointStamped published as serialized CDR every 50 ms,
                        its one alignment padding byte set to 0xAB (rclpy's own serializer
                        leaves it uninitialised): header stamp 7 s, frame "ab", (1, -2, 0.5)
  count TOPIC           a reliable std_msgs/String subscription of depth 1000; prints
                        {"count": n, "warm": w, "ordered": o} every 100 ms while they
                        change: n messages, w whose data is "warm", and o: every other
                        message's data started with its number, 0, 1, 2... in turn
  serve SERVICE         a std_srvs/SetBool server: message "ros2 got <data>"
  call SERVICE          calls std_srvs/SetBool {data: true} once the server is there;
                        prints {"response": {...}} or {"error": ...}
  call_many SERVICE [N] N (10) std_srvs/SetBool calls, 10 ms apart; prints {"answered": n} each
                        time one more is answered, then {"responses": [...]} when all are
  fibonacci ACTION      a test_msgs/Fibonacci action server: feedback per step (50 ms
                        each), honours cancels; prints {"goal": order} per goal
  send_goal ACTION      a test_msgs/Fibonacci action client: order 4 once the server is
                        there; prints {"feedback": seq} each, then {"result": seq, "status": n}
  params NODE_NAME      a node named NODE_NAME declaring speed=1.5 and mode="auto";
                        prints {"speed": value} whenever speed changes
  guarded_params NODE_NAME  a node named NODE_NAME declaring speed=2.5, a read-only
                        model="x1" and limit=1.0, whose set-parameters callback
                        refuses a negative limit ("limit must not be negative")
  byte_params NODE_NAME  a node named NODE_NAME declaring the byte array key=00 01 ff;
                        prints {"key": hex} of its value as the node reads it
                        (get_parameter), at the start and whenever it changes
  read_params NODE      prints {"values": {name: value}} of NODE's speed, model and limit,
                        read once through its get_parameters service
  many_params NODE_NAME N  a node named NODE_NAME declaring N integer parameters
                        p00000, p00001, ... (value n); sets p00000 to a count going
                        up every 50 ms, so each refresh of a copy sees a new value
  param_client NODE     reads NODE's "gain" through its get_parameters service once it
                        is there, prints {"gain": value}, then sets it to 7 and prints
                        {"set": successful}
  param_suite NODE      calls NODE's describe_parameters and get_parameter_types on
                        volume, style and nope, prints {"described": [[name, type,
                        read_only, dynamic_typing], ...]} and {"types": [...]}; then
                        two set_parameters_atomically: style "manual", volume 0.5 and
                        the deletion of nope (not set), and volume 7.0 with the
                        deletion of spare; prints {"atomic": [[successful, reason], ...]}
  many_topics N         std_msgs/String publishers on /many/t000 ... (N of them), then idles
  log MESSAGE           logs MESSAGE at info level every 100 ms (to /rosout)
  tf_static TOPIC       one tf2_msgs/TFMessage as tf2's static broadcaster sends it
                        (transient local, depth 1): base_link -> camera at (0.1, 0, 0.3)
  tf TOPIC              tf2_msgs/TFMessage as tf2's broadcaster (volatile, depth 100)
                        every 50 ms: odom -> base_link at (0.01 n, 0, 0), turned 90 deg
                        about z, stamped now
  tf_echo TOPIC         prints {"frames": [[parent, child], ...]} for each tf2_msgs/TFMessage
  qos_info TOPIC        prints {"publishers": [...], "subscriptions": [...]} of TOPIC's endpoints
                        of other nodes whenever they change, each {node, reliability,
                        durability, history, depth, deadline_ns, lifespan_ns} as rclpy's
                        get_publishers_info_by_topic / get_subscriptions_info_by_topic tell
  durable_listen TOPIC  a reliable transient-local std_msgs/String subscription of depth 5;
                        prints {"heard": data} for each
  (the tf modes need tf2_msgs for rclpy: python -m rwt_ros2.build, test_tf.py)
Bounded: every mode exits after 60 s.
"""

from __future__ import annotations

import json
import sys
import time

import rclpy
from builtin_interfaces.msg import Time
from rcl_interfaces.msg import (
    Parameter,
    ParameterDescriptor,
    ParameterValue,
    SetParametersResult,
)
from rcl_interfaces.srv import (
    DescribeParameters,
    GetParameters,
    GetParameterTypes,
    SetParameters,
    SetParametersAtomically,
)
from rclpy.action import ActionClient, ActionServer, CancelResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.parameter import Parameter as RclpyParameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import String
from std_srvs.srv import SetBool
from test_msgs.action import Fibonacci

LIFETIME_S = 60.0


def say(**fields: object) -> None:
    print(json.dumps(fields), flush=True)


def main() -> None:
    mode, name = sys.argv[1], sys.argv[2]
    rclpy.init()
    default = (
        name
        if mode in ("params", "guarded_params", "many_params", "byte_params")
        else f"peer_{mode}"
    )
    named = len(sys.argv) > 3 and mode not in ("call_many", "many_params")  # a count
    node = rclpy.create_node(sys.argv[3] if named else default)
    tick = None
    if mode == "talk":
        pub = node.create_publisher(String, name, 10)
        count = iter(range(10**9))
        tick = lambda: pub.publish(String(data=str(next(count))))  # noqa: E731
    elif mode == "listen":
        node.create_subscription(String, name, lambda m: say(heard=m.data), 10)
    elif mode == "count":
        heard = {"count": 0, "warm": 0, "ordered": True}
        deep = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)

        def count(message):
            if message.data == "warm":
                heard["warm"] += 1
                return
            if message.data.split(" ", 1)[0] != str(heard["count"]):
                heard["ordered"] = False
            heard["count"] += 1

        node.create_subscription(String, name, count, deep)
        told = dict(heard)

        def report():
            if heard != told:
                told.update(heard)
                say(**heard)

        node.create_timer(0.1, report)
    elif mode == "latched":
        qos = QoSProfile(
            depth=1,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
            reliability=ReliabilityPolicy.RELIABLE,
        )
        data = f"latched by {sys.argv[3]}" if named else "latched"
        node.create_publisher(String, name, qos).publish(String(data=data))
    elif mode == "joints":
        pub = node.create_publisher(JointState, name, 10)
        tick = lambda: pub.publish(JointState(name=["a"], position=[1.5]))  # noqa: E731
    elif mode == "image":
        pub = node.create_publisher(Image, name, 10)
        row = bytes([255, 0, 0] * 4 + [0, 0, 255] * 4)
        frame = Image(height=4, width=8, encoding="rgb8", step=24, data=row * 4)
        tick = lambda: pub.publish(frame)  # noqa: E731
    elif mode == "camodom":
        cam = node.create_publisher(Image, name, 10)
        odom = node.create_publisher(String, "/odom", 10)
        image = Image(height=320, width=320, encoding="mono8", step=320, data=bytes(320 * 320))
        count = iter(range(10**9))
        node.create_timer(0.01, lambda: cam.publish(image))
        node.create_timer(0.02, lambda: odom.publish(String(data=str(next(count)))))
    elif mode == "garbage":
        pub = node.create_publisher(String, name, 10)
        tick = lambda: pub.publish(b"\x00\x01\x00\x00\xff\xff\xff\x7fgarbage")  # noqa: E731
    elif mode == "mixed":
        from rclpy.serialization import serialize_message  # noqa: PLC0415

        pub = node.create_publisher(String, name, 100)
        goods = (serialize_message(String(data=f"g{n}")) for n in range(10**9))

        def burst() -> None:
            for _ in range(5):
                pub.publish(next(goods))
                pub.publish(b"\x00\x01\x00\x00\xff\xff\xff\x7fgarbage")

        tick = burst
    elif mode == "point_raw":
        from geometry_msgs.msg import PointStamped  # noqa: PLC0415
        from rclpy.serialization import serialize_message  # noqa: PLC0415

        point = PointStamped()
        point.header.stamp.sec, point.header.frame_id = 7, "ab"
        point.point.x, point.point.y, point.point.z = 1.0, -2.0, 0.5
        cdr = bytearray(serialize_message(point))
        cdr[4 + 15] = 0xAB  # after sec, nanosec, the frame id's length and "ab\0"
        pub = node.create_publisher(PointStamped, name, 10)
        tick = lambda: pub.publish(bytes(cdr))  # noqa: E731
    elif mode == "serve":

        def answer(request, response):
            response.success = True
            response.message = f"ros2 got {request.data}"
            return response

        node.create_service(SetBool, name, answer)
    elif mode == "call":
        client = node.create_client(SetBool, name)
        say(ready=True)
        if not client.wait_for_service(timeout_sec=20):
            say(error="no service")
            return
        # wait_for_service sees the server from this side; the server's response writer
        # may not have matched this client yet, and a response sent before it has is lost
        # (DDS discovery is not symmetric): a moment's spin lets it match
        rclpy.spin_once(node, timeout_sec=0.5)
        time.sleep(0.5)
        future = client.call_async(SetBool.Request(data=True))
        rclpy.spin_until_future_complete(node, future, timeout_sec=20)
        if future.done():
            r = future.result()
            say(response={"success": r.success, "message": r.message})
        else:
            say(error="no response")
        return
    elif mode == "call_many":
        # kept last 100, not 10: the responses of calls failed at once come in a burst
        client = node.create_client(SetBool, name, qos_profile=QoSProfile(depth=100))
        say(ready=True)
        if not client.wait_for_service(timeout_sec=20):
            say(error="no service")
            return
        count = int(sys.argv[3]) if len(sys.argv) > 3 else 10
        futures = []
        end, answered = time.monotonic() + LIFETIME_S, 0
        while time.monotonic() < end and answered < count:
            if len(futures) < count:
                # one every 10 ms: a service's requests are kept last 10 (rmw's default
                # depth), so a burst of more than 10 would lose some in DDS
                futures.append(client.call_async(SetBool.Request(data=True)))
            rclpy.spin_once(node, timeout_sec=0.01 if len(futures) < count else 0.05)
            done = sum(f.done() for f in futures)
            if done > answered:
                answered = done
                say(answered=answered)
        say(responses=[[f.result().success, f.result().message] for f in futures if f.done()])
        return
    elif mode == "fibonacci":

        def execute(handle):
            say(goal=handle.request.order)
            sequence = [0, 1]
            for _ in range(1, handle.request.order):
                if handle.is_cancel_requested:
                    handle.canceled()
                    return Fibonacci.Result(sequence=sequence)
                sequence.append(sequence[-1] + sequence[-2])
                handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
                time.sleep(0.05)
            handle.succeed()
            return Fibonacci.Result(sequence=sequence)

        ActionServer(
            node,
            Fibonacci,
            name,
            execute,
            cancel_callback=lambda _: CancelResponse.ACCEPT,
            callback_group=ReentrantCallbackGroup(),
        )
        say(ready=True)
        executor = MultiThreadedExecutor()
        executor.add_node(node)
        end = time.monotonic() + LIFETIME_S
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        return
    elif mode == "send_goal":
        client = ActionClient(node, Fibonacci, name)
        say(ready=True)
        if not client.wait_for_server(timeout_sec=20):
            say(error="no action server")
            return
        feedback = lambda m: say(feedback=list(m.feedback.sequence))  # noqa: E731
        sent = client.send_goal_async(Fibonacci.Goal(order=4), feedback_callback=feedback)
        rclpy.spin_until_future_complete(node, sent, timeout_sec=20)
        if not sent.done() or not sent.result().accepted:
            say(error="goal not accepted")
            return
        result = sent.result().get_result_async()
        rclpy.spin_until_future_complete(node, result, timeout_sec=20)
        if not result.done():
            say(error="no result")
            return
        say(result=list(result.result().result.sequence), status=result.result().status)
        return
    elif mode == "params":
        node.declare_parameter("speed", 1.5)
        node.declare_parameter("mode", "auto")

        def changed(params):

            for param in params:
                if param.name == "speed":
                    say(speed=param.value)
            return SetParametersResult(successful=True)

        node.add_on_set_parameters_callback(changed)
    elif mode == "guarded_params":
        node.declare_parameter("speed", 2.5)
        node.declare_parameter("model", "x1", ParameterDescriptor(read_only=True))
        node.declare_parameter("limit", 1.0)

        def guard(params):
            if any(p.name == "limit" and p.value < 0 for p in params):
                return SetParametersResult(successful=False, reason="limit must not be negative")
            return SetParametersResult(successful=True)

        node.add_on_set_parameters_callback(guard)
    elif mode == "byte_params":
        node.declare_parameter("key", [b"\x00", b"\x01", b"\xff"])  # rclpy's form: single bytes
        shown = [None]

        def show_key():
            key = b"".join(node.get_parameter("key").value).hex()
            if key != shown[0]:
                shown[0] = key
                say(key=key)

        tick = show_key
    elif mode == "read_params":
        read_params(node, name)
        return
    elif mode == "many_params":
        count = int(sys.argv[3])
        node.declare_parameters("", [(f"p{n:05}", n) for n in range(count)])
        ticks = iter(range(count, 10**9))
        tick = lambda: node.set_parameters([RclpyParameter("p00000", value=next(ticks))])  # noqa: E731
    elif mode == "param_client":
        get = node.create_client(GetParameters, f"{name}/get_parameters")
        put = node.create_client(SetParameters, f"{name}/set_parameters")
        say(ready=True)
        if not get.wait_for_service(timeout_sec=20) or not put.wait_for_service(timeout_sec=20):
            say(error="no parameter services")
            return
        future = get.call_async(GetParameters.Request(names=["gain"]))
        rclpy.spin_until_future_complete(node, future, timeout_sec=20)
        say(gain=future.result().values[0].double_value)
        seven = Parameter(name="gain", value=ParameterValue(type=3, double_value=7.0))
        future = put.call_async(SetParameters.Request(parameters=[seven]))
        rclpy.spin_until_future_complete(node, future, timeout_sec=20)
        say(set=future.result().results[0].successful)
        return
    elif mode == "param_suite":
        param_suite(node, name)
        return
    elif mode == "many_topics":
        for n in range(int(name)):
            node.create_publisher(String, f"/many/t{n:03}", 10)
    elif mode == "clock":
        clock_pub = node.create_publisher(Clock, name, 10)
        steps = iter(range(10**9))

        def tick_clock():
            ns = 1000 * 10**9 + next(steps) * 50_000_000
            clock_pub.publish(Clock(clock=Time(sec=ns // 10**9, nanosec=ns % 10**9)))

        tick = tick_clock
    elif mode == "log":
        tick = lambda: node.get_logger().info(name)  # noqa: E731
    elif mode == "qos_info":
        tick = qos_reporter(node, name)
    elif mode == "durable_listen":
        durable = QoSProfile(
            depth=5,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        node.create_subscription(String, name, lambda m: say(heard=m.data), durable)
    elif mode in ("tf", "tf_static"):
        tick = tf_broadcaster(node, name, static=mode == "tf_static")
    elif mode == "tf_echo":
        from tf2_msgs.msg import TFMessage  # noqa: PLC0415 (tf2_msgs: as tf_broadcaster)

        def frames(message):
            say(frames=[[t.header.frame_id, t.child_frame_id] for t in message.transforms])

        node.create_subscription(TFMessage, name, frames, 100)
    else:
        raise SystemExit(f"unknown mode {mode}")
    say(ready=True)
    end = time.monotonic() + LIFETIME_S
    while time.monotonic() < end:
        if tick is not None:
            tick()
        rclpy.spin_once(node, timeout_sec=0.05)


def qos_reporter(node, topic):
    """A tick printing the QoS of ``topic``'s endpoints of other nodes when it changes."""
    told = {}

    def describe(info):
        qos = info.qos_profile
        return {
            "node": info.node_name,
            "gid": bytes(info.endpoint_gid).hex(),  # a new endpoint is a new gid
            "reliability": qos.reliability.name,
            "durability": qos.durability.name,
            "history": qos.history.name,
            "depth": qos.depth,
            "deadline_ns": qos.deadline.nanoseconds,
            "lifespan_ns": qos.lifespan.nanoseconds,
        }

    def tick():
        seen = {
            "publishers": [describe(i) for i in node.get_publishers_info_by_topic(topic)],
            "subscriptions": [describe(i) for i in node.get_subscriptions_info_by_topic(topic)],
        }
        for endpoints in seen.values():
            endpoints[:] = [e for e in endpoints if e["node"] != node.get_name()]
        if seen != told:
            told.clear()
            told.update(seen)
            say(**seen)

    return tick


def read_params(node, target):
    get = node.create_client(GetParameters, f"{target}/get_parameters")
    if not get.wait_for_service(timeout_sec=20):
        say(error="no get_parameters")
        return
    say(ready=True)
    names = ["speed", "model", "limit"]
    future = get.call_async(GetParameters.Request(names=names))
    rclpy.spin_until_future_complete(node, future, timeout_sec=20)
    values = future.result().values
    read = [v.double_value if v.type == 3 else v.string_value for v in values]
    say(values=dict(zip(names, read, strict=True)))


def tf_broadcaster(node, topic, *, static):
    """Publish as tf2's (static) transform broadcaster does; the tick for /tf, else None."""
    # here, not at the top: only these modes need tf2_msgs (rwt_ros2.interfaces builds it)
    from geometry_msgs.msg import TransformStamped  # noqa: PLC0415
    from tf2_msgs.msg import TFMessage  # noqa: PLC0415

    def link(parent, child, x, y, z, turn_z):
        t = TransformStamped(child_frame_id=child)
        t.header.frame_id = parent
        t.header.stamp = node.get_clock().now().to_msg()
        t.transform.translation.x, t.transform.translation.y = x, y
        t.transform.translation.z = z
        t.transform.rotation.z, t.transform.rotation.w = turn_z, (1 - turn_z**2) ** 0.5
        return t

    if static:
        kept = QoSProfile(
            depth=1,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
            reliability=ReliabilityPolicy.RELIABLE,
        )
        pub = node.create_publisher(TFMessage, topic, kept)
        pub.publish(TFMessage(transforms=[link("base_link", "camera", 0.1, 0.0, 0.3, 0.0)]))
        return None
    pub = node.create_publisher(TFMessage, topic, QoSProfile(depth=100))
    count = iter(range(10**9))
    quarter = 0.5**0.5  # sin(45 deg): a 90 deg turn about z

    def tick():
        moved = link("odom", "base_link", 0.01 * next(count), 0.0, 0.0, quarter)
        pub.publish(TFMessage(transforms=[moved]))

    return tick


def param_suite(node, target):
    describe = node.create_client(DescribeParameters, f"{target}/describe_parameters")
    types = node.create_client(GetParameterTypes, f"{target}/get_parameter_types")
    atomic = node.create_client(SetParametersAtomically, f"{target}/set_parameters_atomically")
    say(ready=True)
    if not all(c.wait_for_service(timeout_sec=20) for c in (describe, types, atomic)):
        say(error="no parameter services")
        return

    def ask(client, request):
        future = client.call_async(request)
        rclpy.spin_until_future_complete(node, future, timeout_sec=20)
        return future.result()

    names = ["volume", "style", "nope"]
    found = ask(describe, DescribeParameters.Request(names=names)).descriptors
    say(described=[[d.name, d.type, d.read_only, d.dynamic_typing] for d in found])
    say(types=list(ask(types, GetParameterTypes.Request(names=names)).types))

    def param(name, **value):
        return Parameter(name=name, value=ParameterValue(**value))

    unset = {"type": 0}
    refused = [
        param("style", type=4, string_value="manual"),
        param("volume", type=3, double_value=0.5),
    ]
    changes = [
        [*refused, param("nope", **unset)],
        [param("volume", type=3, double_value=7.0), param("spare", **unset)],
    ]
    results = [ask(atomic, SetParametersAtomically.Request(parameters=c)).result for c in changes]
    say(atomic=[[r.successful, r.reason] for r in results])


if __name__ == "__main__":
    main()
