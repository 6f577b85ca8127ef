"""Helpers for the TF tests: transform messages and a sleep the test releases tick by tick."""

from __future__ import annotations

import math

import anyio


def stamp(seconds: float, *, ros1: bool = False) -> dict[str, int]:
    whole = math.floor(seconds)
    nanos = round((seconds - whole) * 1e9)
    return {"secs": whole, "nsecs": nanos} if ros1 else {"sec": whole, "nanosec": nanos}


def transform(
    parent: str,
    child: str,
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0),
    yaw: float = 0.0,
    at: float = 1.0,
    *,
    ros1: bool = False,
) -> dict[str, object]:
    """A geometry_msgs/TransformStamped: ``child`` at ``xyz`` in ``parent``, turned ``yaw`` rad."""
    x, y, z = xyz
    return {
        "header": {"stamp": stamp(at, ros1=ros1), "frame_id": parent},
        "child_frame_id": child,
        "transform": {
            "translation": {"x": x, "y": y, "z": z},
            "rotation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)},
        },
    }


def tf_message(*transforms: dict[str, object]) -> dict[str, object]:
    return {"transforms": list(transforms)}


def yaw_of(rotation: dict[str, float]) -> float:
    """The yaw of a quaternion that only turns about z."""
    return 2 * math.atan2(rotation["z"], rotation["w"])


class Ticks:
    """The republisher's injected sleep, released by the test one tick at a time."""

    def __init__(self) -> None:
        self.periods: list[float] = []
        self._events: list[anyio.Event] = []

    async def sleep(self, seconds: float) -> None:
        self.periods.append(seconds)
        event = anyio.Event()
        self._events.append(event)
        await event.wait()

    @property
    def sleeping(self) -> int:
        return len(self._events)

    async def settle(self) -> None:
        """Wait until every task (the ticking loops) is blocked again."""
        await anyio.wait_all_tasks_blocked()

    async def tick(self) -> None:
        """End the current sleep of every loop and let each run its next tick."""
        events, self._events = self._events, []
        for event in events:
            event.set()
        await self.settle()
