"""Reading bags for replay: opening, checking types, decoding to the graph's form.

``BagSource`` opens ROS 1 bags and ROS 2 bags (sqlite3, MCAP) with rosbags'
``AnyReader`` and checks, before anything is published, that every type to play
is one the graph knows with the same fields as the bag's own definition (a bag
recorded with another version of a message would otherwise be published under
the graph's definition with wrong values). Each message is deserialized with
the bag's definitions and converted to the graph's internal form, checked like
any publication (D7-D10).
"""

from __future__ import annotations

import fnmatch
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rosbags.highlevel import AnyReader
from rosbags.interfaces import Nodetype, QosDurability

from rwt_graph.types import Dialect
from rwt_graph.types.wire import read_cdr, wire_input
from rwt_protocol.errors import GraphError
from rwt_protocol.names import name_problem

from .errors import BagError
from .inflate import ReadBudget
from .ros1read import chunk_messages

if TYPE_CHECKING:
    from collections.abc import Iterator, Sequence

    from rosbags.typesys.store import Typestore

    from rwt_graph.types import MessageType, TypeRegistry

__all__ = ["BagItem", "BagSource", "BagTopic", "is_latched", "shown_name", "shown_text"]

logger = logging.getLogger("rwt.bag")

#: Topics replayed latched even when the bag keeps no QoS (rosbags' writer adds
#: none by default): static transforms, and maps by their type.
LATCHED_TOPICS = frozenset({"/tf_static"})
LATCHED_TYPES = frozenset({"nav_msgs/msg/OccupancyGrid"})
#: Skipped topics named in a log line or an error, and the characters shown of
#: each: a bag of thousands of 5000-character names still logs one short line.
_NAMED = 5
_SHOWN_LENGTH = 60
#: The longest printable text of a bag (a type name) shown as it is.
_PLAIN_LENGTH = 200


@dataclass(frozen=True)
class BagTopic:
    """One topic of a bag as it will be played.

    Attributes:
        topic: the name.
        msgtype: rosbags' name of its type (``tf2_msgs/msg/TFMessage``).
        mtype: the graph's type.
        latched: published latched (D13).
        count: messages in the bag.
    """

    topic: str
    msgtype: str
    mtype: MessageType
    latched: bool
    count: int


BagItem = tuple[BagTopic, int, dict[str, object], bytes]
"""One message of a bag: its topic, bag time (ns), internal form and serialized record."""


def is_latched(topic: str, msgtype: str, ext: object) -> bool:
    """Whether a bag's connection is latched: its QoS or header says so, or by name/type."""
    if topic in LATCHED_TOPICS or msgtype in LATCHED_TYPES:
        return True
    if getattr(ext, "latching", None):
        return True
    profiles = getattr(ext, "offered_qos_profiles", None) or ()
    return any(p.durability == QosDurability.TRANSIENT_LOCAL for p in profiles)


def _shape(store: Typestore, name: str, seen: frozenset[str] = frozenset()) -> object:
    """The fields of ``name`` with nested types expanded: what two definitions must share."""
    if name in seen:
        return name
    _, fields = store.fielddefs[name]
    return tuple((fname, _node_shape(store, node, seen | {name})) for fname, node in fields)


def _node_shape(store: Typestore, node: Any, seen: frozenset[str]) -> object:
    kind, detail = node
    if kind == Nodetype.NAME:
        return _shape(store, detail, seen)
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        element, length = detail
        return (int(kind), _node_shape(store, element, seen), length)
    return detail


def last_ns(reader: AnyReader) -> int:
    """The time of a bag's last message: rosbags' ``end_time`` is one nanosecond past it."""
    return max(int(reader.start_time), int(reader.end_time) - 1)


