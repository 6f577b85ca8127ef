"""The OpenAPI document made in slices, once per change of the graph, and kept (D59).

A graph of 5,000 topics makes a 12 MB document that took 0.15 s of CPU to make;
made for every request on the event loop, four clients fetching it took a core.
So a document is made by a ``DocumentBuild``, a slice at a time
(``STEP_ENTITIES`` entities, a few milliseconds, ``step``), which its driver
(``rwt_transports.http.documents``) runs with a turn of the loop between two
slices, and is kept by a ``DocumentCache``, one per served graph, by the access
rules it was made for. It is made again only when the graph's change feed
moved (``ChangeFeed.version``) and what the document lists changed with it: a
client that subscribes to a listed topic moves the feed but not the document,
which is then kept as it is (its bytes and its ETag), at the cost of one pass
over the entities (sliced too). Its ETag (a hash of its bytes) lets a client ask
``If-None-Match`` and get 304.

The driver's side of it, what a session asks: ``DocumentSource``.
"""

from __future__ import annotations

import hashlib
import logging
from collections import OrderedDict
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from rwt_graph.feed import EntityKind
from rwt_graph.visibility import Visibility
from rwt_protocol.codecs.json import encode_json
from rwt_protocol.errors import RwtError
from rwt_protocol.runtime.access import Family, TopicUse

from .openapi import Entry, document_prefix, document_suffix, listing_path, paths_of

if TYPE_CHECKING:
    from collections.abc import Callable, Generator, Iterator

    from rwt_graph.feed import GraphChange
    from rwt_graph.port import GraphFront
    from rwt_protocol.runtime.access import AccessPolicy

__all__ = [
    "DOCUMENTS_KEPT",
    "STEP_ENTITIES",
    "Document",
    "DocumentBuild",
    "DocumentCache",
    "DocumentSource",
    "rules_key",
]

logger = logging.getLogger("rwt.http")

STEP_ENTITIES = 200
"""Entities of the graph one slice of a build looks at or writes the paths of (about 5 ms
at 5,000 topics: the longest the build holds the event loop)."""

DOCUMENTS_KEPT = 4
"""Documents a cache keeps, one per set of access rules (a server has one set per transport)."""

_FAMILIES = {
    EntityKind.PUBLISHER: Family.TOPICS,
    EntityKind.SUBSCRIPTION: Family.TOPICS,
    EntityKind.SERVICE: Family.SERVICES,
    EntityKind.ACTION: Family.ACTIONS,
}
_ORDER = {Family.TOPICS: 0, Family.SERVICES: 1, Family.ACTIONS: 2}

RulesKey = tuple[tuple[str, ...] | None, ...]


def rules_key(policy: AccessPolicy) -> RulesKey:
    """What tells two access policies apart for the document (their patterns)."""
    fields = (
        policy.topics,
        policy.services,
        policy.params,
        policy.actions,
        policy.topics_pub,
        policy.topics_sub,
    )
    return tuple(None if value is None else tuple(value) for value in fields)


@dataclass(frozen=True, slots=True)
class Document:
    """A made document.

    Attributes:
        body: its JSON text (shared by every response that sends it, never copied).
        etag: its strong entity tag, quoted (``"3f2a..."``): a hash of ``body``.
        feed_version: the graph's change feed version it shows.
        entries: what it lists (the build compares them to reuse ``body``).
    """

    body: bytes
    etag: str
    feed_version: int
    entries: tuple[Entry, ...]

    def matches(self, if_none_match: str | None) -> bool:
        """Whether ``If-None-Match: if_none_match`` names this document (RFC 9110 13.1.2).

        ``*`` matches; entity tags compare weakly (a ``W/`` prefix is ignored).
        """
        if not if_none_match:
            return False
        tags = (tag.strip() for tag in if_none_match.split(","))
        return any(tag == "*" or tag.removeprefix("W/") == self.etag for tag in tags)


