"""A TF buffer: the frame tree from ``/tf`` and ``/tf_static``, and lookups in it.

It does what tf2's buffer does for a web republisher (paper section IV.A):
every ``geometry_msgs/TransformStamped`` sets the link from ``child_frame_id`` to
``header.frame_id``; dynamic links keep a bounded, time-ordered history, static
links one value for ever. ``lookup(target, source)`` answers the transform of
``source`` in ``target`` at the latest time every moving link on the path between
them has data for (tf2's ``TimePointZero`` lookup), interpolating each link's
history there. Frame ids are normalised by stripping a leading ``/``, as
tf2_web_republisher and its clients do (REF §7.3).

Simplifications, documented: a link whose parent changes forgets its history
(tf2 keeps the parent per sample), and a link turning static or dynamic starts
over. Memory is bounded by ``max_frames`` links of at most ``max_samples``
samples each; peers cannot grow it beyond that.
"""

from __future__ import annotations

import bisect
import functools
import logging
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from rwt_graph.types import Dialect
from rwt_graph.types.convert import time_value
from rwt_protocol.errors import GraphError

from .transform import Matrix, from_message, identity, interpolate, inverse, quaternion

__all__ = [
    "DisconnectedFramesError",
    "ExtrapolationError",
    "StampedTransform",
    "TFBuffer",
    "TFError",
    "UnknownFrameError",
    "normalize_frame",
    "stamp_seconds",
]

logger = logging.getLogger("rwt.tf")

#: Stamps closer than this are the same instant (seconds).
_SAME_TIME_S = 1e-9
#: Lookups remembered until the tree changes.
_MEMO_LIMIT = 10_000


class TFError(GraphError):
    """A transform could not be stored or looked up; the message says why."""


class UnknownFrameError(TFError):
    """A frame no transform names (neither as child nor as parent)."""


class DisconnectedFramesError(TFError):
    """Both frames exist but lie in different trees."""


class ExtrapolationError(TFError):
    """The lookup time is outside the history a link still holds."""


def normalize_frame(frame_id: str) -> str:
    """``frame_id`` without one leading ``/`` (REF §7.3: tf2 rejects it)."""
    return frame_id[1:] if frame_id.startswith("/") else frame_id


def stamp_seconds(stamp: Mapping[str, object]) -> float:
    """Seconds of a ROS time dict in either dialect (``sec/nanosec``, ``secs/nsecs``)."""
    sec = stamp.get("sec", stamp.get("secs", 0))
    nsec = stamp.get("nanosec", stamp.get("nsecs", 0))
    assert isinstance(sec, int) and isinstance(nsec, int)
    return sec + nsec * 1e-9


@dataclass(frozen=True)
class StampedTransform:
    """The result of a lookup (shared by every caller until the tree changes: read only).

    Attributes:
        target: the frame the result is expressed in (``header.frame_id``).
        source: the frame whose pose it is (``child_frame_id``).
        stamp: seconds of the time it holds at; 0.0 when only static links are used.
        matrix: the 4x4 transform mapping ``source`` coordinates to ``target``'s.
    """

    target: str
    source: str
    stamp: float
    matrix: Matrix

    @functools.cached_property
    def translation(self) -> tuple[float, float, float]:
        """``(x, y, z)`` in metres, as plain floats."""
        x, y, z = (float(v) for v in self.matrix[:3, 3])
        return x, y, z

    @functools.cached_property
    def rotation(self) -> tuple[float, float, float, float]:
        """The unit quaternion ``(x, y, z, w)``, ``w >= 0``, as plain floats."""
        x, y, z, w = (float(v) for v in quaternion(self.matrix))
        return x, y, z, w

    @functools.cached_property
    def transform(self) -> dict[str, object]:
        """The ``geometry_msgs/Transform`` dict (internal form); treat it as read only."""
        x, y, z = self.translation
        qx, qy, qz, qw = self.rotation
        return {
            "translation": {"x": x, "y": y, "z": z},
            "rotation": {"x": qx, "y": qy, "z": qz, "w": qw},
        }

    @functools.cached_property
    def _messages(self) -> dict[Dialect, dict[str, object]]:
        return {}

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


class _Link:
    """The transform from one frame to its parent, over time."""

    __slots__ = ("parent", "stamps", "static", "values")

    def __init__(self, parent: str, *, static: bool) -> None:
        self.parent = parent
        self.static = static
        self.stamps: list[float] = []
        self.values: list[Matrix] = []

    @property
    def latest(self) -> float:
        return self.stamps[-1]

    def add(self, stamp: float, value: Matrix, cache_time_s: float, max_samples: int) -> None:
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
        if self.static or time is None:
            return self.values[-1]
        stamps = self.stamps
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


