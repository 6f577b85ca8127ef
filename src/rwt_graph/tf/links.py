"""The links of the TF frame tree, and the routes of lookups through them.

A ``Link`` holds one frame's transform to its parent over time. A ``Route``
holds the links between the two frames of a lookup and what its last
computation multiplied, so that a lookup whose links kept their values (fixed
joints, or everything while the robot stands still) reuses the products instead
of multiplying again. Reuse is decided by object identity, never by comparing
floats, and the products are taken in the same order as before, so a result is
bit for bit what computing it afresh gives.
"""

from __future__ import annotations

import bisect
import functools
from typing import TYPE_CHECKING

from .errors import ExtrapolationError
from .transform import identity, interpolate, inverse

if TYPE_CHECKING:
    from .stamped import StampedTransform
    from .transform import Matrix

__all__ = ["Link", "Route"]

#: Stamps closer than this are the same instant (seconds).
_SAME_TIME_S = 1e-9


@functools.cache
def _identities() -> tuple[Matrix, Matrix]:
    """The identity and its inverse: operands only, never returned.

    Made on first use, not at import: numpy loads with the first transform
    (benchmarks B11 base memory). Cached, so routes can compare them by identity.
    """
    unit = identity()
    return unit, inverse(unit)


Step = tuple[str, "Link"]
"""A frame and its link to its parent."""


class Link:
    """The transform from one frame to its parent, over time."""

    __slots__ = ("parent", "stamps", "static", "values")

    def __init__(self, parent: str, *, static: bool) -> None:
        self.parent = parent
        self.static = static
        self.stamps: list[float] = []
        self.values: list[Matrix] = []

    def add(self, stamp: float, value: Matrix, cache_time_s: float, max_samples: int) -> None:
        """Store ``value`` at ``stamp``; history beyond the bounds is dropped.

        A value equal, bit for bit, to the latest one is stored as that same
        object: routes see by identity that nothing changed (a fixed joint
        republished at every tick) and reuse their products.
        """
        if self.values:
            latest = self.values[-1]
            if latest.tobytes() == value.tobytes():
                value = latest
        if self.static:
            self.stamps, self.values = [stamp], [value]
            return
        index = bisect.bisect_left(self.stamps, stamp - _SAME_TIME_S)
        if index < len(self.stamps) and abs(self.stamps[index] - stamp) <= _SAME_TIME_S:
            self.values[index] = value
        else:
            self.stamps.insert(index, stamp)
            self.values.insert(index, value)
        oldest = bisect.bisect_left(self.stamps, self.stamps[-1] - cache_time_s)
        drop = max(oldest, len(self.stamps) - max_samples)
        if drop > 0:
            del self.stamps[:drop], self.values[:drop]

    def at(self, time: float | None, child: str) -> Matrix:
        """The value at ``time`` (None: the latest), interpolated between samples."""
        stamps = self.stamps
        if self.static or time is None or time == stamps[-1]:  # the usual case: no search
            return self.values[-1]
        if time > stamps[-1] + _SAME_TIME_S or time < stamps[0] - _SAME_TIME_S:
            raise ExtrapolationError(
                f"lookup at {time:.6f} s needs {child} -> {self.parent} outside its history"
                f" [{stamps[0]:.6f}, {stamps[-1]:.6f}] s"
            )
        index = bisect.bisect_left(stamps, time - _SAME_TIME_S)
        if abs(stamps[index] - time) <= _SAME_TIME_S:
            return self.values[index]
        before, after = stamps[index - 1], stamps[index]
        ratio = (time - before) / (after - before)
        return interpolate(self.values[index - 1], self.values[index], ratio)


class Route:
    """The links from two frames up to the frame below their common ancestor.

    Args:
        up: ``(child frame, link)`` from the source up, leaf first.
        down: the same from the target up.

    Attributes:
        moving: the dynamic links of both, which set the lookup's time.
        last: the last result computed along this route, if any.
    """

    __slots__ = ("_down_poses", "_inverse", "_product", "_up_poses", "down", "last", "moving", "up")

    def __init__(self, up: tuple[Step, ...], down: tuple[Step, ...]) -> None:
        self.up = up
        self.down = down
        self.moving = tuple(link for _, link in (*up, *down) if not link.static)
        self.last: StampedTransform | None = None
        self._up_poses: list[tuple[Matrix, Matrix]] = []
        self._down_poses: list[tuple[Matrix, Matrix]] = []
        self._inverse: tuple[Matrix, Matrix] | None = None
        self._product: tuple[Matrix, Matrix, Matrix] | None = None

    def matrix(self, time: float | None) -> Matrix:
        """The transform of the source in the target at ``time`` (None: latest values).

        Read only: the same object as the last call's when no value it depends on
        changed.

        Raises:
            ExtrapolationError: a link does not hold ``time``.
        """
        in_common = _chain(self.up, self._up_poses, time) if self.up else _identities()[0]
        if self.down:
            target_in_common = _chain(self.down, self._down_poses, time)
            if self._inverse is None or self._inverse[0] is not target_in_common:
                self._inverse = (target_in_common, inverse(target_in_common))
            to_target = self._inverse[1]
        else:
            to_target = _identities()[1]
        product = self._product
        if product is None or product[0] is not to_target or product[1] is not in_common:
            matrix = to_target @ in_common
            matrix.flags.writeable = False
            product = self._product = (to_target, in_common, matrix)
        return product[2]


def _chain(
    steps: tuple[Step, ...], poses: list[tuple[Matrix, Matrix]], time: float | None
) -> Matrix:
    """The pose of the first step's frame in the parent of the last one's (leaf first).

    ``poses`` holds ``(link value, pose so far)`` per step from the last call;
    from the first step whose value is another object on, the poses are
    multiplied again (and remembered); below it they are reused.
    """
    same = True
    pose: Matrix | None = None
    for index, (frame, link) in enumerate(steps):
        value = link.at(time, frame)
        if same and index < len(poses) and poses[index][0] is value:
            pose = poses[index][1]
            continue
        same = False
        pose = value if pose is None else value @ pose
        if index < len(poses):
            poses[index] = (value, pose)
        else:
            poses.append((value, pose))
    assert pose is not None
    return pose
