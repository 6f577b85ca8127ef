"""The safety rules: what remote clients may command, read from a TOML file or built in Python.

A rules file (``rwt serve --safety FILE``, docs/safety.md) holds one ``[[topic]]`` table
per bounded topic and ``[[service]]``/``[[action]]`` tables for calls that need a
person's approval. This module reads its shape: the keys, their types and ranges, and
where each key is (its line), so that a later check against the message types
(``fields``, ``envelope``) can name the line too. It knows no message type.

A file that does not parse, or has a key it does not know, a value of the wrong type
or out of range, or one topic twice, is refused with ``RulesError``, naming the
file and the line (D66).
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from rwt_protocol.errors import ConfigError
from rwt_protocol.names import name_problem, resolve_name

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

    _Fail = Callable[[str, str], "RulesError"]

__all__ = [
    "APPROVAL_TIMEOUT_S",
    "CallRule",
    "RulesError",
    "SafetyRules",
    "TopicRule",
    "load_rules",
    "parse_rules",
]

APPROVAL_TIMEOUT_S = 60.0
"""Seconds a person has to answer an approval by default (``approval_timeout_s``)."""
MAX_APPROVAL_TIMEOUT_S = 3600.0
"""The longest ``approval_timeout_s`` a file may set (an hour)."""
MAX_RULES = 1024
"""Topic, service and action tables a file may hold together."""

Violation = Literal["clamp", "reject"]

_TOPIC_KEYS = frozenset(
    {"name", "type", "bounds", "on_violation", "max_rate_hz", "deadman_s", "stop", "approval"}
)
_CALL_KEYS = frozenset({"name", "approval"})
_TOP_KEYS = frozenset({"topic", "service", "action", "approval_timeout_s"})


class RulesError(ConfigError):
    """Safety rules that cannot be used; the text names the file and the line (D66).

    Args:
        message: ``FILE line N: what is wrong``, or ``FILE: ...`` where no line is known.
    """


@dataclass(frozen=True)
class TopicRule:
    """What a remote client may publish on one topic (docs/safety.md).

    Attributes:
        name: the topic (resolved: ``/cmd_vel``).
        type: its message type, in any spelling (``geometry_msgs/msg/Twist``).
        bounds: dotted field path (``linear.x``, ``position[0]``, ``position[*]``) ->
            ``(min, max)``, inclusive, in the field's units.
        on_violation: ``clamp`` (the message goes on with the field clamped) or
            ``reject`` (an error, nothing delivered).
        max_rate_hz: commands a second the topic takes from remote clients
            together; None: no limit.
        deadman_s: seconds without a command after which ``stop`` is published;
            None: no dead-man.
        stop: the message published by the dead-man (JSON form), or None.
        approval: an MCP agent's publish waits for a person's yes.
        lines: the line of each key (``bounds.linear.x``, ``stop``) in its file, for errors.
        source: the file it came from (for errors), or "" when built in Python.
    """

    name: str
    type: str
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    on_violation: Violation = "reject"
    max_rate_hz: float | None = None
    deadman_s: float | None = None
    stop: Mapping[str, object] | None = None
    approval: bool = False
    lines: Mapping[str, int] = field(default_factory=dict, compare=False, repr=False)
    source: str = field(default="", compare=False, repr=False)

    def where(self, key: str = "") -> str:
        """``FILE line N: /topic`` for the key, for errors.

        A key not found in the text (``bounds.linear.x`` written in an inline table)
        names the line of the nearest key around it (``bounds``), else its table's.
        """
        parts = key.split(".")
        found = (self.lines.get(".".join(parts[:end])) for end in range(len(parts), 0, -1))
        line = next((each for each in found if each), None) or self.lines.get("")
        place = self.source or "safety rules"
        return f"{place} line {line}: {self.name}" if line else f"{place}: {self.name}"


@dataclass(frozen=True)
class CallRule:
    """A service or action an MCP agent calls only with a person's approval.

    Attributes:
        name: the service or action (resolved).
        approval: whether a person must approve each call.
        lines: the line of each key in its file.
    """

    name: str
    approval: bool = True
    lines: Mapping[str, int] = field(default_factory=dict, compare=False, repr=False)


@dataclass(frozen=True)
class SafetyRules:
    """Every rule of one envelope (docs/safety.md).

    Attributes:
        topics: one rule per bounded topic.
        services: services whose calls need approval.
        actions: actions whose goals need approval.
        approval_timeout_s: seconds a person has to answer (then: nothing done).
        source: the file the rules came from, for errors ("" when built in Python).
    """

    topics: tuple[TopicRule, ...] = ()
    services: tuple[CallRule, ...] = ()
    actions: tuple[CallRule, ...] = ()
    approval_timeout_s: float = APPROVAL_TIMEOUT_S
    source: str = field(default="", compare=False)

    def topic(self, name: str) -> TopicRule | None:
        """The rule of topic ``name`` (any spelling), or None."""
        resolved = resolve_name(name)
        return next((rule for rule in self.topics if rule.name == resolved), None)

    def needs_approval(self, family: str, name: str) -> bool:
        """Whether a call on ``name`` of ``family`` (topics, services, actions) needs a person."""
        resolved = resolve_name(name)
        rules: tuple[TopicRule | CallRule, ...] = ()
        if family == "topics":
            rules = self.topics
        elif family in ("services", "actions"):
            rules = self.services if family == "services" else self.actions
        return any(rule.name == resolved and rule.approval for rule in rules)


def load_rules(path: Path | str) -> SafetyRules:
    """Read a rules file (``parse_rules`` of its text).

    Raises:
        RulesError: it cannot be read, or ``parse_rules`` refuses it.
    """
    source = str(path)
    try:
        text = Path(path).read_text("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.reason if isinstance(exc, UnicodeDecodeError) else exc.strerror
        raise RulesError(f"cannot read {source}: {reason}") from None
    return parse_rules(text, source)


def parse_rules(text: str, source: str = "safety rules") -> SafetyRules:
    """The rules of a TOML text, their shape checked (not yet against message types).

    Args:
        text: the file's text.
        source: its name in errors.

    Raises:
        RulesError: the text is not TOML, or a key, a value or a table is wrong;
            the text names ``source`` and the line.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RulesError(_toml_error(source, str(exc))) from None
    lines = _KeyLines(text)
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise RulesError(f"{_at(source, lines.top(unknown[0]))}unknown key {unknown[0]!r}")
    timeout = data.get("approval_timeout_s", APPROVAL_TIMEOUT_S)
    if not _number(timeout) or not 0 < timeout <= MAX_APPROVAL_TIMEOUT_S:
        where = _at(source, lines.top("approval_timeout_s"))
        raise RulesError(f"{where}approval_timeout_s: a number of seconds in (0, 3600]")
    tables = {kind: _tables(data, kind, source, lines) for kind in ("topic", "service", "action")}
    if sum(len(each) for each in tables.values()) > MAX_RULES:
        raise RulesError(f"{source}: more than {MAX_RULES} tables")
    topics = tuple(
        _topic(table, source, lines.of("topic", index))
        for index, table in enumerate(tables["topic"])
    )
    services = tuple(
        _call(table, "service", source, lines.of("service", index))
        for index, table in enumerate(tables["service"])
    )
    actions = tuple(
        _call(table, "action", source, lines.of("action", index))
        for index, table in enumerate(tables["action"])
    )
    for kind, rules in (("topic", topics), ("service", services), ("action", actions)):
        _no_twice(kind, rules, source)
    return SafetyRules(topics, services, actions, float(timeout), source)


