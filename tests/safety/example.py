"""The safety rules file of docs/safety.md, as it is written there, and a robot that obeys it.

``EXAMPLE`` is the file every test of the envelope uses, byte for byte the example of
the issue that asked for the envelope and of docs/safety.md (a test checks that the
page shows it). ``Robot`` records what reaches the robot's own subscribers of the
bounded topics: what a remote client's command became, and the dead-man's stops.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import anyio

from rwt import Graph
from rwt_graph.safety.rules import SafetyRules, parse_rules
from tests.support.realclients import REPO

EXAMPLE = """\
[[topic]]
name = "/cmd_vel"
type = "geometry_msgs/msg/Twist"
on_violation = "clamp"
deadman_s = 0.5
approval = true
[topic.bounds]
"linear.x" = [-0.5, 0.5]
"angular.z" = [-1.0, 1.0]
[topic.stop]
linear = { x = 0.0, y = 0.0, z = 0.0 }
angular = { x = 0.0, y = 0.0, z = 0.0 }

[[topic]]
name = "/arm/joint_cmd"
type = "std_msgs/msg/Float64"
on_violation = "reject"
[topic.bounds]
"data" = [0.0, 3.14]
"""

STOP = {"linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}
HANG_S = 20.0
"""A bound on a wait that should end at once: a hang guard, not a speed requirement."""

Message = dict[str, Any]


def example_file(folder: Path, text: str = EXAMPLE) -> Path:
    """``text`` written as ``safety.toml`` in ``folder``."""
    path = folder / "safety.toml"
    path.write_text(text, "utf-8")
    return path


@dataclass
class Robot:
    """The robot's side of a graph under the example's rules: what its subscribers hear.

    Attributes:
        graph: the graph, the rules on it.
        cmd_vel: each Twist on ``/cmd_vel``, with the monotonic time it arrived.
        joint: each ``data`` of ``/arm/joint_cmd``.
    """

    graph: Graph
    cmd_vel: list[tuple[float, Message]] = field(default_factory=list)
    joint: list[float] = field(default_factory=list)
    _heard: anyio.Event = field(default_factory=anyio.Event)

    @classmethod
    def make(cls, text: str = EXAMPLE, rules: SafetyRules | None = None) -> Robot:
        """A graph under ``rules``, else under the rules of ``text``, and its subscribers."""
        robot = cls(Graph(safety=rules or parse_rules(text, "safety.toml")))
        robot.graph.create_subscription("/cmd_vel", robot._twist, "geometry_msgs/msg/Twist")
        robot.graph.create_subscription("/arm/joint_cmd", robot._joint, "std_msgs/msg/Float64")
        return robot

    def _twist(self, msg: Message) -> None:
        self.cmd_vel.append((time.monotonic(), msg))
        self._heard.set()

    def _joint(self, msg: Message) -> None:
        self.joint.append(float(msg["data"]))
        self._heard.set()

    @property
    def twists(self) -> list[Message]:
        """The Twists heard, in order."""
        return [msg for _, msg in self.cmd_vel]

    async def wait_for(self, done: Any, what: str) -> None:
        """Wait until ``done()`` is true, within the hang guard (then fail naming ``what``)."""
        try:
            with anyio.fail_after(HANG_S):
                while not done():
                    self._heard = anyio.Event()
                    if done():
                        return
                    await self._heard.wait()
        except TimeoutError:
            raise AssertionError(f"no {what} within {HANG_S:g} s: heard {self.cmd_vel}") from None


def twist(x: float = 0.0, z: float = 0.0) -> Message:
    """A Twist with ``linear.x`` and ``angular.z``."""
    return {"linear": {"x": x, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": z}}


def docs_page() -> str:
    """docs/safety.md."""
    return (REPO / "docs" / "safety.md").read_text("utf-8")
