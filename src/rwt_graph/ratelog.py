"""``EpisodeLog`` with the process's clock: peer-triggered log lines once per episode.

The class and its rule are ``rwt_protocol.ratelog``'s (docs/limits.md, "Logs a peer
can trigger"); the protocol core passes the time in, and here it reads
``time.monotonic`` by default.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from rwt_protocol.ratelog import MAX_KINDS
from rwt_protocol.ratelog import EpisodeLog as _EpisodeLog

if TYPE_CHECKING:
    import logging
    from collections.abc import Callable

__all__ = ["MAX_KINDS", "EpisodeLog"]


class EpisodeLog(_EpisodeLog):
    """Rate-limits one logger's lines per kind of trouble (a key the caller picks).

    Args:
        logger: where lines go.
        every_s: while an episode goes on, a summary line at most this often (seconds).
        quiet_s: an episode ends after this many seconds without a repeat (seconds).
        clock: monotonic seconds; injectable for tests.
    """

    def __init__(
        self,
        logger: logging.Logger,
        *,
        every_s: float = 10.0,
        quiet_s: float = 10.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(logger, every_s=every_s, quiet_s=quiet_s, clock=clock)
