"""File-descriptor budget: the RLIMIT_NOFILE soft limit and the connections it allows.

Every connection holds a descriptor from ``accept()`` on, so a server whose
connections may outnumber its descriptor limit fails ``accept()`` with EMFILE.
``rwt serve`` raises the soft limit to the hard one at start-up, as production
servers do (``--no-raise-fd-limit`` keeps it), and when ``--max-connections`` is
not given derives it from the soft limit, keeping a reserve for listeners, log
and interface files, the video server and the sockets a full server holds to
refuse newcomers (docs/limits.md).
"""

from __future__ import annotations

import logging
import resource  # POSIX, as the rest of the server (non-blocking descriptors, signals)

__all__ = ["FD_RESERVE", "REFUSING_SOCKETS", "default_max_connections", "raise_nofile_limit"]

logger = logging.getLogger("rwt.server")

FD_RESERVE = 128
"""Descriptors kept out of ``--max-connections``: listeners, the UDP socket, the event
loop's own, log and interface files, and the video server's clients (at most half of a
small limit)."""

REFUSING_SOCKETS = 16
"""Sockets a server at ``--max-connections`` still accepts, only to refuse them (HTTP 503
or a "too many connections" status); beyond them it stops accepting until one closes."""


def raise_nofile_limit() -> None:
    """Raise the RLIMIT_NOFILE soft limit to the hard limit (capped at 1 Mi), and log both.

    Never raises: a refused ``setrlimit`` keeps the current limit (logged).
    """
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = hard if hard != resource.RLIM_INFINITY else 1 << 20
    target = min(target, 1 << 20)
    if soft != resource.RLIM_INFINITY and soft < target:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
        except (OSError, ValueError) as exc:
            logger.warning("event=fd_limit soft=%d hard=%d raise_failed=%r", soft, hard, str(exc))
            return
        logger.info("event=fd_limit soft=%d hard=%d raised_from=%d", target, hard, soft)
        return
    logger.info("event=fd_limit soft=%d hard=%d", soft, hard)


def default_max_connections() -> int | None:
    """``--max-connections`` when not given: the soft RLIMIT_NOFILE minus the reserves.

    That is ``soft - min(FD_RESERVE, soft // 2) - REFUSING_SOCKETS``, at least 1; None
    (no limit) when the soft limit is unlimited.
    """
    soft = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    if soft == resource.RLIM_INFINITY:
        return None
    return max(1, soft - min(FD_RESERVE, soft // 2) - REFUSING_SOCKETS)
