"""Fig. 3 (paper IV.A): TF bandwidth of a web client on raw ``/tf`` vs through the republisher.

The paper captured one minute of a mobile robot with a 6-DOF arm and 52 frames,
teleoperated so that base and arm moved, with tf2_web_republisher at 10 Hz and
0.01 m / 0.01 rad thresholds: 208.5 KB/s (sigma 1.5) for a ROS TF subscriber,
96.0 KB/s (sigma 40.6) for the web client, 54 % less.

Here the same kind of robot runs in simulated time (no sleeping, deterministic):
52 transforms published together on ``/tf`` at 10 Hz (fixed joints too, as the
paper's robot_state_publisher did), 13 of them moving (base, 4 wheels, 6 arm
joints, 2 fingers) along a fixed trace: idle, arm only, base only, both, idle.
In the same run one client subscribes to ``/tf`` and ten ``ROS2TFClient``-style
clients send the ``/tf2_web_republisher`` goal for all 52 frames in ``map``; the
bytes are those of the JSON frames rwt queues for the first of them. The raw
client's bytes are JSON too, where the paper's ROS subscriber got binary ROS
messages, so compare reductions more than absolute rates.
"""

from __future__ import annotations

import json
import math
import statistics
import time
from dataclasses import dataclass, field

import anyio

from rwt_graph.graph import Graph
from rwt_graph.tf import install_tf_republisher
from rwt_protocol.server.session import Session
from rwt_transports.server import running_handlers

__all__ = ["FRAMES", "run"]

FIGURE = "Fig. 3"
RATE_HZ = 10.0
EPOCH = 1_700_000_000.0
CLIENTS = 10

#: (parent, child, joint): joint "fixed", "base", "wheel", "arm<i>" or "finger<side>".
FRAMES: list[tuple[str, str, str]] = [
    ("map", "odom", "fixed"),
    ("odom", "base_footprint", "base"),
    ("base_footprint", "base_link", "fixed"),
    *[("base_link", f"{w}_wheel", "wheel") for w in ("front_left", "front_right")],
    *[("base_link", f"{w}_wheel", "wheel") for w in ("rear_left", "rear_right")],
    *[("base_link", name, "fixed") for name in ("laser", "imu", "gps", "torso")],
    *[("base_link", f"sonar_{i}", "fixed") for i in range(8)],
    *[("base_link", f"cliff_{i}", "fixed") for i in range(4)],
    *[
        ("base_link", name, "fixed")
        for name in (
            *("bumper_front", "bumper_rear", "caster_link", "antenna_link"),
            *("microphone_array", "led_ring", "charging_contacts", "emergency_stop"),
            "rear_camera",
        )
    ],
    ("torso", "mast", "fixed"),
    ("mast", "camera_link", "fixed"),
    ("camera_link", "camera_rgb_frame", "fixed"),
    ("camera_rgb_frame", "camera_rgb_optical_frame", "fixed"),
    ("camera_link", "camera_depth_frame", "fixed"),
    ("camera_depth_frame", "camera_depth_optical_frame", "fixed"),
    ("torso", "arm_mount", "fixed"),
    ("arm_mount", "shoulder_pan_link", "arm0"),
    ("shoulder_pan_link", "shoulder_lift_link", "arm1"),
    ("shoulder_lift_link", "upper_arm_link", "fixed"),
    ("upper_arm_link", "elbow_link", "arm2"),
    ("elbow_link", "forearm_link", "fixed"),
    ("forearm_link", "wrist_1_link", "arm3"),
    ("wrist_1_link", "wrist_2_link", "arm4"),
    ("wrist_2_link", "wrist_3_link", "arm5"),
    ("wrist_3_link", "gripper_base", "fixed"),
    ("gripper_base", "left_finger", "finger1"),
    ("gripper_base", "right_finger", "finger-1"),
    ("gripper_base", "tool_frame", "fixed"),
    ("gripper_base", "gripper_camera", "fixed"),
]
assert len(FRAMES) == 52 and sum(j != "fixed" for _, _, j in FRAMES) == 13


class _Clock:
    """Simulated time: the benchmark sets ``t`` (seconds since the start)."""

    def __init__(self) -> None:
        self.t = 0.0

    def monotonic(self) -> float:
        return self.t

    def wall(self) -> float:
        return EPOCH + self.t


class _Ticks:
    """The republisher's sleep, ended by the benchmark once per simulated tick."""

    def __init__(self) -> None:
        self._events: list[anyio.Event] = []

    async def sleep(self, seconds: float) -> None:
        event = anyio.Event()
        self._events.append(event)
        await event.wait()

    async def tick(self) -> None:
        events, self._events = self._events, []
        for event in events:
            event.set()
        await anyio.wait_all_tasks_blocked()


