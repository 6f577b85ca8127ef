"""Log lines a peer can trigger at will, once per episode with counts (docs/limits.md).

Anything a client, a Zenoh peer, a ROS 2 node or a bag can cause on every message
(a refused sample, a bad seek, a deep parameter value) must not let that peer
write the server's log at its own rate: one line per request is a disk-filling
amplifier. ``EpisodeLog`` writes the first line of an episode of one kind of
trouble, counts the repeats silently, and when the episode ends (no repeat for
``quiet_s`` seconds) or at most every ``every_s`` seconds while it goes on, writes
one line with the count. Tracebacks are kept for the first line only.

The protocol core reads no clock: its callers pass ``now`` (the monotonic
seconds a session is given); ``rwt_graph.ratelog.EpisodeLog`` is this class
reading ``time.monotonic`` itself, for everything above the core.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import logging
    from collections.abc import Callable

__all__ = ["EpisodeLog"]

#: Kinds of trouble remembered at once; past it the oldest episode is closed
#: (its count logged), so a peer inventing keys cannot grow this table.
MAX_KINDS = 256


@dataclass
class _Episode:
    first: float
    last: float
    reported: float
    repeats: int = 0


class EpisodeLog:
    """Rate-limits one logger's lines per kind of trouble (a key the caller picks).

    Args:
        logger: where lines go.
        every_s: while an episode goes on, a summary line at most this often (seconds).
        quiet_s: an episode ends after this many seconds without a repeat (seconds).
        clock: monotonic seconds; None when every caller passes ``now`` to ``log``.
    """

    def __init__(
        self,
        logger: logging.Logger,
        *,
        every_s: float = 10.0,
        quiet_s: float = 10.0,
        clock: Callable[[], float] | None = None,
    ) -> None:
        self.logger = logger
        self.every_s = every_s
        self.quiet_s = quiet_s
        self._clock = clock
        self._episodes: dict[str, _Episode] = {}

    def log(
        self,
        level: int,
        key: str,
        msg: str,
        *args: object,
        exc_info: bool = False,
        now: float | None = None,
    ) -> bool:
        """Log ``msg % args`` if it opens an episode of ``key``; else count it.

        Args:
            level: the logging level of the line.
            key: the kind of trouble (bounded: at most ``MAX_KINDS`` are kept).
            msg: the line, %-formatted with ``args``.
            *args: the values of ``msg``.
            exc_info: attach the current exception's traceback (first line only).
            now: monotonic seconds; by default the clock's.

        Returns:
            True when a line was written (the first of an episode, or a summary).

        Raises:
            ValueError: no ``now`` and no clock.
        """
        if now is None:
            if self._clock is None:
                raise ValueError("EpisodeLog.log needs now= when it has no clock")
            now = self._clock()
        episode = self._episodes.get(key)
        if episode is not None and now - episode.last > self.quiet_s:
            self._close(key, episode)
            episode = None
        if episode is None:
            if len(self._episodes) >= MAX_KINDS:
                oldest = next(iter(self._episodes))
                self._close(oldest, self._episodes[oldest])
            self._episodes[key] = _Episode(first=now, last=now, reported=now)
            self.logger.log(level, msg, *args, exc_info=exc_info)
            return True
        episode.repeats += 1
        episode.last = now
        if now - episode.reported < self.every_s:
            return False
        self.logger.log(
            level,
            msg + " (repeated %d times in %.0f s)",
            *args,
            episode.repeats,
            now - episode.first,
        )
        episode.reported = now
        return True

    def _close(self, key: str, episode: _Episode) -> None:
        del self._episodes[key]
        if episode.repeats:
            self.logger.info(
                "event=log_episode_end kind=%s repeats=%d seconds=%.0f",
                key,
                episode.repeats,
                episode.last - episode.first,
            )
