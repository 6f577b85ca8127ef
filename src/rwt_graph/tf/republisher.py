"""What tf2_web_republisher sends at each tick, without any timing (paper section IV.A).

A client asks for ``source_frames`` in ``target_frame`` with an angular and a
translational threshold and a rate (REF §7.3). At each tick, every pair
(source, target) is looked up in the ``TFBuffer``; a pair is sent when the lookup
succeeds and it is the pair's first value, or a threshold is zero, or its
translation moved more than ``trans_thres`` metres or its rotation turned more
than ``angular_thres`` radians since the value last *sent* (tf2_web_republisher's
``TFPair``). Only changed pairs are sent.

One difference from the ROS 1 node, on purpose: it compares tf's
``Quaternion::angle``, which is half the rotation angle; here the angle is the
rotation between the two orientations, so ``angular_thres`` means what its
documentation says (radians of rotation).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from .buffer import StampedTransform, TFBuffer, TFError, normalize_frame

if TYPE_CHECKING:
    from collections.abc import Mapping

    from rwt_graph.types import Dialect

__all__ = ["DEFAULT_RATE_HZ", "MAX_RATE_HZ", "TFRequest", "TFSubscription"]

logger = logging.getLogger("rwt.tf")

#: Rate used when a request gives none (roslibjs and roslibpy default to 10 Hz).
DEFAULT_RATE_HZ = 10.0
#: Fastest tick a client may ask for; faster requests are slowed to this.
MAX_RATE_HZ = 100.0
#: Source frames per request at most (bounds the work a peer can ask for per tick).
MAX_SOURCE_FRAMES = 1000


@dataclass(frozen=True)
class TFRequest:
    """The fields of a ``TFSubscription`` goal or ``RepublishTFs`` request.

    Attributes:
        source_frames: frames to send, normalised, duplicates removed, in order.
        target_frame: the frame they are expressed in, normalised.
        angular_thres: radians; 0 sends every tick.
        trans_thres: metres; 0 sends every tick.
        rate: ticks per second as asked for.
    """

    source_frames: tuple[str, ...]
    target_frame: str
    angular_thres: float
    trans_thres: float
    rate: float

    @classmethod
    def from_message(cls, msg: Mapping[str, object]) -> TFRequest:
        """Read a goal or request dict (already checked against its type).

        Raises:
            TFError: more than ``MAX_SOURCE_FRAMES`` source frames, or no target frame.
        """
        sources = msg.get("source_frames", [])
        assert isinstance(sources, list)
        frames = tuple(dict.fromkeys(normalize_frame(str(f)) for f in sources if f))
        if len(frames) > MAX_SOURCE_FRAMES:
            raise TFError(f"at most {MAX_SOURCE_FRAMES} source frames, got {len(frames)}")
        target = normalize_frame(str(msg.get("target_frame", "")))
        if not target:
            raise TFError("target_frame is empty")
        return cls(
            frames,
            target,
            _float(msg.get("angular_thres", 0.0)),
            _float(msg.get("trans_thres", 0.0)),
            _float(msg.get("rate", 0.0)),
        )

    @property
    def period_s(self) -> float:
        """Seconds between ticks: ``1 / rate``, within the allowed rates.

        ``DEFAULT_RATE_HZ`` when rate is not positive, and no faster than ``MAX_RATE_HZ``.
        """
        rate = self.rate if math.isfinite(self.rate) and self.rate > 0 else DEFAULT_RATE_HZ
        return 1.0 / min(rate, MAX_RATE_HZ)


def _float(value: object) -> float:
    assert isinstance(value, int | float)
    return float(value)


class _Pair:
    __slots__ = ("failing", "sent", "source")

    def __init__(self, source: str) -> None:
        self.source = source
        self.sent: StampedTransform | None = None
        self.failing = False


class TFSubscription:
    """The state of one client's request: the last value sent for each pair.

    Args:
        buffer: where transforms are looked up.
        request: what the client asked for.
        dialect: spelling of the header stamps sent (``sec/nanosec`` or ``secs/nsecs``).
    """

    def __init__(self, buffer: TFBuffer, request: TFRequest, dialect: Dialect) -> None:
        self.buffer = buffer
        self.request = request
        self.dialect = dialect
        self._pairs = [_Pair(source) for source in request.source_frames]
        # a name that kept a leading "/" after TFRequest stripped one ("//arm") is looked
        # up without it, but sent as the request spells it (rare: messages built apart)
        names = (request.target_frame, *request.source_frames)
        self._respelled = any(normalize_frame(name) != name for name in names)

    def changed(self) -> list[dict[str, object]]:
        """The ``geometry_msgs/TransformStamped`` dicts to send at this tick.

        They are in the internal form of the dialect (``StampedTransform.message``),
        so feedback made of them may be sent unchecked, and shared with every other
        subscription that sends the same lookup: read only. Each returned pair
        counts as sent: later ticks compare against it.
        """
        out: list[dict[str, object]] = []
        request = self.request
        trans_thres, angular_thres = request.trans_thres, request.angular_thres
        every_tick = trans_thres == 0.0 or angular_thres == 0.0
        # computed once per tree version for every subscription asking the same
        results = self.buffer.lookup_each(request.target_frame, request.source_frames)
        for pair, found in zip(self._pairs, results, strict=True):
            if isinstance(found, TFError):
                self._failed(pair, found)
                continue
            pair.failing = False
            sent = pair.sent
            if (
                every_tick
                or sent is None
                or (sent is not found and found.moved_from(sent, trans_thres, angular_thres))
            ):
                pair.sent = found
                message = found.message(self.dialect)
                out.append(self._respell(message, pair) if self._respelled else message)
        return out

    def _respell(self, message: dict[str, object], pair: _Pair) -> dict[str, object]:
        header = message["header"]
        assert isinstance(header, dict)
        header = {**header, "frame_id": self.request.target_frame}
        return {**message, "header": header, "child_frame_id": pair.source}

    def _failed(self, pair: _Pair, error: TFError) -> None:
        if not pair.failing:  # once per failure streak, as the ROS node does
            target = self.request.target_frame
            logger.debug("cannot transform %s to %s: %s", pair.source, target, error.message)
            pair.failing = True