@dataclass
class _Trace:
    """The motion: which joints move when, integrated tick by tick (deterministic)."""

    duration_s: float
    arm_s: float = 0.0
    x: float = 0.0
    y: float = 0.0
    heading: float = 0.0
    wheel: dict[str, float] = field(default_factory=dict)

    def phase(self, t: float) -> tuple[bool, bool]:
        """(arm moves, base drives) at ``t``: idle, arm, base, both, idle."""
        f = t / self.duration_s
        return (1 / 6 <= f < 5 / 12 or 2 / 3 <= f < 5 / 6, 5 / 12 <= f < 5 / 6)

    def step(self, t: float, dt: float) -> None:
        arm, base = self.phase(t)
        if arm:
            self.arm_s += dt
        if base:
            speed, turn = 0.3, 0.2  # m/s, rad/s
            self.heading += turn * dt
            self.x += speed * dt * math.cos(self.heading)
            self.y += speed * dt * math.sin(self.heading)
            for side, sign in (("left", -1), ("right", 1)):
                roll = (speed + sign * turn * 0.25) * dt / 0.1  # 0.25 m half track, 0.1 m radius
                self.wheel[side] = self.wheel.get(side, 0.0) + roll

    def transform(self, joint: str, child: str) -> tuple[tuple[float, float, float], tuple]:
        """Translation and quaternion (x, y, z, w) of a joint now."""
        if joint == "base":
            return (self.x, self.y, 0.0), _yaw(self.heading)
        if joint == "wheel":
            side = "left" if "left" in child else "right"
            return (0.2, 0.25 if side == "left" else -0.25, 0.1), _pitch(self.wheel.get(side, 0))
        if joint.startswith("arm"):
            i = int(joint[3:])
            angle = 0.6 * math.sin(2 * math.pi * (0.1 + 0.03 * i) * self.arm_s)
            return (0.0, 0.0, 0.15), (_yaw(angle) if i % 3 == 0 else _pitch(angle))
        if joint.startswith("finger"):
            opening = 0.02 * (1 + math.sin(2 * math.pi * 0.3 * self.arm_s))
            return (0.05, int(joint[6:]) * opening, 0.0), (0.0, 0.0, 0.0, 1.0)
        offset = (len(child) % 5) * 0.05  # fixed joints: some made-up but constant offset
        return (offset, 0.0, 0.1), (0.0, 0.0, 0.0, 1.0)

    def message(self, stamp: float) -> dict[str, object]:
        sec = math.floor(stamp)
        header_stamp = {"sec": sec, "nanosec": round((stamp - sec) * 1e9)}
        transforms = []
        for parent, child, joint in FRAMES:
            (x, y, z), (qx, qy, qz, qw) = self.transform(joint, child)
            transforms.append(
                {
                    "header": {"stamp": header_stamp, "frame_id": parent},
                    "child_frame_id": child,
                    "transform": {
                        "translation": {"x": x, "y": y, "z": z},
                        "rotation": {"x": qx, "y": qy, "z": qz, "w": qw},
                    },
                }
            )
        return {"transforms": transforms}


def _yaw(angle: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2))


def _pitch(angle: float) -> tuple[float, float, float, float]:
    return (0.0, math.sin(angle / 2), 0.0, math.cos(angle / 2))


def _drain(session: Session) -> int:
    return sum(len(frame.data) for frame in session.frames_to_send())


@dataclass
class Capture:
    """Bytes per simulated second for both clients, and the republisher's cost."""

    raw: list[int]
    republished: list[int]
    tick_ms: list[float] = field(default_factory=list)
    tick_cpu_ms: list[float] = field(default_factory=list)


async def capture(duration_s: float, clients: int = CLIENTS) -> Capture:
    """Run the trace for ``duration_s`` simulated seconds; count what the clients get."""
    clock = _Clock()
    graph = Graph(clock=clock)
    ticks = _Ticks()
    install_tf_republisher(graph, ticks.sleep)
    trace = _Trace(duration_s)
    publisher = graph.create_publisher("/tf", "tf2_msgs/msg/TFMessage")
    raw = Session(graph.port, "raw")
    raw.receive_frame(json.dumps({"op": "subscribe", "topic": "/tf"}), 0.0)
    goal = {
        "source_frames": [child for _, child, _ in FRAMES],
        "target_frame": "map",
        "angular_thres": 0.01,
        "trans_thres": 0.01,
        "rate": RATE_HZ,
    }
    web = [Session(graph.port, f"web{i}") for i in range(clients)]
    seconds = math.ceil(duration_s)
    out = Capture([0] * seconds, [0] * seconds)
    dt = 1.0 / RATE_HZ
    async with running_handlers(graph) as tg:
        publisher.publish(trace.message(clock.wall()))
        for i, session in enumerate(web):
            op = {
                "op": "send_action_goal",
                "action": "/tf2_web_republisher",
                "action_type": "tf2_web_republisher_interfaces/action/TFSubscription",
                "args": goal,
                "feedback": True,
                "id": f"g{i}",
            }
            session.receive_frame(json.dumps(op), 0.0)
        await anyio.wait_all_tasks_blocked()  # every goal ran its first tick
        for step in range(round(duration_s * RATE_HZ)):
            second = int(clock.t)
            out.raw[second] += _drain(raw)
            out.republished[second] += _drain(web[0])
            for session in web[1:]:
                _drain(session)
            trace.step(clock.t, dt)
            clock.t = (step + 1) * dt
            publisher.publish(trace.message(clock.wall()))
            start, start_cpu = time.perf_counter(), time.thread_time()
            await ticks.tick()
            out.tick_ms.append((time.perf_counter() - start) * 1000)
            out.tick_cpu_ms.append((time.thread_time() - start_cpu) * 1000)
        tg.cancel_scope.cancel()
    return out