class TFBuffer:
    """The frame tree and its recent history.

    Args:
        cache_time_s: seconds of history kept per dynamic link (tf2's default is 10).
        max_samples: samples kept per dynamic link, whatever their times.
        max_frames: links held at most; transforms for further new frames are refused.

    Attributes:
        version: increases with every stored transform (lookups are cached per version).
    """

    def __init__(
        self, *, cache_time_s: float = 10.0, max_samples: int = 200, max_frames: int = 2000
    ) -> None:
        self.cache_time_s = cache_time_s
        self.max_samples = max_samples
        self.max_frames = max_frames
        self.version = 0
        self._links: dict[str, _Link] = {}
        self._parents: dict[str, int] = {}  # frame -> number of links naming it as parent
        self._memo: dict[tuple[str, str], StampedTransform] = {}
        self._memo_version = -1

    # ---- storing ---------------------------------------------------------------

    def add_message(self, msg: Mapping[str, object], *, static: bool) -> int:
        """Store every transform of a ``tf2_msgs/TFMessage`` dict.

        Transforms that cannot be stored are skipped and logged (one bad entry
        from one publisher must not drop the others).

        Returns:
            How many were stored.
        """
        transforms = msg.get("transforms", ())
        assert isinstance(transforms, list)
        stored = 0
        for transform in transforms:
            try:
                self.set_transform(transform, static=static)
            except TFError as exc:
                logger.debug("ignored a transform: %s", exc.message)
            else:
                stored += 1
        return stored

    def set_transform(self, transform: Mapping[str, object], *, static: bool) -> None:
        """Store one ``geometry_msgs/TransformStamped`` dict (internal form).

        Raises:
            TFError: an empty frame id, a frame that is its own parent, a value
                that is not finite, or a new frame beyond ``max_frames``.
        """
        header = transform["header"]
        assert isinstance(header, Mapping)
        parent = normalize_frame(str(header["frame_id"]))
        child = normalize_frame(str(transform["child_frame_id"]))
        if not parent or not child:
            raise TFError(f"empty frame id in {parent!r} -> {child!r}")
        if parent == child:
            raise TFError(f"frame {child!r} cannot be its own parent")
        stamp_value = header["stamp"]
        assert isinstance(stamp_value, Mapping)
        value = transform["transform"]
        assert isinstance(value, Mapping)
        matrix = from_message(value)
        if not np.isfinite(matrix).all():
            raise TFError(f"transform {parent!r} -> {child!r} is not finite")
        link = self._link(child, parent, static=static)
        link.add(stamp_seconds(stamp_value), matrix, self.cache_time_s, self.max_samples)
        self.version += 1

    def _link(self, child: str, parent: str, *, static: bool) -> _Link:
        link = self._links.get(child)
        if link is not None and link.parent == parent and link.static == static:
            return link
        if link is None and len(self._links) >= self.max_frames:
            raise TFError(f"more than {self.max_frames} frames: {child!r} refused")
        if link is not None:
            self._unref(link.parent)
        self._parents[parent] = self._parents.get(parent, 0) + 1
        link = self._links[child] = _Link(parent, static=static)
        return link

    def _unref(self, parent: str) -> None:
        count = self._parents[parent] - 1
        if count:
            self._parents[parent] = count
        else:
            del self._parents[parent]

    def clear(self) -> None:
        """Forget every frame."""
        self._links.clear()
        self._parents.clear()
        self.version += 1

    # ---- queries ----------------------------------------------------------------

    def frames(self) -> list[str]:
        """Every known frame (children and parents), sorted."""
        return sorted(self._links.keys() | self._parents.keys())

    def has_frame(self, frame_id: str) -> bool:
        """Whether a transform names ``frame_id`` (leading ``/`` ignored)."""
        frame = normalize_frame(frame_id)
        return frame in self._links or frame in self._parents

    def parent(self, frame_id: str) -> str | None:
        """The parent of ``frame_id``, None for a root or an unknown frame."""
        link = self._links.get(normalize_frame(frame_id))
        return None if link is None else link.parent

    def lookup(self, target_frame: str, source_frame: str) -> StampedTransform:
        """The transform of ``source_frame`` in ``target_frame`` at their latest common time.

        Raises:
            UnknownFrameError: a frame no transform names.
            DisconnectedFramesError: the frames are in different trees.
            ExtrapolationError: a link no longer holds the common time.
            TFError: the links form a loop.
        """
        target, source = normalize_frame(target_frame), normalize_frame(source_frame)
        if self._memo_version != self.version or len(self._memo) >= _MEMO_LIMIT:
            self._memo.clear()
            self._memo_version = self.version
        found = self._memo.get((target, source))
        if found is None:
            found = self._memo[(target, source)] = self._lookup(target, source)
        return found

    def _lookup(self, target: str, source: str) -> StampedTransform:
        for frame in (target, source):
            if not (frame in self._links or frame in self._parents):
                raise UnknownFrameError(f"frame {frame!r} does not exist")
        if target == source:
            return StampedTransform(target, source, 0.0, identity())
        source_up = self._path_up(source)
        depth = {frame: index for index, frame in enumerate(source_up)}
        target_up: list[str] = []
        for frame in self._path_up(target):
            if frame in depth:
                break
            target_up.append(frame)
        else:
            raise DisconnectedFramesError(
                f"frames {target!r} and {source!r} are not connected (roots"
                f" {target_up[-1]!r} and {source_up[-1]!r})"
            )
        source_links = source_up[: depth[frame]]
        stamps = [
            self._links[f].latest for f in (*source_links, *target_up) if not self._links[f].static
        ]
        time = min(stamps) if stamps else None
        in_common = self._chain(source_links, time) if source_links else identity()
        target_in_common = self._chain(target_up, time) if target_up else identity()
        return StampedTransform(target, source, time or 0.0, inverse(target_in_common) @ in_common)

    def _path_up(self, frame: str) -> list[str]:
        """``frame`` and its ancestors up to the root."""
        path = [frame]
        seen = {frame}
        link = self._links.get(frame)
        while link is not None:
            if link.parent in seen:
                raise TFError(f"frames form a loop through {link.parent!r}")
            path.append(link.parent)
            seen.add(link.parent)
            link = self._links.get(link.parent)
        return path

    def _chain(self, frames: list[str], time: float | None) -> Matrix:
        """The pose of ``frames[0]`` in the parent of ``frames[-1]``."""
        pose = self._links[frames[0]].at(time, frames[0])
        for frame in frames[1:]:
            pose = self._links[frame].at(time, frame) @ pose
        return pose
