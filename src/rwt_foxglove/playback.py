"""The ``playbackControl`` capability: Foxglove's playback bar drives a played bag.

While a bag plays into the graph (``rwt serve --play``, the embedding API's
``Player``), the graph offers the player as its ``playback``
(``rwt_graph.playback``). A client that connects then is told the capability and
the bag's time range (``serverInfo``'s ``dataStartTime``/``dataEndTime``), and its
playback control requests (binary ``0x03``) are applied in the SDK's order: the
seek, then the speed, then play or pause. Each is answered with a playback
state (binary ``0x05``) that carries the request's id.

Every other client with the capability learns of the change from its own time
tick (``servertime.TIME_INTERVAL_S``): a session sends a state without request
id whenever the status, the speed or the count of jumps (seeks, loop restarts)
differs from what it last told its client. That needs no registry of sessions,
and it also tells of changes made elsewhere (the ``/rwt/player/*`` services, the
terminal's keys, the bag's end). docs/foxglove.md has the mapping.
"""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING, Final

from rwt_graph.playback import PlaybackStatus, rate_problem

from .limits import MAX_PLAYBACK_REQUEST_ID_BYTES
from .protocol import (
    FoxgloveInputError,
    PlaybackCommand,
    PlaybackStatusCode,
    Timestamp,
    encode_playback_state,
)

if TYPE_CHECKING:
    from rwt_graph.playback import Playback

    from .protocol import PlaybackControlRequest

__all__ = ["PLAYBACK_CAPABILITY", "PlaybackControl"]

PLAYBACK_CAPABILITY: Final = "playbackControl"

_CODES: Final = {
    PlaybackStatus.PLAYING: PlaybackStatusCode.PLAYING,
    PlaybackStatus.PAUSED: PlaybackStatusCode.PAUSED,
    PlaybackStatus.ENDED: PlaybackStatusCode.ENDED,
}
_F32: Final = struct.Struct("<f")
_F32_MAX: Final = 3.4028234663852886e38


def _f32(value: float) -> float:
    """``value`` as the 32-bit float the wire carries (huge rates clamped to its largest)."""
    return float(_F32.unpack(_F32.pack(min(value, _F32_MAX)))[0])


def _shortest(speed: float) -> float:
    """The shortest decimal that is ``speed`` as a 32-bit float (0.1, not 0.10000000149).

    So the player's rate (``/rwt/player/get_status``) reads as the user chose it.
    """
    for digits in range(1, 10):  # 9 significant digits always round-trip a float32
        decimal = float(f"{speed:.{digits}g}")
        if _f32(decimal) == speed:
            return decimal
    return speed


class PlaybackControl:
    """One client's view of the graph's player: requests applied, states told.

    Args:
        playback: the player the graph offered when the client connected; it
            stays this client's (a player whose ``run`` ended reports ended).
    """

    __slots__ = ("_playback", "_told")

    def __init__(self, playback: Playback) -> None:
        self._playback = playback
        # (status, speed as f32, jumps) of the last state told to this client
        self._told: tuple[PlaybackStatus, float, int] | None = None

    def time_range(self) -> tuple[Timestamp, Timestamp]:
        """``serverInfo``'s ``dataStartTime`` and ``dataEndTime``: the bag's range."""
        first, last = self._playback.time_range_ns
        return Timestamp.of(first), Timestamp.of(last)

    def apply(self, request: PlaybackControlRequest) -> bytes:
        """Apply ``request`` (seek clamped to the range, speed, play or pause).

        Returns:
            The playback state frame that answers it, with its request id;
            ``did_seek`` is set when it sought.

        Raises:
            FoxgloveInputError: the request id is longer than
                ``MAX_PLAYBACK_REQUEST_ID_BYTES``, or the speed is one the player
                refuses (``rwt_graph.playback.rate_problem``: outside 0.001 to
                1000000); nothing is applied.
        """
        size = len(request.request_id.encode())
        if size > MAX_PLAYBACK_REQUEST_ID_BYTES:
            raise FoxgloveInputError(
                f"playback control request: a request id of {size} bytes "
                f"(at most {MAX_PLAYBACK_REQUEST_ID_BYTES})"
            )
        playback = self._playback
        rate = None
        if _f32(playback.rate) != request.speed:  # the speed came as f32: compare as one
            rate = _shortest(request.speed)
            problem = rate_problem(rate)  # asked before the seek: all of it or nothing
            if problem is not None:
                raise FoxgloveInputError(f"playback control request: {problem}")
        if request.seek_ns is not None:
            playback.seek_ns(request.seek_ns)
        if rate is not None:
            playback.set_rate(rate)
        if request.command is PlaybackCommand.PLAY:
            playback.resume()
        else:
            playback.pause()
        return self._state(request.request_id, sought=request.seek_ns is not None)

    def frame(self) -> bytes | None:
        """A state without request id when the playback changed since last told, else None."""
        playback = self._playback
        now = (playback.status, _f32(playback.rate), playback.jumps)
        if now == self._told:
            return None
        return self._state("", sought=False)

    def _state(self, request_id: str, *, sought: bool) -> bytes:
        playback = self._playback
        status, speed, jumps = playback.status, _f32(playback.rate), playback.jumps
        told, self._told = self._told, (status, speed, jumps)
        # a jump this client has not been told of (another client's seek, a loop)
        jumped = told is not None and told[2] != jumps
        return encode_playback_state(
            _CODES[status],
            playback.clock_ns(),
            speed,
            did_seek=sought or jumped,
            request_id=request_id,
        )