#: (arm moves, base drives) -> the phase's name in the rows.
_PHASES = {
    (False, False): "robot idle",
    (True, False): "arm only",
    (False, True): "base only",
    (True, True): "base and arm",
}


def _kb(series: list[int]) -> tuple[float, float]:
    kbs = [b / 1000 for b in series]
    return statistics.fmean(kbs), statistics.pstdev(kbs)


def run(quick: bool) -> list[dict[str, object]]:
    """Fig. 3 rows: raw and republished KB/s, the reduction, the cost per tick.

    ``quick`` simulates 6 s instead of the paper's 60 s.
    """
    duration = 6.0 if quick else 60.0
    got = anyio.run(capture, duration)
    raw_mean, raw_sd = _kb(got.raw)
    web_mean, web_sd = _kb(got.republished)
    seconds = f"{duration:g} s simulated"
    main = _main_rows(raw_mean, raw_sd, web_mean, web_sd, seconds)
    return [*main, *_phase_rows(got, duration), *_cost_rows(got, duration)]


def _cost_rows(got: Capture, duration: float) -> list[dict[str, object]]:
    """The republisher's CPU per tick (thread CPU time: other processes do not count)."""
    trace = _Trace(duration)
    by_phase: dict[tuple[bool, bool], list[float]] = {}
    for step, cpu_ms in enumerate(got.tick_cpu_ms):  # tick ``step`` follows motion at step * dt
        by_phase.setdefault(trace.phase(step / RATE_HZ), []).append(cpu_ms)
    phases = ", ".join(
        f"{name} {statistics.median(by_phase[key]):.2f}"
        for key, name in _PHASES.items()
        if key in by_phase
    )
    busiest = by_phase.get((True, True), got.tick_cpu_ms)
    return [
        {
            "figure": FIGURE,
            "metric": f"republisher CPU per tick, {CLIENTS} clients",
            "paper": None,
            "ours": statistics.median(got.tick_cpu_ms),
            "unit": "ms",
            "note": f"median (wall {statistics.median(got.tick_ms):.2f}); by phase: {phases}"
            " (B12: <= 1 ms)",
        },
        {
            "figure": FIGURE,
            "metric": f"republisher CPU per tick, {CLIENTS} clients, base and arm moving",
            "paper": None,
            "ours": statistics.median(busiest),
            "unit": "ms",
            "note": "median of the busiest phase: all 52 frames resent to every client",
        },
    ]


def _phase_rows(got: Capture, duration: float) -> list[dict[str, object]]:
    """The republished rate in each phase of the trace (the paper gives no such split)."""
    trace = _Trace(duration)
    names = _PHASES
    by_phase: dict[str, list[int]] = {}
    for second, sent in enumerate(got.republished[1:], start=1):  # 0 holds the first full tree
        by_phase.setdefault(names[trace.phase(second + 0.5)], []).append(sent)
    return [
        {
            "figure": FIGURE,
            "metric": f"through the republisher, {name}",
            "paper": None,
            "ours": _kb(by_phase[name])[0],
            "unit": "KB/s",
            "note": f"{len(by_phase[name])} s of the trace",
        }
        for name in names.values()
        if name in by_phase
    ]


def _main_rows(
    raw_mean: float, raw_sd: float, web_mean: float, web_sd: float, seconds: str
) -> list[dict[str, object]]:
    return [
        {
            "figure": FIGURE,
            "metric": "client on raw /tf",
            "paper": 208.5,
            "ours": raw_mean,
            "unit": "KB/s",
            "note": f"sigma paper 1.5, ours {raw_sd:.1f}; JSON, paper ROS binary; {seconds}",
        },
        {
            "figure": FIGURE,
            "metric": "client through the republisher",
            "paper": 96.0,
            "ours": web_mean,
            "unit": "KB/s",
            "note": f"sigma paper 40.6, ours {web_sd:.1f}; 10 Hz, 0.01 m / 0.01 rad",
        },
        {
            "figure": FIGURE,
            "metric": "bandwidth saved by the republisher",
            "paper": 54.0,
            "ours": 100 * (1 - web_mean / raw_mean),
            "unit": "%",
            "note": "52 frames, 13 moving: idle, arm, base, both, idle",
        },
    ]