class DocumentBuild:
    """One making of the document for one set of access rules, in slices (``step``).

    It shows the graph as its change feed stood when the build began (a
    snapshot); the graph may change between slices without harm.

    Args:
        graph: the served graph (its feed for the entities, its registry for the types).
        policy: the client's access rules: what it may see and do.
        version: the server's version, for ``info.version``.
        kept: the document kept for these rules, if any: reused whole when it
            lists what the graph lists now.
    """

    def __init__(
        self, graph: GraphFront, policy: AccessPolicy, version: str, kept: Document | None = None
    ) -> None:
        self.graph = graph
        self.policy = policy
        self.version = version
        self.kept = kept
        self.feed_version, self._entities = graph.feed.snapshot()
        self.document: Document | None = None
        """The document, once ``step`` said it is done."""
        self._steps = self._run()

    def step(self) -> bool:
        """Make one slice (at most ``STEP_ENTITIES`` entities); True once ``document`` is set."""
        if self.document is not None:
            return True
        for _ in self._steps:
            return False
        return True

    def run(self) -> Document:
        """Make the whole document at once (no event loop to share: a test, a tool)."""
        while not self.step():
            pass
        assert self.document is not None
        return self.document

    def _run(self) -> Iterator[None]:
        entries = yield from self._entries()
        kept = self.kept
        if kept is not None and kept.entries == entries:  # the change did not touch it
            self.document = Document(kept.body, kept.etag, self.feed_version, entries)
            return
        digest = hashlib.blake2b(digest_size=16)
        parts: list[bytes] = []

        def add(part: bytes) -> None:
            parts.append(part)
            digest.update(part)

        add(document_prefix(self.version))
        add(encode_json(listing_path())[1:-1])
        schemas: dict[str, object] = {}
        for start in range(0, len(entries), STEP_ENTITIES):
            paths: dict[str, object] = {}
            for entry in entries[start : start + STEP_ENTITIES]:
                try:
                    paths.update(paths_of(self.graph, entry, schemas))
                except RwtError as exc:  # a type the registry cannot resolve: left out
                    logger.debug("event=openapi_skipped name=%s reason=%r", entry.name, str(exc))
            if paths:
                add(b"," + encode_json(paths)[1:-1])
            yield
        add(document_suffix(schemas))
        body = b"".join(parts)
        self.document = Document(body, f'"{digest.hexdigest()}"', self.feed_version, entries)

    def _entries(self) -> Generator[None, None, tuple[Entry, ...]]:
        """What the document lists, sorted (a generator: a slice a step); its value the entries."""
        visibility = Visibility.of(self.policy)
        topics: dict[str, GraphChange] = {}
        others: dict[tuple[Family, str], str] = {}
        entities = self._entities
        for start in range(0, len(entities), STEP_ENTITIES):
            for change in entities[start : start + STEP_ENTITIES]:
                if not visibility.sees(change):
                    continue
                family = _FAMILIES[change.kind]
                if family is not Family.TOPICS:
                    others.setdefault((family, change.name), change.type_name)
                elif change.kind is EntityKind.PUBLISHER or change.name not in topics:
                    topics[change.name] = change  # a publisher's type is what a GET answers
            yield
        self._entities = []
        entries = [self._topic(change) for change in topics.values()]
        entries += [Entry(family, name, type_name) for (family, name), type_name in others.items()]
        entries.sort(key=lambda entry: (_ORDER[entry.family], entry.name))
        return tuple(entries)

    def _topic(self, change: GraphChange) -> Entry:
        """A visible topic with what the rules let the client do with it (D50)."""
        policy = self.policy
        if not policy.restricted:
            return Entry(Family.TOPICS, change.name, change.type_name)
        read = policy.allows(Family.TOPICS, change.name, TopicUse.SUBSCRIBE)
        write = policy.allows(Family.TOPICS, change.name, TopicUse.PUBLISH)
        return Entry(Family.TOPICS, change.name, change.type_name, read, write)


class DocumentCache:
    """The documents of one served graph, one per set of access rules (``DOCUMENTS_KEPT``).

    Args:
        graph: the served graph.
        version: the server's version, for ``info.version``.
    """

    def __init__(self, graph: GraphFront, version: str) -> None:
        self.graph = graph
        self.version = version
        self._kept: OrderedDict[RulesKey, Document] = OrderedDict()

    def fresh(self, policy: AccessPolicy) -> Document | None:
        """The document kept for ``policy`` if the graph has not changed since; else None."""
        key = rules_key(policy)
        document = self._kept.get(key)
        if document is None or document.feed_version != self.graph.feed.version:
            return None
        self._kept.move_to_end(key)
        return document

    def build(self, policy: AccessPolicy) -> DocumentBuild:
        """A new build for ``policy`` (reusing the kept document if the change spared it)."""
        return DocumentBuild(self.graph, policy, self.version, self._kept.get(rules_key(policy)))

    def keep(self, policy: AccessPolicy, document: Document) -> None:
        """Keep ``document`` for ``policy`` (the least recently used set of rules goes)."""
        key = rules_key(policy)
        self._kept[key] = document
        self._kept.move_to_end(key)
        while len(self._kept) > DOCUMENTS_KEPT:
            self._kept.popitem(last=False)


class DocumentSource(Protocol):
    """Where a session gets the document: made once, in slices, off its own call."""

    def fetch(self, policy: AccessPolicy, ready: Callable[[Document | None], None]) -> None:
        """Call ``ready`` with the document for ``policy``.

        At once if it is kept and fresh, else on the event loop once its build is
        done (None: the build failed, a bug).
        """