def _tables(
    data: dict[str, object], kind: str, source: str, lines: _KeyLines
) -> list[dict[str, object]]:
    value = data.get(kind, [])
    if not isinstance(value, list) or not all(isinstance(each, dict) for each in value):
        raise RulesError(f"{_at(source, lines.top(kind))}{kind}: tables ([[{kind}]])")
    return value


def _topic(table: dict[str, object], source: str, lines: dict[str, int]) -> TopicRule:
    """One ``[[topic]]`` table, its shape checked."""
    name = _name(table, "topic", source, lines)

    def fail(key: str, problem: str) -> RulesError:
        return RulesError(f"{_at(source, lines.get(key) or lines.get(''))}{name}: {problem}")

    _no_unknown(table, _TOPIC_KEYS, fail)
    type_name = table.get("type")
    if not isinstance(type_name, str) or not type_name:
        raise fail("type", "type: a message type (pkg/msg/Type) is needed")
    given = table.get("on_violation", "reject")
    if given not in ("clamp", "reject"):
        raise fail("on_violation", f"on_violation: clamp or reject, not {given!r}")
    violation: Violation = "clamp" if given == "clamp" else "reject"
    rate = _positive(table, "max_rate_hz", fail)
    deadman = _positive(table, "deadman_s", fail)
    stop = table.get("stop")
    if stop is not None and not isinstance(stop, dict):
        raise fail("stop", "stop: a table (the message to publish)")
    if deadman is not None and stop is None:
        raise fail("deadman_s", "deadman_s needs stop (the message the dead-man publishes)")
    if stop is not None and deadman is None:
        raise fail("stop", "stop is the dead-man's message: add deadman_s")
    approval = table.get("approval", False)
    if not isinstance(approval, bool):
        raise fail("approval", "approval: true or false")
    return TopicRule(
        name,
        type_name,
        _bounds(table.get("bounds", {}), fail),
        violation,
        rate,
        deadman,
        stop,
        approval,
        lines,
        source,
    )


def _bounds(value: object, fail: _Fail) -> dict[str, tuple[float, float]]:
    if not isinstance(value, dict):
        raise fail("bounds", "bounds: a table of field = [min, max]")
    bounds: dict[str, tuple[float, float]] = {}
    for path, pair in value.items():
        key = f"bounds.{path}"
        if not isinstance(pair, list) or len(pair) != 2 or not all(_number(v) for v in pair):
            raise fail(key, f"bounds {path!r}: [min, max], two numbers")
        low, high = float(pair[0]), float(pair[1])
        if not (math.isfinite(low) and math.isfinite(high)) or low > high:
            raise fail(key, f"bounds {path!r}: finite numbers with min <= max, not {pair}")
        bounds[path] = (low, high)
    return bounds


