"""The OpenAPI document's builds run on the event loop, a slice a turn, paced (D59).

``rwt_http.document`` makes the document in slices and keeps it per set of access
rules; here its builds run: one at a time over the server, a turn of the loop
between two slices (so a client waits at most one slice, a few milliseconds,
behind a build), and spaced so that making documents takes at most
``BUILD_SHARE`` of the loop's time however fast the graph changes and clients
ask (a build that took ``t`` seconds is followed by ``t * (1 / BUILD_SHARE - 1)``
seconds without one). Requests that ask while a build for their rules is under
way wait for it, one build for all of them (a ``DocumentSource`` for the
sessions).
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import anyio
import anyio.lowlevel

from rwt_graph.ratelog import EpisodeLog
from rwt_http.document import DocumentCache, rules_key

if TYPE_CHECKING:
    from collections.abc import Callable

    from anyio.abc import TaskGroup

    from rwt_graph.port import GraphFront
    from rwt_http.document import Document, RulesKey
    from rwt_protocol.runtime.access import AccessPolicy

__all__ = ["BUILD_SHARE", "DocumentBuilds"]

logger = logging.getLogger("rwt.http")
_episodes = EpisodeLog(logger)

BUILD_SHARE = 0.5
"""The most of the event loop's time that making OpenAPI documents takes, over time."""


class DocumentBuilds:
    """Runs the builds of one server's OpenAPI documents (a ``rwt_http.document.DocumentSource``).

    Args:
        graph: the served graph.
        version: the server's version, for ``info.version``.
    """

    def __init__(self, graph: GraphFront, version: str) -> None:
        self.cache = DocumentCache(graph, version)
        self._tg: TaskGroup | None = None
        self._waiting: dict[RulesKey, list[Callable[[Document | None], None]]] = {}
        self._lock = anyio.Lock()
        self._next_at = 0.0  # the loop's time before which no build starts (pacing)

    def bind(self, tg: TaskGroup | None) -> None:
        """Run builds in ``tg`` (the server's connections); None: stopping, build no more."""
        self._tg = tg

    def fetch(self, policy: AccessPolicy, ready: Callable[[Document | None], None]) -> None:
        """Call ``ready`` with the document for ``policy`` (``DocumentSource``).

        At once when it is kept and the graph has not changed since; else once a
        build is done, the build under way for the same rules or a new one (None
        if it failed: a bug, logged). Not bound to a task group (not serving), it
        is made here, whole.
        """
        document = self.cache.fresh(policy)
        if document is not None:
            ready(document)
            return
        if self._tg is None:
            document = self.cache.build(policy).run()
            self.cache.keep(policy, document)
            ready(document)
            return
        key = rules_key(policy)
        waiting = self._waiting.get(key)
        if waiting is not None:
            waiting.append(ready)
            return
        self._waiting[key] = [ready]
        self._tg.start_soon(self._build, key, policy)

    async def _build(self, key: RulesKey, policy: AccessPolicy) -> None:
        """Make the document for ``policy`` when the pace allows, then answer who waits."""
        document: Document | None = None
        try:
            async with self._lock:
                await anyio.sleep(max(0.0, self._next_at - anyio.current_time()))
                start = anyio.current_time()
                build = self.cache.build(policy)
                while not build.step():
                    await anyio.lowlevel.checkpoint()  # a turn of the loop for everyone else
                spent = anyio.current_time() - start
                self._next_at = anyio.current_time() + spent * (1 / BUILD_SHARE - 1)
            document = build.document
            if document is not None:
                self.cache.keep(policy, document)
        except Exception:  # a bug: the requests waiting for it get a 500, the server goes on
            _episodes.log(logging.ERROR, "openapi_build", "event=bug where=openapi", exc_info=True)
        finally:
            waiting = self._waiting.pop(key, [])
        for ready in waiting:
            try:
                ready(document)
            except Exception:  # one session's bug: the others still get theirs
                _episodes.log(
                    logging.ERROR, "openapi_ready", "event=bug where=openapi_ready", exc_info=True
                )