class BagSource:
    """One or more bag files (split parts) read as one, in time order.

    Args:
        paths: the bag files (ROS 1 ``.bag``) or folders (ROS 2).
        registry: the graph's types.
        topics: glob patterns of the topics to play; all by default.

    Raises:
        BagError: a file cannot be opened (missing, truncated, not a bag), or a
            topic's type is unknown to the graph or defined differently; the
            text names the file, topic and type.
    """

    def __init__(
        self, paths: Sequence[Path | str], registry: TypeRegistry, topics: Sequence[str] = ()
    ) -> None:
        self.paths = [Path(p) for p in paths]
        self._registry = registry
        try:
            self._reader = AnyReader(self.paths, default_typestore=registry.typestore())
            with ReadBudget.for_paths(self.paths).active():  # a summary-less MCAP is scanned
                self._reader.open()
        except BagError:  # past a decompression limit: the text names the bag already
            raise
        except Exception as exc:  # rosbags raises its own errors, OSError, struct/zstd errors
            raise BagError(f"cannot read {_names(self.paths)}: {_reason(exc)}") from exc
        try:
            chosen = self._valid_names(self._chosen(topics))
            self.connections = chosen
            #: times of the first and last message, ns since the epoch (kept after close)
            self.start_ns = int(self._reader.start_time)
            self.end_ns = last_ns(self._reader)
            self.topics = self._check(chosen)
        except BagError:
            self._reader.close()
            raise

    def _chosen(self, topics: Sequence[str]) -> list[Any]:
        """The connections whose topic matches one of the glob patterns ``topics`` (all: ``*``).

        Raises:
            BagError: the bag has topics but the patterns match none of them.
        """
        patterns = tuple(topics) or ("*",)
        every = self._reader.connections
        chosen = [c for c in every if any(fnmatch.fnmatchcase(c.topic, p) for p in patterns)]
        if every and not chosen:
            raise BagError(
                f"cannot play {_names(self.paths)}: none of its {_topic_count(every)} "
                f"matches the topics to play ({_listed(patterns)})"
            )
        return chosen

    def _valid_names(self, connections: list[Any]) -> list[Any]:
        """The connections whose topic is a name a client's ``advertise`` would accept.

        A bag is input like any client's (docs/limits.md): ``/x y``, ``/../..``,
        control characters or a 5000-character name are skipped, with one log
        line naming the bag, how many were skipped, the first ``_NAMED`` of
        them (escaped and cut: ``shown_name``) and the first reason.

        Raises:
            BagError: every connection is skipped, so nothing could be played.
        """
        kept: list[Any] = []
        skipped: dict[str, str] = {}  # name -> problem, in the bag's order, once each
        for conn in connections:
            problem = name_problem(conn.topic)
            if problem is None:
                kept.append(conn)
            else:  # split parts (and ROS 1 bags) may hold a topic in several connections
                skipped.setdefault(conn.topic, problem)
        if not skipped:
            return kept
        first = next(iter(skipped.values()))
        if not kept:
            raise BagError(
                f"cannot play {_names(self.paths)}: no topic to play has a valid name "
                f"({len(skipped)} skipped: {_listed(list(skipped))}): {first}"
            )
        logger.warning(
            "event=bag_topics_skipped bag=%s count=%d topics=%s reason=%s",
            _names(self.paths),
            len(skipped),
            _listed(list(skipped)),
            first,
        )
        return kept

    def _check(self, connections: list[Any]) -> dict[int, BagTopic]:
        """The graph's type of each connection (by id), refusing unknown or conflicting ones."""
        found: dict[int, BagTopic] = {}
        graph_store = self._registry.typestore()
        for conn in connections:
            where = f"{_names(self.paths)}: topic {conn.topic} (type {shown_text(conn.msgtype)})"
            try:
                mtype = self._registry.message(conn.msgtype)
            except GraphError as exc:
                raise BagError(f"{where}: {exc}") from exc
            if mtype.rosbags_name not in graph_store.fielddefs:
                raise BagError(f"{where}: the graph cannot serialize this type")
            ours = _shape(graph_store, mtype.rosbags_name)
            theirs = _shape(self._reader.typestore, conn.msgtype)
            if ours != theirs:
                raise BagError(
                    f"{where}: the bag's definition differs from the graph's "
                    f"({self._registry.dialect.value} {mtype.name}){self._dialect_hint()}"
                )
            latched = is_latched(conn.topic, conn.msgtype, conn.ext)
            found[conn.id] = BagTopic(conn.topic, conn.msgtype, mtype, latched, conn.msgcount)
        return found

    def _dialect_hint(self) -> str:
        """A hint when the bag's ROS version is not the graph's dialect."""
        bag_ros1 = not self._reader.is2
        if bag_ros1 == (self._registry.dialect is Dialect.ROS1):
            return ""
        wanted = "ros1" if bag_ros1 else "ros2"
        return f"; a ROS {1 if bag_ros1 else 2} bag plays on a {wanted} graph (--dialect {wanted})"

    def messages(self, start_ns: int | None = None) -> Iterator[BagItem]:
        """Each message from ``start_ns`` on, as ``(topic, bag time ns, message, record)``.

        ``record`` is the message's serialization as the bag holds it (CDR, or
        ROS 1's), which replay passes on to subscribers that send that form.

        Raises:
            BagError: as ``batches``.
        """
        for batch in self.batches(start_ns):
            yield from batch

    def batches(
        self,
        start_ns: int | None = None,
        *,
        max_messages: int = 512,
        max_bytes: int = 1024 * 1024,
    ) -> Iterator[list[BagItem]]:
        """The messages of ``messages`` in lists of up to ``max_messages`` or ``max_bytes``.

        A list ends at the first message that reaches either bound; the last may
        be shorter, and none is empty. The decompression budget is set once per
        list, not per message (a context variable set and reset each time).

        Raises:
            BagError: a message cannot be read or decoded (names topic and type), or
                the pass decompresses past the limits of ``rwt_bag.inflate``.
        """
        if not self.connections:  # rosbags reads every connection when given none
            return
        budget = ReadBudget.for_paths(self.paths)  # one per pass: bounded work per read
        items = chunk_messages(self._reader, self.connections, start_ns)
        if items is None:
            items = self._reader.messages(connections=self.connections, start=start_ns)
        while True:
            with budget.active():
                batch = self._take(items, max_messages, max_bytes)
            if not batch:
                return
            yield batch

    def _take(
        self, items: Iterator[tuple[Any, int, bytes]], max_messages: int, max_bytes: int
    ) -> list[BagItem]:
        """Read and decode the next messages of ``items`` up to the bounds of ``batches``."""
        reader = self._reader
        deserialize = (
            (lambda raw, msgtype: read_cdr(reader.typestore, raw, msgtype))  # trailing bytes
            if reader.is2
            else reader.typestore.deserialize_ros1
        )
        topics, convert = self.topics, self._convert
        batch: list[BagItem] = []
        size = 0
        while len(batch) < max_messages and size < max_bytes:
            try:
                conn, ns, raw = next(items)
            except StopIteration:
                break
            except BagError:
                raise
            except Exception as exc:
                raise BagError(f"cannot read {_names(self.paths)}: {_reason(exc)}") from exc
            topic = topics[conn.id]
            try:
                msg = convert(topic.mtype, deserialize(wire_input(raw), conn.msgtype))
            except Exception as exc:  # a corrupt payload: rosbags raises struct/index errors
                raise BagError(
                    f"{_names(self.paths)}: a message of {topic.topic} (type {topic.msgtype}) "
                    f"at {ns} ns cannot be decoded: {_reason(exc)}"
                ) from exc
            batch.append((topic, ns, msg, raw if type(raw) is bytes else bytes(raw)))
            size += len(raw)
        return batch

    def _convert(self, mtype: MessageType, obj: object) -> dict[str, object]:
        """A rosbags message in the graph's internal form, checked (D7-D10).

        rosbags' values are already well typed, so the fast path (one check per
        field, no conversion) takes nearly every message; the full conversion
        is the fallback, as for ``MessageType.from_python``.
        """
        plain = mtype.plain_from_rosbags(obj)
        fast = mtype.fast(plain)
        return fast if fast is not None else mtype.from_json(plain, now=0.0).msg

    def check_all(self) -> int:
        """Read and decode every message once (before playing), returning the count.

        Raises:
            BagError: as ``messages``.
        """
        return sum(1 for _ in self.messages())

    def close(self) -> None:
        """Close the files."""
        self._reader.close()


