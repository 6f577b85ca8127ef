"""A TF buffer: the frame tree from ``/tf`` and ``/tf_static``, and lookups in it.

It does what tf2's buffer does for a web republisher (paper section IV.A):
every ``geometry_msgs/TransformStamped`` sets the link from ``child_frame_id`` to
``header.frame_id``; dynamic links keep a bounded, time-ordered history, static
links one value for ever. ``lookup(target, source)`` answers the transform of
``source`` in ``target`` at the latest time every moving link on the path between
them has data for (tf2's ``TimePointZero`` lookup), interpolating each link's
history there. Frame ids are normalised by stripping a leading ``/``, as
tf2_web_republisher and its clients do (REF §7.3).

Lookups are computed once per tree ``version`` (every stored transform makes a
new one), however many callers ask: the TF republisher's goals at one tick share
one computation per pair (``lookup_each``). The route between two frames is
remembered until the tree's shape changes, with the products along it, which
are reused while the links below them keep their values (see ``links.py``).
Neither the wall clock nor the monotonic one is an input of a lookup (it is
taken at the frames' latest common time, not at now), so time passing alone
changes no answer.

Simplifications, documented: a link whose parent changes forgets its history
(tf2 keeps the parent per sample), and a link turning static or dynamic starts
over. Memory is bounded by ``max_frames`` links of at most ``max_samples``
samples each, and by the limits on what is remembered below; peers cannot grow
it beyond that.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping

from ..types.convert import time_parts
from .errors import DisconnectedFramesError, ExtrapolationError, TFError, UnknownFrameError
from .links import Link, Route
from .stamped import StampedTransform
from .transform import from_message, identity

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

#: Lookups remembered until the tree changes.
_MEMO_LIMIT = 10_000
#: ``lookup_each`` lists remembered until the tree changes.
_EACH_LIMIT = 1_000
#: Links held by remembered routes between frames, at most (each with one 4x4 product).
_ROUTE_ITEMS_LIMIT = 50_000


def normalize_frame(frame_id: str) -> str:
    """``frame_id`` without one leading ``/`` (REF §7.3: tf2 rejects it)."""
    return frame_id[1:] if frame_id.startswith("/") else frame_id


def stamp_seconds(stamp: Mapping[str, object]) -> float:
    """Seconds of a ROS time dict in either dialect (``sec/nanosec``, ``secs/nsecs``)."""
    parts = time_parts(stamp)
    assert parts is not None  # converted messages always hold valid times
    sec, nsec = parts
    return sec + nsec * 1e-9


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
        self._links: dict[str, Link] = {}
        self._parents: dict[str, int] = {}  # frame -> number of links naming it as parent
        # per version: results (errors too) of single lookups and of lookup_each
        self._memo: dict[tuple[str, str], StampedTransform | TFError] = {}
        self._each: dict[tuple[str, tuple[str, ...]], list[StampedTransform | TFError]] = {}
        self._memo_version = -1
        # (target, source) -> the links between them, until the tree's shape changes
        self._routes: dict[tuple[str, str], Route] = {}
        self._route_items = 0

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
        if not all(math.isfinite(v) for row in matrix.tolist() for v in row):
            raise TFError(f"transform {parent!r} -> {child!r} is not finite")
        link = self._link(child, parent, static=static)
        link.add(stamp_seconds(stamp_value), matrix, self.cache_time_s, self.max_samples)
        self.version += 1

    def _link(self, child: str, parent: str, *, static: bool) -> Link:
        link = self._links.get(child)
        if link is not None and link.parent == parent and link.static == static:
            return link
        if link is None and len(self._links) >= self.max_frames:
            raise TFError(f"more than {self.max_frames} frames: {child!r} refused")
        if link is not None:
            self._unref(link.parent)
        self._forget_routes()
        self._parents[parent] = self._parents.get(parent, 0) + 1
        link = self._links[child] = Link(parent, static=static)
        return link

    def _forget_routes(self) -> None:
        self._routes.clear()
        self._route_items = 0

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
        self._forget_routes()
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

        Results are remembered until the tree changes (``version``): asking again,
        from any caller, costs a dict lookup and returns the same object.

        Raises:
            UnknownFrameError: a frame no transform names.
            DisconnectedFramesError: the frames are in different trees.
            ExtrapolationError: a link no longer holds the common time.
            TFError: the links form a loop.
        """
        found = self._found(normalize_frame(target_frame), normalize_frame(source_frame))
        if isinstance(found, TFError):
            raise type(found)(found.message)  # a fresh one: callers may keep or chain it
        return found

    def lookup_each(
        self, target_frame: str, source_frames: tuple[str, ...]
    ) -> list[StampedTransform | TFError]:
        """``lookup(target_frame, source)`` for every source, errors returned in place.

        The list is computed once per ``version`` for a given ``(target_frame,
        source_frames)`` and then shared by every caller that asks the same (the
        TF republisher's goals at one tick): treat it and its items as read only.
        """
        self._check_version()
        key = (target_frame, source_frames)
        found = self._each.get(key)
        if found is None:
            if len(self._each) >= _EACH_LIMIT:
                self._each.clear()
            target = normalize_frame(target_frame)
            found = [self._found(target, normalize_frame(s)) for s in source_frames]
            self._each[key] = found
        return found

    def _check_version(self) -> None:
        if self._memo_version != self.version:
            self._memo.clear()
            self._each.clear()
            self._memo_version = self.version

    def _found(self, target: str, source: str) -> StampedTransform | TFError:
        """The memoised result of one lookup of normalised frames, or its error."""
        self._check_version()
        found = self._memo.get((target, source))
        if found is None:
            if len(self._memo) >= _MEMO_LIMIT:
                self._memo.clear()
            try:
                found = self._lookup(target, source)
            except TFError as exc:
                found = exc.with_traceback(None)  # kept: let go of the frames it saw
            self._memo[(target, source)] = found
        return found

    def _lookup(self, target: str, source: str) -> StampedTransform:
        for frame in (target, source):
            if not (frame in self._links or frame in self._parents):
                raise UnknownFrameError(f"frame {frame!r} does not exist")
        if target == source:
            matrix = identity()
            matrix.flags.writeable = False
            return StampedTransform(target, source, 0.0, matrix)
        route = self._route(target, source)
        time = min(link.stamps[-1] for link in route.moving) if route.moving else None
        matrix = route.matrix(time)
        last = route.last
        if last is not None and last.matrix is matrix:  # nothing moved: reuse what it derived
            found = last.restamped(time or 0.0)
        else:
            found = StampedTransform(target, source, time or 0.0, matrix)
        route.last = found
        return found

    def _route(self, target: str, source: str) -> Route:
        """The links between two frames, remembered until the tree's shape changes."""
        route = self._routes.get((target, source))
        if route is None:
            route = self._find_route(target, source)
            size = len(route.up) + len(route.down)
            self._route_items += size
            if self._route_items > _ROUTE_ITEMS_LIMIT:  # a huge tree: memory stays bounded
                self._forget_routes()
                self._route_items = size
            self._routes[(target, source)] = route
        return route

    def _find_route(self, target: str, source: str) -> Route:
        source_up = self._walk_up(source)
        depth = {frame: index for index, frame in enumerate(source_up)}
        target_up: list[str] = []
        for frame in self._walk_up(target):
            if frame in depth:
                break
            target_up.append(frame)
        else:
            raise DisconnectedFramesError(
                f"frames {target!r} and {source!r} are not connected (roots"
                f" {target_up[-1]!r} and {source_up[-1]!r})"
            )
        up = tuple((f, self._links[f]) for f in source_up[: depth[frame]])
        down = tuple((f, self._links[f]) for f in target_up)
        return Route(up, down)

    def _walk_up(self, frame: str) -> list[str]:
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
