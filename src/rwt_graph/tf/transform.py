"""Rigid transforms for the TF buffer: 4x4 homogeneous matrices in numpy.

A transform of frame ``child`` in frame ``parent`` (a ``geometry_msgs/Transform``
with ``header.frame_id = parent``) maps points given in ``child`` coordinates to
``parent`` coordinates, as in tf2. Quaternions are ``(x, y, z, w)`` like the
messages. Translations are metres, angles radians.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, TypeAlias

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

__all__ = [
    "Matrix",
    "from_message",
    "from_parts",
    "identity",
    "interpolate",
    "inverse",
    "quaternion",
    "quaternion_tuple",
]

Matrix: TypeAlias = "npt.NDArray[np.float64]"
"""A 4x4 homogeneous rigid transform."""

# Each function imports numpy itself: `rwt serve` installs the TF republisher at
# start but needs numpy only with the first transform (benchmarks B11 base memory).

_AXES = ("x", "y", "z")


def identity() -> Matrix:
    """The identity transform."""
    import numpy as np  # noqa: PLC0415

    return np.eye(4)


def from_parts(translation: npt.ArrayLike, rotation: npt.ArrayLike) -> Matrix:
    """A transform from a translation ``(x, y, z)`` and a quaternion ``(x, y, z, w)``.

    The quaternion is normalised; a zero quaternion (an all-default message in
    ROS 1, where ``w`` starts at 0) counts as no rotation.
    """
    import numpy as np  # noqa: PLC0415

    x, y, z, w = (float(v) for v in np.asarray(rotation, dtype=np.float64))
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if norm < 1e-12:
        x, y, z, w = 0.0, 0.0, 0.0, 1.0
    else:
        x, y, z, w = x / norm, y / norm, z / norm, w / norm
    out = np.empty((4, 4))
    out[0, :3] = (1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w))
    out[1, :3] = (2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w))
    out[2, :3] = (2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y))
    out[:3, 3] = np.asarray(translation, dtype=np.float64)
    out[3] = (0.0, 0.0, 0.0, 1.0)
    return out


def from_message(transform: Mapping[str, object]) -> Matrix:
    """A transform from a ``geometry_msgs/Transform`` dict (internal form).

    Raises:
        KeyError, TypeError, ValueError: the dict is not a Transform (the graph
            has checked messages on typed topics, so this means a caller's bug).
    """
    translation = transform["translation"]
    rotation = transform["rotation"]
    assert isinstance(translation, Mapping) and isinstance(rotation, Mapping)
    return from_parts(
        [float(translation[k]) for k in _AXES],
        [float(rotation[k]) for k in (*_AXES, "w")],
    )


def quaternion(matrix: Matrix) -> npt.NDArray[np.float64]:
    """The unit quaternion ``(x, y, z, w)`` of a transform's rotation, with ``w >= 0``."""
    import numpy as np  # noqa: PLC0415

    return np.array(quaternion_tuple(matrix))


def quaternion_tuple(matrix: Matrix) -> tuple[float, float, float, float]:
    """``quaternion(matrix)`` as plain floats (cheaper: the TF republisher needs many)."""
    import numpy as np  # noqa: PLC0415

    # plain floats do the same IEEE operations as numpy scalars, several times faster
    (m00, m01, m02, _), (m10, m11, m12, _), (m20, m21, m22, _), _ = matrix.tolist()
    trace = m00 + m11 + m22
    if trace > 0:
        s = math.sqrt(trace + 1.0) * 2
        q = [(m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, s / 4]
    elif m00 > m11 and m00 > m22:
        s = math.sqrt(1.0 + m00 - m11 - m22) * 2
        q = [s / 4, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s]
    elif m11 > m22:
        s = math.sqrt(1.0 + m11 - m00 - m22) * 2
        q = [(m01 + m10) / s, s / 4, (m12 + m21) / s, (m02 - m20) / s]
    else:
        s = math.sqrt(1.0 + m22 - m00 - m11) * 2
        q = [(m02 + m20) / s, (m12 + m21) / s, s / 4, (m10 - m01) / s]
    vector = np.array(q)
    norm = math.sqrt(vector.dot(vector))  # as np.linalg.norm computes it
    x, y, z, w = (v / norm for v in q)
    return (-x, -y, -z, -w) if w < 0 else (x, y, z, w)


def inverse(matrix: Matrix) -> Matrix:
    """The inverse of a rigid transform (transpose of the rotation)."""
    import numpy as np  # noqa: PLC0415

    out = np.eye(4)
    rotation_t = matrix[:3, :3].T
    out[:3, :3] = rotation_t
    out[:3, 3] = -rotation_t @ matrix[:3, 3]
    return out


def interpolate(a: Matrix, b: Matrix, ratio: float) -> Matrix:
    """The transform ``ratio`` of the way from ``a`` to ``b`` (0 gives ``a``).

    Translation is linear, rotation spherical-linear (slerp), as tf2 interpolates
    between two stamped samples.
    """
    qa, qb = quaternion(a), quaternion(b)
    dot = float(qa @ qb)
    if dot < 0:  # the shorter way round
        qb, dot = -qb, -dot
    if dot > 0.9995:  # nearly equal: linear is exact enough and avoids 0/0
        q = qa + ratio * (qb - qa)
    else:
        theta = math.acos(dot)
        q = (math.sin((1 - ratio) * theta) * qa + math.sin(ratio * theta) * qb) / math.sin(theta)
    translation = a[:3, 3] + ratio * (b[:3, 3] - a[:3, 3])
    return from_parts(translation, q)