def _names(paths: Sequence[Path]) -> str:
    return ", ".join(str(p) for p in paths)


def shown_name(name: str) -> str:
    """A name from a bag as a log line or an error shows it: quoted, escaped, cut.

    Control, bidirectional and non-ASCII characters (a lone surrogate too) are
    escaped as Python's ``ascii`` does, so a hostile bag cannot write them to a
    terminal or break a log line's encoding; past 60 characters it is cut.
    """
    return ascii(name if len(name) <= _SHOWN_LENGTH else name[: _SHOWN_LENGTH - 3] + "...")


def shown_text(text: str) -> str:
    """A text from a bag (a type name, a format) as it is when printable and short, else escaped.

    Up to 200 printable characters are shown as they are; others as ``shown_name``.
    """
    return text if text.isprintable() and len(text) <= _PLAIN_LENGTH else shown_name(text)


def _listed(names: Sequence[str]) -> str:
    """The first ``_NAMED`` of ``names`` shown, comma-separated, with a count of the rest."""
    shown = ",".join(shown_name(n) for n in names[:_NAMED])
    more = len(names) - _NAMED
    return shown if more <= 0 else f"{shown},... ({more} more)"


def _topic_count(connections: Sequence[Any]) -> str:
    count = len({c.topic for c in connections})
    return f"{count} topic" if count == 1 else f"{count} topics"


def _reason(exc: BaseException) -> str:
    return str(exc) or type(exc).__name__
