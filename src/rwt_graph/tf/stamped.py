"""The result of a TF lookup, and the ``geometry_msgs/TransformStamped`` made of it."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from rwt_graph.types import Dialect
from rwt_graph.types.convert import time_value

from .transform import quaternion_tuple

if TYPE_CHECKING:
    from .transform import Matrix

__all__ = ["StampedTransform"]


class StampedTransform:
    """The result of a lookup (shared by every caller until the tree changes: read only).

    Attributes:
        target: the frame the result is expressed in (``header.frame_id``).
        source: the frame whose pose it is (``child_frame_id``).
        stamp: seconds of the time it holds at; 0.0 when only static links are used.
        matrix: the 4x4 transform mapping ``source`` coordinates to ``target``'s.
    """

    # plain slots, filled on first use: read at every tick for every pair and goal
    __slots__ = (
        "_messages",
        "_rest_angle",
        "_rotation",
        "_transform",
        "_translation",
        "matrix",
        "source",
        "stamp",
        "target",
    )

    def __init__(self, target: str, source: str, stamp: float, matrix: Matrix) -> None:
        self.target = target
        self.source = source
        self.stamp = stamp
        self.matrix = matrix
        self._translation: tuple[float, float, float] | None = None
        self._rotation: tuple[float, float, float, float] | None = None
        self._transform: dict[str, object] | None = None
        self._messages: dict[Dialect, dict[str, object]] = {}
        self._rest_angle: float | None = None

    def restamped(self, stamp: float) -> StampedTransform:
        """The same transform at another ``stamp``, sharing what was derived from the matrix."""
        out = StampedTransform(self.target, self.source, stamp, self.matrix)
        out._translation, out._rotation = self._translation, self._rotation
        out._transform, out._rest_angle = self._transform, self._rest_angle
        return out

    def moved_from(self, sent: StampedTransform, trans_thres: float, angular_thres: float) -> bool:
        """Whether this pose is beyond either threshold from ``sent``'s (tf2_web_republisher).

        Beyond means a translation more than ``trans_thres`` metres, or a rotation
        of more than ``angular_thres`` radians: ``2 acos |q1 . q2|``, the angle
        between the two orientations, in plain floats.
        """
        if sent.matrix is self.matrix:  # restamped: the same pose, compared once per pose
            if self._rest_angle is None:
                self._rest_angle = _angle(self.rotation, self.rotation)
            return trans_thres < 0.0 or self._rest_angle > angular_thres
        if math.dist(sent.translation, self.translation) > trans_thres:
            return True
        return _angle(sent.rotation, self.rotation) > angular_thres

    def __repr__(self) -> str:
        return f"StampedTransform({self.target!r}, {self.source!r}, {self.stamp!r})"

    @property
    def translation(self) -> tuple[float, float, float]:
        """``(x, y, z)`` in metres, as plain floats."""
        if self._translation is None:
            x, y, z = self.matrix[:3, 3].tolist()
            self._translation = (x, y, z)
        return self._translation

    @property
    def rotation(self) -> tuple[float, float, float, float]:
        """The unit quaternion ``(x, y, z, w)``, ``w >= 0``, as plain floats."""
        if self._rotation is None:
            self._rotation = quaternion_tuple(self.matrix)
        return self._rotation

    @property
    def transform(self) -> dict[str, object]:
        """The ``geometry_msgs/Transform`` dict (internal form); treat it as read only."""
        if self._transform is None:
            x, y, z = self.translation
            qx, qy, qz, qw = self.rotation
            self._transform = {
                "translation": {"x": x, "y": y, "z": z},
                "rotation": {"x": qx, "y": qy, "z": qz, "w": qw},
            }
        return self._transform

    def message(self, dialect: Dialect) -> dict[str, object]:
        """The ``geometry_msgs/TransformStamped`` dict, in the internal form of ``dialect``.

        Every field is there in declaration order (``header.seq`` is 0 in ROS 1),
        as the type's conversion would give it, so it may be sent unchecked. It is
        built once per dialect and shared by every caller: treat it as read only.
        """
        built = self._messages.get(dialect)
        if built is None:
            stamp = time_value(self.stamp, dialect)
            header: dict[str, object] = (
                {"seq": 0, "stamp": stamp, "frame_id": self.target}
                if dialect is Dialect.ROS1
                else {"stamp": stamp, "frame_id": self.target}
            )
            built = self._messages[dialect] = {
                "header": header,
                "child_frame_id": self.source,
                "transform": self.transform,
            }
        return built


def _angle(a: tuple[float, float, float, float], b: tuple[float, float, float, float]) -> float:
    """Radians between two unit quaternions' orientations (a little above 0 for equal ones)."""
    dot = abs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3])
    return 2 * math.acos(min(1.0, dot))