def _call(table: dict[str, object], kind: str, source: str, lines: dict[str, int]) -> CallRule:
    """One ``[[service]]`` or ``[[action]]`` table."""
    name = _name(table, kind, source, lines)

    def fail(key: str, problem: str) -> RulesError:
        return RulesError(f"{_at(source, lines.get(key) or lines.get(''))}{name}: {problem}")

    _no_unknown(table, _CALL_KEYS, fail)
    approval = table.get("approval", True)
    if not isinstance(approval, bool):
        raise fail("approval", "approval: true or false")
    return CallRule(name, approval, lines)


def _name(table: dict[str, object], kind: str, source: str, lines: dict[str, int]) -> str:
    name = table.get("name")
    where = _at(source, lines.get("name") or lines.get(""))
    if not isinstance(name, str):
        raise RulesError(f"{where}[[{kind}]]: name: a {kind} name is needed")
    problem = name_problem(name)
    if problem is not None:
        raise RulesError(f"{where}[[{kind}]]: name {name!r}: {problem}")
    return resolve_name(name)


def _no_unknown(table: dict[str, object], known: frozenset[str], fail: _Fail) -> None:
    for key in table:
        if key not in known:
            raise fail(key, f"unknown key {key!r} (known: {', '.join(sorted(known))})")


def _positive(table: dict[str, object], key: str, fail: _Fail) -> float | None:
    value = table.get(key)
    if value is None:
        return None
    if not isinstance(value, int | float) or isinstance(value, bool):
        raise fail(key, f"{key}: a positive number, not {value!r}")
    if not (math.isfinite(value) and value > 0):
        raise fail(key, f"{key}: a positive number, not {value!r}")
    return float(value)


def _no_twice(kind: str, rules: tuple[TopicRule | CallRule, ...], source: str) -> None:
    seen: set[str] = set()
    for rule in rules:
        if rule.name in seen:
            raise RulesError(f"{_at(source, rule.lines.get(''))}{rule.name}: a second [[{kind}]]")
        seen.add(rule.name)


def _number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _at(source: str, line: int | None) -> str:
    return f"{source} line {line}: " if line else f"{source}: "


_TOML_AT = re.compile(r"\s*\(at line (\d+), column (\d+)\)$")
_TOML_END = re.compile(r"\s*\(at end of document\)$")


def _toml_error(source: str, text: str) -> str:
    """The TOML reader's text, ``Invalid value (at line 3, column 10)``, as ``FILE line 3: ...``."""
    found = _TOML_AT.search(text)
    if found is not None:
        reason = text[: found.start()]
        return f"{source} line {found[1]}: {reason[:1].lower()}{reason[1:]} (column {found[2]})"
    reason = _TOML_END.sub("", text)
    return f"{source}: {reason[:1].lower()}{reason[1:]} (at the end of the file)"


_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?")
_KEY = re.compile(
    r"""^\s*((?:"[^"]*"|'[^']*'|[A-Za-z0-9_-]+)(?:\s*\.\s*(?:"[^"]*"|'[^']*'|[A-Za-z0-9_-]+))*)\s*="""
)
_PART = re.compile(r"""\s*("[^"]*"|'[^']*'|[A-Za-z0-9_-]+)\s*(?:\.|$)""")


class _KeyLines:
    """Where each key of a rules file is: ``of(kind, index)[key]`` is its line (1-based).

    A best effort from the text, for error messages: a table's keys by their
    dotted path within it (``bounds.linear.x``), its header as ``""``. A key
    inside a multi-line value is not found; the error then names its table's line.
    """

    def __init__(self, text: str) -> None:
        self._top: dict[str, int] = {}
        self._tables: dict[tuple[str, int], dict[str, int]] = {}
        counts: dict[str, int] = {}
        current: dict[str, int] = self._top
        prefix = ""
        for number, line in enumerate(text.splitlines(), 1):
            header = _HEADER.match(line)
            if header is not None:
                parts = _parts(header[2])
                if header[1] == "[[" and len(parts) == 1:
                    kind = parts[0]
                    index = counts.get(kind, 0)
                    counts[kind] = index + 1
                    current = self._tables.setdefault((kind, index), {"": number})
                    prefix = ""
                elif parts and (parts[0], counts.get(parts[0], 0) - 1) in self._tables:
                    current = self._tables[(parts[0], counts[parts[0]] - 1)]
                    prefix = ".".join(parts[1:]) + "."
                    current.setdefault(prefix[:-1], number)
                continue
            key = _KEY.match(line)
            if key is not None:
                current.setdefault(prefix + ".".join(_parts(key[1])), number)

    def top(self, key: str) -> int | None:
        """The line of a top-level key."""
        return self._top.get(key)

    def of(self, kind: str, index: int) -> dict[str, int]:
        """The lines of the ``index``-th ``[[kind]]`` table's keys."""
        return self._tables.get((kind, index), {})


def _parts(dotted: str) -> list[str]:
    return [part.strip("\"'") for part in _PART.findall(dotted)]
